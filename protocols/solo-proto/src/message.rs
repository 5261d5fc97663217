//! [`SoloMessage`]: every message of the protocol as one value, with its type id,
//! name, encoding and decoding. The field layouts live in the family files.

use bytes::{BufMut, Bytes, BytesMut};

use crate::catalog::{self, Family};
use crate::error::DecodeError;
use crate::general::{ButtonSetting, Location};
use crate::geofence::GeofenceData;
use crate::gopro::GoProState;
use crate::spline::SplinePoint;
use crate::wire::{name_of, Reader};
use crate::{general, geofence, gopro, ids, options, sitescan, spline, HEADER_LEN};

/// One decoded Solo message. Field units are in their names (`_deg`, `_m`, `_s`);
/// speeds are m/s. Values built by hand are not checked until
/// [`SoloMessage::validate`] or the peer's decode.
#[derive(Debug, Clone, PartialEq)]
pub enum SoloMessage {
    /// ShotManager → app: the shot now running ([`crate::shots`], −1 none).
    GetCurrentShot(i32),
    /// App → ShotManager: start this shot.
    SetCurrentShot(i32),
    Location(Location),
    RecordPosition,
    /// `cam_interpolation` 1 on / 0 off, `yaw_direction_cw` 1 clockwise / 0 ccw.
    CableCamOptions {
        cam_interpolation: u16,
        yaw_direction_cw: u16,
        cruise_speed: f32,
    },
    GetButtonSetting(ButtonSetting),
    SetButtonSetting(ButtonSetting),
    Pause,
    /// `look_at` 1 yes / 0 no.
    FollowOptions {
        cruise_speed: f32,
        look_at: i32,
    },
    /// `follow_preference` 0 hold angle, 1 free look, 2 leash.
    FollowOptionsV2 {
        cruise_speed: f32,
        look_at: i32,
        follow_preference: i32,
    },
    /// Negative speeds are valid (cable cam direction).
    ShotOptions {
        cruise_speed: f32,
    },
    /// 0 bad EKF, 1 unarmed, 2 RTL.
    ShotError(u32),
    /// `pano_type` 0 cylinder, 1 sphere, 2 video; `run_state` 0 setup, 1 run.
    PanoOptions {
        pano_type: u8,
        run_state: u8,
        cylinder_fov: i16,
        deg_second_yaw: f32,
        lens_fov: f32,
    },
    /// `is_3d` 1 yes / 0 no, `cam_pointing` 1 spot lock / 0 free look.
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
    PanoState {
        index: u8,
        total: u8,
    },
    HomeLocation(Location),
    ZiplineLock,
    SplineRecord,
    SplinePlay,
    SplinePoint(SplinePoint),
    /// `cruise_state` −1 toward the start, 0 paused, 1 toward the end.
    SplineSeek {
        u_position: f32,
        cruise_state: i32,
    },
    SplinePlaybackStatus {
        u_position: f32,
        cruise_state: i32,
    },
    /// `camera_control` 0 ShotManager points the camera, 1 Artoo only.
    SplinePathSettings {
        camera_control: u32,
        desired_time_s: f32,
    },
    SplineDurations {
        min_time_s: f32,
        max_time_s: f32,
    },
    /// Keypoint index to attach to (or attached to, from ShotManager).
    SplineAttach(u32),
    /// Exception text; decoded as lossy UTF-8.
    ShotManagerError(String),
    CableCamWaypoint {
        lat_deg: f64,
        lon_deg: f64,
        alt_m: f32,
        yaw_deg: f32,
        pitch_deg: f32,
    },
    SecondPhoneNotification,
    GeofenceSetData(GeofenceData),
    GeofenceSetAck {
        count: u16,
        valid: bool,
    },
    /// `action` 0 update, 1 add, 2 remove a vertex (coordinates ignored for remove).
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
    GeofenceActivated,
    /// 0 off, 1 on.
    GoProSetEnabled(u32),
    GoProSetRequest {
        command: u16,
        value: u16,
    },
    /// 0 stop, 1 start, 2 toggle.
    GoProRecord(u32),
    GoProV1State(GoProState),
    GoProV2State(GoProState),
    GoProRequestState,
    GoProSetExtendedRequest {
        command: u16,
        value: [u8; 4],
    },
    GoProPhoto {
        lat_deg: f64,
        lon_deg: f64,
        alt_m: f32,
        time: u32,
    },
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

impl SoloMessage {
    /// The type id on the wire ([`crate::ids`]).
    pub fn msg_type(&self) -> u32 {
        use SoloMessage as M;
        match self {
            M::GetCurrentShot(_) => ids::GET_CURRENT_SHOT,
            M::SetCurrentShot(_) => ids::SET_CURRENT_SHOT,
            M::Location(_) => ids::LOCATION,
            M::RecordPosition => ids::RECORD_POSITION,
            M::CableCamOptions { .. } => ids::CABLE_CAM_OPTIONS,
            M::GetButtonSetting(_) => ids::GET_BUTTON_SETTING,
            M::SetButtonSetting(_) => ids::SET_BUTTON_SETTING,
            M::Pause => ids::PAUSE,
            M::FollowOptions { .. } => ids::FOLLOW_OPTIONS,
            M::FollowOptionsV2 { .. } => ids::FOLLOW_OPTIONS_V2,
            M::ShotOptions { .. } => ids::SHOT_OPTIONS,
            M::ShotError(_) => ids::SHOT_ERROR,
            M::PanoOptions { .. } => ids::PANO_OPTIONS,
            M::ZiplineOptions { .. } => ids::ZIPLINE_OPTIONS,
            M::RewindOptions { .. } => ids::REWIND_OPTIONS,
            M::PanoState { .. } => ids::PANO_STATE,
            M::HomeLocation(_) => ids::HOME_LOCATION,
            M::ZiplineLock => ids::ZIPLINE_LOCK,
            M::SplineRecord => ids::SPLINE_RECORD,
            M::SplinePlay => ids::SPLINE_PLAY,
            M::SplinePoint(_) => ids::SPLINE_POINT,
            M::SplineSeek { .. } => ids::SPLINE_SEEK,
            M::SplinePlaybackStatus { .. } => ids::SPLINE_PLAYBACK_STATUS,
            M::SplinePathSettings { .. } => ids::SPLINE_PATH_SETTINGS,
            M::SplineDurations { .. } => ids::SPLINE_DURATIONS,
            M::SplineAttach(_) => ids::SPLINE_ATTACH,
            M::ShotManagerError(_) => ids::SHOTMANAGER_ERROR,
            M::CableCamWaypoint { .. } => ids::CABLE_CAM_WAYPOINT,
            M::SecondPhoneNotification => ids::SECOND_PHONE_NOTIFICATION,
            M::GeofenceSetData(_) => ids::GEOFENCE_SET_DATA,
            M::GeofenceSetAck { .. } => ids::GEOFENCE_SET_ACK,
            M::GeofenceUpdatePoly { .. } => ids::GEOFENCE_UPDATE_POLY,
            M::GeofenceClear => ids::GEOFENCE_CLEAR,
            M::GeofenceActivated => ids::GEOFENCE_ACTIVATED,
            M::GoProSetEnabled(_) => ids::GOPRO_SET_ENABLED,
            M::GoProSetRequest { .. } => ids::GOPRO_SET_REQUEST,
            M::GoProRecord(_) => ids::GOPRO_RECORD,
            M::GoProV1State(_) => ids::GOPRO_V1_STATE,
            M::GoProV2State(_) => ids::GOPRO_V2_STATE,
            M::GoProRequestState => ids::GOPRO_REQUEST_STATE,
            M::GoProSetExtendedRequest { .. } => ids::GOPRO_SET_EXTENDED_REQUEST,
            M::GoProPhoto { .. } => ids::GOPRO_PHOTO,
            M::InspectStart { .. } => ids::INSPECT_START,
            M::InspectSetWaypoint { .. } => ids::INSPECT_SET_WAYPOINT,
            M::InspectMoveGimbal { .. } => ids::INSPECT_MOVE_GIMBAL,
            M::InspectMoveVehicle { .. } => ids::INSPECT_MOVE_VEHICLE,
            M::ScanStart => ids::SCAN_START,
            M::SurveyStart => ids::SURVEY_START,
        }
    }

    /// Stable snake_case label (`"location"`, `"gopro_v2_state"`), for metrics.
    pub fn name(&self) -> &'static str {
        name_of(self.msg_type())
    }

    /// Writes the value only (no header), little-endian, at its exact length.
    pub fn encode_value(&self, dst: &mut BytesMut) {
        match catalog::entry(self.msg_type()).map(|e| e.family) {
            Some(Family::General) => general::encode(self, dst),
            Some(Family::Options) => options::encode(self, dst),
            Some(Family::Spline) => spline::encode(self, dst),
            Some(Family::GoPro) => gopro::encode(self, dst),
            Some(Family::Geofence) => geofence::encode(self, dst),
            Some(Family::SiteScan) => sitescan::encode(self, dst),
            // Every variant's id is in the catalog (tested).
            None => debug_assert!(false, "{self:?} has no catalog entry"),
        }
    }

    /// Writes header and value.
    pub fn encode(&self, dst: &mut BytesMut) {
        let start = dst.len();
        dst.reserve(HEADER_LEN);
        dst.put_u32_le(self.msg_type());
        dst.put_u32_le(0);
        self.encode_value(dst);
        let value_len = dst.len() - start - HEADER_LEN;
        // A value longer than u32::MAX cannot be built from a String the peer would
        // accept anyway; saturate rather than wrap so the peer refuses it as too long.
        let declared = u32::try_from(value_len).unwrap_or(u32::MAX);
        dst[start + 4..start + HEADER_LEN].copy_from_slice(&declared.to_le_bytes());
    }

    /// Header and value as one buffer.
    pub fn to_bytes(&self) -> Bytes {
        let mut dst = BytesMut::new();
        self.encode(&mut dst);
        dst.freeze()
    }

    /// The value alone as one buffer.
    pub fn value_bytes(&self) -> Bytes {
        let mut dst = BytesMut::new();
        self.encode_value(&mut dst);
        dst.freeze()
    }

    /// Reads one message from its type id and value bytes, checking the length
    /// against the catalog and every field (finite floats, coordinates, enums).
    pub fn decode(msg_type: u32, value: &[u8]) -> Result<SoloMessage, DecodeError> {
        let entry = catalog::entry(msg_type).ok_or(DecodeError::UnknownType(msg_type))?;
        if !entry.len.accepts(value.len()) {
            let expected = match entry.len {
                catalog::ValueLen::Exact(n) => n,
                catalog::ValueLen::Variable { max } => max,
            };
            return Err(DecodeError::WrongLength {
                msg_type,
                name: entry.name,
                expected,
                got: value.len(),
            });
        }
        let mut r = Reader::new(msg_type, value);
        let msg = match entry.family {
            Family::General => general::decode(&mut r)?,
            Family::Options => options::decode(&mut r)?,
            Family::Spline => spline::decode(&mut r)?,
            Family::GoPro => gopro::decode(&mut r)?,
            Family::Geofence => geofence::decode(&mut r)?,
            Family::SiteScan => sitescan::decode(&mut r)?,
        };
        r.finish(msg)
    }

    /// Checks a message built by hand the way the peer will: encodes it and decodes
    /// the bytes. The engine calls this before publishing what it built.
    pub fn validate(&self) -> Result<(), DecodeError> {
        let mut value = BytesMut::new();
        self.encode_value(&mut value);
        Self::decode(self.msg_type(), &value).map(|_| ())
    }
}
