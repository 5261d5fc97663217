//! DigiView parameters ↔ the pipeline's `ViewControl` / `ViewReply` (pure).
//!
//! digiview-proto has already turned the wire's fixed point into radians, degrees,
//! metres, normalised offsets and ratios; this module only moves those values into
//! the pipeline's fields and names its enums. The pipeline decides what a value
//! does (ranges, "leave unchanged" values, unknown streams and cameras).
//!
//! | DigiView SET | `ViewControlKind` |
//! |---|---|
//! | AI | `Ai` |
//! | VIDEO_OUTPUT | `Output` (views, boxes and fps are the pipeline's to compute) |
//! | CAPTURE | `Capture` |
//! | DETECTION | `Detection` (score 255 = [`SCORE_KEEP`]) |
//! | CAM_TARGETING | `Targeting` (`altitude` is relative to the vehicle) |
//! | CAM_OPTICS_AND_CONTROL | `Optics` |
//! | SINGLE_TARGET_TRACKING | `SingleTarget` (command 0–4, `rel_frame_of_reference` 0 global / 1 heading / 2 camera) |
//! | GET CAM_OFFSET | `DirectionAt`; its reply becomes the CURRENT payload |

use digiview_proto::{
    CamOffset, FixedName, Param, SingleTargetTracking, StreamName, SCORE_KEEP as WIRE_SCORE_KEEP,
};
use skymesh_ipc_types::view::SCORE_KEEP;
use skymesh_ipc_types::{FixedStr, ReferenceFrame, TrackCommand, ViewControl, ViewControlKind};

/// A bus name from a wire name (wire names are at most as long as bus names).
fn bus_name<const N: usize>(name: &FixedName<N>) -> FixedStr<N> {
    FixedStr::new(name.as_str())
}

fn control(kind: ViewControlKind, stream: &StreamName, cam: u8) -> ViewControl {
    ViewControl {
        kind: kind.to_wire(),
        stream: bus_name(stream),
        cam,
        ..ViewControl::default()
    }
}

/// DigiView's score byte "keep" as the pipeline's.
fn score(v: u8) -> u8 {
    if v == WIRE_SCORE_KEEP {
        SCORE_KEEP
    } else {
        v
    }
}

fn track_command(s: &SingleTargetTracking) -> Option<(TrackCommand, ReferenceFrame)> {
    let command = match s.command {
        0 => TrackCommand::Disable,
        1 => TrackCommand::Direction,
        2 => TrackCommand::Detection,
        3 => TrackCommand::Nudge,
        4 => TrackCommand::NoOp,
        _ => return None,
    };
    let reference = match s.rel_frame {
        0 => ReferenceFrame::Global,
        1 => ReferenceFrame::Heading,
        2 => ReferenceFrame::Camera,
        _ => return None,
    };
    Some((command, reference))
}

/// The request a checked SET of `param` becomes; `None` for what cannot be set
/// (GET-only and disabled types, refused before) or a command/frame value out of
/// range (refused by validation before).
pub fn set_control(param: &Param) -> Option<ViewControl> {
    Some(match param {
        Param::Ai(a) => ViewControl {
            kind: ViewControlKind::Ai.to_wire(),
            ai_enabled: u8::from(a.enabled),
            scan_model: bus_name(&a.scan_model),
            track_model: bus_name(&a.track_model),
            ..ViewControl::default()
        },
        Param::VideoOutput(v) => ViewControl {
            width: v.width,
            height: v.height,
            layout_mode: v.layout_mode,
            overlay_mode: v.overlay_mode,
            ..control(ViewControlKind::Output, &v.stream, 0)
        },
        Param::Capture(c) => ViewControl {
            capture_image: u8::from(c.single_image),
            record: u8::from(c.record_video),
            ..control(ViewControlKind::Capture, &c.stream, 0)
        },
        Param::Detection(d) => ViewControl {
            kind: ViewControlKind::Detection.to_wire(),
            detection_mode: d.mode,
            sorting_mode: d.sorting_mode,
            track_confidence: d.track_confidence,
            scan_confidence: d.scan_confidence,
            track_overlap: d.track_overlap,
            scan_overlap: d.scan_overlap,
            creation_score: score(d.creation_score),
            bonus_detection: score(d.bonus_detection),
            bonus_redetection: score(d.bonus_redetection),
            missed_detection_penalty: score(d.missed_detection_penalty),
            missed_redetection_penalty: score(d.missed_redetection_penalty),
            ..ViewControl::default()
        },
        Param::CamTargeting(t) => ViewControl {
            targeting_mode: t.mode,
            euler_delta: u8::from(t.euler_delta),
            yaw_rad: t.yaw,
            pitch_rad: t.pitch,
            roll_rad: t.roll,
            lock_flags: t.lock_flags,
            x_offset: t.x_offset,
            y_offset: t.y_offset,
            lat_deg: t.latitude,
            lon_deg: t.longitude,
            alt_rel_m: t.altitude,
            ..control(ViewControlKind::Targeting, &t.stream, t.cam)
        },
        Param::CamOpticsAndControl(o) => ViewControl {
            zoom: o.zoom,
            fov_rad: o.fov,
            crop_mode: o.crop_mode,
            ..control(ViewControlKind::Optics, &o.stream, o.cam)
        },
        Param::SingleTargetTracking(s) => {
            let (command, reference) = track_command(s)?;
            ViewControl {
                track_command: command.to_wire(),
                reference: reference.to_wire(),
                x_offset: s.x_offset,
                y_offset: s.y_offset,
                detection_id: s.detection_id,
                track_zoom: s.zoom,
                yaw_rad: s.yaw_global,
                pitch_rad: s.pitch_global,
                ..control(ViewControlKind::SingleTarget, &s.stream, s.cam)
            }
        }
        Param::SystemStatus(_)
        | Param::Model(_)
        | Param::DetectedRoi(_)
        | Param::CamOffset(_)
        | Param::Sensor(_)
        | Param::CamDepthEstimation(_) => return None,
    })
}

/// CAM_OFFSET's question: the direction at (x, y) of the camera's view.
pub fn direction_at(req: &CamOffset) -> ViewControl {
    ViewControl {
        x_offset: req.x,
        y_offset: req.y,
        ..control(ViewControlKind::DirectionAt, &req.stream, req.cam)
    }
}

/// CAM_OFFSET's answer: the question with the pipeline's direction.
pub fn cam_offset(req: &CamOffset, reply: &skymesh_ipc_types::ViewReply) -> CamOffset {
    CamOffset {
        yaw_global: reply.yaw_global_rad,
        pitch_global: reply.pitch_global_rad,
        yaw_rel: reply.yaw_camera_rad,
        pitch_rel: reply.pitch_camera_rad,
        ..*req
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use digiview_proto::{
        Ai, CamOpticsAndControl, CamTargeting, Capture, Detection, ModelName, VideoOutput,
    };
    use skymesh_ipc_types::ViewReply;

    fn main() -> StreamName {
        StreamName::new("main").unwrap()
    }

    #[test]
    fn every_settable_parameter_becomes_its_control() {
        let ai = set_control(&Param::Ai(Ai {
            enabled: true,
            scan_model: ModelName::new("blobs").unwrap(),
            track_model: ModelName::empty(),
        }))
        .unwrap();
        assert_eq!(ai.kind(), Ok(ViewControlKind::Ai));
        assert_eq!(
            (
                ai.ai_enabled,
                ai.scan_model.as_str(),
                ai.track_model.as_str()
            ),
            (1, "blobs", "")
        );
        let v = set_control(&Param::VideoOutput(VideoOutput {
            stream: main(),
            width: 1920,
            height: 1080,
            layout_mode: 4,
            overlay_mode: 2,
            ..VideoOutput::default()
        }))
        .unwrap();
        assert_eq!(
            (
                v.kind(),
                v.stream.as_str(),
                v.width,
                v.height,
                v.layout_mode,
                v.overlay_mode
            ),
            (Ok(ViewControlKind::Output), "main", 1920, 1080, 4, 2)
        );
        let c = set_control(&Param::Capture(Capture {
            stream: main(),
            single_image: true,
            record_video: false,
            ..Capture::default()
        }))
        .unwrap();
        assert_eq!((c.capture_image, c.record), (1, 0));
        let d = set_control(&Param::Detection(Detection {
            sorting_mode: 1,
            track_confidence: 0.5,
            creation_score: 60,
            bonus_detection: WIRE_SCORE_KEEP,
            ..Detection::default()
        }))
        .unwrap();
        assert_eq!(
            (
                d.sorting_mode,
                d.track_confidence,
                d.creation_score,
                d.bonus_detection
            ),
            (1, 0.5, 60, SCORE_KEEP)
        );
        let t = set_control(&Param::CamTargeting(CamTargeting {
            stream: main(),
            cam: 2,
            mode: 1,
            euler_delta: true,
            yaw: 1.5,
            pitch: -0.5,
            roll: 0.1,
            lock_flags: 0b101,
            x_offset: 0.25,
            y_offset: -0.75,
            latitude: 47.1,
            longitude: 8.2,
            altitude: -50.0,
        }))
        .unwrap();
        assert_eq!(t.kind(), Ok(ViewControlKind::Targeting));
        assert_eq!(
            (t.cam, t.targeting_mode, t.euler_delta, t.lock_flags),
            (2, 1, 1, 0b101)
        );
        assert_eq!(
            [t.yaw_rad, t.pitch_rad, t.roll_rad, t.x_offset, t.y_offset],
            [1.5, -0.5, 0.1, 0.25, -0.75]
        );
        assert_eq!([t.lat_deg, t.lon_deg, t.alt_rel_m], [47.1, 8.2, -50.0]);
        let o = set_control(&Param::CamOpticsAndControl(CamOpticsAndControl {
            stream: main(),
            cam: 1,
            zoom: -20,
            fov: 1.0,
            crop_mode: 2,
        }))
        .unwrap();
        assert_eq!((o.cam, o.zoom, o.fov_rad, o.crop_mode), (1, -20, 1.0, 2));
    }

    #[test]
    fn single_target_commands_and_frames_are_named() {
        let s = SingleTargetTracking {
            command: 1,
            stream: main(),
            cam: 3,
            x_offset: 0.5,
            y_offset: -0.5,
            detection_id: 9,
            zoom: 4,
            yaw_global: 1.0,
            pitch_global: -0.25,
            rel_frame: 0,
            ..SingleTargetTracking::default()
        };
        let c = set_control(&Param::SingleTargetTracking(s)).unwrap();
        assert_eq!(c.kind(), Ok(ViewControlKind::SingleTarget));
        assert_eq!(
            (
                c.cam,
                c.track_command,
                c.reference,
                c.detection_id,
                c.track_zoom
            ),
            (
                3,
                TrackCommand::Direction.to_wire(),
                ReferenceFrame::Global.to_wire(),
                9,
                4
            )
        );
        assert_eq!(
            [c.yaw_rad, c.pitch_rad, c.x_offset, c.y_offset],
            [1.0, -0.25, 0.5, -0.5]
        );
        for (command, want) in [
            (0, TrackCommand::Disable),
            (2, TrackCommand::Detection),
            (3, TrackCommand::Nudge),
            (4, TrackCommand::NoOp),
        ] {
            let c = set_control(&Param::SingleTargetTracking(SingleTargetTracking {
                command,
                ..s
            }))
            .unwrap();
            assert_eq!(c.track_command, want.to_wire());
        }
        let c = set_control(&Param::SingleTargetTracking(SingleTargetTracking {
            rel_frame: 2,
            ..s
        }))
        .unwrap();
        assert_eq!(c.reference, ReferenceFrame::Camera.to_wire());
        assert!(
            set_control(&Param::SingleTargetTracking(SingleTargetTracking {
                command: 5,
                ..s
            }))
            .is_none()
        );
        assert!(set_control(&Param::CamOffset(CamOffset::default())).is_none());
    }

    #[test]
    fn cam_offset_asks_and_answers_in_the_wire_units() {
        let req = CamOffset {
            stream: main(),
            cam: 1,
            x: 0.5,
            y: -0.25,
            ..CamOffset::default()
        };
        let q = direction_at(&req);
        assert_eq!(
            (q.kind(), q.stream.as_str(), q.cam, q.x_offset, q.y_offset),
            (Ok(ViewControlKind::DirectionAt), "main", 1, 0.5, -0.25)
        );
        let reply = ViewReply {
            yaw_global_rad: 1.25,
            pitch_global_rad: -0.5,
            yaw_camera_rad: 0.3,
            pitch_camera_rad: -0.1,
            ..ViewReply::default()
        };
        assert_eq!(
            cam_offset(&req, &reply),
            CamOffset {
                yaw_global: 1.25,
                pitch_global: -0.5,
                yaw_rel: 0.3,
                pitch_rel: -0.1,
                ..req
            }
        );
    }
}
