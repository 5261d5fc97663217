//! The shot engine's protocol-neutral vocabulary: what an app asks of it
//! ([`ShotRequest`]) and what it tells the app ([`ShotEvent`]), and the fixed-size
//! bus samples that carry them ([`ShotRequestSample`], [`ShotEventSample`]).
//!
//! A gateway translates its own wire protocol into requests and the engine's events
//! back (solo-gateway: the Solo app protocol, both ways), so the engine never sees a
//! protocol's bytes and any protocol that can express a request can drive a shot.
//!
//! # Encoding
//! A sample holds a kind tag (`kind`, one per variant, stable: never reused) and
//! the variant's fields in declaration order, little-endian, packed, in `body`
//! (`len` bytes of it). Floats must be finite, latitudes within ±90° and longitudes
//! within ±180°, the body exactly as long as its kind needs (text: any length up to
//! the capacity, lossy UTF-8). Encoding and decoding live here only; a change of a
//! kind's fields needs a new kind tag or a new `type_name` version.

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;

/// Bytes of body a sample carries: every request and event fits, error text is cut
/// to it by the encoder (at a character boundary).
pub const SHOT_BODY_CAPACITY: usize = 240;

/// Shot indices on the bus. They are numbered as the Solo app protocol numbers
/// them (so solo-gateway passes them through unchanged); other gateways map their
/// own shots onto these. The Site Scan shots have no index ([`crate::ShotStatus`]
/// numbers them 100..=102).
pub mod shots {
    pub const NONE: i32 = -1;
    pub const SELFIE: i32 = 0;
    pub const ORBIT: i32 = 1;
    pub const CABLECAM: i32 = 2;
    pub const ZIPLINE: i32 = 3;
    pub const FOLLOW: i32 = 5;
    pub const MULTIPOINT: i32 = 6;
    pub const PANO: i32 = 7;
    pub const REWIND: i32 = 8;
    pub const TRANSECT: i32 = 9;
    pub const RTL: i32 = 10;

    pub const MIN: i32 = NONE;
    pub const MAX: i32 = RTL;

    /// A stable label for logs and metrics; `None` outside `MIN..=MAX`. (4 is the
    /// Solo's "record" shot, which no app enters and skymesh does not fly.)
    pub fn name(shot: i32) -> Option<&'static str> {
        Some(match shot {
            NONE => "none",
            SELFIE => "selfie",
            ORBIT => "orbit",
            CABLECAM => "cablecam",
            ZIPLINE => "zipline",
            4 => "record",
            FOLLOW => "follow",
            MULTIPOINT => "multipoint",
            PANO => "pano",
            REWIND => "rewind",
            TRANSECT => "transect",
            RTL => "rtl",
            _ => return None,
        })
    }
}

/// A position: WGS-84 degrees, altitude in metres (relative to home unless the
/// request says otherwise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f32,
}

impl Location {
    /// Finite coordinates within ±90° / ±180°, finite altitude: what a sample
    /// carrying it must hold.
    pub fn validate(&self) -> Result<(), ShotDecodeError> {
        check_lat("latitude", self.lat_deg)?;
        check_lon("longitude", self.lon_deg)?;
        check_f32("altitude", self.alt_m)?;
        Ok(())
    }
}

/// A controller button mapping: `button` and `event` as [`crate::Button`] and
/// [`crate::ButtonEventKind`] number them, `shot` a [`shots`] index, `mode` an
/// ArduCopter mode number (−1 none).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ButtonSetting {
    pub button: i32,
    pub event: i32,
    pub shot: i32,
    pub mode: i32,
}

/// A keypoint of a multipoint (spline) path, both ways: the app records or edits
/// one, the engine answers with it and its `status` (0 ok, negative refused).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplinePoint {
    pub version: i16,
    pub abs_alt_ref_m: f32,
    pub index: i32,
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f32,
    pub pitch_deg: f32,
    pub yaw_deg: f32,
    pub u_position: f32,
    pub status: i16,
}

/// The GoPro's state as the engine reports it (HERO4 fields; `extra_*` reserved).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GoProState {
    pub version: u8,
    pub model: u8,
    pub status: u8,
    pub recording: u8,
    pub capture_mode: u8,
    pub ntsc_pal: u8,
    pub video_resolution: u8,
    pub video_fps: u8,
    pub video_fov: u8,
    pub video_low_light: u8,
    pub photo_resolution: u8,
    pub photo_burst_rate: u8,
    pub video_protune: u8,
    pub video_white_balance: u8,
    pub video_color: u8,
    pub video_gain: u8,
    pub video_sharpness: u8,
    pub video_exposure: u8,
    pub gimbal_enabled: u8,
    pub extra_u8: [u8; 7],
    pub extra_u16: [u16; 5],
}

/// What an app asks of the shot engine. Speeds are m/s, angles degrees.
#[derive(Debug, Clone, PartialEq)]
pub enum ShotRequest {
    /// Start the shot with this [`shots`] index ([`shots::NONE`]: end the shot).
    StartShot(i32),
    /// A position for the shot: the region of interest, a corner, the target (on
    /// the follow stream, see [`request_flags::FOLLOW_STREAM`]).
    Location(Location),
    /// Record the vehicle's position as the next point (cable cam).
    RecordPosition,
    /// Cable cam: `cam_interpolation` 1 on / 0 off, `yaw_direction_cw` 1 clockwise.
    CableOptions {
        cam_interpolation: u16,
        yaw_direction_cw: u16,
        cruise_speed: f32,
    },
    /// Ask for a button's mapping (answered by [`ShotEvent::ButtonSetting`]).
    GetButtonSetting(ButtonSetting),
    SetButtonSetting(ButtonSetting),
    /// Toggle pause of the running shot.
    Pause,
    /// Follow: `look_at` 1 yes / 0 no.
    FollowOptions {
        cruise_speed: f32,
        look_at: i32,
    },
    /// Follow with a preference: 0 hold angle, 1 free look, 2 leash.
    FollowOptionsV2 {
        cruise_speed: f32,
        look_at: i32,
        follow_preference: i32,
    },
    /// The running shot's cruise speed (negative is valid: cable cam direction).
    ShotOptions {
        cruise_speed: f32,
    },
    /// 0 off, 1 on.
    GoProSetEnabled(u32),
    GoProSetRequest {
        command: u16,
        value: u16,
    },
    GoProSetExtendedRequest {
        command: u16,
        value: [u8; 4],
    },
    /// 0 stop, 1 start, 2 toggle.
    GoProRecord(u32),
    /// Ask for the GoPro state (answered by the state events).
    GoProRequestState,
    /// Multipoint: add or edit a keypoint (answered with the keypoint).
    SplinePoint(SplinePoint),
    /// `action` 0 update, 1 add, 2 remove a vertex.
    GeofenceUpdatePoly {
        action: u8,
        polygon_index: u16,
        vertex_index: u16,
        lat_deg: f64,
        lon_deg: f64,
        sub_lat_deg: f64,
        sub_lon_deg: f64,
    },
    GeofenceClear,
    SplineRecord,
    SplinePlay,
    /// `cruise_state` −1 toward the start, 0 paused, 1 toward the end.
    SplineSeek {
        u_position: f32,
        cruise_state: i32,
    },
    /// `camera_control` 0 the engine points the camera, 1 the pilot does.
    SplinePathSettings {
        camera_control: u32,
        desired_time_s: f32,
    },
    /// Attach to the path at this keypoint.
    SplineAttach(u32),
    /// `is_3d` 1 yes, `cam_pointing` 1 spot lock / 0 free look.
    ZiplineOptions {
        cruise_speed: f32,
        is_3d: u8,
        cam_pointing: u8,
    },
    ZiplineLock,
    /// `pano_type` 0 cylinder, 1 sphere, 2 video; `run_state` 0 setup, 1 run.
    PanoOptions {
        pano_type: u8,
        run_state: u8,
        cylinder_fov: i16,
        deg_second_yaw: f32,
        lens_fov: f32,
    },
    RewindOptions {
        enabled: u8,
        hover: u8,
        rewind_distance: f32,
    },
    /// Move the vehicle's home here (horizontally).
    HomeLocation(Location),
    InspectStart {
        takeoff_alt_m: f32,
    },
    InspectSetWaypoint {
        lat_deg: f32,
        lon_deg: f32,
        alt_m: f32,
    },
    InspectMoveGimbal {
        pitch_deg: f32,
        roll_deg: f32,
        yaw_deg: f32,
    },
    /// Body-frame NED velocity, m/s.
    InspectMoveVehicle {
        vx: f32,
        vy: f32,
        vz: f32,
    },
    ScanStart,
    SurveyStart,
}

/// What the shot engine tells the app.
#[derive(Debug, Clone, PartialEq)]
pub enum ShotEvent {
    /// The shot now running ([`shots`] index, [`shots::NONE`] none).
    CurrentShot(i32),
    /// A shot was refused: 0 bad position estimate, 1 unarmed, 2 returning home.
    Refused(u32),
    /// A readable explanation of something the engine did not do.
    Error(String),
    /// The shot's region of interest (or corner) as the engine uses it.
    Location(Location),
    /// The vehicle's home.
    HomeLocation(Location),
    /// A button's mapping (answer to [`ShotRequest::GetButtonSetting`]).
    ButtonSetting(ButtonSetting),
    /// The shot was paused.
    Pause,
    CableOptions {
        cam_interpolation: u16,
        yaw_direction_cw: u16,
        cruise_speed: f32,
    },
    FollowOptions {
        cruise_speed: f32,
        look_at: i32,
    },
    FollowOptionsV2 {
        cruise_speed: f32,
        look_at: i32,
        follow_preference: i32,
    },
    ShotOptions {
        cruise_speed: f32,
    },
    PanoOptions {
        pano_type: u8,
        run_state: u8,
        cylinder_fov: i16,
        deg_second_yaw: f32,
        lens_fov: f32,
    },
    ZiplineOptions {
        cruise_speed: f32,
        is_3d: u8,
        cam_pointing: u8,
    },
    RewindOptions {
        enabled: u8,
        hover: u8,
        rewind_distance: f32,
    },
    /// Pano progress: picture `index` of `total`.
    PanoState {
        index: u8,
        total: u8,
    },
    /// The GoPro state in its first (version 1) form.
    GoProV1State(GoProState),
    /// The GoPro state in its current form.
    GoProV2State(GoProState),
    /// The geofence now holds `count` polygons; `valid` false: the request was refused.
    GeofenceSetAck {
        count: u16,
        valid: bool,
    },
    /// The vehicle reached the geofence.
    GeofenceActivated,
    /// The app's geofence is gone.
    GeofenceClear,
    /// A recorded cable cam point.
    CableCamWaypoint {
        lat_deg: f64,
        lon_deg: f64,
        alt_m: f32,
        yaw_deg: f32,
        pitch_deg: f32,
    },
    SplinePoint(SplinePoint),
    SplinePlay,
    SplinePlaybackStatus {
        u_position: f32,
        cruise_state: i32,
    },
    SplineDurations {
        min_time_s: f32,
        max_time_s: f32,
    },
    SplineAttach(u32),
}

/// A sample body that does not decode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShotDecodeError {
    #[error("unknown kind {0}")]
    UnknownKind(u16),
    #[error("kind {kind}: body of {len} bytes, expected {expected}")]
    WrongLength {
        kind: u16,
        len: usize,
        expected: usize,
    },
    #[error("{0}")]
    Invalid(String),
}

/// Flag bits of [`ShotRequestSample::flags`].
pub mod request_flags {
    /// The request came on the app's follow stream (target positions), not its
    /// control connection.
    pub const FOLLOW_STREAM: u32 = 0x01;
}

/// One [`ShotRequest`] on the bus (gateway → shot engine).
///
/// Topic: [`crate::topics::shot_requests`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ShotRequestSample.v1")]
#[repr(C)]
pub struct ShotRequestSample {
    pub header: SampleHeader,
    /// The app connection it came from (1, 2, …; follow-stream requests carry the
    /// session of the connected app, or 0 with none).
    pub session: u32,
    /// See [`request_flags`].
    pub flags: u32,
    /// Which [`ShotRequest`] (see the encoding in the module docs).
    pub kind: u16,
    /// Bytes of `body` in use.
    pub len: u16,
    pub reserved: u32,
    pub body: [u8; SHOT_BODY_CAPACITY],
}
crate::assert_layout!(
    ShotRequestSample,
    size = 24 + 16 + SHOT_BODY_CAPACITY,
    align = 8
);

/// One [`ShotEvent`] on the bus (shot engine → gateways).
///
/// Topic: [`crate::topics::shot_events`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ShotEventSample.v1")]
#[repr(C)]
pub struct ShotEventSample {
    pub header: SampleHeader,
    /// 0 = whichever app is connected now, else only that session.
    pub session: u32,
    pub reserved: u32,
    /// Which [`ShotEvent`].
    pub kind: u16,
    /// Bytes of `body` in use.
    pub len: u16,
    pub reserved2: u32,
    pub body: [u8; SHOT_BODY_CAPACITY],
}
crate::assert_layout!(
    ShotEventSample,
    size = 24 + 16 + SHOT_BODY_CAPACITY,
    align = 8
);

crate::impl_sample!(ShotRequestSample, ShotEventSample);

impl Default for ShotRequestSample {
    fn default() -> Self {
        ShotRequestSample {
            header: SampleHeader::default(),
            session: 0,
            flags: 0,
            kind: 0,
            len: 0,
            reserved: 0,
            body: [0; SHOT_BODY_CAPACITY],
        }
    }
}

impl Default for ShotEventSample {
    fn default() -> Self {
        ShotEventSample {
            header: SampleHeader::default(),
            session: 0,
            reserved: 0,
            kind: 0,
            len: 0,
            reserved2: 0,
            body: [0; SHOT_BODY_CAPACITY],
        }
    }
}

impl ShotRequestSample {
    /// `request` from app `session`.
    pub fn new(session: u32, request: &ShotRequest) -> Self {
        let mut w = Writer::default();
        let kind = request.encode(&mut w);
        ShotRequestSample {
            session,
            kind,
            len: w.len as u16,
            body: w.buf,
            ..Default::default()
        }
    }

    /// The request, checked (a `len` beyond capacity is refused).
    pub fn request(&self) -> Result<ShotRequest, ShotDecodeError> {
        let mut r = Reader::new(self.kind, &self.body, self.len)?;
        let m = ShotRequest::decode(self.kind, &mut r)?;
        r.finish(m)
    }

    pub fn is_follow_stream(&self) -> bool {
        self.flags & request_flags::FOLLOW_STREAM != 0
    }
}

impl ShotEventSample {
    /// `event` for app `session` (0: whichever is connected).
    pub fn new(session: u32, event: &ShotEvent) -> Self {
        let mut w = Writer::default();
        let kind = event.encode(&mut w);
        ShotEventSample {
            session,
            kind,
            len: w.len as u16,
            body: w.buf,
            ..Default::default()
        }
    }

    /// The event, checked.
    pub fn event(&self) -> Result<ShotEvent, ShotDecodeError> {
        let mut r = Reader::new(self.kind, &self.body, self.len)?;
        let m = ShotEvent::decode(self.kind, &mut r)?;
        r.finish(m)
    }
}

mod body;
mod codec;

use body::{check_f32, check_lat, check_lon, Reader, Writer};

#[cfg(test)]
mod tests;
