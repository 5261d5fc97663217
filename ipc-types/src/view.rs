//! Settings of the vision pipeline, in the pipeline's own terms: what a protocol
//! gateway sends to change or ask about the pipeline's views, detector and tracker.
//!
//! A [`ViewControl`] names a stream by name and carries one request
//! ([`ViewControlKind`]); the pipeline answers each with exactly one [`ViewReply`]
//! with the same `request_id` and `origin`, after it has published the
//! [`crate::VisionState`] that contains the change (read your writes). What the
//! pipeline holds is read from that state; [`ViewControlKind::DirectionAt`] asks for
//! what the state cannot hold: the direction at any point of a view.
//!
//! Units: angles in radians (yaw from true north clockwise, pitch from the horizon
//! up, roll right-wing-down), positions in degrees and metres, view offsets
//! normalised −1..1 (x right, y up, ±1 at the view's edges), ratios 0..1. A gateway
//! converts its wire's fixed point into these; the pipeline checks ranges and
//! answers `Invalid` (out of range, not finite), `Ignored` (names nothing that
//! exists, or a value that leaves the setting unchanged) or `Unsupported`.
//!
//! | kind | fields |
//! |---|---|
//! | `Ai` | `ai_enabled`, `scan_model`, `track_model` (empty = keep) |
//! | `Output` | `stream`, `width`, `height`, `layout_mode` (0–6), `overlay_mode` (0–5); out-of-range modes keep |
//! | `Capture` | `stream`, `capture_image`, `record` (1 start, 0 stop) |
//! | `Detection` | `detection_mode`, `sorting_mode` (0–2), confidences and overlaps 0..0.99, scores 0–254 ([`SCORE_KEEP`] keeps); out-of-range values keep |
//! | `Targeting` | `stream`, `cam`, `targeting_mode` ([`crate::TargetingMode`]), `euler_delta`, `yaw/pitch/roll_rad`, `lock_flags` (`LOCK_*`), `x/y_offset`, `lat/lon_deg`, `alt_rel_m` (target height relative to the vehicle) |
//! | `Optics` | `stream`, `cam`, `zoom` (−127..127, 0 none), `fov_rad` (horizontal), `crop_mode` ([`crate::CropMode`]) |
//! | `SingleTarget` | `stream`, `cam`, `track_command` ([`TrackCommand`]), `reference` ([`ReferenceFrame`]: `Global` aims at `yaw/pitch_rad`, otherwise at `x/y_offset` of the camera's view), `detection_id`, `track_zoom` (0–10) |
//! | `DirectionAt` | `stream`, `cam`, `x/y_offset`; the reply carries the direction (global and relative to the camera's axis) of that point of the camera's last rendered view |
//!
//! Topics: [`view_control`] (every requester → pipeline), [`view_reply`] (pipeline →
//! every requester; each matches its own `origin` and `request_id`).

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::topics::{Topic, TopicQos};
use crate::vision::{ModelName, StreamName};
use crate::wire_enum;

/// Detection score meaning "keep the current value".
pub const SCORE_KEEP: u8 = 255;

wire_enum! {
    /// What a [`ViewControl`] asks for.
    pub enum ViewControlKind: u8 {
        /// Detector on/off and its models.
        Ai = 1 => "ai",
        /// A stream's output size, layout and detection overlay.
        Output = 2 => "output",
        /// One image and/or start/stop recording a stream's output.
        Capture = 3 => "capture",
        /// The tracker's thresholds and scores.
        Detection = 4 => "detection",
        /// How a virtual camera is aimed.
        Targeting = 5 => "targeting",
        /// A virtual camera's zoom, field of view and projection.
        Optics = 6 => "optics",
        /// A command to a stream's single-target tracker.
        SingleTarget = 7 => "single_target",
        /// Where a point of a virtual camera's view looks (nothing changes).
        DirectionAt = 8 => "direction_at",
    }
}

wire_enum! {
    /// A single-target tracker command.
    pub enum TrackCommand: u8 {
        /// Stop tracking.
        Disable = 0 => "disable",
        /// Track whatever is in a direction (see [`ReferenceFrame`]).
        Direction = 1 => "direction",
        /// Follow detection `detection_id`.
        Detection = 2 => "detection",
        /// Move the tracked target by `x/y_offset` of the camera's view.
        Nudge = 3 => "nudge",
        /// Change nothing but the zoom level.
        NoOp = 4 => "no_op",
    }
}

wire_enum! {
    /// The frame a direction is given or reported in.
    pub enum ReferenceFrame: u8 {
        /// Yaw from true north, pitch from the horizon.
        Global = 0 => "global",
        /// Yaw relative to the vehicle's heading.
        Heading = 1 => "heading",
        /// Relative to the camera's axis.
        Camera = 2 => "camera",
    }
}

/// A request to the vision pipeline's views, detector or tracker; answered by one
/// [`ViewReply`]. Fields a kind does not use are ignored.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ViewControl.v1")]
#[repr(C)]
pub struct ViewControl {
    pub header: SampleHeader,
    /// Chosen by the sender, unique per sender; echoed in the reply.
    pub request_id: u64,
    /// The stream (all kinds but `Ai` and `Detection`).
    pub stream: StreamName,
    /// [`ViewControlKind`] as stored on the wire.
    pub kind: u8,
    /// [`crate::VisionOrigin`] of the sender, echoed in the reply.
    pub origin: u8,
    /// Virtual camera 0–3.
    pub cam: u8,
    pub ai_enabled: u8,
    pub layout_mode: u8,
    pub overlay_mode: u8,
    /// `Capture`: 1 takes one image.
    pub capture_image: u8,
    /// `Capture`: 1 records, 0 stops recording.
    pub record: u8,
    /// `Detection`: stored and reported, not used.
    pub detection_mode: u8,
    pub sorting_mode: u8,
    pub creation_score: u8,
    pub bonus_detection: u8,
    pub bonus_redetection: u8,
    pub missed_detection_penalty: u8,
    pub missed_redetection_penalty: u8,
    /// [`crate::TargetingMode`] as stored on the wire.
    pub targeting_mode: u8,
    /// `Targeting`: 1 adds the angles to the current ones.
    pub euler_delta: u8,
    /// `Targeting`: `LOCK_*` bits.
    pub lock_flags: u8,
    pub zoom: i8,
    /// [`crate::CropMode`] as stored on the wire.
    pub crop_mode: u8,
    /// [`TrackCommand`] as stored on the wire.
    pub track_command: u8,
    /// [`ReferenceFrame`] as stored on the wire.
    pub reference: u8,
    pub detection_id: u8,
    pub reserved: u8,
    /// `SingleTarget`: tracking box zoom level 0–10.
    pub track_zoom: u16,
    /// `Output`: pixels.
    pub width: u16,
    pub height: u16,
    pub reserved2: u16,
    pub scan_model: ModelName,
    pub track_model: ModelName,
    pub track_confidence: f64,
    pub scan_confidence: f64,
    pub track_overlap: f64,
    pub scan_overlap: f64,
    pub yaw_rad: f64,
    pub pitch_rad: f64,
    pub roll_rad: f64,
    pub x_offset: f64,
    pub y_offset: f64,
    pub fov_rad: f64,
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_rel_m: f64,
}
crate::assert_layout!(
    ViewControl,
    size = 24 + 8 + 8 + 24 + 8 + 32 + 4 * 8 + 9 * 8,
    align = 8
);

crate::impl_sample!(ViewControl);

impl ViewControl {
    pub fn kind(&self) -> Result<ViewControlKind, crate::UnknownValue> {
        ViewControlKind::try_from(self.kind)
    }
}

/// The pipeline's answer to one [`ViewControl`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ViewReply.v1")]
#[repr(C)]
pub struct ViewReply {
    pub header: SampleHeader,
    pub request_id: u64,
    /// [`crate::VisionResult`] as stored on the wire.
    pub result: u8,
    /// The request's kind and origin, echoed.
    pub kind: u8,
    pub origin: u8,
    pub reserved: [u8; 5],
    /// `DirectionAt`: the point's direction, global and relative to the camera's
    /// axis (0 otherwise).
    pub yaw_global_rad: f64,
    pub pitch_global_rad: f64,
    pub yaw_camera_rad: f64,
    pub pitch_camera_rad: f64,
    /// Why, for anything but `Applied` (empty otherwise).
    pub message: FixedStr<96>,
}
crate::assert_layout!(ViewReply, size = 24 + 8 + 8 + 32 + 96, align = 8);

crate::impl_sample!(ViewReply);

impl ViewReply {
    pub fn result(&self) -> crate::VisionResult {
        crate::VisionResult::try_from(self.result).unwrap_or(crate::VisionResult::Invalid)
    }
}

/// [`ViewControl`] requests to the vision pipeline (protocol gateways).
pub fn view_control() -> Topic {
    Topic {
        name: "skymesh/vision/view_control".into(),
        qos: TopicQos::COMMANDS,
    }
}

/// [`ViewReply`]s of the vision pipeline, one per [`ViewControl`].
pub fn view_reply() -> Topic {
    Topic {
        name: "skymesh/vision/view_reply".into(),
        qos: TopicQos::EVENTS,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_and_commands_round_trip() {
        for k in ViewControlKind::ALL {
            assert_eq!(ViewControlKind::try_from(k.to_wire()), Ok(*k));
        }
        assert!(ViewControlKind::try_from(0).is_err());
        assert!(TrackCommand::try_from(5).is_err());
        assert_eq!(ReferenceFrame::try_from(2), Ok(ReferenceFrame::Camera));
        let c = ViewControl {
            kind: ViewControlKind::Optics.to_wire(),
            ..ViewControl::default()
        };
        assert_eq!(c.kind(), Ok(ViewControlKind::Optics));
        assert_eq!(view_control().qos, TopicQos::COMMANDS);
        assert_ne!(view_control().name, view_reply().name);
    }
}
