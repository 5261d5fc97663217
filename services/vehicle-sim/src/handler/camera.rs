//! MAVLink camera-protocol commands for the autopilot-attached camera (camera id
//! 1; 0 addresses every camera, any other id is DENIED as MAVLink asks of an
//! autopilot with no such local camera). The zoom is in [`super::actuators`].
//!
//! | command | accepted | refused |
//! |---|---|---|
//! | SET_CAMERA_MODE p1 camera, p2 CAMERA_MODE | 0 image, 1 video, 2 image survey: the mode is recorded ([`crate::model::Payload::camera_mode`]) | DENIED: unknown camera, a mode MAVLink does not define |
//! | IMAGE_START_CAPTURE p1 camera, p2 interval s, p3 total (0 = until stopped) | one photo at once; a sequence then takes one per interval; a finite total without an interval all at once | DENIED: unknown camera, a total that is not a whole number ≥ 0, a negative or non-number interval, an endless sequence without an interval |
//! | IMAGE_STOP_CAPTURE p1 camera | ends a running interval or endless sequence (accepted when none runs, too) | DENIED: unknown camera |
//! | SET_CAMERA_FOCUS p1 SET_FOCUS_TYPE, p2 value, p3 camera | 0 step ±1 (1 % of the range); 1 continuous −1..=1 × 20 %/s until 0 or an end (beyond ±1 clipped); 2 range 0..=100 %; 3 metres ≥ 0; 4 auto, 5 auto single, 6 auto continuous (value ignored) | DENIED: unknown camera, a value out of range or not a number, a type MAVLink does not define |
//!
//! ArduPilot answers the focus types it cannot drive (step, metres) DENIED; the
//! simulated lens does them all, so a client's use of each can be tested.

use mavlink::dialects::ardupilotmega::MavResult;
use tracing::info;

use super::actuators::CAMERA_ID;
use super::command::Cmd;
use crate::model::{CameraMode, FocusControl, Vehicle};

/// Camera id params: 0 (all) or the simulator's one camera.
fn known_camera(id: f32) -> bool {
    id == 0.0 || id == CAMERA_ID
}

/// MAV_CMD_SET_CAMERA_MODE.
pub(super) fn set_mode(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    let [camera, mode, _, _] = cmd.p;
    if !known_camera(camera) {
        return MavResult::MAV_RESULT_DENIED;
    }
    match CameraMode::from_param(mode) {
        Some(mode) => {
            info!(?mode, "camera mode");
            v.payload_mut().camera_mode = mode;
            MavResult::MAV_RESULT_ACCEPTED
        }
        None => MavResult::MAV_RESULT_DENIED,
    }
}

/// MAV_CMD_IMAGE_START_CAPTURE.
pub(super) fn start_capture(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    let [camera, interval, total, _] = cmd.p;
    if !known_camera(camera) {
        return MavResult::MAV_RESULT_DENIED;
    }
    match v
        .payload_mut()
        .start_capture(f64::from(interval), f64::from(total))
    {
        Ok(()) => MavResult::MAV_RESULT_ACCEPTED,
        Err(why) => {
            info!(?why, "image capture refused");
            MavResult::MAV_RESULT_DENIED
        }
    }
}

/// MAV_CMD_IMAGE_STOP_CAPTURE.
pub(super) fn stop_capture(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    if !known_camera(cmd.p[0]) {
        return MavResult::MAV_RESULT_DENIED;
    }
    if v.payload_mut().stop_capture() {
        info!("image sequence stopped");
    }
    MavResult::MAV_RESULT_ACCEPTED
}

/// MAV_CMD_SET_CAMERA_FOCUS.
pub(super) fn focus(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    use MavResult::*;
    let [kind, value, camera, _] = cmd.p;
    if !known_camera(camera) {
        return MAV_RESULT_DENIED;
    }
    let value = f64::from(value);
    let focus = &mut v.payload_mut().focus;
    let mut auto = |control| {
        focus.auto(control);
        Ok(())
    };
    let result = match kind {
        0.0 => focus.step_by(value),
        1.0 => focus.continuous(value),
        2.0 => focus.set_level(value),
        3.0 => focus.set_distance(value),
        // The automatic types ignore the value, whatever it is.
        4.0 => auto(FocusControl::Auto),
        5.0 => auto(FocusControl::AutoSingle),
        6.0 => auto(FocusControl::AutoContinuous),
        _ => return MAV_RESULT_DENIED,
    };
    match result {
        Ok(()) => MAV_RESULT_ACCEPTED,
        Err(why) => {
            info!(?why, "focus refused");
            MAV_RESULT_DENIED
        }
    }
}
