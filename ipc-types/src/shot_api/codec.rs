//! The encoding of [`ShotRequest`] and [`ShotEvent`] bodies (see the parent
//! module's docs): one kind tag per variant, fields little-endian in declaration
//! order, checked on the way in.

use super::{
    ButtonSetting, GoProState, Location, ShotDecodeError, ShotEvent, ShotRequest, SplinePoint,
    SHOT_BODY_CAPACITY,
};

impl ShotRequest {
    /// Stable snake_case label for logs and metrics.
    pub fn name(&self) -> &'static str {
        use ShotRequest as R;
        match self {
            R::StartShot(_) => "start_shot",
            R::Location(_) => "location",
            R::RecordPosition => "record_position",
            R::CableOptions { .. } => "cable_options",
            R::GetButtonSetting(_) => "get_button_setting",
            R::SetButtonSetting(_) => "set_button_setting",
            R::Pause => "pause",
            R::FollowOptions { .. } => "follow_options",
            R::FollowOptionsV2 { .. } => "follow_options_v2",
            R::ShotOptions { .. } => "shot_options",
            R::GoProSetEnabled(_) => "gopro_set_enabled",
            R::GoProSetRequest { .. } => "gopro_set_request",
            R::GoProSetExtendedRequest { .. } => "gopro_set_extended_request",
            R::GoProRecord(_) => "gopro_record",
            R::GoProRequestState => "gopro_request_state",
            R::SplinePoint(_) => "spline_point",
            R::GeofenceUpdatePoly { .. } => "geofence_update_poly",
            R::GeofenceClear => "geofence_clear",
            R::SplineRecord => "spline_record",
            R::SplinePlay => "spline_play",
            R::SplineSeek { .. } => "spline_seek",
            R::SplinePathSettings { .. } => "spline_path_settings",
            R::SplineAttach(_) => "spline_attach",
            R::ZiplineOptions { .. } => "zipline_options",
            R::ZiplineLock => "zipline_lock",
            R::PanoOptions { .. } => "pano_options",
            R::RewindOptions { .. } => "rewind_options",
            R::HomeLocation(_) => "home_location",
            R::InspectStart { .. } => "inspect_start",
            R::InspectSetWaypoint { .. } => "inspect_set_waypoint",
            R::InspectMoveGimbal { .. } => "inspect_move_gimbal",
            R::InspectMoveVehicle { .. } => "inspect_move_vehicle",
            R::ScanStart => "scan_start",
            R::SurveyStart => "survey_start",
        }
    }

    /// Writes the fields; returns the kind tag.
    pub(super) fn encode(&self, w: &mut Writer) -> u16 {
        use ShotRequest as R;
        match self {
            R::StartShot(s) => {
                w.i32(*s);
                1
            }
            R::Location(l) => {
                w.location(l);
                2
            }
            R::RecordPosition => 3,
            R::CableOptions {
                cam_interpolation,
                yaw_direction_cw,
                cruise_speed,
            } => {
                w.u16(*cam_interpolation);
                w.u16(*yaw_direction_cw);
                w.f32(*cruise_speed);
                4
            }
            R::GetButtonSetting(b) => {
                w.button(b);
                5
            }
            R::SetButtonSetting(b) => {
                w.button(b);
                6
            }
            R::Pause => 7,
            R::FollowOptions {
                cruise_speed,
                look_at,
            } => {
                w.f32(*cruise_speed);
                w.i32(*look_at);
                8
            }
            R::FollowOptionsV2 {
                cruise_speed,
                look_at,
                follow_preference,
            } => {
                w.f32(*cruise_speed);
                w.i32(*look_at);
                w.i32(*follow_preference);
                9
            }
            R::ShotOptions { cruise_speed } => {
                w.f32(*cruise_speed);
                10
            }
            R::GoProSetEnabled(v) => {
                w.u32(*v);
                11
            }
            R::GoProSetRequest { command, value } => {
                w.u16(*command);
                w.u16(*value);
                12
            }
            R::GoProSetExtendedRequest { command, value } => {
                w.u16(*command);
                w.bytes(value);
                13
            }
            R::GoProRecord(v) => {
                w.u32(*v);
                14
            }
            R::GoProRequestState => 15,
            R::SplinePoint(p) => {
                w.spline_point(p);
                16
            }
            R::GeofenceUpdatePoly {
                action,
                polygon_index,
                vertex_index,
                lat_deg,
                lon_deg,
                sub_lat_deg,
                sub_lon_deg,
            } => {
                w.u8(*action);
                w.u16(*polygon_index);
                w.u16(*vertex_index);
                w.f64(*lat_deg);
                w.f64(*lon_deg);
                w.f64(*sub_lat_deg);
                w.f64(*sub_lon_deg);
                17
            }
            R::GeofenceClear => 18,
            R::SplineRecord => 19,
            R::SplinePlay => 20,
            R::SplineSeek {
                u_position,
                cruise_state,
            } => {
                w.f32(*u_position);
                w.i32(*cruise_state);
                21
            }
            R::SplinePathSettings {
                camera_control,
                desired_time_s,
            } => {
                w.u32(*camera_control);
                w.f32(*desired_time_s);
                22
            }
            R::SplineAttach(i) => {
                w.u32(*i);
                23
            }
            R::ZiplineOptions {
                cruise_speed,
                is_3d,
                cam_pointing,
            } => {
                w.f32(*cruise_speed);
                w.u8(*is_3d);
                w.u8(*cam_pointing);
                24
            }
            R::ZiplineLock => 25,
            R::PanoOptions {
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov,
            } => {
                w.pano(
                    *pano_type,
                    *run_state,
                    *cylinder_fov,
                    *deg_second_yaw,
                    *lens_fov,
                );
                26
            }
            R::RewindOptions {
                enabled,
                hover,
                rewind_distance,
            } => {
                w.u8(*enabled);
                w.u8(*hover);
                w.f32(*rewind_distance);
                27
            }
            R::HomeLocation(l) => {
                w.location(l);
                28
            }
            R::InspectStart { takeoff_alt_m } => {
                w.f32(*takeoff_alt_m);
                29
            }
            R::InspectSetWaypoint {
                lat_deg,
                lon_deg,
                alt_m,
            } => {
                w.f32(*lat_deg);
                w.f32(*lon_deg);
                w.f32(*alt_m);
                30
            }
            R::InspectMoveGimbal {
                pitch_deg,
                roll_deg,
                yaw_deg,
            } => {
                w.f32(*pitch_deg);
                w.f32(*roll_deg);
                w.f32(*yaw_deg);
                31
            }
            R::InspectMoveVehicle { vx, vy, vz } => {
                w.f32(*vx);
                w.f32(*vy);
                w.f32(*vz);
                32
            }
            R::ScanStart => 33,
            R::SurveyStart => 34,
        }
    }

    pub(super) fn decode(kind: u16, r: &mut Reader<'_>) -> Result<ShotRequest, ShotDecodeError> {
        use ShotRequest as R;
        Ok(match kind {
            1 => R::StartShot(r.i32()?),
            2 => R::Location(r.location()?),
            3 => R::RecordPosition,
            4 => R::CableOptions {
                cam_interpolation: r.u16()?,
                yaw_direction_cw: r.u16()?,
                cruise_speed: r.f32("cruise_speed")?,
            },
            5 => R::GetButtonSetting(r.button()?),
            6 => R::SetButtonSetting(r.button()?),
            7 => R::Pause,
            8 => R::FollowOptions {
                cruise_speed: r.f32("cruise_speed")?,
                look_at: r.i32()?,
            },
            9 => R::FollowOptionsV2 {
                cruise_speed: r.f32("cruise_speed")?,
                look_at: r.i32()?,
                follow_preference: r.i32()?,
            },
            10 => R::ShotOptions {
                cruise_speed: r.f32("cruise_speed")?,
            },
            11 => R::GoProSetEnabled(r.u32()?),
            12 => R::GoProSetRequest {
                command: r.u16()?,
                value: r.u16()?,
            },
            13 => R::GoProSetExtendedRequest {
                command: r.u16()?,
                value: r.array()?,
            },
            14 => R::GoProRecord(r.u32()?),
            15 => R::GoProRequestState,
            16 => R::SplinePoint(r.spline_point()?),
            17 => R::GeofenceUpdatePoly {
                action: r.u8()?,
                polygon_index: r.u16()?,
                vertex_index: r.u16()?,
                lat_deg: r.lat("latitude")?,
                lon_deg: r.lon("longitude")?,
                sub_lat_deg: r.lat("sub latitude")?,
                sub_lon_deg: r.lon("sub longitude")?,
            },
            18 => R::GeofenceClear,
            19 => R::SplineRecord,
            20 => R::SplinePlay,
            21 => R::SplineSeek {
                u_position: r.f32("u_position")?,
                cruise_state: r.i32()?,
            },
            22 => R::SplinePathSettings {
                camera_control: r.u32()?,
                desired_time_s: r.f32("desired_time")?,
            },
            23 => R::SplineAttach(r.u32()?),
            24 => R::ZiplineOptions {
                cruise_speed: r.f32("cruise_speed")?,
                is_3d: r.u8()?,
                cam_pointing: r.u8()?,
            },
            25 => R::ZiplineLock,
            26 => {
                let (pano_type, run_state, cylinder_fov, deg_second_yaw, lens_fov) = r.pano()?;
                R::PanoOptions {
                    pano_type,
                    run_state,
                    cylinder_fov,
                    deg_second_yaw,
                    lens_fov,
                }
            }
            27 => R::RewindOptions {
                enabled: r.u8()?,
                hover: r.u8()?,
                rewind_distance: r.f32("rewind_distance")?,
            },
            28 => R::HomeLocation(r.location()?),
            29 => R::InspectStart {
                takeoff_alt_m: r.f32("takeoff_alt")?,
            },
            30 => R::InspectSetWaypoint {
                lat_deg: r.f32("latitude")?,
                lon_deg: r.f32("longitude")?,
                alt_m: r.f32("altitude")?,
            },
            31 => R::InspectMoveGimbal {
                pitch_deg: r.f32("pitch")?,
                roll_deg: r.f32("roll")?,
                yaw_deg: r.f32("yaw")?,
            },
            32 => R::InspectMoveVehicle {
                vx: r.f32("vx")?,
                vy: r.f32("vy")?,
                vz: r.f32("vz")?,
            },
            33 => R::ScanStart,
            34 => R::SurveyStart,
            other => return Err(ShotDecodeError::UnknownKind(other)),
        })
    }
}

impl ShotEvent {
    /// Stable snake_case label for logs and metrics.
    pub fn name(&self) -> &'static str {
        use ShotEvent as E;
        match self {
            E::CurrentShot(_) => "current_shot",
            E::Refused(_) => "refused",
            E::Error(_) => "error",
            E::Location(_) => "location",
            E::HomeLocation(_) => "home_location",
            E::ButtonSetting(_) => "button_setting",
            E::Pause => "pause",
            E::CableOptions { .. } => "cable_options",
            E::FollowOptions { .. } => "follow_options",
            E::FollowOptionsV2 { .. } => "follow_options_v2",
            E::ShotOptions { .. } => "shot_options",
            E::PanoOptions { .. } => "pano_options",
            E::ZiplineOptions { .. } => "zipline_options",
            E::RewindOptions { .. } => "rewind_options",
            E::PanoState { .. } => "pano_state",
            E::GoProV1State(_) => "gopro_v1_state",
            E::GoProV2State(_) => "gopro_v2_state",
            E::GeofenceSetAck { .. } => "geofence_set_ack",
            E::GeofenceActivated => "geofence_activated",
            E::GeofenceClear => "geofence_clear",
            E::CableCamWaypoint { .. } => "cable_cam_waypoint",
            E::SplinePoint(_) => "spline_point",
            E::SplinePlay => "spline_play",
            E::SplinePlaybackStatus { .. } => "spline_playback_status",
            E::SplineDurations { .. } => "spline_durations",
            E::SplineAttach(_) => "spline_attach",
        }
    }

    /// Writes the fields; returns the kind tag.
    pub(super) fn encode(&self, w: &mut Writer) -> u16 {
        use ShotEvent as E;
        match self {
            E::CurrentShot(s) => {
                w.i32(*s);
                1
            }
            E::Refused(code) => {
                w.u32(*code);
                2
            }
            E::Error(text) => {
                w.text(text);
                3
            }
            E::Location(l) => {
                w.location(l);
                4
            }
            E::HomeLocation(l) => {
                w.location(l);
                5
            }
            E::ButtonSetting(b) => {
                w.button(b);
                6
            }
            E::Pause => 7,
            E::CableOptions {
                cam_interpolation,
                yaw_direction_cw,
                cruise_speed,
            } => {
                w.u16(*cam_interpolation);
                w.u16(*yaw_direction_cw);
                w.f32(*cruise_speed);
                8
            }
            E::FollowOptions {
                cruise_speed,
                look_at,
            } => {
                w.f32(*cruise_speed);
                w.i32(*look_at);
                9
            }
            E::FollowOptionsV2 {
                cruise_speed,
                look_at,
                follow_preference,
            } => {
                w.f32(*cruise_speed);
                w.i32(*look_at);
                w.i32(*follow_preference);
                10
            }
            E::ShotOptions { cruise_speed } => {
                w.f32(*cruise_speed);
                11
            }
            E::PanoOptions {
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov,
            } => {
                w.pano(
                    *pano_type,
                    *run_state,
                    *cylinder_fov,
                    *deg_second_yaw,
                    *lens_fov,
                );
                12
            }
            E::ZiplineOptions {
                cruise_speed,
                is_3d,
                cam_pointing,
            } => {
                w.f32(*cruise_speed);
                w.u8(*is_3d);
                w.u8(*cam_pointing);
                13
            }
            E::RewindOptions {
                enabled,
                hover,
                rewind_distance,
            } => {
                w.u8(*enabled);
                w.u8(*hover);
                w.f32(*rewind_distance);
                14
            }
            E::PanoState { index, total } => {
                w.u8(*index);
                w.u8(*total);
                15
            }
            E::GoProV1State(s) => {
                w.gopro(s);
                16
            }
            E::GoProV2State(s) => {
                w.gopro(s);
                17
            }
            E::GeofenceSetAck { count, valid } => {
                w.u16(*count);
                w.u8(u8::from(*valid));
                18
            }
            E::GeofenceActivated => 19,
            E::GeofenceClear => 20,
            E::CableCamWaypoint {
                lat_deg,
                lon_deg,
                alt_m,
                yaw_deg,
                pitch_deg,
            } => {
                w.f64(*lat_deg);
                w.f64(*lon_deg);
                w.f32(*alt_m);
                w.f32(*yaw_deg);
                w.f32(*pitch_deg);
                21
            }
            E::SplinePoint(p) => {
                w.spline_point(p);
                22
            }
            E::SplinePlay => 23,
            E::SplinePlaybackStatus {
                u_position,
                cruise_state,
            } => {
                w.f32(*u_position);
                w.i32(*cruise_state);
                24
            }
            E::SplineDurations {
                min_time_s,
                max_time_s,
            } => {
                w.f32(*min_time_s);
                w.f32(*max_time_s);
                25
            }
            E::SplineAttach(i) => {
                w.u32(*i);
                26
            }
        }
    }

    pub(super) fn decode(kind: u16, r: &mut Reader<'_>) -> Result<ShotEvent, ShotDecodeError> {
        use ShotEvent as E;
        Ok(match kind {
            1 => E::CurrentShot(r.i32()?),
            2 => E::Refused(r.u32()?),
            3 => E::Error(r.text()),
            4 => E::Location(r.location()?),
            5 => E::HomeLocation(r.location()?),
            6 => E::ButtonSetting(r.button()?),
            7 => E::Pause,
            8 => E::CableOptions {
                cam_interpolation: r.u16()?,
                yaw_direction_cw: r.u16()?,
                cruise_speed: r.f32("cruise_speed")?,
            },
            9 => E::FollowOptions {
                cruise_speed: r.f32("cruise_speed")?,
                look_at: r.i32()?,
            },
            10 => E::FollowOptionsV2 {
                cruise_speed: r.f32("cruise_speed")?,
                look_at: r.i32()?,
                follow_preference: r.i32()?,
            },
            11 => E::ShotOptions {
                cruise_speed: r.f32("cruise_speed")?,
            },
            12 => {
                let (pano_type, run_state, cylinder_fov, deg_second_yaw, lens_fov) = r.pano()?;
                E::PanoOptions {
                    pano_type,
                    run_state,
                    cylinder_fov,
                    deg_second_yaw,
                    lens_fov,
                }
            }
            13 => E::ZiplineOptions {
                cruise_speed: r.f32("cruise_speed")?,
                is_3d: r.u8()?,
                cam_pointing: r.u8()?,
            },
            14 => E::RewindOptions {
                enabled: r.u8()?,
                hover: r.u8()?,
                rewind_distance: r.f32("rewind_distance")?,
            },
            15 => E::PanoState {
                index: r.u8()?,
                total: r.u8()?,
            },
            16 => E::GoProV1State(r.gopro()?),
            17 => E::GoProV2State(r.gopro()?),
            18 => E::GeofenceSetAck {
                count: r.u16()?,
                valid: r.u8()? != 0,
            },
            19 => E::GeofenceActivated,
            20 => E::GeofenceClear,
            21 => E::CableCamWaypoint {
                lat_deg: r.lat("latitude")?,
                lon_deg: r.lon("longitude")?,
                alt_m: r.f32("altitude")?,
                yaw_deg: r.f32("yaw")?,
                pitch_deg: r.f32("pitch")?,
            },
            22 => E::SplinePoint(r.spline_point()?),
            23 => E::SplinePlay,
            24 => E::SplinePlaybackStatus {
                u_position: r.f32("u_position")?,
                cruise_state: r.i32()?,
            },
            25 => E::SplineDurations {
                min_time_s: r.f32("min_time")?,
                max_time_s: r.f32("max_time")?,
            },
            26 => E::SplineAttach(r.u32()?),
            other => return Err(ShotDecodeError::UnknownKind(other)),
        })
    }
}

pub(super) fn check_f32(field: &str, v: f32) -> Result<f32, ShotDecodeError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} is not finite ({v})"
        )))
    }
}

fn check_f64(field: &str, v: f64) -> Result<f64, ShotDecodeError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} is not finite ({v})"
        )))
    }
}

pub(super) fn check_lat(field: &str, v: f64) -> Result<f64, ShotDecodeError> {
    let v = check_f64(field, v)?;
    if (-90.0..=90.0).contains(&v) {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} {v} is outside -90..=90"
        )))
    }
}

pub(super) fn check_lon(field: &str, v: f64) -> Result<f64, ShotDecodeError> {
    let v = check_f64(field, v)?;
    if (-180.0..=180.0).contains(&v) {
        Ok(v)
    } else {
        Err(ShotDecodeError::Invalid(format!(
            "{field} {v} is outside -180..=180"
        )))
    }
}

/// Little-endian writer into a fixed body. Every fixed-size kind fits with room
/// to spare (the largest, a keypoint, is 44 bytes); text is cut to what is left.
pub(super) struct Writer {
    pub(super) buf: [u8; SHOT_BODY_CAPACITY],
    pub(super) len: usize,
}

impl Default for Writer {
    fn default() -> Self {
        Writer {
            buf: [0; SHOT_BODY_CAPACITY],
            len: 0,
        }
    }
}

impl Writer {
    fn bytes(&mut self, b: &[u8]) {
        let end = self.len + b.len();
        debug_assert!(end <= SHOT_BODY_CAPACITY, "fixed-size kinds fit");
        let end = end.min(SHOT_BODY_CAPACITY);
        let n = end - self.len;
        self.buf[self.len..end].copy_from_slice(&b[..n]);
        self.len = end;
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn i16(&mut self, v: i16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
    /// The text, cut at a character boundary to the room left.
    fn text(&mut self, text: &str) {
        let mut end = text.len().min(SHOT_BODY_CAPACITY - self.len);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.bytes(&text.as_bytes()[..end]);
    }
    fn location(&mut self, l: &Location) {
        self.f64(l.lat_deg);
        self.f64(l.lon_deg);
        self.f32(l.alt_m);
    }
    fn button(&mut self, b: &ButtonSetting) {
        self.i32(b.button);
        self.i32(b.event);
        self.i32(b.shot);
        self.i32(b.mode);
    }
    fn pano(&mut self, pano_type: u8, run_state: u8, fov: i16, rate: f32, lens: f32) {
        self.u8(pano_type);
        self.u8(run_state);
        self.i16(fov);
        self.f32(rate);
        self.f32(lens);
    }
    fn spline_point(&mut self, p: &SplinePoint) {
        self.i16(p.version);
        self.f32(p.abs_alt_ref_m);
        self.i32(p.index);
        self.f64(p.lat_deg);
        self.f64(p.lon_deg);
        self.f32(p.alt_m);
        self.f32(p.pitch_deg);
        self.f32(p.yaw_deg);
        self.f32(p.u_position);
        self.i16(p.status);
    }
    fn gopro(&mut self, s: &GoProState) {
        self.bytes(&[
            s.version,
            s.model,
            s.status,
            s.recording,
            s.capture_mode,
            s.ntsc_pal,
            s.video_resolution,
            s.video_fps,
            s.video_fov,
            s.video_low_light,
            s.photo_resolution,
            s.photo_burst_rate,
            s.video_protune,
            s.video_white_balance,
            s.video_color,
            s.video_gain,
            s.video_sharpness,
            s.video_exposure,
            s.gimbal_enabled,
        ]);
        self.bytes(&s.extra_u8);
        for v in s.extra_u16 {
            self.u16(v);
        }
    }
}

/// Little-endian reader of a body; running out is a wrong length.
pub(super) struct Reader<'a> {
    kind: u16,
    rest: &'a [u8],
    len: usize,
}

impl<'a> Reader<'a> {
    pub(super) fn new(kind: u16, body: &'a [u8], len: u16) -> Result<Self, ShotDecodeError> {
        let len = usize::from(len);
        if len > body.len() {
            return Err(ShotDecodeError::WrongLength {
                kind,
                len,
                expected: body.len(),
            });
        }
        Ok(Reader {
            kind,
            rest: &body[..len],
            len,
        })
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], ShotDecodeError> {
        if self.rest.len() < N {
            return Err(ShotDecodeError::WrongLength {
                kind: self.kind,
                len: self.len,
                expected: self.len - self.rest.len() + N,
            });
        }
        let (head, tail) = self.rest.split_at(N);
        self.rest = tail;
        let mut out = [0; N];
        out.copy_from_slice(head);
        Ok(out)
    }
    fn u8(&mut self) -> Result<u8, ShotDecodeError> {
        Ok(self.array::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, ShotDecodeError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    fn i16(&mut self) -> Result<i16, ShotDecodeError> {
        Ok(i16::from_le_bytes(self.array()?))
    }
    fn u32(&mut self) -> Result<u32, ShotDecodeError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn i32(&mut self) -> Result<i32, ShotDecodeError> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    fn f32(&mut self, field: &str) -> Result<f32, ShotDecodeError> {
        check_f32(field, f32::from_le_bytes(self.array()?))
    }
    fn lat(&mut self, field: &str) -> Result<f64, ShotDecodeError> {
        check_lat(field, f64::from_le_bytes(self.array()?))
    }
    fn lon(&mut self, field: &str) -> Result<f64, ShotDecodeError> {
        check_lon(field, f64::from_le_bytes(self.array()?))
    }
    /// The rest of the body as text (lossy UTF-8).
    fn text(&mut self) -> String {
        let s = String::from_utf8_lossy(self.rest).into_owned();
        self.rest = &[];
        s
    }
    fn location(&mut self) -> Result<Location, ShotDecodeError> {
        Ok(Location {
            lat_deg: self.lat("latitude")?,
            lon_deg: self.lon("longitude")?,
            alt_m: self.f32("altitude")?,
        })
    }
    fn button(&mut self) -> Result<ButtonSetting, ShotDecodeError> {
        Ok(ButtonSetting {
            button: self.i32()?,
            event: self.i32()?,
            shot: self.i32()?,
            mode: self.i32()?,
        })
    }
    #[allow(clippy::type_complexity)]
    fn pano(&mut self) -> Result<(u8, u8, i16, f32, f32), ShotDecodeError> {
        Ok((
            self.u8()?,
            self.u8()?,
            self.i16()?,
            self.f32("deg_second_yaw")?,
            self.f32("lens_fov")?,
        ))
    }
    fn spline_point(&mut self) -> Result<SplinePoint, ShotDecodeError> {
        Ok(SplinePoint {
            version: self.i16()?,
            abs_alt_ref_m: self.f32("abs_alt_ref")?,
            index: self.i32()?,
            lat_deg: self.lat("latitude")?,
            lon_deg: self.lon("longitude")?,
            alt_m: self.f32("altitude")?,
            pitch_deg: self.f32("pitch")?,
            yaw_deg: self.f32("yaw")?,
            u_position: self.f32("u_position")?,
            status: self.i16()?,
        })
    }
    fn gopro(&mut self) -> Result<GoProState, ShotDecodeError> {
        let b: [u8; 19] = self.array()?;
        let extra_u8: [u8; 7] = self.array()?;
        let mut extra_u16 = [0u16; 5];
        for v in &mut extra_u16 {
            *v = self.u16()?;
        }
        Ok(GoProState {
            version: b[0],
            model: b[1],
            status: b[2],
            recording: b[3],
            capture_mode: b[4],
            ntsc_pal: b[5],
            video_resolution: b[6],
            video_fps: b[7],
            video_fov: b[8],
            video_low_light: b[9],
            photo_resolution: b[10],
            photo_burst_rate: b[11],
            video_protune: b[12],
            video_white_balance: b[13],
            video_color: b[14],
            video_gain: b[15],
            video_sharpness: b[16],
            video_exposure: b[17],
            gimbal_enabled: b[18],
            extra_u8,
            extra_u16,
        })
    }
    /// Every byte must have been read.
    pub(super) fn finish<T>(self, v: T) -> Result<T, ShotDecodeError> {
        if self.rest.is_empty() {
            Ok(v)
        } else {
            Err(ShotDecodeError::WrongLength {
                kind: self.kind,
                len: self.len,
                expected: self.len - self.rest.len(),
            })
        }
    }
}
