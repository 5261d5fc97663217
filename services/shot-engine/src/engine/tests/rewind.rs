//! Rewind: breadcrumbs, flying back, hover or RTL at the end, options both ways, the
//! home location both ways.

use skymesh_ipc_types::shot_api::shots::{NONE, REWIND};
use skymesh_ipc_types::shot_api::{Location, ShotEvent, ShotRequest};
use skymesh_ipc_types::{AckResult, Command, CommandKind, FlightMode, RefusalReason};

use super::*;

const HOME: Location = Location {
    lat_deg: -35.363,
    lon_deg: 149.165,
    alt_m: 584.0,
};

fn rewind_options(enabled: u8, hover: u8, distance: f32) -> ShotEvent {
    ShotEvent::RewindOptions {
        enabled,
        hover,
        rewind_distance: distance,
    }
}

fn with_home(h: &mut Harness, home: Location) {
    h.status.home_lat_deg = home.lat_deg;
    h.status.home_lon_deg = home.lon_deg;
    h.status.home_alt_msl_m = home.alt_m;
    h.push_status();
}

/// Ready, having flown 40 m north (a tick per metre).
fn flown() -> Harness {
    let mut h = Harness::ready();
    for _ in 0..40 {
        h.move_north(1.0);
        h.tick();
    }
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

#[test]
fn home_and_the_rewind_options_are_sent_on_connect_and_home_when_it_moves() {
    let mut h = Harness::new();
    h.vehicle_ok();
    with_home(&mut h, HOME);
    let out = h.connect_app(1);
    let n = out.to_app.len();
    assert_eq!(
        out.to_app[n - 2..],
        [ShotEvent::HomeLocation(HOME), rewind_options(1, 0, 20.0)]
    );
    // Unchanged: nothing; moved: told.
    h.push_status();
    assert!(h.drain().to_app.is_empty());
    let moved = Location {
        lat_deg: HOME.lat_deg + 0.001,
        ..HOME
    };
    with_home(&mut h, moved);
    assert_eq!(h.drain().to_app, [ShotEvent::HomeLocation(moved)]);
    // No home known: none sent on connect.
    let mut h = Harness::new();
    h.vehicle_ok();
    h.status.home_valid = 0;
    h.push_status();
    let out = h.connect_app(1);
    assert!(!out
        .to_app
        .iter()
        .any(|m| matches!(m, ShotEvent::HomeLocation(_))));
}

/// `north_m` north of [`HOME`], `up_m` above it.
fn near_home(north_m: f64, up_m: f32) -> Location {
    Location {
        lat_deg: HOME.lat_deg + north_m * M_LAT,
        alt_m: HOME.alt_m + up_m,
        ..HOME
    }
}

fn set_home(loc: Location) -> Command {
    Command::SetHome {
        lat_deg: loc.lat_deg,
        lon_deg: loc.lon_deg,
        alt_msl_m: loc.alt_m,
    }
}

fn app_error(out: &Outputs) -> &str {
    match out.to_app.as_slice() {
        [ShotEvent::Error(t)] => t,
        other => panic!("expected one SHOTMANAGER_ERROR, got {other:?}"),
    }
}

/// Ready, home at [`HOME`] (already told to the app).
fn ready_at_home() -> Harness {
    let mut h = Harness::ready();
    with_home(&mut h, HOME);
    h.drain();
    h
}

#[test]
fn the_apps_home_is_set_on_the_vehicle_and_the_new_home_is_told_back() {
    let mut h = ready_at_home();
    // The phone says 6 m higher: only the horizontal position moves home.
    let asked = near_home(50.0, 6.0);
    let there = near_home(50.0, 0.0);
    let out = h.app(ShotRequest::HomeLocation(asked));
    // Idle: the implicit grab is given back at once.
    assert_eq!(
        cmds(&out),
        [set_home(there), Command::ReleaseFlightAuthority]
    );
    assert!(all_ours(&out));
    assert!(out.to_app.is_empty(), "told once the vehicle reports it");
    let sent = find(&out, CommandKind::SetHome).unwrap();
    assert_eq!(sent.f[0], HOME.alt_m, "home keeps its altitude (MSL)");
    let out = h.ack(&sent, AckResult::Accepted, RefusalReason::None);
    assert!(out.to_app.is_empty() && out.commands.is_empty());
    with_home(&mut h, there);
    assert_eq!(h.drain().to_app, [ShotEvent::HomeLocation(there)]);
    assert_eq!(
        h.counter("skymesh_shot_unimplemented_requests_total", &[]),
        0
    );
}

#[test]
fn a_refused_home_is_told_to_the_app_with_the_reason() {
    let mut h = ready_at_home();
    let out = h.app(ShotRequest::HomeLocation(near_home(50.0, 0.0)));
    let sent = find(&out, CommandKind::SetHome).unwrap();
    // In progress is not an answer yet.
    let out = h.ack(&sent, AckResult::InProgress, RefusalReason::None);
    assert!(out.to_app.is_empty());
    let out = h.ack(
        &sent,
        AckResult::Refused,
        RefusalReason::TemporarilyRejected,
    );
    assert_eq!(
        app_error(&out),
        "home location refused (temporarily_rejected: test)"
    );
    assert!(out.commands.is_empty());
    // Answered: the next request goes out at once.
    let out = h.app(ShotRequest::HomeLocation(near_home(10.0, 0.0)));
    assert_eq!(kinds(&out)[0], CommandKind::SetHome);
}

#[test]
fn impossible_app_homes_are_refused_without_a_command() {
    let mut h = ready_at_home();
    let out = h.app(ShotRequest::HomeLocation(Location {
        lat_deg: 0.0,
        lon_deg: 0.0,
        alt_m: 10.0,
    }));
    assert!(app_error(&out).contains("no position"), "{out:?}");
    assert!(out.commands.is_empty());
    // (An out-of-range latitude never gets here: the codec refuses it at the gateway.)
    // No home yet: nothing to keep the altitude of.
    let mut h = Harness::ready();
    h.status.home_valid = 0;
    h.push_status();
    h.drain();
    let out = h.app(ShotRequest::HomeLocation(near_home(10.0, 0.0)));
    assert!(app_error(&out).contains("no home yet"), "{out:?}");
    assert!(out.commands.is_empty());
}

#[test]
fn the_home_in_effect_is_answered_at_once_without_a_command() {
    let mut h = ready_at_home();
    let out = h.app(ShotRequest::HomeLocation(HOME));
    assert_eq!(out.to_app, [ShotEvent::HomeLocation(HOME)]);
    assert!(out.commands.is_empty());
}

#[test]
fn one_home_request_at_a_time_and_only_the_newest_waiting_one_is_sent() {
    let mut h = ready_at_home();
    let first = find(
        &h.app(ShotRequest::HomeLocation(near_home(10.0, 0.0))),
        CommandKind::SetHome,
    )
    .unwrap();
    // While it is unanswered, newer locations wait; the newest wins.
    for north in [20.0, 30.0] {
        let out = h.app(ShotRequest::HomeLocation(near_home(north, 0.0)));
        assert!(out.commands.is_empty() && out.to_app.is_empty());
    }
    let out = h.ack(&first, AckResult::Accepted, RefusalReason::None);
    assert_eq!(
        cmds(&out),
        [
            set_home(near_home(30.0, 0.0)),
            Command::ReleaseFlightAuthority
        ]
    );
    // An answer that never comes does not block the app for good.
    h.now += super::super::rewind::HOME_ANSWER_WAIT_NS;
    let out = h.app(ShotRequest::HomeLocation(near_home(40.0, 0.0)));
    assert_eq!(cmds(&out)[0], set_home(near_home(40.0, 0.0)));
}

#[test]
fn setting_home_in_a_flying_shot_keeps_authority_and_a_refusal_keeps_the_shot() {
    let mut h = ready_at_home();
    h.orbiting();
    h.drain();
    let out = h.app(ShotRequest::HomeLocation(near_home(50.0, 0.0)));
    assert_eq!(kinds(&out), [CommandKind::SetHome]);
    let sent = find(&out, CommandKind::SetHome).unwrap();
    let out = h.ack(&sent, AckResult::Refused, RefusalReason::Denied);
    assert_eq!(app_error(&out), "home location refused (denied: test)");
    assert!(h.engine.is_flying());
    assert!(!kinds(&h.tick()).contains(&CommandKind::ReleaseFlightAuthority));
}

#[test]
fn rewind_options_are_clamped_and_answered_and_disabled_refuses_the_shot() {
    let mut h = flown();
    let out = h.app(rewind_options(1, 1, 100.0));
    assert_eq!(out.to_app, [rewind_options(1, 1, 60.0)]);
    let out = h.app(rewind_options(0, 0, 5.0));
    assert_eq!(out.to_app, [rewind_options(0, 0, 10.0)]);
    let out = h.app(ShotRequest::StartShot(REWIND));
    assert!(matches!(&out.to_app[0], ShotEvent::Error(t) if t.contains("disabled")));
    assert_eq!(out.to_app[1], ShotEvent::CurrentShot(NONE));
    assert!(out.commands.is_empty());
    assert_eq!(
        h.counter(
            "skymesh_shot_entry_refusals_total",
            &[("error", "rewind_disabled")]
        ),
        1
    );
}

#[test]
fn rewind_flies_back_along_the_path_then_returns_home() {
    let mut h = flown();
    let out = h.app(ShotRequest::StartShot(REWIND));
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(REWIND)]);
    assert_eq!(
        cmds(&out),
        [
            Command::GrabFlightAuthority,
            Command::SetMode(FlightMode::Guided)
        ]
    );
    h.set_mode(FlightMode::Guided);
    let v = last_velocity(&h.run(2_000));
    assert!(v[0] < -1.0 && v[1].abs() < 0.1, "back south: {v:?}");
    assert!(
        h.engine.status().progress < 0.1,
        "the vehicle has not moved"
    );
    // Rewinding does not lay crumbs: arrive at the end, 20 m back (the default).
    h.state.lat_deg = LAT + 20.0 * M_LAT;
    h.state.vel_ned_mps = [0.0; 3];
    let out = h.run(1_000);
    let c = cmds(&out);
    let rtl = c
        .iter()
        .position(|c| *c == Command::ReturnToLaunch)
        .expect("RTL");
    assert_eq!(c[rtl + 1], Command::ReleaseFlightAuthority);
    assert!(!c.contains(&Command::SetMode(FlightMode::Loiter)));
    assert!(out.to_app.contains(&ShotEvent::CurrentShot(NONE)));
    assert_eq!(h.engine.last_exit(), "finished_rtl");
}

#[test]
fn rewind_with_hover_ends_in_loiter_and_respects_the_distance() {
    let mut h = flown();
    h.app(rewind_options(1, 1, 10.0));
    h.app(ShotRequest::StartShot(REWIND));
    h.set_mode(FlightMode::Guided);
    h.run(400);
    // 10 m back, not 20: the end is at 30 m north.
    h.state.lat_deg = LAT + 30.0 * M_LAT;
    let out = h.run(1_000);
    let c = cmds(&out);
    assert!(c.contains(&Command::Brake));
    assert!(c.contains(&Command::SetMode(FlightMode::Loiter)));
    assert!(!c.contains(&Command::ReturnToLaunch));
    assert_eq!(h.engine.last_exit(), "finished");
}

#[test]
fn rewind_without_a_flown_path_says_so_and_ends() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::StartShot(REWIND));
    assert!(out
        .to_app
        .iter()
        .any(|m| matches!(m, ShotEvent::Error(t) if t.contains("no flown path"))));
    h.set_mode(FlightMode::Guided);
    let out = h.run(400);
    assert!(cmds(&out).contains(&Command::ReturnToLaunch));
    assert_eq!(h.engine.current_shot(), NONE);
}

#[test]
fn disarming_forgets_the_breadcrumbs() {
    let mut h = flown();
    h.status.armed = 0;
    h.push_status();
    h.tick();
    h.status.armed = 1;
    h.push_status();
    h.tick();
    let out = h.app(ShotRequest::StartShot(REWIND));
    assert!(out
        .to_app
        .iter()
        .any(|m| matches!(m, ShotEvent::Error(t) if t.contains("no flown path"))));
    assert!(kinds(&out).contains(&CommandKind::GrabFlightAuthority));
}
