//! Entry gating, entry and exit messages, the status sample.

use skymesh_ipc_types::shot_api::shots::{CABLECAM, FOLLOW, NONE, ORBIT, SELFIE};
use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest};
use skymesh_ipc_types::{Button, CommandKind, FlightMode, ShotPhase};

use super::*;

fn refused_with(h: &mut Harness, code: u32) {
    let out = h.app(ShotRequest::StartShot(ORBIT));
    assert_eq!(out.to_app, [ShotEvent::Refused(code)]);
    assert!(out.commands.is_empty());
    assert_eq!(h.engine.current_shot(), NONE);
}

#[test]
fn gating_refuses_bad_ekf_unarmed_and_rtl() {
    let mut h = Harness::ready();
    h.status.ekf_healthy = 0;
    h.push_status();
    refused_with(&mut h, 0);

    h.status.ekf_healthy = 1;
    h.status.armed = 0;
    h.push_status();
    refused_with(&mut h, 1);

    h.status.armed = 1;
    for mode in [FlightMode::Rtl, FlightMode::SmartRtl, FlightMode::Land] {
        h.set_mode(mode);
        refused_with(&mut h, 2);
    }
    h.set_mode(FlightMode::Loiter);
    h.status.battery_remaining_pct = 10;
    h.push_status();
    refused_with(&mut h, 2);

    h.status.battery_remaining_pct = 80;
    h.status.link_up = 0;
    h.push_status();
    refused_with(&mut h, 2);

    assert_eq!(
        h.counter("skymesh_shot_entry_refusals_total", &[("error", "rtl")]),
        5
    );
    assert_eq!(
        h.counter("skymesh_shot_entry_refusals_total", &[("error", "bad_ekf")]),
        1
    );
    assert_eq!(
        h.counter("skymesh_shot_entry_refusals_total", &[("error", "unarmed")]),
        1
    );
}

#[test]
fn no_vehicle_state_yet_is_refused_as_rtl() {
    let mut h = Harness::new();
    h.connect_app(1);
    refused_with(&mut h, 2);
    // Status alone is not enough either.
    h.vehicle_ok();
    h.engine.inputs.state = None;
    h.drain(); // the home location the first status gave the app
    refused_with(&mut h, 2);
}

#[test]
fn entry_tells_the_app_and_exit_sends_minus_one() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::StartShot(ORBIT));
    assert_eq!(out.to_app[0], ShotEvent::CurrentShot(ORBIT));
    // Orbit tells the app its (initial) speed.
    assert_eq!(out.to_app[1], ShotEvent::ShotOptions { cruise_speed: 0.0 });
    assert!(out.commands.is_empty(), "setup sends no flight command");
    assert_eq!(h.engine.current_shot(), ORBIT);
    let st = out.status.unwrap();
    assert_eq!(st.shot, ORBIT as i8);
    assert_eq!(st.phase(), ShotPhase::Setup);
    assert!(st.last_exit.is_empty());

    let out = h.app(ShotRequest::StartShot(NONE));
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(NONE)]);
    assert!(out.commands.is_empty(), "nothing was flying");
    assert_eq!(h.engine.last_exit(), "app");
    let st = out.status.unwrap();
    assert_eq!(st.shot, -1);
    assert_eq!(st.last_exit.as_str(), "app");
    assert_eq!(
        h.counter("skymesh_shot_entered_total", &[("shot", "orbit")]),
        1
    );
    assert_eq!(
        h.counter("skymesh_shot_exits_total", &[("reason", "app")]),
        1
    );
}

#[test]
fn a_button_entry_also_tells_the_app_the_shot() {
    let mut h = Harness::ready();
    // Factory defaults: A = cable cam, B = orbit.
    let out = h.button(Button::A);
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(CABLECAM)]);
    assert_eq!(h.engine.current_shot(), CABLECAM);
    h.button(Button::Fly);
    let out = h.button(Button::B);
    assert_eq!(out.to_app[0], ShotEvent::CurrentShot(ORBIT));
}

#[test]
fn a_refused_entry_leaves_the_current_shot_running() {
    let mut h = Harness::ready();
    h.orbiting();
    h.status.armed = 0;
    h.push_status();
    let out = h.app(ShotRequest::StartShot(SELFIE));
    assert_eq!(out.to_app, [ShotEvent::Refused(1)]);
    assert_eq!(h.engine.current_shot(), ORBIT);
    assert!(h.engine.is_flying());
}

#[test]
fn the_same_shot_again_is_only_re_announced_and_another_replaces_it() {
    let mut h = Harness::ready();
    h.orbiting();
    let out = h.app(ShotRequest::StartShot(ORBIT));
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(ORBIT)]);
    assert!(out.commands.is_empty());
    assert!(h.engine.is_flying());

    let out = h.app(ShotRequest::StartShot(SELFIE));
    assert_eq!(
        out.to_app[..2],
        [ShotEvent::CurrentShot(NONE), ShotEvent::CurrentShot(SELFIE)]
    );
    // The orbit hands the vehicle back before the selfie's setup.
    assert_eq!(
        kinds(&out),
        [
            CommandKind::Brake,
            CommandKind::SetMode,
            CommandKind::ClearRoi,
            CommandKind::ReleaseFlightAuthority
        ]
    );
    assert_eq!(h.engine.last_exit(), "");
    assert_eq!(
        h.counter("skymesh_shot_exits_total", &[("reason", "replaced")]),
        1
    );
}

#[test]
fn buttons_without_an_app_enter_nothing_and_follow_is_not_for_buttons() {
    let mut h = Harness::new();
    h.vehicle_ok();
    let out = h.button(Button::A);
    assert!(out.to_app.is_empty() && out.commands.is_empty());
    assert_eq!(h.engine.current_shot(), NONE);

    let mut h = Harness::ready();
    h.app(ShotRequest::SetButtonSetting(
        skymesh_ipc_types::shot_api::ButtonSetting {
            button: 4,
            event: 0,
            shot: FOLLOW,
            mode: -1,
        },
    ));
    let out = h.button(Button::A);
    assert!(matches!(&out.to_app[..], [ShotEvent::Error(t)] if t.contains("controller")));
    assert_eq!(h.engine.current_shot(), NONE);
}

#[test]
fn status_reports_phase_speed_roi_and_is_rate_limited() {
    let mut h = Harness::ready();
    let out = h.orbiting();
    let st = out.status.unwrap();
    assert_eq!(st.phase(), ShotPhase::Paused, "orbit starts at cruise 0");
    assert_eq!(st.has_authority, 1);
    assert_eq!(st.roi_valid, 1);
    assert!((st.roi_lat_deg - (LAT + 30.0 * M_LAT)).abs() < 1e-9);
    assert!((st.progress - 30.0).abs() < 0.5, "radius {}", st.progress);
    h.app(ShotRequest::ShotOptions { cruise_speed: 2.0 });
    // A change publishes at once; nothing new within 200 ms; then the 5 Hz repeat.
    let next = h.tick();
    assert_eq!(next.status.map(|s| s.phase()), None);
    let mut seen = 0;
    for _ in 0..10 {
        seen += usize::from(h.tick().status.is_some());
    }
    assert!((2..=3).contains(&seen), "{seen} status samples in 400 ms");
}
