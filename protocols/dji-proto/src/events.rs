//! Outbound `data` of events and `drc/up` pushes, serialised with the document's
//! field names (`serde_json::to_value` gives the `data` for the encoders).

use serde::{Serialize, Serializer};

/// A trajectory point of a progress event (height: ellipsoid, metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PathPoint {
    pub latitude: f64,
    pub longitude: f64,
    pub height: f64,
}

/// `status` of fly_to_point_progress / takeoff_to_point_progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskStatus {
    /// takeoff only
    TaskReady,
    WaylineProgress,
    WaylineOk,
    WaylineFailed,
    WaylineCancel,
    /// takeoff only
    TaskFinish,
}

/// `fly_to_point_progress` data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlyToPointProgress {
    pub fly_to_id: String,
    pub status: TaskStatus,
    pub result: u32,
    pub way_point_index: i64,
    /// metres, one decimal
    pub remaining_distance: f64,
    /// seconds, one decimal
    pub remaining_time: f64,
    pub planned_path_points: Vec<PathPoint>,
}

/// `takeoff_to_point_progress` data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TakeoffToPointProgress {
    pub status: TaskStatus,
    pub result: u32,
    pub flight_id: String,
    pub track_id: String,
    pub way_point_index: i64,
    pub remaining_distance: f64,
    pub remaining_time: f64,
    pub planned_path_points: Vec<PathPoint>,
}

/// `drc_status_notify` data; drc_state 0 not connected, 1 connecting, 2 connected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct DrcStatusNotify {
    pub result: u32,
    pub drc_state: u8,
}

/// `joystick_invalid_notify.reason`. Serialises as its code (an integer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JoystickInvalidReason {
    RcLost = 0,
    LowBatteryReturn = 1,
    LowBatteryLanding = 2,
    NearRestrictedZone = 3,
    RcTakeover = 4,
}

impl JoystickInvalidReason {
    /// The document's code (0..=4).
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The reason of a code, `None` if the document defines none.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0 => JoystickInvalidReason::RcLost,
            1 => JoystickInvalidReason::LowBatteryReturn,
            2 => JoystickInvalidReason::LowBatteryLanding,
            3 => JoystickInvalidReason::NearRestrictedZone,
            4 => JoystickInvalidReason::RcTakeover,
            _ => return None,
        })
    }
}

impl Serialize for JoystickInvalidReason {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u8(self.code())
    }
}

/// `joystick_invalid_notify` data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct JoystickInvalidNotify {
    pub reason: u8,
}

impl From<JoystickInvalidReason> for JoystickInvalidNotify {
    fn from(reason: JoystickInvalidReason) -> Self {
        JoystickInvalidNotify {
            reason: reason.code(),
        }
    }
}

/// `poi_status_notify.status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PoiStatus {
    Failed,
    InProgress,
    Ok,
}

/// `poi_status_notify` data; reason 0 normal … 8 link lost (the document's table).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoiStatusNotify {
    pub status: PoiStatus,
    pub reason: u8,
    pub circle_radius: f64,
    pub circle_speed: f64,
    pub max_circle_speed: f64,
}

/// `camera_photo_take_progress` data (`output` + `result`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraPhotoTakeProgress {
    pub output: PhotoTakeOutput,
    pub result: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhotoTakeOutput {
    /// "fail" | "in_progress" | "ok"
    pub status: &'static str,
    pub progress: PhotoTakeProgress,
    pub ext: PhotoTakeExt,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PhotoTakeProgress {
    /// 3000 not started/finished, 3002 capturing, 3005 synthesizing
    pub current_step: u16,
    /// 0..=100
    pub percent: u8,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct PhotoTakeExt {
    /// 3 = panorama
    pub camera_mode: u8,
}

/// `osd_info_push` data (drc/up).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OsdInfoPush {
    /// heading, degrees
    pub attitude_head: f64,
    pub latitude: f64,
    pub longitude: f64,
    /// metres (the document's unit column says degree; it is a height)
    pub height: f64,
    /// m/s north
    pub speed_x: f64,
    /// m/s east
    pub speed_y: f64,
    /// m/s up
    pub speed_z: f64,
    pub gimbal_pitch: f64,
    pub gimbal_roll: f64,
    pub gimbal_yaw: f64,
}

/// `hsi_info_push` data (drc/up): obstacle distances in mm. skymesh has no obstacle
/// sensors: enables/works false, distances the document's "no data" (60000 mm).
/// Field names are the Data table's (`around_distances`, as DJI's SDKs send it); the
/// document's example writes `around_distance` and adds left/right/front/back/
/// vertical/horizontal enable/work flags the table does not define.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HsiInfoPush {
    pub up_distance: i64,
    pub down_distance: i64,
    pub up_enable: bool,
    pub up_work: bool,
    pub down_enable: bool,
    pub down_work: bool,
    /// 360 entries, one per degree
    pub around_distances: Vec<i64>,
}

/// `drc/up` `drone_control` answer data: `{"result": .., "output": {"seq": ..}}` (the
/// document's example answers 319033 with seq −1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct DroneControlReply {
    pub result: u32,
    pub output: DroneControlReplyOutput,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct DroneControlReplyOutput {
    pub seq: i64,
}

impl DroneControlReply {
    pub fn new(result: u32, seq: i64) -> Self {
        DroneControlReply {
            result,
            output: DroneControlReplyOutput { seq },
        }
    }
}

/// `drc/up` answer data with only a result (`drone_emergency_stop`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct DrcResult {
    pub result: u32,
}

/// `drc/up` `heart_beat` data: the received seq and timestamp echoed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct HeartBeatEcho {
    pub seq: i64,
    pub timestamp: i64,
}

/// `delay_info_push` data (drc/up).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DelayInfoPush {
    /// ms
    pub sdr_cmd_delay: i64,
    pub liveview_delay_list: Vec<LiveviewDelay>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LiveviewDelay {
    pub video_id: String,
    /// ms
    pub liveview_delay_time: i64,
}
