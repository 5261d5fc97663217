//! Selfie, orbit and cable cam: setup, start of flight, options and pause.

use skymesh_ipc_types::shot_api::shots::{CABLECAM, NONE, ORBIT, SELFIE};
use skymesh_ipc_types::shot_api::{Location, ShotEvent, ShotRequest};
use skymesh_ipc_types::{Button, Command, CommandKind, FlightMode, ShotPhase};

use super::*;
use crate::shots::CABLE_MIN_LENGTH_M;

fn roi_of(c: &Command) -> (f64, f64, f32) {
    match *c {
        Command::SetRoi {
            lat_deg,
            lon_deg,
            alt_rel_m,
        } => (lat_deg, lon_deg, alt_rel_m),
        other => panic!("not a SetRoi: {other:?}"),
    }
}

#[test]
fn selfie_collects_near_far_roi_then_flies() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::StartShot(SELFIE));
    assert_eq!(
        out.to_app,
        [
            ShotEvent::CurrentShot(SELFIE),
            ShotEvent::ShotOptions { cruise_speed: 2.0 }
        ]
    );
    for n in [5.0, 40.0] {
        let out = h.app(ShotRequest::Location(loc(n)));
        assert!(
            out.commands.is_empty(),
            "not flying before the third location"
        );
        assert!(out.to_app.is_empty());
    }
    let roi = Location {
        alt_m: 1.5,
        ..loc(-20.0)
    };
    let out = h.app(ShotRequest::Location(roi));
    let c = cmds(&out);
    assert_eq!(c[0], Command::GrabFlightAuthority);
    assert_eq!(c[1], Command::SetMode(FlightMode::Guided));
    assert_eq!(
        roi_of(&c[2]),
        (roi.lat_deg, roi.lon_deg, 1.5),
        "ROI altitude as sent"
    );
    assert!(all_ours(&out));

    // Every tick: one velocity setpoint with the configured max age.
    let out = h.tick();
    let v = find(&out, CommandKind::VelocityNed).unwrap();
    assert_eq!(v.max_age_ms, 500);
    assert_eq!(out.commands.iter().filter(|c| c.kind == v.kind).count(), 1);

    // A fourth location is ignored: nothing changes.
    let out = h.app(ShotRequest::Location(loc(100.0)));
    assert!(out.commands.is_empty() && out.to_app.is_empty());
    assert_eq!(h.engine.status().roi_lat_deg, roi.lat_deg);

    // SHOT_OPTIONS sets the speed (no echo).
    let out = h.app(ShotRequest::ShotOptions { cruise_speed: 4.0 });
    assert!(out.to_app.is_empty());
    assert_eq!(h.engine.status().cruise_speed_mps, 4.0);
}

#[test]
fn orbit_echoes_its_roi_and_a_new_location_starts_a_new_orbit() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(ORBIT));
    let out = h.app(ShotRequest::Location(loc(30.0)));
    assert_eq!(out.to_app, [ShotEvent::Location(loc(30.0))]);
    assert_eq!(
        kinds(&out),
        [
            CommandKind::GrabFlightAuthority,
            CommandKind::SetMode,
            CommandKind::SetRoi
        ]
    );
    // Once GUIDED, the ROI is sent again (GUIDED resets ArduCopter's yaw mode).
    h.set_mode(FlightMode::Guided);
    assert_eq!(kinds(&h.tick()), [CommandKind::SetRoi]);
    h.run(200);

    let out = h.app(ShotRequest::Location(loc(-10.0)));
    assert_eq!(out.to_app, [ShotEvent::Location(loc(-10.0))]);
    // Same flight: a new ROI, no new GUIDED or grab.
    assert_eq!(kinds(&out), [CommandKind::SetRoi]);
    assert!((h.engine.status().progress - 10.0).abs() < 0.5);
}

#[test]
fn orbit_roi_from_the_a_button_is_the_projected_roi() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(ORBIT));
    // Camera level, vehicle heading east: the ROI is 20 m east at the vehicle's altitude.
    let out = h.button(Button::A);
    let [ShotEvent::Location(l)] = out.to_app[..] else {
        panic!("{:?}", out.to_app);
    };
    assert!((l.lat_deg - LAT).abs() < 1e-6);
    assert!(l.lon_deg > LON);
    assert_eq!(l.alt_m, ALT);
    assert!(h.engine.is_flying());

    // RECORD_POSITION does the same (camera pointing straight down → below the vehicle).
    let mut h = Harness::ready();
    h.payload(skymesh_ipc_types::PayloadState {
        gimbal_valid: 1,
        gimbal_pitch_deg: -90.0,
        ..Default::default()
    });
    h.app(ShotRequest::StartShot(ORBIT));
    let out = h.app(ShotRequest::RecordPosition);
    let l = out
        .to_app
        .iter()
        .find_map(|m| match m {
            ShotEvent::Location(l) => Some(*l),
            _ => None,
        })
        .unwrap();
    assert!((l.lat_deg - LAT).abs() < 1e-6 && (l.lon_deg - LON).abs() < 1e-6);
    assert_eq!(l.alt_m, 0.0);
}

#[test]
fn pause_toggles_both_ways_and_tells_the_app() {
    let mut h = Harness::ready();
    h.orbiting();
    h.app(ShotRequest::ShotOptions { cruise_speed: 3.0 });
    // From the app: options back, no SOLO_PAUSE echo.
    let out = h.app(ShotRequest::Pause);
    assert_eq!(out.to_app, [ShotEvent::ShotOptions { cruise_speed: 0.0 }]);
    assert_eq!(out.status.unwrap().phase(), ShotPhase::Paused);
    let out = h.app(ShotRequest::Pause);
    assert_eq!(out.to_app, [ShotEvent::ShotOptions { cruise_speed: 3.0 }]);
    // From the controller: the app also gets SOLO_PAUSE.
    let out = h.button(Button::Pause);
    assert_eq!(
        out.to_app,
        [
            ShotEvent::Pause,
            ShotEvent::ShotOptions { cruise_speed: 0.0 }
        ]
    );
    let out = h.button(Button::Pause);
    assert_eq!(
        out.to_app,
        [
            ShotEvent::Pause,
            ShotEvent::ShotOptions { cruise_speed: 3.0 }
        ]
    );
    // Outside a shot a pause does nothing.
    h.button(Button::Fly);
    assert!(h.button(Button::Pause).to_app.is_empty());
}

#[test]
fn cable_cam_waypoints_overwrite_and_options_after_the_second_point() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::StartShot(CABLECAM));
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(CABLECAM)]);
    h.payload(skymesh_ipc_types::PayloadState {
        gimbal_valid: 1,
        gimbal_pitch_deg: -30.0,
        ..Default::default()
    });

    let out = h.app(ShotRequest::RecordPosition);
    assert_eq!(
        out.to_app,
        [ShotEvent::CableCamWaypoint {
            lat_deg: LAT,
            lon_deg: LON,
            alt_m: ALT,
            yaw_deg: 90.0,
            pitch_deg: -30.0
        }]
    );

    // A second point on top of the first replaces it: -1, 2, the new first point.
    h.move_north(CABLE_MIN_LENGTH_M / 2.0);
    let out = h.button(Button::A);
    let moved = h.state.lat_deg;
    assert_eq!(
        out.to_app,
        [
            ShotEvent::CurrentShot(NONE),
            ShotEvent::CurrentShot(CABLECAM),
            ShotEvent::CableCamWaypoint {
                lat_deg: moved,
                lon_deg: LON,
                alt_m: ALT,
                yaw_deg: 90.0,
                pitch_deg: -30.0
            }
        ]
    );
    assert!(out.commands.is_empty());
    assert_eq!(h.engine.current_shot(), CABLECAM, "still in cable cam");

    // The real second point: waypoint, options (interpolation on, memorised
    // direction, current speed), then the flight starts.
    h.state.heading_deg = 120.0;
    h.move_north(30.0);
    let out = h.app(ShotRequest::RecordPosition);
    assert!(
        matches!(out.to_app[0], ShotEvent::CableCamWaypoint { yaw_deg, .. } if yaw_deg == 120.0)
    );
    assert_eq!(
        out.to_app[1],
        ShotEvent::CableOptions {
            cam_interpolation: 1,
            yaw_direction_cw: 1,
            cruise_speed: 0.0
        }
    );
    assert_eq!(out.to_app.len(), 2);
    assert_eq!(
        kinds(&out),
        [CommandKind::GrabFlightAuthority, CommandKind::SetMode]
    );
    h.set_mode(FlightMode::Guided);
    assert!(h.engine.is_flying());

    // The app's options: speed, then pause → speed 0 and back.
    h.app(ShotRequest::CableOptions {
        cam_interpolation: 0,
        yaw_direction_cw: 0,
        cruise_speed: -2.5,
    });
    let out = h.button(Button::Pause);
    assert_eq!(
        out.to_app,
        [
            ShotEvent::Pause,
            ShotEvent::CableOptions {
                cam_interpolation: 0,
                yaw_direction_cw: 0,
                cruise_speed: 0.0
            }
        ]
    );
    let out = h.app(ShotRequest::Pause);
    assert_eq!(
        out.to_app,
        [ShotEvent::CableOptions {
            cam_interpolation: 0,
            yaw_direction_cw: 0,
            cruise_speed: -2.5
        }]
    );
    // A third record is ignored.
    let out = h.app(ShotRequest::RecordPosition);
    assert!(out.to_app.is_empty() && out.commands.is_empty());
}

#[test]
fn cruise_speeds_from_the_app_are_limited_to_max_speed() {
    let mut h = Harness::ready();
    h.orbiting();
    h.app(ShotRequest::ShotOptions {
        cruise_speed: -40.0,
    });
    assert_eq!(h.engine.status().cruise_speed_mps, -6.0);
}

#[test]
fn flying_sends_camera_commands_only_on_change() {
    let mut h = Harness::ready();
    h.orbiting();
    h.tick();
    let out = h.run(2_000);
    // The ROI does not move: not re-sent.
    assert!(find(&out, CommandKind::SetRoi).is_none());
    assert_eq!(out.commands.len(), 50, "one setpoint per tick");
}
