//! The DJI side of a panorama capture. `camera_mode_switch` 3 puts the gateway's
//! payload in panorama mode (the MAVLink camera itself stays in image mode);
//! `camera_photo_take` then asks the shot engine's task runner for a panorama
//! sweep ([`crate::tasks`], `PanoStart`): the runner turns the gimbal through the
//! stations from where it points (`[payload] pano_stations`, default 8 — DJI's own
//! full-circle panorama takes 8 — at `pano_pitch_deg`, each reached within
//! `pano_settle_timeout_ms`), takes one photo at each and turns it back. Its Pano
//! events become `camera_photo_take_progress` here ([`progress`]).
//!
//! | runner | event | need_reply |
//! |---|---|---|
//! | reply ok | camera_photo_take answered 0 with `output.status` `in_progress` | |
//! | `InProgress` (started, after each photo) | `in_progress`, current_step 3002, the runner's percent | 0 (a lost one is superseded by the next) |
//! | `Done` | `ok`, current_step 3000, 100 % | 1, re-sent until the cloud answers |
//! | `Stopped` (camera_photo_stop, answered 0) | `fail`, **result 0** (stopped on request, not an error), 3000, the percent reached | 1 |
//! | `Failed` | `fail`, the result's DJI code (314013 the gimbal never reached a station, 314012 link down, 314010 payload authority lost), 3000, the percent reached | 1 |
//!
//! skymesh does not stitch: the photos stay on the camera (there is no 3005
//! "synthesizing" step); the cloud, or a desktop tool, stitches them.

use dji_proto::{codes, CameraPhotoTakeProgress, PhotoTakeExt, PhotoTakeOutput, PhotoTakeProgress};
use skymesh_ipc_types::task::PanoTaskStatus;
use skymesh_ipc_types::TaskEvent;

use crate::tasks::result_code;

/// The event method of a panorama's progress.
pub const METHOD: &str = "camera_photo_take_progress";
/// `current_step`: "Panorama photo capturing is not started or is finished".
pub const STEP_IDLE: u16 = 3000;
/// `current_step`: "Panorama photo is capturing".
pub const STEP_CAPTURING: u16 = 3002;
/// `ext.camera_mode` of every panorama event.
pub const CAMERA_MODE_PANORAMA: u8 = 3;

/// `camera_photo_take_progress` data of a Pano event, and whether it ends the
/// panorama (then it needs a reply); `None` for an unknown status.
pub fn progress(e: &TaskEvent) -> Option<(CameraPhotoTakeProgress, bool)> {
    let percent = e.pano_percent.min(100);
    let (status, current_step, percent, result) = match e.pano_status().ok()? {
        PanoTaskStatus::InProgress => ("in_progress", STEP_CAPTURING, percent, codes::OK),
        PanoTaskStatus::Done => ("ok", STEP_IDLE, 100, codes::OK),
        PanoTaskStatus::Stopped => ("fail", STEP_IDLE, percent, codes::OK),
        PanoTaskStatus::Failed => (
            "fail",
            STEP_IDLE,
            percent,
            e.result().map_or(codes::INTERNAL, result_code),
        ),
    };
    let data = CameraPhotoTakeProgress {
        output: PhotoTakeOutput {
            status,
            progress: PhotoTakeProgress {
                current_step,
                percent,
            },
            ext: PhotoTakeExt {
                camera_mode: CAMERA_MODE_PANORAMA,
            },
        },
        result,
    };
    Some((data, status != "in_progress"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;
    use skymesh_ipc_types::{TaskEventKind, TaskResult};

    fn event(status: PanoTaskStatus, result: TaskResult, percent: u8) -> TaskEvent {
        TaskEvent {
            kind: TaskEventKind::Pano.to_wire(),
            status: status.to_wire(),
            result: result.to_wire(),
            pano_photos: 1,
            pano_stations: 8,
            pano_percent: percent,
            ..Default::default()
        }
    }

    #[test]
    fn progress_events_have_the_documented_shape() {
        let (d, end) = progress(&event(PanoTaskStatus::InProgress, TaskResult::Ok, 11)).unwrap();
        assert!(!end);
        assert_eq!(
            serde_json::to_value(d).unwrap(),
            json!({
                "output": {
                    "status": "in_progress",
                    "progress": { "current_step": 3002, "percent": 11 },
                    "ext": { "camera_mode": 3 },
                },
                "result": 0,
            })
        );
        let (fail, end) =
            progress(&event(PanoTaskStatus::Failed, TaskResult::WrongState, 11)).unwrap();
        let fail = serde_json::to_value(fail).unwrap();
        assert!(end);
        assert_eq!(fail["output"]["status"], "fail");
        assert_eq!(fail["output"]["progress"]["current_step"], 3000);
        assert_eq!(fail["output"]["progress"]["percent"], 11);
        assert_eq!(fail["result"], 314013);
        let (stopped, end) = progress(&event(PanoTaskStatus::Stopped, TaskResult::Ok, 22)).unwrap();
        let stopped = serde_json::to_value(stopped).unwrap();
        assert!(end);
        assert_eq!(stopped["output"]["status"], "fail");
        assert_eq!(
            (
                stopped["result"].clone(),
                stopped["output"]["progress"]["percent"].clone()
            ),
            (json!(0), json!(22))
        );
        let (ok, end) = progress(&event(PanoTaskStatus::Done, TaskResult::Ok, 88)).unwrap();
        let ok = serde_json::to_value(ok).unwrap();
        assert!(end);
        assert_eq!(ok["output"]["status"], "ok");
        assert_eq!(ok["output"]["progress"]["percent"], 100);
        assert_eq!(ok["output"]["progress"]["current_step"], 3000);
        assert!(progress(&TaskEvent {
            status: 9,
            ..Default::default()
        })
        .is_none());
    }
}
