//! Decisions of [`super::Arbiter`], with explicit times: no sleeping.

use super::*;
use skymesh_ipc_types::{AckResult, AuthorityChange, FenceKind, FlightMode, GeofenceSet};
use CommandSource::*;

const MS: u64 = 1_000_000;
pub(super) const S: u64 = 1000 * MS;
/// Home of vehicle-sim.
pub(super) const HOME: (f64, f64) = (-35.363261, 149.165230);
/// Its altitude above sea level, m.
pub(super) const HOME_ALT_MSL: f32 = 584.0;

pub(super) fn settings() -> ArbiterSettings {
    use skymesh_runtime::ServiceConfig;
    crate::config::RawConfig::default()
        .validate()
        .expect("defaults")
        .arbiter
}

pub(super) fn sample(source: CommandSource, cmd: Command, stamp_ns: u64) -> VehicleCommand {
    let mut s = VehicleCommand::new(1, source, 7, &cmd).expect("valid");
    s.header.stamp_ns = stamp_ns;
    s
}

pub(super) fn vel(n: f32, e: f32, d: f32) -> Command {
    Command::VelocityNed {
        vel_ned_mps: [n, e, d],
        yaw_rate_dps: None,
    }
}

/// Hovering at 10 m over a point `north`/`east` metres from home, in GUIDED.
pub(super) fn flying(north: f64, east: f64, vel_ned_mps: [f32; 3]) -> VehicleView {
    let frame = geofence::LocalFrame::new(HOME.0, HOME.1);
    let unit = frame.to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    VehicleView {
        armed: true,
        mode: FlightMode::Guided,
        position: Some(Kinematics {
            lat_deg: HOME.0 + north / unit.x * 1e-3,
            lon_deg: HOME.1 + east / unit.y * 1e-3,
            alt_rel_m: 10.0,
            vel_ned_mps,
            age_s: 0.0,
        }),
        home: Some(Home {
            lat_deg: HOME.0,
            lon_deg: HOME.1,
            alt_msl_m: HOME_ALT_MSL,
        }),
    }
}

pub(super) fn refusal(d: &Decision) -> (RefusalReason, &str) {
    match &d.outcome {
        Outcome::Refused { reason, detail } => (*reason, detail.as_str()),
        other => panic!("expected a refusal, got {other:?}"),
    }
}

pub(super) fn executed(d: &Decision) -> Command {
    match &d.outcome {
        Outcome::Execute { command, .. } => *command,
        other => panic!("expected execution, got {other:?}"),
    }
}

pub(super) fn authority_changes(d: &[Effect]) -> Vec<AuthorityChange> {
    d.iter()
        .filter_map(|e| match e {
            Effect::Authority(c) => Some(c.change),
            _ => None,
        })
        .collect()
}

#[test]
fn commands_grab_implicitly_and_lower_sources_are_refused_with_the_holder_named() {
    let mut a = Arbiter::new(settings());
    let v = VehicleView::default();
    let d = a.decide(S, &sample(ShotEngine, Command::Land, S), &v);
    assert_eq!(executed(&d), Command::Land);
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Granted]);
    let d = a.decide(S, &sample(Vision, Command::ReturnToLaunch, S), &v);
    assert_eq!(
        refusal(&d),
        (
            RefusalReason::NoAuthority,
            "flight authority held by shot_engine"
        )
    );
    assert!(d.effects.is_empty());
    // The same source again only refreshes; a higher one pre-empts by commanding.
    let d = a.decide(2 * S, &sample(ShotEngine, Command::Land, 2 * S), &v);
    assert!(d.effects.is_empty());
    let d = a.decide(3 * S, &sample(ManualRc, Command::ReturnToLaunch, 3 * S), &v);
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Preempted]);
    let st = a.authority().state(1);
    assert_eq!(
        (st.flight(), st.flight_previous),
        (Some(ManualRc), ShotEngine.to_wire())
    );
    // Payload authority is separate.
    let d = a.decide(3 * S, &sample(Vision, Command::CameraCapture, 3 * S), &v);
    assert_eq!(executed(&d), Command::CameraCapture);
    assert_eq!(a.authority().state(1).payload(), Some(Vision));
}

#[test]
fn explicit_grab_and_release_are_answered_by_the_arbiter() {
    let mut a = Arbiter::new(settings());
    let v = VehicleView::default();
    let d = a.decide(S, &sample(SwarmQueue, Command::GrabFlightAuthority, S), &v);
    assert_eq!(
        d.outcome,
        Outcome::Done {
            detail: "flight authority granted".into()
        }
    );
    let d = a.decide(S, &sample(Imc, Command::GrabFlightAuthority, S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::NoAuthority);
    let d = a.decide(S, &sample(DjiDrc, Command::GrabFlightAuthority, S), &v);
    assert_eq!(d.detail(), "flight authority taken from swarm_queue");
    let d = a.decide(
        S,
        &sample(SwarmQueue, Command::ReleaseFlightAuthority, S),
        &v,
    );
    assert_eq!(d.detail(), "flight authority was not held");
    assert!(d.effects.is_empty());
    let d = a.decide(S, &sample(DjiDrc, Command::ReleaseFlightAuthority, S), &v);
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Released]);
    let d = a.decide(S, &sample(Vision, Command::GrabPayloadAuthority, S), &v);
    assert_eq!(d.result(), AckResult::Accepted);
    assert_eq!(a.authority().state(1).payload(), Some(Vision));
}

#[test]
fn a_quiet_holder_loses_authority_and_grabs_keep_it_alive() {
    let mut a = Arbiter::new(settings());
    let v = VehicleView::default();
    a.decide(S, &sample(Imc, Command::GrabFlightAuthority, S), &v);
    assert_eq!(a.next_deadline_ns(), Some(6 * S));
    a.decide(5 * S, &sample(Imc, Command::GrabFlightAuthority, 5 * S), &v);
    assert!(a.poll(9 * S).is_empty());
    let effects = a.poll(10 * S);
    assert_eq!(authority_changes(&effects), [AuthorityChange::Timeout]);
    assert_eq!(a.authority().state(1).flight(), None);
    assert_eq!(a.next_deadline_ns(), None);
}

#[test]
fn a_refused_command_from_a_higher_source_preempts_nobody() {
    let mut a = Arbiter::new(settings());
    let v = VehicleView::default();
    a.decide(S, &sample(Vision, Command::GrabFlightAuthority, S), &v);
    // Stale on arrival.
    let d = a.decide(2 * S, &sample(Operator, vel(1.0, 0.0, 0.0), S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Stale);
    assert_eq!(a.authority().state(1).flight(), Some(Vision));
}

#[test]
fn stale_setpoints_are_refused_and_a_stopped_stream_is_braked() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [0.0; 3]);
    let d = a.decide(S + 501 * MS, &sample(ShotEngine, vel(3.0, 0.0, 0.0), S), &v);
    assert_eq!(
        refusal(&d),
        (RefusalReason::Stale, "501 ms old, max 500 ms")
    );
    // A fresh stream: each setpoint pushes the deadline to its stamp + max age.
    for i in 0..10 {
        let t = 2 * S + i * 100 * MS;
        let d = a.decide(t + 5 * MS, &sample(ShotEngine, vel(3.0, 0.0, 0.0), t), &v);
        assert_eq!(executed(&d), vel(3.0, 0.0, 0.0));
    }
    let last = 2 * S + 900 * MS;
    assert_eq!(a.next_deadline_ns(), Some(last + 500 * MS));
    assert!(a.poll(last + 499 * MS).is_empty());
    assert_eq!(
        a.poll(last + 500 * MS),
        [Effect::StaleBrake { source: ShotEngine }]
    );
    assert!(a.poll(last + 600 * MS).is_empty(), "once");
    // A sample's own max age, capped at 2 s.
    let mut s = sample(ShotEngine, vel(1.0, 0.0, 0.0), 10 * S);
    s.max_age_ms = 60_000;
    a.decide(10 * S, &s, &v);
    assert_eq!(a.next_deadline_ns(), Some(12 * S));
    // A stream that ends with zero velocity needs no brake; nor one replaced by a GoTo.
    a.decide(11 * S, &sample(ShotEngine, vel(0.0, 0.0, 0.0), 11 * S), &v);
    assert!(a
        .poll(20 * S)
        .iter()
        .all(|e| !matches!(e, Effect::StaleBrake { .. })));
    a.decide(21 * S, &sample(ShotEngine, vel(1.0, 0.0, 0.0), 21 * S), &v);
    let goto = Command::GoTo {
        lat_deg: HOME.0,
        lon_deg: HOME.1,
        alt_rel_m: 10.0,
        yaw_deg: None,
        speed_mps: None,
    };
    a.decide(
        21 * S + 100 * MS,
        &sample(ShotEngine, goto, 21 * S + 100 * MS),
        &v,
    );
    assert!(a
        .poll(30 * S)
        .iter()
        .all(|e| !matches!(e, Effect::StaleBrake { .. })));
}

#[test]
fn gopro_set_needs_payload_authority_only_and_leaves_the_flight_alone() {
    let mut a = Arbiter::new(settings());
    // In the air (unknown position counts as flying) with a velocity stream running.
    let v = VehicleView {
        armed: true,
        ..VehicleView::default()
    };
    let gopro = Command::GoProSet {
        command: 1,
        value: [1, 0, 0, 0],
    };
    a.decide(S, &sample(ShotEngine, vel(2.0, 0.0, 0.0), S), &v);
    // A lower-ranked source holds no flight authority, but takes payload authority.
    let d = a.decide(S + 100 * MS, &sample(Imc, gopro, S + 100 * MS), &v);
    assert_eq!(executed(&d), gopro, "no envelope change, no in-air refusal");
    assert_eq!(d.result(), AckResult::Accepted);
    let st = a.authority().state(1);
    assert_eq!((st.flight(), st.payload()), (Some(ShotEngine), Some(Imc)));
    // The velocity stream was not ended by it: its stale brake is still due.
    assert_eq!(
        a.poll(S + 500 * MS),
        [Effect::StaleBrake { source: ShotEngine }]
    );
    // The payload holder's priority decides between GoPro senders.
    let d = a.decide(2 * S, &sample(Vision, gopro, 2 * S), &v);
    assert_eq!(
        refusal(&d),
        (RefusalReason::NoAuthority, "payload authority held by imc")
    );
    let d = a.decide(2 * S, &sample(ShotEngine, gopro, 2 * S), &v);
    assert_eq!(executed(&d), gopro);
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Preempted]);
    assert_eq!(a.authority().state(1).payload(), Some(ShotEngine));
    assert_eq!(a.authority().state(1).flight(), Some(ShotEngine));
}

#[test]
fn emergency_stop_from_anyone_blocks_everyone_but_safety_until_its_engagers_release() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [2.0, 0.0, 0.0]);
    a.decide(S, &sample(ManualRc, vel(2.0, 0.0, 0.0), S), &v);
    let d = a.decide(S, &sample(Vision, Command::EmergencyStop, S), &v);
    assert_eq!(executed(&d), Command::EmergencyStop);
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Emergency]);
    assert!(d.effects.iter().any(|e| matches!(
        e,
        Effect::Event {
            kind: ArbiterEventKind::EmergencyStop,
            source: Some(Vision),
            ..
        }
    )));
    let st = a.authority().state(1);
    assert_eq!((st.flight(), st.emergency), (Some(Safety), 1));
    assert!(
        a.poll(60 * S).is_empty(),
        "no stale brake after the stop, no timeout for safety"
    );
    let d = a.decide(61 * S, &sample(ManualRc, Command::Land, 61 * S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Emergency);
    let d = a.decide(
        61 * S,
        &sample(ManualRc, Command::ReleaseFlightAuthority, 61 * S),
        &v,
    );
    assert_eq!(refusal(&d).0, RefusalReason::Emergency);
    let d = a.decide(
        61 * S,
        &sample(ManualRc, Command::EmergencyStop, 61 * S),
        &v,
    );
    assert_eq!(
        executed(&d),
        Command::EmergencyStop,
        "stopping again is always allowed"
    );
    assert!(authority_changes(&d.effects).is_empty());
    assert_eq!(
        executed(&a.decide(62 * S, &sample(Safety, Command::Land, 62 * S), &v)),
        Command::Land
    );
    // Releasing authority never ends a stop, not even safety's release.
    let d = a.decide(
        63 * S,
        &sample(Safety, Command::ReleaseFlightAuthority, 63 * S),
        &v,
    );
    assert!(d.effects.is_empty(), "{d:?}");
    let st = a.authority().state(1);
    assert_eq!((st.flight(), st.emergency), (Some(Safety), 1));
    // Vision and manual RC engaged it: both must withdraw.
    let d = a.decide(
        64 * S,
        &sample(ManualRc, Command::ReleaseEmergency, 64 * S),
        &v,
    );
    assert_eq!(d.detail(), "manual_rc released; still held by vision");
    assert_eq!(a.authority().state(1).emergency, 1);
    let d = a.decide(64 * S, &sample(ManualRc, Command::Land, 64 * S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Emergency);
    let d = a.decide(
        65 * S,
        &sample(Vision, Command::ReleaseEmergency, 65 * S),
        &v,
    );
    assert_eq!(d.detail(), "emergency stop ended");
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Released]);
    assert_eq!(a.authority().state(1).emergency, 0);
    let d = a.decide(66 * S, &sample(ManualRc, Command::Land, 66 * S), &v);
    assert_eq!(executed(&d), Command::Land);
}

#[test]
fn motor_kill_is_refused_in_the_air_unless_flagged_as_an_emergency() {
    let mut a = Arbiter::new(settings());
    let kill = Command::MotorKill { emergency: false };
    let d = a.decide(S, &sample(Operator, kill, S), &flying(0.0, 0.0, [0.0; 3]));
    assert_eq!(refusal(&d).0, RefusalReason::InAir);
    let unknown = VehicleView {
        armed: true,
        ..VehicleView::default()
    };
    assert_eq!(
        refusal(&a.decide(S, &sample(Operator, kill, S), &unknown)).0,
        RefusalReason::InAir
    );
    let mut on_ground = flying(0.0, 0.0, [0.0, 0.0, 0.1]);
    if let Some(k) = &mut on_ground.position {
        k.alt_rel_m = 0.2;
    }
    assert_eq!(
        executed(&a.decide(S, &sample(Operator, kill, S), &on_ground)),
        kill
    );
    let d = a.decide(
        S,
        &sample(Operator, Command::MotorKill { emergency: true }, S),
        &flying(0.0, 0.0, [0.0; 3]),
    );
    assert_eq!(executed(&d), Command::MotorKill { emergency: true });
}

#[test]
fn numbers_are_rechecked_and_limited() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [0.0; 3]);
    let mut corrupt = sample(Operator, vel(1.0, 0.0, 0.0), S);
    corrupt.f[1] = f32::NAN;
    let d = a.decide(S, &corrupt, &v);
    assert_eq!(refusal(&d).0, RefusalReason::InvalidParameter);
    corrupt.f[1] = 0.0;
    corrupt.source = 42;
    assert_eq!(
        refusal(&a.decide(S, &corrupt, &v)).0,
        RefusalReason::InvalidParameter
    );
    // Valid for the wire (≤ 50 m/s) but above the configured 12 m/s.
    let d = a.decide(S, &sample(Operator, vel(16.0, 12.0, -9.0), S), &v);
    assert_eq!(d.result(), AckResult::Limited);
    let Command::VelocityNed {
        vel_ned_mps: [n, e, dn],
        ..
    } = executed(&d)
    else {
        unreachable!()
    };
    assert!((n.hypot(e) - 12.0).abs() < 1e-4 && (n / e - 16.0 / 12.0).abs() < 1e-4);
    assert_eq!(dn, -5.0, "climb limited to 5 m/s");
    let yaw = Command::SetYaw {
        yaw_deg: 90.0,
        rate_dps: 500.0,
        relative: false,
    };
    let d = a.decide(S, &sample(Operator, yaw, S), &v);
    assert_eq!(d.result(), AckResult::Limited);
    assert!(matches!(executed(&d), Command::SetYaw { rate_dps, .. } if rate_dps == 180.0));
}

/// A keep-in square of ±`half` metres around home, plus an optional keep-out.
pub(super) fn fence_set(
    source: CommandSource,
    half: f64,
    keep_out: Option<[(f64, f64); 2]>,
) -> GeofenceSet {
    let frame = geofence::LocalFrame::new(HOME.0, HOME.1);
    let unit = frame.to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    let ll = |n: f64, e: f64| [HOME.0 + n / unit.x * 1e-3, HOME.1 + e / unit.y * 1e-3];
    let mut set = GeofenceSet {
        vehicle_id: 1,
        enabled: 1,
        source: source.to_wire(),
        ceiling_m: 30.0,
        floor_m: -5.0,
        ..Default::default()
    };
    set.push_polygon(
        FenceKind::KeepIn,
        &[
            ll(-half, -half),
            ll(half, -half),
            ll(half, half),
            ll(-half, half),
        ],
    );
    if let Some([(n0, e0), (n1, e1)]) = keep_out {
        set.push_polygon(
            FenceKind::KeepOut,
            &[ll(n0, e0), ll(n1, e0), ll(n1, e1), ll(n0, e1)],
        );
    }
    set
}

pub(super) fn goto_ne(north: f64, east: f64, alt: f32) -> Command {
    let v = flying(north, east, [0.0; 3]).position.unwrap();
    Command::GoTo {
        lat_deg: v.lat_deg,
        lon_deg: v.lon_deg,
        alt_rel_m: alt,
        yaw_deg: None,
        speed_mps: None,
    }
}

pub(super) fn event_kinds(effects: &[Effect]) -> Vec<ArbiterEventKind> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Event { kind, .. } | Effect::Fence { kind, .. } => Some(*kind),
            _ => None,
        })
        .collect()
}

#[test]
fn the_geofence_refuses_targets_and_limits_velocities() {
    let mut a = Arbiter::new(settings());
    let fx = a.set_geofence(
        &fence_set(Operator, 50.0, Some([(20.0, -5.0), (30.0, 5.0)])),
        1,
    );
    assert_eq!(event_kinds(&fx), [ArbiterEventKind::GeofenceUpdated]);
    let v = flying(0.0, 0.0, [0.0; 3]);
    let d = a.decide(S, &sample(Operator, goto_ne(80.0, 0.0, 10.0), S), &v);
    assert_eq!(
        refusal(&d),
        (RefusalReason::Geofence, "target outside the fence")
    );
    assert_eq!(event_kinds(&d.effects), [ArbiterEventKind::GeofenceRefused]);
    assert_eq!(
        a.authority().state(1).flight(),
        None,
        "refused: no implicit grab"
    );
    let d = a.decide(S, &sample(Operator, goto_ne(25.0, 0.0, 10.0), S), &v);
    assert_eq!(
        refusal(&d).0,
        RefusalReason::Geofence,
        "inside the keep-out"
    );
    let d = a.decide(S, &sample(Operator, goto_ne(40.0, 0.0, 10.0), S), &v);
    assert_eq!(
        refusal(&d),
        (
            RefusalReason::Geofence,
            "path passes within 2.0 m of the fence"
        )
    );
    let d = a.decide(S, &sample(Operator, goto_ne(40.0, 20.0, 10.0), S), &v);
    assert_eq!(
        d.result(),
        AckResult::Accepted,
        "a path around the keep-out"
    );
    let d = a.decide(S, &sample(Operator, goto_ne(10.0, 0.0, 45.0), S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Geofence, "above the ceiling");
    let d = a.decide(
        S,
        &sample(Operator, Command::Takeoff { alt_rel_m: 40.0 }, S),
        &v,
    );
    assert_eq!(refusal(&d).0, RefusalReason::Geofence);
    // Velocity toward the keep-out 20 m ahead: √(2·1.5·18) ≈ 7.3 m/s.
    let d = a.decide(2 * S, &sample(Operator, vel(10.0, 0.0, 0.0), 2 * S), &v);
    assert_eq!(d.result(), AckResult::Limited);
    assert_eq!(event_kinds(&d.effects), [ArbiterEventKind::GeofenceLimited]);
    let Command::VelocityNed { vel_ned_mps, .. } = executed(&d) else {
        unreachable!()
    };
    // Below √(2·1.5·18) ≈ 7.3 m/s: the lag and the margin measured perpendicular.
    assert!(
        vel_ned_mps[0] > 4.0 && vel_ned_mps[0] < 7.3,
        "{vel_ned_mps:?}"
    );
    let d = a.decide(2 * S, &sample(Operator, vel(10.0, 0.0, 0.0), 2 * S), &v);
    assert!(
        event_kinds(&d.effects).is_empty(),
        "the event marks the start only"
    );
    // Outside: only back in.
    let outside = flying(60.0, 0.0, [0.0; 3]);
    let d = a.decide(
        3 * S,
        &sample(Operator, vel(2.0, 0.0, 0.0), 3 * S),
        &outside,
    );
    assert_eq!(executed(&d), vel(0.0, 0.0, 0.0));
    // Unknown position: nothing moves under a fence.
    let d = a.decide(
        4 * S,
        &sample(Operator, vel(2.0, 0.0, 0.0), 4 * S),
        &VehicleView::default(),
    );
    assert_eq!(
        (executed(&d), d.detail()),
        (vel(0.0, 0.0, 0.0), "position unknown: fence holds")
    );
}

#[test]
fn fence_updates_are_validated_and_owned() {
    let mut a = Arbiter::new(settings());
    a.set_geofence(&fence_set(Operator, 50.0, None), 1);
    let mut bad = fence_set(Operator, 10.0, None);
    bad.polygons[0].vertices[1][0] = f64::NAN;
    assert_eq!(
        event_kinds(&a.set_geofence(&bad, 1)),
        [ArbiterEventKind::GeofenceInvalid]
    );
    assert_eq!(
        event_kinds(&a.set_geofence(&fence_set(Operator, 10.0, None), 2)),
        [ArbiterEventKind::GeofenceInvalid]
    );
    // Vision's own 10 m fence is added to the operator's, not in its place.
    let fx = a.set_geofence(&fence_set(Vision, 10.0, None), 1);
    assert_eq!(event_kinds(&fx), [ArbiterEventKind::GeofenceUpdated]);
    let v = flying(0.0, 0.0, [0.0; 3]);
    let d = a.decide(S, &sample(Operator, goto_ne(30.0, 0.0, 10.0), S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Geofence, "outside vision's");
    let own = GeofenceSet {
        vehicle_id: 1,
        source: Vision.to_wire(),
        ..Default::default()
    };
    a.set_geofence(&own, 1);
    let d = a.decide(S, &sample(Operator, goto_ne(30.0, 0.0, 10.0), S), &v);
    assert_eq!(
        d.result(),
        AckResult::Accepted,
        "the 50 m fence is still in force"
    );
    let clear = GeofenceSet {
        vehicle_id: 1,
        source: Safety.to_wire(),
        target_source: Operator.to_wire(),
        ..Default::default()
    };
    assert_eq!(
        event_kinds(&a.set_geofence(&clear, 1)),
        [ArbiterEventKind::GeofenceUpdated]
    );
    assert!(a.fence().is_empty());
}

#[test]
fn link_loss_clears_authority_but_not_an_emergency() {
    let mut a = Arbiter::new(settings());
    let v = VehicleView::default();
    assert_eq!(
        event_kinds(&a.link_changed(true, S)),
        [ArbiterEventKind::LinkRestored]
    );
    a.decide(S, &sample(ShotEngine, Command::GrabFlightAuthority, S), &v);
    a.decide(S, &sample(Vision, Command::GrabPayloadAuthority, S), &v);
    let fx = a.link_changed(false, 2 * S);
    assert_eq!(
        authority_changes(&fx),
        [AuthorityChange::LinkLost, AuthorityChange::LinkLost]
    );
    assert_eq!(event_kinds(&fx), [ArbiterEventKind::LinkLost]);
    assert!(a.link_changed(false, 2 * S).is_empty());
    a.link_changed(true, 3 * S);
    a.decide(3 * S, &sample(Imc, Command::EmergencyStop, 3 * S), &v);
    let fx = a.link_changed(false, 4 * S);
    assert!(authority_changes(&fx).is_empty());
    assert_eq!(a.authority().state(1).flight(), Some(Safety));
}

#[test]
fn set_home_needs_flight_authority_and_keeps_the_stream() {
    let mut a = Arbiter::new(settings());
    a.set_geofence(&fence_set(Operator, 50.0, None), 1);
    let v = flying(0.0, 0.0, [0.0; 3]);
    // 20 m north, inside the 50 m keep-in, at home's altitude: executed as sent.
    let p = flying(20.0, 0.0, [0.0; 3]).position.unwrap();
    let home = Command::SetHome {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_msl_m: HOME_ALT_MSL + 0.5,
    };
    a.decide(S, &sample(ShotEngine, vel(2.0, 0.0, 0.0), S), &v);
    let d = a.decide(S + 100 * MS, &sample(ShotEngine, home, S + 100 * MS), &v);
    assert_eq!(executed(&d), home);
    assert_eq!(d.result(), AckResult::Accepted);
    // The velocity stream goes on: its stale brake is still due.
    assert_eq!(
        a.poll(S + 500 * MS),
        [Effect::StaleBrake { source: ShotEngine }]
    );
    // Flight authority: a lower source is refused, naming the holder.
    let d = a.decide(2 * S, &sample(Vision, home, 2 * S), &v);
    assert_eq!(
        refusal(&d),
        (
            RefusalReason::NoAuthority,
            "flight authority held by shot_engine"
        )
    );
}
