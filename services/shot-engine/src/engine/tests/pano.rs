//! Pano: holds from entry, options both ways, a cylinder photographed station by
//! station until it exits to FLY, the sphere's count, the video pan and its pause, A
//! and B.

use skymesh_ipc_types::shot_api::shots::{NONE, PANO};
use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest};
use skymesh_ipc_types::{Button, Command, CommandKind, FlightMode, PayloadState};

use super::*;
use crate::shots::pano::{DEFAULT_LENS_FOV_DEG, SPHERE_ROWS};

fn options(pano_type: u8, run_state: u8, fov: i16, rate: f32, lens: f32) -> ShotEvent {
    ShotEvent::PanoOptions {
        pano_type,
        run_state,
        cylinder_fov: fov,
        deg_second_yaw: rate,
        lens_fov: lens,
    }
}

/// In pano (setup), GUIDED reached, a gimbal reporting level.
fn in_pano() -> Harness {
    let mut h = Harness::ready();
    camera(&mut h, 0.0);
    let out = h.app(ShotRequest::StartShot(PANO));
    assert_eq!(
        out.to_app,
        [
            ShotEvent::CurrentShot(PANO),
            options(0, 0, 220, 2.0, DEFAULT_LENS_FOV_DEG)
        ]
    );
    assert_eq!(
        cmds(&out),
        [
            Command::GrabFlightAuthority,
            Command::SetMode(FlightMode::Guided)
        ]
    );
    h.set_mode(FlightMode::Guided);
    h
}

fn camera(h: &mut Harness, pitch: f32) {
    h.payload(PayloadState {
        gimbal_valid: 1,
        gimbal_pitch_deg: pitch,
        ..PayloadState::default()
    });
}

/// Ticks for `ms`, the simulated vehicle and gimbal turning at once to what is asked.
fn run_with_camera(h: &mut Harness, ms: u64) -> Outputs {
    let mut all = Outputs::default();
    for _ in 0..ms / 40 {
        let o = h.tick();
        for c in cmds(&o) {
            match c {
                Command::SetYaw { yaw_deg, .. } => h.state.heading_deg = yaw_deg,
                Command::Gimbal { pitch_deg, .. } => camera(h, pitch_deg),
                _ => {}
            }
        }
        all.commands.extend(o.commands);
        all.to_app.extend(o.to_app);
    }
    all
}

fn pano_states(out: &Outputs) -> Vec<(u8, u8)> {
    out.to_app
        .iter()
        .filter_map(|m| match m {
            ShotEvent::PanoState { index, total } => Some((*index, *total)),
            _ => None,
        })
        .collect()
}

fn captures(out: &Outputs) -> usize {
    kinds(out)
        .iter()
        .filter(|k| **k == CommandKind::CameraCapture)
        .count()
}

#[test]
fn setup_holds_position_and_leaves_the_camera_to_the_pilot() {
    let mut h = in_pano();
    let out = h.run(1_000);
    assert!(captures(&out) == 0);
    assert!(!kinds(&out).contains(&CommandKind::SetYaw));
    assert!(cmds(&out).iter().all(|c| match c {
        Command::VelocityNed { vel_ned_mps, .. } => vel_ned_mps.iter().all(|v| v.abs() < 0.05),
        _ => true,
    }));
}

#[test]
fn a_cylinder_is_photographed_station_by_station_then_the_shot_exits_to_fly() {
    let mut h = in_pano();
    // 180° with a 90° lens: 3 photos, 45° apart around the camera yaw (east).
    let out = h.app(options(0, 1, 180, 0.0, 90.0));
    assert_eq!(out.to_app, [ShotEvent::PanoState { index: 0, total: 3 }]);
    let out = run_with_camera(&mut h, 15_000);
    assert_eq!(captures(&out), 3);
    assert_eq!(pano_states(&out), [(1, 3), (2, 3), (3, 3)]);
    let yaws: Vec<f32> = cmds(&out)
        .into_iter()
        .filter_map(|c| match c {
            Command::SetYaw { yaw_deg, .. } => Some(yaw_deg),
            _ => None,
        })
        .collect();
    assert_eq!(yaws, [45.0, 90.0, 135.0]);
    // Finished: the options say so (runState 2), then the shot ends in LOITER.
    let i = out
        .to_app
        .iter()
        .position(|m| *m == ShotEvent::CurrentShot(NONE))
        .expect("exited");
    assert_eq!(out.to_app[i - 1], options(0, 2, 180, 0.0, 90.0));
    assert!(cmds(&out).contains(&Command::SetMode(FlightMode::Loiter)));
    assert_eq!(h.engine.last_exit(), "finished");
    assert_eq!(h.engine.current_shot(), NONE);
}

#[test]
fn a_sphere_counts_its_photos() {
    let mut h = in_pano();
    let out = h.app(options(1, 1, 220, 0.0, 60.0));
    let total: u8 = SPHERE_ROWS.iter().map(|r| r.1).sum();
    assert_eq!(pano_states(&out), [(0, total)]);
    let out = run_with_camera(&mut h, 60_000);
    assert_eq!(captures(&out), usize::from(total));
    assert_eq!(h.engine.last_exit(), "finished");
}

#[test]
fn options_are_clamped_like_the_reference() {
    let mut h = in_pano();
    let out = h.app(options(0, 0, 30, 500.0, 500.0));
    assert!(out.to_app.is_empty(), "no echo");
    // B in setup answers with the options in use.
    h.button(Button::B);
    let out = h.button(Button::B);
    assert_eq!(out.to_app, [options(1, 0, 91, 0.0, 180.0)]);
}

#[test]
fn b_cycles_the_type_in_setup() {
    let mut h = in_pano();
    let mut types = Vec::new();
    for _ in 0..3 {
        match h.button(Button::B).to_app[..] {
            [ShotEvent::PanoOptions {
                pano_type,
                run_state: 0,
                deg_second_yaw,
                ..
            }] => {
                assert_eq!(deg_second_yaw, 0.0);
                types.push(pano_type)
            }
            ref other => panic!("{other:?}"),
        }
    }
    assert_eq!(types, [2, 1, 0], "cylinder → video → sphere → cylinder");
}

#[test]
fn a_starts_and_cancels_the_run() {
    let mut h = in_pano();
    let out = h.button(Button::A);
    assert_eq!(
        out.to_app,
        [
            ShotEvent::PanoState { index: 0, total: 5 },
            options(0, 1, 220, 2.0, DEFAULT_LENS_FOV_DEG)
        ]
    );
    run_with_camera(&mut h, 1_000);
    let out = h.button(Button::A);
    assert_eq!(out.to_app, [options(0, 0, 220, 2.0, DEFAULT_LENS_FOV_DEG)]);
    // The app's runState 0 cancels too.
    h.button(Button::A);
    h.app(options(0, 0, 220, 2.0, DEFAULT_LENS_FOV_DEG));
    let out = run_with_camera(&mut h, 2_000);
    assert_eq!(captures(&out), 0);
    assert_eq!(h.engine.current_shot(), PANO);
}

#[test]
fn the_video_pan_turns_until_paused_and_resumes() {
    let mut h = in_pano();
    h.app(options(2, 1, 220, 20.0, 90.0));
    let out = run_with_camera(&mut h, 2_000);
    let yaws: Vec<f32> = cmds(&out)
        .into_iter()
        .filter_map(|c| match c {
            Command::SetYaw { yaw_deg, .. } => Some(yaw_deg),
            _ => None,
        })
        .collect();
    assert!(yaws.len() >= 5, "{yaws:?}");
    assert!(yaws.windows(2).all(|w| w[1] > w[0]), "clockwise: {yaws:?}");
    assert!(h.state.heading_deg > 115.0, "{}", h.state.heading_deg);
    assert_eq!(captures(&out), 0, "a video pan takes no photos");
    let out = h.button(Button::Pause);
    assert_eq!(
        out.to_app,
        [ShotEvent::Pause, options(2, 1, 220, 0.0, 90.0)]
    );
    run_with_camera(&mut h, 400);
    let out = run_with_camera(&mut h, 2_000);
    assert!(!kinds(&out).contains(&CommandKind::SetYaw), "paused");
    let out = h.button(Button::Pause);
    assert_eq!(out.to_app[1], options(2, 1, 220, 20.0, 90.0));
    let out = run_with_camera(&mut h, 1_000);
    assert!(kinds(&out).contains(&CommandKind::SetYaw), "turning again");
    assert_eq!(h.engine.current_shot(), PANO, "runs until it is ended");
}
