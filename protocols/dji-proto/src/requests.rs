//! Inbound requests: every `services` method, every `drc/down` method, and
//! `events_reply`, as typed values that passed the document's constraint column.
//! Field names are the document's JSON names.

use crate::{Envelope, Reject};

/// A point of `fly_to_point` / `fly_to_point_update` (height: ellipsoid, 2..=10000 m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoPoint {
    /// −90..=90
    pub latitude: f64,
    /// −180..=180
    pub longitude: f64,
    pub height: f64,
}

/// `drc_mode_enter.mqtt_broker`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttBroker {
    /// `host:port`, port 1..=65535 (an IPv6 host in brackets); no scheme.
    pub address: String,
    /// Non-empty text.
    pub client_id: String,
    /// May be empty (a broker without authentication), at most [`crate::codes::MAX_TEXT_LEN`].
    pub username: String,
    /// May be empty; often a JWT, so up to [`crate::codes::MAX_SECRET_LEN`] bytes.
    pub password: String,
    /// Seconds; ≥ 0.
    pub expire_time: i64,
    pub enable_tls: bool,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DrcModeEnter {
    pub mqtt_broker: MqttBroker,
    /// 1..=30 Hz
    pub osd_frequency: u8,
    /// 1..=30 Hz
    pub hsi_frequency: u8,
}

/// `rc_lost_action`: 0 hover, 1 land, 2 return home.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RcLostAction {
    Hover = 0,
    Land = 1,
    ReturnHome = 2,
}

/// `simulate_mission` (optional).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulateMission {
    pub is_enable: bool,
    pub latitude: f64,
    pub longitude: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TakeoffToPoint {
    /// −90..=90
    pub target_latitude: f64,
    /// −180..=180
    pub target_longitude: f64,
    /// 2..=1500 m (ellipsoid)
    pub target_height: f64,
    /// 20..=1500 m above the takeoff point
    pub security_takeoff_height: f64,
    /// 2..=1500 m
    pub rth_altitude: i64,
    pub rc_lost_action: RcLostAction,
    /// deprecated, optional: 0/1
    pub exit_wayline_when_rc_lost: Option<u8>,
    /// optional: 0/1
    pub commander_mode_lost_action: Option<u8>,
    /// optional: 2..=3000 m above the takeoff point
    pub commander_flight_height: Option<f64>,
    /// non-empty text
    pub flight_id: String,
    /// 1..=15 m/s
    pub max_speed: i64,
    pub simulate_mission: Option<SimulateMission>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FlyToPoint {
    pub fly_to_id: String,
    /// 0..=15 m/s
    pub max_speed: i64,
    /// exactly one point ("Only supports 1 target point")
    pub points: Vec<GeoPoint>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FlyToPointUpdate {
    /// 1..=15 m/s
    pub max_speed: i64,
    /// exactly one point
    pub points: Vec<GeoPoint>,
}

/// `camera_type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraType {
    Wide,
    Zoom,
    Ir,
}

impl CameraType {
    /// The document's name (`wide`, `zoom`, `ir`).
    pub fn as_str(self) -> &'static str {
        match self {
            CameraType::Wide => "wide",
            CameraType::Zoom => "zoom",
            CameraType::Ir => "ir",
        }
    }
}

/// `camera_mode` of camera_mode_switch: 0 capturing, 1 recording, 2 smart low-light, 3 panorama.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraMode {
    Photo = 0,
    Video = 1,
    LowLight = 2,
    Panorama = 3,
}

/// `photo_storage_settings` / `video_storage_settings` items.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StorageLens {
    Current,
    Wide,
    Zoom,
    Ir,
}

impl StorageLens {
    /// The document's name (`current`, `wide`, `zoom`, `ir`).
    pub fn as_str(self) -> &'static str {
        match self {
            StorageLens::Current => "current",
            StorageLens::Wide => "wide",
            StorageLens::Zoom => "zoom",
            StorageLens::Ir => "ir",
        }
    }
}

/// One `services` request, checked. `payload_index` is non-empty text of the form
/// `{type}-{subtype}-{gimbalindex}` (three decimal integers, each fitting u32).
///
/// [`ServiceRequest::to_data`] gives the request's `data` back (a cloud's side, for
/// tests and fake clouds); `parse_service` of it gives the same request.
#[derive(Debug, Clone, PartialEq)]
pub enum ServiceRequest {
    FlightAuthorityGrab,
    PayloadAuthorityGrab {
        payload_index: String,
    },
    DrcModeEnter(DrcModeEnter),
    DrcModeExit,
    TakeoffToPoint(TakeoffToPoint),
    FlyToPoint(FlyToPoint),
    FlyToPointStop,
    FlyToPointUpdate(FlyToPointUpdate),
    CameraModeSwitch {
        payload_index: String,
        camera_mode: CameraMode,
    },
    CameraPhotoTake {
        payload_index: String,
    },
    CameraPhotoStop {
        payload_index: String,
    },
    CameraRecordingStart {
        payload_index: String,
    },
    CameraRecordingStop {
        payload_index: String,
    },
    /// Rates in deg/s, finite, |rate| ≤ 360 (the document gives no range; skymesh's).
    /// `yaw_speed` only matters when `locked` is false (the document's words).
    CameraScreenDrag {
        payload_index: String,
        locked: bool,
        pitch_speed: f64,
        yaw_speed: f64,
    },
    /// x, y in 0..=1 (upper-left origin).
    CameraAim {
        payload_index: String,
        camera_type: CameraType,
        locked: bool,
        x: f64,
        y: f64,
    },
    /// zoom_factor 2..=200 (visible), 2..=20 (ir).
    CameraFocalLengthSet {
        payload_index: String,
        camera_type: CameraType,
        zoom_factor: f64,
    },
    /// reset_mode 0 recentre, 1 down, 2 pan recentre, 3 pitch down.
    GimbalReset {
        payload_index: String,
        reset_mode: u8,
    },
    /// height 2..=10000 m
    CameraLookAt {
        payload_index: String,
        locked: bool,
        latitude: f64,
        longitude: f64,
        height: f64,
    },
    CameraScreenSplit {
        payload_index: String,
        enable: bool,
    },
    /// non-empty set, no duplicates
    PhotoStorageSet {
        payload_index: String,
        photo_storage_settings: Vec<StorageLens>,
    },
    VideoStorageSet {
        payload_index: String,
        video_storage_settings: Vec<StorageLens>,
    },
    /// camera_type wide|zoom (as for the other exposure/focus methods);
    /// exposure_mode 1 auto, 2 shutter, 3 aperture, 4 manual.
    CameraExposureModeSet {
        payload_index: String,
        camera_type: CameraType,
        exposure_mode: u8,
    },
    /// exposure_value: the document's enum_string keys "1".."31" (−5.0 EV … +5.0 EV) and
    /// "255" (FIXED). Its example sends the integer 5: the string and the integer form
    /// are both accepted.
    CameraExposureSet {
        payload_index: String,
        camera_type: CameraType,
        exposure_value: u8,
    },
    /// focus_mode 0 MF, 1 AFS, 2 AFC.
    CameraFocusModeSet {
        payload_index: String,
        camera_type: CameraType,
        focus_mode: u8,
    },
    /// focus_value ≥ 0 (the range comes from aircraft properties).
    CameraFocusValueSet {
        payload_index: String,
        camera_type: CameraType,
        focus_value: i64,
    },
    CameraPointFocusAction {
        payload_index: String,
        camera_type: CameraType,
        x: f64,
        y: f64,
    },
    /// mode 0 off, 1 point, 2 area.
    IrMeteringModeSet {
        payload_index: String,
        mode: u8,
    },
    IrMeteringPointSet {
        payload_index: String,
        x: f64,
        y: f64,
    },
    IrMeteringAreaSet {
        payload_index: String,
        x: f64,
        y: f64,
        width: f64,
        height: f64,
    },
    /// height 2..=10000 m, relative to the takeoff point (as the document says).
    PoiModeEnter {
        latitude: f64,
        longitude: f64,
        height: f64,
    },
    PoiModeExit,
    /// m/s, finite; sign = direction (negative clockwise). The maximum is the gateway's
    /// (reported in poi_status_notify), checked there.
    PoiCircleSpeedSet {
        circle_speed: f64,
    },
}

impl ServiceRequest {
    /// The method name on the wire.
    pub fn method(&self) -> &'static str {
        use ServiceRequest as S;
        match self {
            S::FlightAuthorityGrab => "flight_authority_grab",
            S::PayloadAuthorityGrab { .. } => "payload_authority_grab",
            S::DrcModeEnter(_) => "drc_mode_enter",
            S::DrcModeExit => "drc_mode_exit",
            S::TakeoffToPoint(_) => "takeoff_to_point",
            S::FlyToPoint(_) => "fly_to_point",
            S::FlyToPointStop => "fly_to_point_stop",
            S::FlyToPointUpdate(_) => "fly_to_point_update",
            S::CameraModeSwitch { .. } => "camera_mode_switch",
            S::CameraPhotoTake { .. } => "camera_photo_take",
            S::CameraPhotoStop { .. } => "camera_photo_stop",
            S::CameraRecordingStart { .. } => "camera_recording_start",
            S::CameraRecordingStop { .. } => "camera_recording_stop",
            S::CameraScreenDrag { .. } => "camera_screen_drag",
            S::CameraAim { .. } => "camera_aim",
            S::CameraFocalLengthSet { .. } => "camera_focal_length_set",
            S::GimbalReset { .. } => "gimbal_reset",
            S::CameraLookAt { .. } => "camera_look_at",
            S::CameraScreenSplit { .. } => "camera_screen_split",
            S::PhotoStorageSet { .. } => "photo_storage_set",
            S::VideoStorageSet { .. } => "video_storage_set",
            S::CameraExposureModeSet { .. } => "camera_exposure_mode_set",
            S::CameraExposureSet { .. } => "camera_exposure_set",
            S::CameraFocusModeSet { .. } => "camera_focus_mode_set",
            S::CameraFocusValueSet { .. } => "camera_focus_value_set",
            S::CameraPointFocusAction { .. } => "camera_point_focus_action",
            S::IrMeteringModeSet { .. } => "ir_metering_mode_set",
            S::IrMeteringPointSet { .. } => "ir_metering_point_set",
            S::IrMeteringAreaSet { .. } => "ir_metering_area_set",
            S::PoiModeEnter { .. } => "poi_mode_enter",
            S::PoiModeExit => "poi_mode_exit",
            S::PoiCircleSpeedSet { .. } => "poi_circle_speed_set",
        }
    }

    /// The `payload_index` of a payload method (`None` for flight methods).
    pub fn payload_index(&self) -> Option<&str> {
        use ServiceRequest as S;
        match self {
            S::PayloadAuthorityGrab { payload_index }
            | S::CameraModeSwitch { payload_index, .. }
            | S::CameraPhotoTake { payload_index }
            | S::CameraPhotoStop { payload_index }
            | S::CameraRecordingStart { payload_index }
            | S::CameraRecordingStop { payload_index }
            | S::CameraScreenDrag { payload_index, .. }
            | S::CameraAim { payload_index, .. }
            | S::CameraFocalLengthSet { payload_index, .. }
            | S::GimbalReset { payload_index, .. }
            | S::CameraLookAt { payload_index, .. }
            | S::CameraScreenSplit { payload_index, .. }
            | S::PhotoStorageSet { payload_index, .. }
            | S::VideoStorageSet { payload_index, .. }
            | S::CameraExposureModeSet { payload_index, .. }
            | S::CameraExposureSet { payload_index, .. }
            | S::CameraFocusModeSet { payload_index, .. }
            | S::CameraFocusValueSet { payload_index, .. }
            | S::CameraPointFocusAction { payload_index, .. }
            | S::IrMeteringModeSet { payload_index, .. }
            | S::IrMeteringPointSet { payload_index, .. }
            | S::IrMeteringAreaSet { payload_index, .. } => Some(payload_index),
            S::FlightAuthorityGrab
            | S::DrcModeEnter(_)
            | S::DrcModeExit
            | S::TakeoffToPoint(_)
            | S::FlyToPoint(_)
            | S::FlyToPointStop
            | S::FlyToPointUpdate(_)
            | S::PoiModeEnter { .. }
            | S::PoiModeExit
            | S::PoiCircleSpeedSet { .. } => None,
        }
    }
}

/// Every `services` method of the document, in the document's order.
pub const SERVICE_METHODS: &[&str] = &[
    "flight_authority_grab",
    "payload_authority_grab",
    "drc_mode_enter",
    "drc_mode_exit",
    "takeoff_to_point",
    "fly_to_point",
    "fly_to_point_stop",
    "fly_to_point_update",
    "camera_mode_switch",
    "camera_photo_take",
    "camera_photo_stop",
    "camera_recording_start",
    "camera_recording_stop",
    "camera_screen_drag",
    "camera_aim",
    "camera_focal_length_set",
    "gimbal_reset",
    "camera_look_at",
    "camera_screen_split",
    "photo_storage_set",
    "video_storage_set",
    "camera_exposure_mode_set",
    "camera_exposure_set",
    "camera_focus_mode_set",
    "camera_focus_value_set",
    "camera_point_focus_action",
    "ir_metering_mode_set",
    "ir_metering_point_set",
    "ir_metering_area_set",
    "poi_mode_enter",
    "poi_mode_exit",
    "poi_circle_speed_set",
];

/// Check a `services` envelope's data against its method's constraints (the
/// document's Data table, fields in its order: the first violation is reported).
/// Unknown method → [`crate::codes::UNKNOWN_METHOD`].
///
/// Every field of the table is required except those the document marks optional or
/// deprecated (takeoff_to_point's `exit_wayline_when_rc_lost`,
/// `commander_mode_lost_action`, `commander_flight_height`, `simulate_mission`).
/// A JSON `null` counts as absent. Fields the document does not define are ignored
/// (forward compatibility). Methods without data accept `data` absent, null or any
/// object.
pub fn parse_service(env: &Envelope) -> Result<ServiceRequest, Reject> {
    crate::services::parse(env)
}

/// `drone_control` stick command (body frame, as the document defines it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DroneControl {
    /// ≥ 0 (seq 0 restarts the count).
    pub seq: i64,
    /// −17..=17 m/s, positive = LEFT (the document's words; see docs/protocols.md).
    pub x: f64,
    /// −17..=17 m/s, positive = forward.
    pub y: f64,
    /// −4..=5 m/s, positive = up (the document lists min 5, max −4: read as −4..=5).
    pub h: f64,
    /// −90..=90 deg/s, positive = clockwise.
    pub w: f64,
}

/// One `drc/down` message, checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DrcDown {
    DroneControl(DroneControl),
    DroneEmergencyStop,
    HeartBeat { seq: i64, timestamp: i64 },
}

impl DrcDown {
    /// The method name on the wire.
    pub fn method(&self) -> &'static str {
        match self {
            DrcDown::DroneControl(_) => "drone_control",
            DrcDown::DroneEmergencyStop => "drone_emergency_stop",
            DrcDown::HeartBeat { .. } => "heart_beat",
        }
    }
}

/// Check a `drc/down` envelope. `seq` is read from `data.seq` (or the top level).
/// drone_control: seq integer ≥ 0, x/y/h/w numbers in range, all required;
/// drone_emergency_stop: data absent, null or an object; heart_beat: seq and
/// timestamp integers (echoed, any value). Unknown method →
/// [`crate::codes::UNKNOWN_METHOD`].
pub fn parse_drc(env: &Envelope) -> Result<DrcDown, Reject> {
    crate::drc::parse(env)
}

/// The cloud's answer to an event with `need_reply: 1`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EventReply {
    pub tid: String,
    pub bid: String,
    pub method: String,
    /// `data.result`
    pub result: i64,
}

/// Check an `events_reply` envelope (`data.result` integer required; tid, bid and
/// method copied from the envelope).
pub fn parse_event_reply(env: &Envelope) -> Result<EventReply, Reject> {
    crate::drc::parse_event_reply(env)
}
