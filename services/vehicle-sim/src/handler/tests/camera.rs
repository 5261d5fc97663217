//! Camera and gimbal-rate handler tests: SET_CAMERA_MODE, IMAGE_START/STOP_CAPTURE,
//! SET_CAMERA_FOCUS and DO_GIMBAL_MANAGER_PITCHYAW with rates, each in the form
//! autopilot-link sends (reserved params NaN) and refused with bad values.

use super::*;
use crate::model::{CameraMode, FocusControl, GimbalTarget, MIN_FOCUS_M};

const OK: MavResult = MavResult::MAV_RESULT_ACCEPTED;
const DENIED: MavResult = MavResult::MAV_RESULT_DENIED;
const FAILED: MavResult = MavResult::MAV_RESULT_FAILED;
const NAN: f32 = f32::NAN;

fn camera_mode(h: &Handler, v: &mut Vehicle, camera: f32, mode: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_SET_CAMERA_MODE,
        [camera, mode, NAN, NAN, 0., 0., NAN],
    )
}

fn start(h: &Handler, v: &mut Vehicle, camera: f32, interval: f32, total: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_IMAGE_START_CAPTURE,
        [camera, interval, total, 0., 0., 0., 0.],
    )
}

fn stop(h: &Handler, v: &mut Vehicle, camera: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE,
        [camera, NAN, NAN, NAN, 0., 0., NAN],
    )
}

fn focus(h: &Handler, v: &mut Vehicle, kind: f32, value: f32, camera: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_SET_CAMERA_FOCUS,
        [kind, value, camera, NAN, 0., 0., 0.],
    )
}

/// autopilot-link's GimbalRate: angles NaN, rates, yaw in the vehicle frame.
fn rates(h: &Handler, v: &mut Vehicle, pitch: f32, yaw: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        [NAN, NAN, pitch, yaw, 32., 0., 0.],
    )
}

fn pitch_yaw_deg(v: &Vehicle) -> (f64, f64) {
    let a = v.gimbal().attitude();
    (a.pitch.to_degrees(), a.yaw.to_degrees())
}

#[test]
fn camera_mode_is_set_for_this_or_every_camera() {
    let (h, mut v) = setup();
    assert_eq!(
        v.payload().camera_mode,
        CameraMode::Image,
        "starts in photo"
    );
    assert_eq!(camera_mode(&h, &mut v, 0., 1.), OK);
    assert_eq!(v.payload().camera_mode, CameraMode::Video);
    assert_eq!(camera_mode(&h, &mut v, 1., 2.), OK);
    assert_eq!(v.payload().camera_mode, CameraMode::ImageSurvey);
    assert_eq!(camera_mode(&h, &mut v, 1., 0.), OK);
    assert_eq!(v.payload().camera_mode, CameraMode::Image);
}

#[test]
fn camera_mode_refusals_change_nothing() {
    let (h, mut v) = setup();
    assert_eq!(camera_mode(&h, &mut v, 0., 1.), OK);
    for (camera, mode) in [
        (0., 3.),
        (0., 0.5),
        (0., -1.),
        (0., NAN),
        (2., 0.),
        (NAN, 0.),
    ] {
        assert_eq!(
            camera_mode(&h, &mut v, camera, mode),
            DENIED,
            "{camera} {mode}"
        );
    }
    assert_eq!(v.payload().camera_mode, CameraMode::Video);
}

#[test]
fn image_stop_capture_ends_an_endless_interval_sequence() {
    let (h, mut v) = setup();
    // Every 1 s until stopped: one at once, then one a second.
    assert_eq!(start(&h, &mut v, 0., 1., 0.), OK);
    assert_eq!(v.payload().images_captured, 1);
    run(&mut v, 3.5);
    assert_eq!(v.payload().images_captured, 4);
    assert!(v.payload().image_sequence.is_some());
    assert_eq!(stop(&h, &mut v, 0.), OK);
    assert_eq!(v.payload().image_sequence, None);
    run(&mut v, 3.0);
    assert_eq!(v.payload().images_captured, 4, "no photo after the stop");
    // Stopping when nothing runs is still accepted; this camera by id too.
    assert_eq!(stop(&h, &mut v, 1.), OK);
    // A finite sequence stopped half way.
    assert_eq!(start(&h, &mut v, 1., 2., 10.), OK);
    run(&mut v, 2.5);
    assert_eq!(v.payload().images_captured, 6);
    assert_eq!(stop(&h, &mut v, 1.), OK);
    run(&mut v, 30.0);
    assert_eq!(v.payload().images_captured, 6);
}

#[test]
fn capture_refusals_are_denied_and_keep_the_sequence() {
    let (h, mut v) = setup();
    assert_eq!(start(&h, &mut v, 0., 5., 0.), OK);
    assert_eq!(stop(&h, &mut v, 3.), DENIED, "no camera 3");
    assert_eq!(stop(&h, &mut v, NAN), DENIED);
    assert!(v.payload().image_sequence.is_some(), "still running");
    for (camera, interval, total) in [
        (2., 1., 1.),
        (0., 0., 0.),
        (0., -1., 0.),
        (0., NAN, 5.),
        (0., 1., -1.),
        (0., 1., 2.5),
    ] {
        assert_eq!(
            start(&h, &mut v, camera, interval, total),
            DENIED,
            "{camera} {interval} {total}"
        );
    }
    assert_eq!(v.payload().images_captured, 1);
}

#[test]
fn gimbal_rate_turns_until_a_rate_of_zero() {
    let (h, mut v) = setup();
    assert_eq!(rates(&h, &mut v, -20., 30.), OK);
    assert_eq!(
        v.gimbal().target(),
        GimbalTarget::Rates {
            pitch: (-20f64).to_radians(),
            yaw: 30f64.to_radians()
        }
    );
    run(&mut v, 1.0);
    let (p, y) = pitch_yaw_deg(&v);
    assert!((p + 20.0).abs() < 0.5 && (y - 30.0).abs() < 0.5, "{p} {y}");
    run(&mut v, 1.0);
    let (p, y) = pitch_yaw_deg(&v);
    assert!((p + 40.0).abs() < 0.5 && (y - 60.0).abs() < 0.5, "{p} {y}");
    let m = v.payload().mount.expect("recorded");
    assert_eq!((m.pitch_rate_dps, m.yaw_rate_dps), (-20.0, 30.0));
    assert!(m.pitch_deg.is_nan() && m.yaw_deg.is_nan());
    // Rate 0: holds where it is.
    assert_eq!(rates(&h, &mut v, 0., 0.), OK);
    run(&mut v, 2.0);
    let (p2, y2) = pitch_yaw_deg(&v);
    assert!((p2 - p).abs() < 0.5 && (y2 - y).abs() < 0.5, "{p2} {y2}");
}

#[test]
fn gimbal_rate_respects_slew_rate_and_travel_and_yields_to_an_angle() {
    let (h, mut v) = setup();
    // 300 deg/s asked, the gimbal turns at its 90 deg/s slew rate.
    assert_eq!(rates(&h, &mut v, 0., 300.), OK);
    run(&mut v, 1.0);
    let y = pitch_yaw_deg(&v).1;
    assert!((y - 90.0).abs() < 1.0, "{y}");
    // ... and stops at the end of its travel (±180°, pitch −90..=+30).
    assert_eq!(rates(&h, &mut v, -300., 300.), OK);
    run(&mut v, 5.0);
    let (p, y) = pitch_yaw_deg(&v);
    assert!(
        (p + 90.0).abs() < 1e-6 && (y - 180.0).abs() < 1e-6,
        "{p} {y}"
    );
    assert_eq!(rates(&h, &mut v, 300., 0.), OK);
    run(&mut v, 5.0);
    assert!((pitch_yaw_deg(&v).0 - 30.0).abs() < 1e-6);
    // An angle command ends the rates.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [-10., 20., NAN, NAN, 32., 0., 0.]
        ),
        OK
    );
    run(&mut v, 5.0);
    let (p, y) = pitch_yaw_deg(&v);
    assert!(
        (p + 10.0).abs() < 1e-6 && (y - 20.0).abs() < 1e-6,
        "{p} {y}"
    );
}

#[test]
fn gimbal_rate_refusals() {
    let (h, mut v) = setup();
    for (pitch, yaw) in [
        (361., 0.),
        (0., -400.),
        (f32::INFINITY, 0.),
        (0., f32::NEG_INFINITY),
    ] {
        assert_eq!(rates(&h, &mut v, pitch, yaw), DENIED, "{pitch} {yaw}");
    }
    // One rate unset and no angles: nothing usable, as ArduPilot (FAILED).
    assert_eq!(rates(&h, &mut v, 10., NAN), FAILED);
    assert_eq!(v.payload().mount, None, "refusals are not recorded");
    assert_eq!(v.gimbal().target(), GimbalTarget::Hold);
}

#[test]
fn camera_focus_each_type() {
    let (h, mut v) = setup();
    let f = |v: &Vehicle| v.payload().focus;
    assert_eq!(f(&v).level_pct(), 100.0, "starts at infinity");
    // Step in.
    assert_eq!(focus(&h, &mut v, 0., -1., 0.), OK);
    assert_eq!(f(&v).level_pct(), 99.0);
    // Continuous in at full rate (20 %/s) until stopped.
    assert_eq!(focus(&h, &mut v, 1., -1., 1.), OK);
    run(&mut v, 1.0);
    assert!(
        (f(&v).level_pct() - 79.0).abs() < 1e-6,
        "{}",
        f(&v).level_pct()
    );
    assert_eq!(focus(&h, &mut v, 1., 0., 0.), OK);
    run(&mut v, 1.0);
    assert!((f(&v).level_pct() - 79.0).abs() < 1e-6, "stopped");
    // Range, metres.
    assert_eq!(focus(&h, &mut v, 2., 25., 0.), OK);
    assert_eq!(f(&v).level_pct(), 25.0);
    assert_eq!(focus(&h, &mut v, 3., 5., 0.), OK);
    assert!((f(&v).distance_m() - 5.0).abs() < 1e-5);
    assert_eq!(focus(&h, &mut v, 3., 0., 0.), OK);
    assert_eq!(f(&v).distance_m(), MIN_FOCUS_M, "its closest");
    assert_eq!(f(&v).control(), FocusControl::Manual);
    // The automatic types ignore the value (autopilot-link sends 0; anything goes).
    for (kind, control) in [
        (4., FocusControl::Auto),
        (5., FocusControl::AutoSingle),
        (6., FocusControl::AutoContinuous),
    ] {
        assert_eq!(focus(&h, &mut v, kind, NAN, 0.), OK);
        assert_eq!(f(&v).control(), control);
    }
    assert_eq!(focus(&h, &mut v, 2., 60., 0.), OK);
    assert_eq!(f(&v).control(), FocusControl::Manual, "manual again");
}

#[test]
fn camera_focus_refusals_change_nothing() {
    let (h, mut v) = setup();
    assert_eq!(focus(&h, &mut v, 2., 40., 0.), OK);
    for (kind, value, camera) in [
        (0., 2., 0.),
        (0., NAN, 0.),
        (1., f32::INFINITY, 0.),
        (2., 100.5, 0.),
        (2., -0.5, 0.),
        (3., -1., 0.),
        (3., f32::INFINITY, 0.),
        // Not a SET_FOCUS_TYPE.
        (7., 0., 0.),
        (2.5, 50., 0.),
        (NAN, 50., 0.),
        // No such camera.
        (2., 50., 2.),
        (4., 0., 9.),
    ] {
        assert_eq!(
            focus(&h, &mut v, kind, value, camera),
            DENIED,
            "{kind} {value} {camera}"
        );
    }
    assert_eq!(v.payload().focus.level_pct(), 40.0);
    assert_eq!(v.payload().focus.control(), FocusControl::Manual);
}
