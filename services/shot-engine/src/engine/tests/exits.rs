//! How shots end: FLY, mode change, pre-emption, app loss, link loss, shutdown.

use skymesh_ipc_types::shot_api::shots::{CABLECAM, FOLLOW, NONE, ORBIT, SELFIE};
use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest};
use skymesh_ipc_types::{
    AckResult, ArbiterEvent, ArbiterEventKind, Button, Command, CommandKind, CommandSource,
    FixedStr, FlightMode, RefusalReason,
};

use super::*;

#[test]
fn fly_brakes_hands_over_in_loiter_and_tells_the_app() {
    let mut h = Harness::ready();
    h.orbiting();
    h.run(200);
    let out = h.button(Button::Fly);
    assert_eq!(
        cmds(&out),
        [
            Command::Brake,
            Command::SetMode(FlightMode::Loiter),
            Command::ClearRoi,
            Command::ReleaseFlightAuthority
        ]
    );
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(NONE)]);
    assert_eq!(h.engine.last_exit(), "fly_button");
    assert_eq!(out.status.unwrap().last_exit.as_str(), "fly_button");
    // No more setpoints.
    assert!(h.run(400).commands.is_empty());
}

#[test]
fn leaving_guided_ends_the_shot_without_overriding_the_pilot() {
    let mut h = Harness::ready();
    h.orbiting();
    h.run(120);
    // Still LOITER before GUIDED took effect would not end it; after GUIDED, leaving does.
    let out = h.set_mode(FlightMode::PosHold);
    assert_eq!(
        cmds(&out),
        [Command::ClearRoi, Command::ReleaseFlightAuthority]
    );
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(NONE)]);
    assert_eq!(h.engine.last_exit(), "mode_change");
}

#[test]
fn a_status_before_guided_took_effect_does_not_end_the_shot() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(ORBIT));
    h.app(ShotRequest::Location(loc(30.0)));
    // The vehicle is still in LOITER: the mode change has not happened yet.
    h.set_mode(FlightMode::Loiter);
    assert!(h.engine.is_flying());
    h.set_mode(FlightMode::Guided);
    assert!(h.engine.is_flying());
}

/// A shot that ended a moment ago asked for LOITER, but no heartbeat has shown it yet:
/// the last status still says GUIDED. The next shot must not take that for its own
/// GUIDED, or the heartbeat the autopilot sent in LOITER, just before it switched to
/// the new shot's GUIDED, ends the new shot. (The end-to-end Solo test hit this.)
#[test]
fn a_shot_right_after_another_waits_for_its_own_guided() {
    let mut h = Harness::ready();
    h.orbiting();
    h.run(200);
    let out = h.app(ShotRequest::StartShot(NONE));
    assert!(cmds(&out).contains(&Command::SetMode(FlightMode::Loiter)));
    // The next shot 40 ms later; still no heartbeat since the LOITER.
    h.tick();
    h.app(ShotRequest::StartShot(ORBIT));
    h.app(ShotRequest::Location(loc(30.0)));
    assert!(h.engine.is_flying());
    // autopilot-link's once-a-second status repeats the last heartbeat (GUIDED, from
    // before both requests): not evidence for the new one.
    h.now += 300 * MS;
    h.status.heartbeat_age_ms = 900;
    h.push_status();
    h.status.heartbeat_age_ms = 0;
    // The heartbeat sent in LOITER, arriving after the new request.
    let out = h.set_mode(FlightMode::Loiter);
    assert!(
        h.engine.is_flying(),
        "ended by a heartbeat from before the switch: {out:?}"
    );
    // The new shot's GUIDED, then the pilot takes the vehicle: that ends it.
    h.set_mode(FlightMode::Guided);
    assert!(h.engine.is_flying());
    h.set_mode(FlightMode::PosHold);
    assert!(!h.engine.is_flying());
    assert_eq!(h.engine.last_exit(), "mode_change");
}

#[test]
fn guided_refused_or_never_reached_ends_the_shot() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(ORBIT));
    let out = h.app(ShotRequest::Location(loc(30.0)));
    let set_mode = find(&out, CommandKind::SetMode).unwrap();
    let out = h.ack(&set_mode, AckResult::Refused, RefusalReason::Denied);
    assert!(matches!(&out.to_app[0], ShotEvent::Error(t) if t.contains("refused")));
    assert_eq!(out.to_app[1], ShotEvent::CurrentShot(NONE));
    assert_eq!(h.engine.last_exit(), "guided_refused");

    h.app(ShotRequest::StartShot(ORBIT));
    h.app(ShotRequest::Location(loc(30.0)));
    let out = h.run(6_000);
    assert!(out.to_app.contains(&ShotEvent::CurrentShot(NONE)));
    assert_eq!(h.engine.last_exit(), "guided_refused");
}

#[test]
fn another_holder_in_the_authority_state_preempts_the_shot() {
    let mut h = Harness::ready();
    h.orbiting();
    // Before our grab shows up, another holder means nothing yet.
    h.authority(Some(CommandSource::Operator));
    assert!(h.engine.is_flying());
    h.authority(Some(CommandSource::ShotEngine));
    h.run(80);
    let out = h.authority(Some(CommandSource::ManualRc));
    assert!(out.commands.is_empty(), "no command once authority is gone");
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(NONE)]);
    assert_eq!(h.engine.last_exit(), "preempted");
    assert!(h.run(200).commands.is_empty());
}

#[test]
fn a_refused_flight_command_ends_the_shot() {
    for (reason, exit) in [
        (RefusalReason::NoAuthority, "no_authority"),
        (RefusalReason::Preempted, "preempted"),
        (RefusalReason::Emergency, "emergency"),
        (RefusalReason::LinkDown, "link_down"),
    ] {
        let mut h = Harness::ready();
        h.orbiting();
        let out = h.tick();
        let v = find(&out, CommandKind::VelocityNed).unwrap();
        let out = h.ack(&v, AckResult::Refused, reason);
        assert!(
            out.to_app.contains(&ShotEvent::CurrentShot(NONE)),
            "{reason}"
        );
        assert!(out.commands.is_empty(), "{reason}");
        assert_eq!(h.engine.last_exit(), exit);
        assert_eq!(
            h.counter(
                "skymesh_shot_commands_refused_total",
                &[("reason", reason.as_str())]
            ),
            1
        );
    }
}

#[test]
fn a_refusal_from_an_earlier_flight_or_a_stale_setpoint_does_not_end_the_shot() {
    let mut h = Harness::ready();
    h.orbiting();
    let old = find(&h.tick(), CommandKind::VelocityNed).unwrap();
    h.button(Button::Fly);
    h.orbiting();
    h.ack(&old, AckResult::Refused, RefusalReason::NoAuthority);
    assert!(h.engine.is_flying());
    let v = find(&h.tick(), CommandKind::VelocityNed).unwrap();
    h.ack(&v, AckResult::Refused, RefusalReason::Stale);
    assert!(h.engine.is_flying());
}

#[test]
fn an_arbiter_event_about_our_authority_ends_the_shot() {
    let mut h = Harness::ready();
    h.orbiting();
    let ev = ArbiterEvent {
        vehicle_id: VEHICLE,
        kind: ArbiterEventKind::AuthorityChanged.to_wire(),
        source: CommandSource::ShotEngine.to_wire(),
        detail: FixedStr::new("flight: shot_engine -> operator (preempted)"),
        ..ArbiterEvent::default()
    };
    h.engine.handle_arbiter_event(&ev, h.now);
    assert_eq!(h.engine.last_exit(), "preempted");
}

#[test]
fn app_loss_ends_follow_selfie_and_setups_but_not_a_flying_orbit_or_cable() {
    // Orbit flying: continues.
    let mut h = Harness::ready();
    h.orbiting();
    let out = h.session(1, false);
    assert!(out.commands.is_empty());
    assert!(h.engine.is_flying());
    assert!(!h.run(200).commands.is_empty(), "setpoints continue");

    // Cable cam in setup (one point): ends.
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(CABLECAM));
    h.app(ShotRequest::RecordPosition);
    h.session(1, false);
    assert_eq!(h.engine.current_shot(), NONE);
    assert_eq!(h.engine.last_exit(), "app_disconnected");

    // Selfie flying: ends, braked and handed over.
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(SELFIE));
    for n in [10.0, 40.0, 0.0] {
        h.app(ShotRequest::Location(loc(n)));
    }
    h.set_mode(FlightMode::Guided);
    let out = h.session(1, false);
    assert_eq!(
        kinds(&out),
        [
            CommandKind::Brake,
            CommandKind::SetMode,
            CommandKind::ClearRoi,
            CommandKind::ReleaseFlightAuthority
        ]
    );
    assert!(out.to_app.is_empty(), "nobody to tell");
    assert_eq!(h.engine.last_exit(), "app_disconnected");

    // Follow flying: ends when the gateway stops reporting the session (gateway gone).
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(FOLLOW));
    h.fix(20.0);
    h.tick();
    assert!(h.engine.is_flying());
    h.gateway_alive = false;
    h.run(5_000);
    assert_eq!(h.engine.current_shot(), NONE);
    assert_eq!(h.engine.last_exit(), "app_disconnected");
}

#[test]
fn a_reconnecting_app_learns_the_current_shot() {
    let mut h = Harness::ready();
    h.orbiting();
    h.session(1, false);
    let out = h.connect_app(2);
    assert_eq!(out.to_app[0], ShotEvent::CurrentShot(ORBIT));
    assert!(matches!(out.to_app[1], ShotEvent::GoProV1State(_)));
    assert!(matches!(out.to_app[2], ShotEvent::GoProV2State(_)));
}

#[test]
fn link_down_ends_any_shot_without_commands() {
    let mut h = Harness::ready();
    h.orbiting();
    h.status.link_up = 0;
    h.push_status();
    let out = h.drain();
    assert!(out.commands.is_empty());
    assert_eq!(h.engine.last_exit(), "link_down");
}

#[test]
fn shutdown_hands_the_vehicle_back() {
    let mut h = Harness::ready();
    h.orbiting();
    let out = h.engine.shutdown(h.now);
    assert_eq!(
        kinds(&out),
        [
            CommandKind::Brake,
            CommandKind::SetMode,
            CommandKind::ClearRoi,
            CommandKind::ReleaseFlightAuthority
        ]
    );
    assert_eq!(out.status.unwrap().last_exit.as_str(), "shutdown");
    assert!(all_ours(&out));
}

#[test]
fn fly_before_guided_took_effect_still_ends_in_loiter() {
    let mut h = Harness::ready();
    h.app(ShotRequest::StartShot(ORBIT));
    h.app(ShotRequest::Location(loc(30.0)));
    // Our SetMode(Guided) may still be on its way: LOITER follows it, no brake.
    let out = h.button(Button::Fly);
    assert_eq!(
        cmds(&out),
        [
            Command::SetMode(FlightMode::Loiter),
            Command::ClearRoi,
            Command::ReleaseFlightAuthority
        ]
    );
}
