//! The vision pipeline's bus contract (issue 8).
//!
//! The pipeline owns every DigiView parameter and every virtual camera. It publishes
//! one [`VisionState`] (all parameters, the virtual cameras' current aim, the
//! single-target tracker and the known detections) after every processed frame and
//! at 1 Hz when no frame arrives. Everybody who wants to change something sends a
//! [`VisionControl`] and gets exactly one [`VisionReply`] with the same
//! `request_id`:
//!
//! | writer | kinds |
//! |---|---|
//! | `autopilot-link` (gimbal protocol v2 for the virtual cameras) | `GimbalAttitude`, `RoiLocation`, `RoiNone`, `Zoom` |
//! | `autopilot-link` (camera commands of other gateways accepted by the arbiter) | `Zoom`, `GimbalAttitude`, `ImageCapture`, `RecordStart`, `RecordStop` |
//!
//! Angles on this bus are radians, Tait-Bryan yaw then pitch: yaw from true north
//! (clockwise positive), pitch from the horizon (up positive), unless a field says
//! otherwise. A virtual camera's orientation quaternion is camera → NED with the
//! camera frame of `vision_pipeline::geometry` (x along the optical axis, y right,
//! z down), `[w, x, y, z]`.
//!
//! Protocol gateways (the DigiView gateway) change the views, detector and tracker
//! with [`crate::view::ViewControl`] instead.
//!
//! Topics: [`crate::topics::vision_state`], [`crate::topics::vision_control`],
//! [`crate::topics::vision_reply`]; rendered output frames on
//! [`crate::topics::vision_output`] (the same `FrameHeader` slices as the camera's).

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

/// Streams one pipeline serves (each a camera topic of the same name).
pub const VISION_MAX_STREAMS: usize = 2;
/// User-controllable (virtual) cameras per stream: DigiView's `cam_id` 0–3.
pub const VISION_MAX_CAMS: usize = 4;
/// Detections the state carries (the highest scored, in sorting order).
pub const VISION_MAX_DETECTIONS: usize = 32;
/// Detector models the pipeline can list (DigiView MODEL replies).
pub const VISION_MAX_MODELS: usize = 4;
/// A stream name: DigiView's `char[8]`.
pub type StreamName = FixedStr<8>;
/// A model name: DigiView's `char[16]`.
pub type ModelName = FixedStr<16>;

wire_enum! {
    /// How a virtual camera is aimed (DigiView CAM_TARGETING `targeting_mode`).
    pub enum TargetingMode: u8 {
        /// Global euler angles (`yaw`, `pitch`), subject to the lock flags.
        Directional = 0 => "directional",
        /// At a latitude/longitude/altitude.
        Coordinal = 1 => "coordinal",
        /// At a detection (`detection_id`).
        Detection = 2 => "detection",
        /// At the single-target tracker's target.
        SingleTarget = 3 => "single_target",
    }
}

wire_enum! {
    /// How a virtual camera's view is projected (CAM_OPTICS_AND_CONTROL `crop_mode`;
    /// 0 and 1 both mean rectified, see digiview-proto).
    pub enum CropMode: u8 {
        Default = 0 => "default",
        /// A rectilinear (pinhole, undistorted) view.
        Rectified = 1 => "rectified",
        /// A cylindrical panorama: yaw linear across the view.
        Panoramic = 2 => "panoramic",
    }
}

wire_enum! {
    /// The single-target tracker's mode (DigiView SINGLE_TARGET_TRACKING `command`,
    /// as it stands after the last command: nudge and no-op leave it unchanged).
    pub enum SttMode: u8 {
        Disabled = 0 => "disabled",
        /// Tracking whatever was in a direction (template tracking).
        Direction = 1 => "direction",
        /// Following a detection id.
        Detection = 2 => "detection",
    }
}

/// Lock flag bits of a virtual camera (DigiView CAM_TARGETING `lock_flags`): a locked
/// axis is stabilised against the vehicle (held in the world); an unlocked axis
/// follows the vehicle.
pub const LOCK_YAW: u8 = 0b001;
pub const LOCK_PITCH: u8 = 0b010;
pub const LOCK_ROLL: u8 = 0b100;

/// One virtual camera: what it was told and where it looks now.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct VirtualCamState {
    /// [`TargetingMode`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::TargetingMode>")
    )]
    pub targeting_mode: u8,
    /// 1 if the last CAM_TARGETING SET was a delta.
    pub euler_delta: u8,
    /// `LOCK_*` bits.
    pub lock_flags: u8,
    /// [`CropMode`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CropMode>")
    )]
    pub crop_mode: u8,
    /// DigiView zoom, −127..127 (0 none, positive in).
    pub zoom: i8,
    /// 1 if the stream's layout shows this camera.
    pub active: u8,
    /// The detection followed in [`TargetingMode::Detection`] (255 none).
    pub detection_id: u8,
    /// 1 while the aim is valid (pose known, target resolvable); 0 e.g. before the
    /// first frame or while its detection is lost (the view then holds its last aim).
    pub aim_valid: u8,
    /// CAM_TARGETING angles as last set (after applying deltas), radians. In the
    /// frames the lock flags select: a locked axis is global, an unlocked one relative
    /// to the vehicle's heading / body.
    pub yaw_rad: f32,
    pub pitch_rad: f32,
    pub roll_rad: f32,
    /// CAM_TARGETING offsets, −1..1.
    pub x_offset: f32,
    pub y_offset: f32,
    /// CAM_OPTICS_AND_CONTROL field of view as set (horizontal), radians.
    pub fov_rad: f32,
    /// The horizontal field of view rendered, after zoom, radians.
    pub effective_hfov_rad: f32,
    /// Coordinal target altitude relative to the vehicle, m (DigiView's meaning).
    pub target_alt_rel_m: f32,
    pub target_lat_deg: f64,
    pub target_lon_deg: f64,
    /// The orientation rendered for the last frame (camera → NED, `[w, x, y, z]`).
    pub ned_from_cam_q: [f32; 4],
    /// Global yaw / pitch of the view's centre for the last frame, radians.
    pub view_yaw_rad: f32,
    pub view_pitch_rad: f32,
    /// The view's rectangle in the output frame: x, y, w, h pixels.
    pub view_rect: [u16; 4],
}
crate::assert_layout!(VirtualCamState, size = 8 + 32 + 16 + 16 + 8 + 8, align = 8);

/// The single-target tracker of one stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct SttState {
    /// [`SttMode`] as stored on the wire.
    #[cfg_attr(feature = "serde", serde(with = "crate::json::Wire::<crate::SttMode>"))]
    pub mode: u8,
    /// The virtual camera the command named.
    pub cam: u8,
    /// The followed detection in [`SttMode::Detection`] (255 none).
    pub detection_id: u8,
    /// 1 while the target is found in the current frame.
    pub locked: u8,
    /// DigiView `rel_frame_of_reference` of the last command (0 global, 1 heading, 2 camera).
    pub rel_frame: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: u8,
    /// Zoom level 0–10 (0 largest tracking box).
    pub zoom_level: u16,
    /// Match confidence of the last update, 0..1.
    pub confidence: f32,
    /// The target direction: global, relative to the heading, relative to the
    /// physical camera's axis; radians.
    pub yaw_global_rad: f32,
    pub pitch_global_rad: f32,
    pub yaw_heading_rad: f32,
    pub pitch_heading_rad: f32,
    pub yaw_camera_rad: f32,
    pub pitch_camera_rad: f32,
    /// The target's box in the source frame: x, y, w, h pixels.
    pub bbox: [u16; 4],
}
crate::assert_layout!(SttState, size = 44, align = 4);

/// One stream: output layout, capture counters, virtual cameras, tracker.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct VisionStreamState {
    pub name: StreamName,
    /// 1 if this slot holds a configured stream.
    pub configured: u8,
    /// 1 while frames arrive (one within the last second).
    pub receiving: u8,
    /// VIDEO_OUTPUT layout 0–6.
    pub layout_mode: u8,
    /// VIDEO_OUTPUT detection overlay mode 0–5.
    pub overlay_mode: u8,
    /// User views the layout shows (1–4; layout 6, the debug view, shows 1).
    pub num_views: u8,
    /// 1 while a video is being recorded.
    pub recording: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 2],
    /// Output resolution.
    pub out_width: u16,
    pub out_height: u16,
    /// The detection overlay's rectangle (x, y, w, h) and one detection tile's side.
    pub overlay_box: [u16; 4],
    pub single_detection_size: u16,
    pub images_captured: u16,
    pub videos_captured: u16,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved2: u16,
    /// The source (physical camera) frame size.
    pub source_width: u32,
    pub source_height: u32,
    /// Vehicle heading at the last frame, radians from true north.
    pub vehicle_heading_rad: f32,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved3: u32,
    pub frames_processed: u64,
    pub frames_dropped: u64,
    /// `frame_seq` and `capture_mono_ns` of the last processed frame.
    pub last_frame_seq: u64,
    pub last_capture_mono_ns: u64,
    /// When processing of that frame finished (detections known), monotonic ns.
    pub last_processed_mono_ns: u64,
    pub cams: [VirtualCamState; VISION_MAX_CAMS],
    pub stt: SttState,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved4: u32,
}
crate::assert_layout!(
    VisionStreamState,
    size = 8 + 8 + 4 + 8 + 8 + 8 + 8 + 4 + 40 + 88 * VISION_MAX_CAMS + 44 + 4,
    align = 8
);

/// One tracked detection.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct VisionDetection {
    /// Stable id for the object's lifetime (0–253, reused only after it is gone).
    pub id: u8,
    /// Tracking score 0–254.
    pub score: u8,
    /// Stream index (into `VisionState::streams`).
    pub stream: u8,
    /// The detection tile showing it (255 none): "visible in the output overlay".
    pub overlay_slot: u8,
    /// 1 if latitude/longitude/altitude/distance come from a ground intersection.
    pub geo_valid: u8,
    /// Index of the model that found it (`VisionState::models`).
    pub model: u8,
    /// Object class (DigiView DETECTED_ROI `type`); 0 = generic blob.
    pub object_type: i16,
    /// Frames since the object was created.
    pub age_frames: u32,
    /// Detector confidence of the last match, 0..1.
    pub confidence: f32,
    /// Box in the source frame: x, y, w, h pixels.
    pub bbox: [u16; 4],
    /// Direction of the box centre: global, heading-relative, camera-relative; radians.
    pub yaw_global_rad: f32,
    pub pitch_global_rad: f32,
    pub yaw_heading_rad: f32,
    pub pitch_heading_rad: f32,
    pub yaw_camera_rad: f32,
    pub pitch_camera_rad: f32,
    /// Ground intersection of that ray (valid if `geo_valid`).
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_msl_m: f32,
    /// Camera to ground point, m.
    pub distance_m: f32,
}
crate::assert_layout!(VisionDetection, size = 8 + 8 + 8 + 24 + 16 + 8, align = 8);

/// Everything the pipeline knows, after every processed frame and at 1 Hz.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.VisionState.v1")]
#[repr(C)]
pub struct VisionState {
    pub header: SampleHeader,
    /// DigiView SYSTEM_STATUS: 0 idle (no frames), 1 running, 2 finished, 3 error.
    pub status: u8,
    pub ai_enabled: u8,
    /// Models in `models`.
    pub model_count: u8,
    /// Streams in use (slots `0..stream_count` of `streams`).
    pub stream_count: u8,
    /// Detections in `detections`.
    pub detection_count: u8,
    /// 1 if `temperature_c` was read from the machine.
    pub temperature_valid: u8,
    /// DETECTION `mode` (unused by DigiView, stored) and `sorting_mode` 0–2.
    pub detection_mode: u8,
    pub sorting_mode: u8,
    pub temperature_c: f32,
    /// DETECTION parameters: thresholds and overlaps 0..0.99, scores 0–254.
    pub track_confidence: f32,
    pub scan_confidence: f32,
    pub track_overlap: f32,
    pub scan_overlap: f32,
    pub creation_score: u8,
    pub bonus_detection: u8,
    pub bonus_redetection: u8,
    pub missed_detection_penalty: u8,
    pub missed_redetection_penalty: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 7],
    pub track_model: ModelName,
    pub scan_model: ModelName,
    pub models: [ModelName; VISION_MAX_MODELS],
    pub streams: [VisionStreamState; VISION_MAX_STREAMS],
    /// Sorted by the sorting mode (best first).
    pub detections: [VisionDetection; VISION_MAX_DETECTIONS],
}
crate::assert_layout!(
    VisionState,
    size = 24
        + 8
        + 20
        + 12
        + 32
        + 16 * VISION_MAX_MODELS
        + core::mem::size_of::<VisionStreamState>() * VISION_MAX_STREAMS
        + core::mem::size_of::<VisionDetection>() * VISION_MAX_DETECTIONS,
    align = 8
);

crate::impl_sample!(VisionState);

impl VisionState {
    /// The streams in use.
    pub fn streams(&self) -> &[VisionStreamState] {
        &self.streams[..usize::from(self.stream_count).min(VISION_MAX_STREAMS)]
    }

    /// The index of the stream called `name`.
    pub fn stream_index(&self, name: &str) -> Option<usize> {
        self.streams().iter().position(|s| s.name.as_str() == name)
    }

    /// The detections in use, best first.
    pub fn detections(&self) -> &[VisionDetection] {
        &self.detections[..usize::from(self.detection_count).min(VISION_MAX_DETECTIONS)]
    }

    /// The models in use.
    pub fn models(&self) -> &[ModelName] {
        &self.models[..usize::from(self.model_count).min(VISION_MAX_MODELS)]
    }
}

wire_enum! {
    /// What a [`VisionControl`] asks for.
    pub enum VisionControlKind: u8 {
        /// Aim virtual camera `cam`: `yaw_rad`/`pitch_rad` (NaN = leave that axis),
        /// and/or `yaw_rate_rps`/`pitch_rate_rps` (NaN = none; a rate turns the aim
        /// until the next command). `gimbal_flags` are MAVLink GIMBAL_MANAGER_FLAGS:
        /// YAW_LOCK (16) / YAW_IN_EARTH_FRAME (64) make yaw global, otherwise it is
        /// relative to the vehicle's heading; pitch is always from the horizon.
        /// Switches the camera to [`TargetingMode::Directional`].
        GimbalAttitude = 2 => "gimbal_attitude",
        /// Aim virtual camera `cam` (255 = every camera of the stream) at
        /// `lat_deg`/`lon_deg`/`alt_msl_m` (coordinal mode).
        RoiLocation = 3 => "roi_location",
        /// Leave coordinal mode: the camera holds its current direction (directional).
        RoiNone = 4 => "roi_none",
        /// Zoom virtual camera `cam` (255 = every camera): `zoom_mode` is MAVLink
        /// CAMERA_ZOOM_TYPE (0 step, 1 continuous, 2 range 0–100 %, 3 focal length mm),
        /// `value` its value.
        Zoom = 5 => "zoom",
        /// Capture one image of the stream's output.
        ImageCapture = 6 => "image_capture",
        /// Start recording the stream's output.
        RecordStart = 7 => "record_start",
        /// Stop recording.
        RecordStop = 8 => "record_stop",
    }
}

wire_enum! {
    /// Who sent a [`VisionControl`] (for logs and metrics).
    pub enum VisionOrigin: u8 {
        DigiView = 1 => "digiview",
        GimbalV2 = 2 => "gimbal_v2",
        /// A camera command of another gateway, accepted by the arbiter.
        Payload = 3 => "payload",
    }
}

/// A request to the vision pipeline; answered by one [`VisionReply`].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.VisionControl.v2")]
#[repr(C)]
pub struct VisionControl {
    pub header: SampleHeader,
    /// Chosen by the sender, unique per sender; echoed in the reply.
    pub request_id: u64,
    /// [`VisionControlKind`] as stored on the wire.
    pub kind: u8,
    /// [`VisionOrigin`] as stored on the wire.
    pub origin: u8,
    /// Stream index.
    pub stream: u8,
    /// Virtual camera 0–3, 255 = every camera of the stream (where the kind allows).
    pub cam: u8,
    /// MAVLink CAMERA_ZOOM_TYPE (`Zoom`).
    pub zoom_mode: u8,
    pub reserved: [u8; 3],
    /// MAVLink GIMBAL_MANAGER_FLAGS (`GimbalAttitude`).
    pub gimbal_flags: u32,
    pub yaw_rad: f32,
    pub pitch_rad: f32,
    pub yaw_rate_rps: f32,
    pub pitch_rate_rps: f32,
    /// Zoom value (`Zoom`).
    pub value: f32,
    pub alt_msl_m: f32,
    pub reserved2: u32,
    pub lat_deg: f64,
    pub lon_deg: f64,
}
crate::assert_layout!(
    VisionControl,
    size = 24 + 8 + 8 + 4 + 24 + 4 + 16,
    align = 8
);

crate::impl_sample!(VisionControl);

impl Default for VisionControl {
    fn default() -> Self {
        VisionControl {
            header: SampleHeader::default(),
            request_id: 0,
            kind: 0,
            origin: 0,
            stream: 0,
            cam: 0,
            zoom_mode: 0,
            reserved: [0; 3],
            gimbal_flags: 0,
            yaw_rad: f32::NAN,
            pitch_rad: f32::NAN,
            yaw_rate_rps: f32::NAN,
            pitch_rate_rps: f32::NAN,
            value: 0.0,
            alt_msl_m: 0.0,
            reserved2: 0,
            lat_deg: 0.0,
            lon_deg: 0.0,
        }
    }
}

wire_enum! {
    /// How the pipeline answered a [`VisionControl`].
    pub enum VisionResult: u8 {
        /// Done (or, for capture, started).
        Applied = 0 => "applied",
        /// Not applied because it names nothing that exists here (unknown stream,
        /// camera not in the layout, detection id not known) or the document says
        /// the value leaves the setting unchanged; `message` says which.
        Ignored = 1 => "ignored",
        /// The request itself is invalid (bad kind, NaN, out of range, undecodable).
        Invalid = 2 => "invalid",
        /// Not implemented here (SENSOR, CAM_DEPTH_ESTIMATION: disabled as in DigiView).
        Unsupported = 3 => "unsupported",
        /// Tried and failed (a capture file could not be written).
        Failed = 4 => "failed",
    }
}

/// The pipeline's answer to one [`VisionControl`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.VisionReply.v1")]
#[repr(C)]
pub struct VisionReply {
    pub header: SampleHeader,
    pub request_id: u64,
    /// [`VisionResult`] as stored on the wire.
    pub result: u8,
    /// The request's kind and origin, echoed.
    pub kind: u8,
    pub origin: u8,
    pub reserved: [u8; 5],
    /// Why, for anything but `Applied` (empty otherwise).
    pub message: FixedStr<96>,
}
crate::assert_layout!(VisionReply, size = 24 + 8 + 8 + 96, align = 8);

crate::impl_sample!(VisionReply);

/// A consumer's word that it uses the vision pipeline's output now (its state,
/// detections, virtual cameras): the DigiView gateway says so while a client is
/// connected, tools and tests while they read. The pipeline processes frames only
/// while some word says `wanted` (or its output frames have a subscriber, a capture
/// runs, a control came recently, or its config says `always_on`); it keeps each
/// publisher's (header `service`, `instance`) newest word for [`VISION_DEMAND_LEASE_NS`],
/// so a word is renewed every second and a dead publisher's lapses. A word that says
/// `wanted` resumes the pipeline at once.
///
/// Topic: [`crate::topics::vision_demand`] (latest value per publisher).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.VisionDemand.v1")]
#[repr(C)]
pub struct VisionDemand {
    pub header: SampleHeader,
    /// 1: the output is used now; 0: not any more.
    pub wanted: u8,
    pub reserved: [u8; 7],
}
crate::assert_layout!(VisionDemand, size = 24 + 8, align = 8);

/// How long a [`VisionDemand`] that says `wanted` holds without being renewed.
pub const VISION_DEMAND_LEASE_NS: u64 = 3_000_000_000;

crate::impl_sample!(VisionDemand);

impl VisionReply {
    pub fn result(&self) -> VisionResult {
        VisionResult::try_from(self.result).unwrap_or(VisionResult::Invalid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_lookups_stay_within_the_counts() {
        let mut s = VisionState::default();
        assert!(s.streams().is_empty());
        s.stream_count = 1;
        s.streams[0].name = StreamName::new("main");
        assert_eq!(s.stream_index("main"), Some(0));
        assert_eq!(s.stream_index("other"), None);
        s.detection_count = 200;
        assert_eq!(s.detections().len(), VISION_MAX_DETECTIONS);
    }

    #[test]
    fn a_default_control_leaves_every_axis_unchanged() {
        let c = VisionControl::default();
        assert!(c.yaw_rad.is_nan() && c.pitch_rad.is_nan());
        assert!(c.yaw_rate_rps.is_nan() && c.pitch_rate_rps.is_nan());
    }
}
