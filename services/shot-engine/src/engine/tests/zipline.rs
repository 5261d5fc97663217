//! Zipline: flies from entry, options both ways, A (new line), B / ZIPLINE_LOCK (spot
//! lock), LOCATION while locked, pause.

use skymesh_ipc_types::shot_api::shots::ZIPLINE;
use skymesh_ipc_types::shot_api::{Location, ShotEvent, ShotRequest};
use skymesh_ipc_types::{Button, Command, CommandKind, FlightMode};

use super::*;
use crate::shots::{projected_roi, VehicleView};

fn options(cruise: f32, is_3d: u8, cam: u8) -> ShotEvent {
    ShotEvent::ZiplineOptions {
        cruise_speed: cruise,
        is_3d,
        cam_pointing: cam,
    }
}

/// Zipline entered (vehicle heading east, no gimbal: the camera looks east, level),
/// GUIDED reached.
fn zipping() -> Harness {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::StartShot(ZIPLINE));
    assert_eq!(
        out.to_app,
        [ShotEvent::CurrentShot(ZIPLINE), options(0.0, 0, 0)]
    );
    assert_eq!(
        cmds(&out),
        [
            Command::GrabFlightAuthority,
            Command::SetMode(FlightMode::Guided)
        ]
    );
    assert!(h.engine.is_flying());
    h.set_mode(FlightMode::Guided);
    h
}

fn last_velocity(out: &Outputs) -> [f32; 3] {
    cmds(out)
        .into_iter()
        .rev()
        .find_map(|c| match c {
            Command::VelocityNed { vel_ned_mps, .. } => Some(vel_ned_mps),
            _ => None,
        })
        .expect("a setpoint")
}

fn view(h: &Harness) -> VehicleView {
    VehicleView {
        position: crate::shots::GeoPoint {
            lat_deg: h.state.lat_deg,
            lon_deg: h.state.lon_deg,
            alt_rel_m: h.state.alt_rel_m,
        },
        vel_ned_mps: [0.0; 3],
        heading_deg: h.state.heading_deg,
        camera_pitch_deg: 0.0,
        camera_yaw_deg: h.state.heading_deg,
    }
}

#[test]
fn zipline_holds_at_cruise_zero_then_flies_along_the_camera() {
    let mut h = zipping();
    let v = last_velocity(&h.run(400));
    assert!(v.iter().all(|x| x.abs() < 0.05), "cruise 0 holds: {v:?}");
    // The app sets the speed: no echo.
    let out = h.app(options(2.0, 0, 0));
    assert!(out.to_app.is_empty());
    assert_eq!(h.engine.status().cruise_speed_mps, 2.0);
    let v = last_velocity(&h.run(2_000));
    assert!((v[1] - 2.0).abs() < 0.1, "east at 2 m/s: {v:?}");
    assert!(v[0].abs() < 0.1 && v[2].abs() < 0.1, "{v:?}");
    // Free look: the camera is the pilot's.
    let out = h.run(400);
    assert!(!kinds(&out).contains(&CommandKind::SetYaw));
    assert!(!kinds(&out).contains(&CommandKind::SetRoi));
    // Negative: back the other way.
    h.app(options(-1.0, 0, 0));
    let v = last_velocity(&h.run(3_000));
    assert!((v[1] + 1.0).abs() < 0.1, "{v:?}");
}

#[test]
fn b_and_zipline_lock_toggle_the_spot_lock() {
    let mut h = zipping();
    let spot = projected_roi(&view(&h));
    let out = h.button(Button::B);
    assert_eq!(
        out.to_app,
        [
            ShotEvent::Location(Location {
                lat_deg: spot.lat_deg,
                lon_deg: spot.lon_deg,
                alt_m: spot.alt_rel_m
            }),
            options(0.0, 0, 1)
        ]
    );
    let out = h.tick();
    assert!(cmds(&out).contains(&Command::SetRoi {
        lat_deg: spot.lat_deg,
        lon_deg: spot.lon_deg,
        alt_rel_m: spot.alt_rel_m
    }));
    assert_eq!(h.engine.status().roi_valid, 1);
    // The app's lock toggles it off: the ROI is cleared.
    let out = h.app(ShotRequest::ZiplineLock);
    assert_eq!(out.to_app, [options(0.0, 0, 0)]);
    assert!(kinds(&h.tick()).contains(&CommandKind::ClearRoi));
    // Options with camPointing 1 lock it again.
    let out = h.app(options(1.0, 1, 1));
    assert!(matches!(out.to_app[0], ShotEvent::Location(_)));
    assert_eq!(out.to_app[1], options(1.0, 1, 1));
}

#[test]
fn a_location_moves_a_locked_spot_keeping_its_altitude() {
    let mut h = zipping();
    let out = h.app(ShotRequest::Location(loc(50.0)));
    assert!(out.to_app.is_empty(), "no spot lock: ignored");
    h.button(Button::B);
    let spot = projected_roi(&view(&h));
    let target = Location {
        alt_m: 7.0,
        ..loc(50.0)
    };
    let out = h.app(ShotRequest::Location(target));
    let moved = Location {
        alt_m: spot.alt_rel_m,
        ..loc(50.0)
    };
    assert_eq!(out.to_app, [ShotEvent::Location(moved)]);
    assert_eq!(h.engine.status().roi_lat_deg, moved.lat_deg);
}

#[test]
fn a_lays_a_new_line_from_the_camera_now() {
    let mut h = zipping();
    h.app(options(2.0, 0, 0));
    h.state.heading_deg = 0.0;
    h.push_state();
    let out = h.button(Button::A);
    assert_eq!(out.to_app, [options(2.0, 0, 0)]);
    let v = last_velocity(&h.run(3_000));
    assert!(
        (v[0] - 2.0).abs() < 0.1 && v[1].abs() < 0.1,
        "north now: {v:?}"
    );
}

#[test]
fn pause_toggles_the_cruise_speed_and_tells_the_app() {
    let mut h = zipping();
    h.app(options(2.5, 0, 0));
    let out = h.button(Button::Pause);
    assert_eq!(out.to_app, [ShotEvent::Pause, options(0.0, 0, 0)]);
    let out = h.app(ShotRequest::Pause);
    assert_eq!(out.to_app, [options(2.5, 0, 0)]);
}

#[test]
fn zipline_entry_is_gated_like_every_shot() {
    let mut h = Harness::ready();
    h.status.armed = 0;
    h.push_status();
    let out = h.app(ShotRequest::StartShot(ZIPLINE));
    assert_eq!(out.to_app, [ShotEvent::Refused(1)]);
    assert!(out.commands.is_empty());
}
