//! Issue 42's arbiter rules: the emergency stop owned by its engagers, forced
//! arm/disarm, bounded `SetHome`, orphaned position targets, autopilot failsafes.

use super::tests::{
    authority_changes, event_kinds, executed, fence_set, flying, goto_ne, refusal, sample,
    settings, vel, HOME_ALT_MSL, S,
};
use super::*;
use skymesh_ipc_types::{AckResult, AuthorityChange, FlightMode};
use CommandSource::*;

fn stop_by(a: &mut Arbiter, source: CommandSource, id: u32, t: u64, v: &VehicleView) -> Decision {
    let mut s = sample(source, Command::EmergencyStop, t);
    s.command_id = id;
    a.decide(t, &s, v)
}

#[test]
fn two_engagers_the_stop_holds_until_both_release() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [3.0, 0.0, 0.0]);
    assert_eq!(
        executed(&stop_by(&mut a, DjiDrc, 5, S, &v)),
        Command::EmergencyStop
    );
    assert_eq!(
        executed(&stop_by(&mut a, Operator, 9, S, &v)),
        Command::EmergencyStop
    );
    let st = a.authority().state(1);
    assert_eq!((st.flight(), st.emergency), (Some(Safety), 1));
    assert_eq!(
        st.emergency_sources,
        1 << DjiDrc.to_wire() | 1 << Operator.to_wire()
    );
    // A source that engaged nothing lifts nothing.
    let d = a.decide(
        2 * S,
        &sample(SwarmQueue, Command::ReleaseEmergency, 2 * S),
        &v,
    );
    assert_eq!(d.detail(), "no emergency stop by swarm_queue in force");
    assert!(d.effects.is_empty());
    let d = a.decide(
        2 * S,
        &sample(Operator, Command::ReleaseEmergency, 2 * S),
        &v,
    );
    assert_eq!(d.result(), AckResult::Accepted);
    assert_eq!(
        event_kinds(&d.effects),
        [ArbiterEventKind::EmergencyReleased]
    );
    assert!(authority_changes(&d.effects).is_empty());
    assert_eq!(
        a.authority().state(1).emergency_sources,
        1 << DjiDrc.to_wire()
    );
    // Still in force: the operator itself may not command now.
    let d = a.decide(3 * S, &sample(Operator, vel(1.0, 0.0, 0.0), 3 * S), &v);
    assert_eq!(refusal(&d).0, RefusalReason::Emergency);
    let d = a.decide(4 * S, &sample(DjiDrc, Command::ReleaseEmergency, 4 * S), &v);
    assert_eq!(
        event_kinds(&d.effects),
        [
            ArbiterEventKind::EmergencyReleased,
            ArbiterEventKind::EmergencyCleared
        ]
    );
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Released]);
    let st = a.authority().state(1);
    assert_eq!(
        (st.flight(), st.emergency, st.emergency_sources),
        (None, 0, 0)
    );
    let d = a.decide(5 * S, &sample(ShotEngine, vel(1.0, 0.0, 0.0), 5 * S), &v);
    assert_eq!(d.result(), AckResult::Accepted);
}

#[test]
fn releasing_flight_authority_never_ends_a_stop() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [0.0; 3]);
    stop_by(&mut a, SwarmQueue, 1, S, &v);
    for source in [Safety, SwarmQueue] {
        let d = a.decide(
            2 * S,
            &sample(source, Command::ReleaseFlightAuthority, 2 * S),
            &v,
        );
        assert!(d.effects.is_empty(), "{source}: {d:?}");
        if source == Safety {
            assert_eq!(d.detail(), "emergency stop in force: safety keeps it");
        } else {
            assert_eq!(d.reason(), RefusalReason::Emergency);
        }
        assert_eq!(a.authority().state(1).emergency, 1, "{source}");
        assert_eq!(a.authority().state(1).flight(), Some(Safety));
    }
}

#[test]
fn clear_emergency_only_from_operator_or_safety_and_names_the_sender() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [0.0; 3]);
    stop_by(&mut a, DjiDrc, 1, S, &v);
    stop_by(&mut a, Imc, 2, S, &v);
    for source in [ShotEngine, DjiDrc, ManualRc] {
        let d = a.decide(2 * S, &sample(source, Command::ClearEmergency, 2 * S), &v);
        let (reason, detail) = refusal(&d);
        assert_eq!(reason, RefusalReason::Denied, "{source}");
        assert_eq!(detail, "clear_emergency: operator or safety only");
        assert!(d.effects.is_empty());
        assert_eq!(a.authority().state(1).emergency, 1);
    }
    let d = a.decide(3 * S, &sample(Operator, Command::ClearEmergency, 3 * S), &v);
    assert_eq!(d.detail(), "cleared by operator; engaged by dji_drc, imc");
    assert!(d.effects.contains(&Effect::Event {
        kind: ArbiterEventKind::EmergencyCleared,
        source: Some(Operator),
        detail: "cleared by operator; engaged by dji_drc, imc".into(),
    }));
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Released]);
    assert_eq!(a.authority().state(1).emergency, 0);
    let d = a.decide(4 * S, &sample(Safety, Command::ClearEmergency, 4 * S), &v);
    assert_eq!(d.detail(), "no emergency stop in force");
    assert!(d.effects.is_empty());
    // Safety may clear too.
    stop_by(&mut a, Vision, 3, 5 * S, &v);
    let d = a.decide(6 * S, &sample(Safety, Command::ClearEmergency, 6 * S), &v);
    assert_eq!(d.detail(), "cleared by safety; engaged by vision");
}

#[test]
fn forced_disarm_is_refused_in_the_air_and_forced_arm_only_from_safety_or_operator() {
    let mut a = Arbiter::new(settings());
    let air = flying(0.0, 0.0, [0.0; 3]);
    for source in [Safety, Operator, ManualRc] {
        let d = a.decide(S, &sample(source, Command::Disarm { force: true }, S), &air);
        assert_eq!(refusal(&d).0, RefusalReason::InAir, "{source}");
    }
    assert_eq!(
        executed(&a.decide(
            S,
            &sample(Safety, Command::Disarm { force: false }, S),
            &air
        )),
        Command::Disarm { force: false },
        "a plain disarm is left to the autopilot's landed check"
    );
    let mut ground = flying(0.0, 0.0, [0.0; 3]);
    if let Some(k) = &mut ground.position {
        k.alt_rel_m = 0.1;
    }
    assert_eq!(
        executed(&a.decide(
            2 * S,
            &sample(Safety, Command::Disarm { force: true }, 2 * S),
            &ground
        )),
        Command::Disarm { force: true }
    );
    let mut a = Arbiter::new(settings());
    let idle = VehicleView::default();
    for source in [Imc, ShotEngine, DjiDrc, ManualRc, Vision, SwarmQueue] {
        let d = a.decide(
            3 * S,
            &sample(source, Command::Arm { force: true }, 3 * S),
            &idle,
        );
        assert_eq!(refusal(&d).0, RefusalReason::Denied, "{source}");
    }
    assert_eq!(
        executed(&a.decide(
            4 * S,
            &sample(Imc, Command::Arm { force: false }, 4 * S),
            &idle
        )),
        Command::Arm { force: false }
    );
    for source in [Operator, Safety] {
        let d = a.decide(
            5 * S,
            &sample(source, Command::Arm { force: true }, 5 * S),
            &idle,
        );
        assert_eq!(executed(&d), Command::Arm { force: true }, "{source}");
    }
}

fn home_at(north: f64, east: f64, alt_msl_m: f32) -> Command {
    let p = flying(north, east, [0.0; 3]).position.unwrap();
    Command::SetHome {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_msl_m,
    }
}

#[test]
fn set_home_is_bounded_by_distance_altitude_and_the_fences() {
    let mut a = Arbiter::new(settings());
    let v = flying(0.0, 0.0, [0.0; 3]);
    let unknown = VehicleView { home: None, ..v };
    let d = a.decide(
        S,
        &sample(Operator, home_at(5.0, 0.0, HOME_ALT_MSL), S),
        &unknown,
    );
    assert_eq!(refusal(&d).0, RefusalReason::WrongState);
    // Default limits: 50 m, ±1 m.
    let d = a.decide(
        S,
        &sample(Operator, home_at(45.0, 30.0, HOME_ALT_MSL), S),
        &v,
    );
    let (reason, detail) = refusal(&d);
    assert_eq!(reason, RefusalReason::Denied);
    assert_eq!(detail, "new home 54 m from the current one, max 50 m");
    let d = a.decide(
        S,
        &sample(Operator, home_at(0.0, -49.0, HOME_ALT_MSL), S),
        &v,
    );
    assert_eq!(d.result(), AckResult::Accepted);
    let d = a.decide(
        S,
        &sample(Operator, home_at(5.0, 0.0, HOME_ALT_MSL + 1.5), S),
        &v,
    );
    assert_eq!(refusal(&d).0, RefusalReason::Denied);
    let d = a.decide(
        S,
        &sample(Operator, home_at(5.0, 0.0, HOME_ALT_MSL - 1.5), S),
        &v,
    );
    assert_eq!(refusal(&d).0, RefusalReason::Denied);
    // Inside every fence: a 30 m keep-in of one source and a keep-out of another.
    a.set_geofence(&fence_set(Operator, 30.0, None), 1);
    a.set_geofence(
        &fence_set(ShotEngine, 100.0, Some([(5.0, 5.0), (15.0, 15.0)])),
        1,
    );
    let d = a.decide(
        2 * S,
        &sample(Operator, home_at(40.0, 0.0, HOME_ALT_MSL), 2 * S),
        &v,
    );
    assert_eq!(
        refusal(&d),
        (RefusalReason::Geofence, "new home outside the geofence")
    );
    let d = a.decide(
        2 * S,
        &sample(Operator, home_at(10.0, 10.0, HOME_ALT_MSL), 2 * S),
        &v,
    );
    assert_eq!(refusal(&d).0, RefusalReason::Geofence, "in the keep-out");
    let d = a.decide(
        2 * S,
        &sample(Operator, home_at(-10.0, 20.0, HOME_ALT_MSL + 1.0), 2 * S),
        &v,
    );
    assert_eq!(d.result(), AckResult::Accepted);
}

fn target_brakes(effects: &[Effect]) -> Vec<CommandSource> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::TargetBrake { source } => Some(*source),
            _ => None,
        })
        .collect()
}

#[test]
fn a_position_target_reached_is_over_and_its_source_may_go_quiet() {
    let moving = flying(0.0, 0.0, [2.0, 0.0, 0.0]);
    let mut a = Arbiter::new(settings());
    executed(&a.decide(S, &sample(SwarmQueue, goto_ne(40.0, 0.0, 10.0), S), &moving));
    // Close but still moving, or at rest short of the point: not reached.
    a.observe(&flying(39.5, 0.0, [1.0, 0.0, 0.0]));
    a.observe(&flying(30.0, 0.0, [0.0; 3]));
    let fx = a.poll(7 * S);
    assert_eq!(
        target_brakes(&fx),
        [SwarmQueue],
        "quiet before arriving: braked"
    );
    // At rest within 1.5 m and 1 m of altitude: over, no brake when it goes quiet.
    let mut a = Arbiter::new(settings());
    executed(&a.decide(S, &sample(SwarmQueue, goto_ne(40.0, 0.0, 10.0), S), &moving));
    a.observe(&flying(39.2, 0.5, [0.1, 0.0, 0.0]));
    let fx = a.poll(7 * S);
    assert_eq!(authority_changes(&fx), [AuthorityChange::Timeout]);
    assert!(target_brakes(&fx).is_empty(), "arrived, then quiet: {fx:?}");
    // A take-off is reached at its altitude (wherever it drifted horizontally).
    let mut a = Arbiter::new(settings());
    let climb = Command::Takeoff { alt_rel_m: 10.0 };
    executed(&a.decide(S, &sample(SwarmQueue, climb, S), &moving));
    a.observe(&flying(3.0, 3.0, [0.0, 0.0, -0.2]));
    assert!(target_brakes(&a.poll(7 * S)).is_empty());
}

#[test]
fn a_position_target_is_braked_when_its_source_loses_authority() {
    let v = flying(0.0, 0.0, [2.0, 0.0, 0.0]);
    // Pre-empted by a command that does not replace the target (a yaw).
    let mut a = Arbiter::new(settings());
    executed(&a.decide(S, &sample(ShotEngine, goto_ne(40.0, 0.0, 10.0), S), &v));
    let yaw = Command::SetYaw {
        yaw_deg: 90.0,
        rate_dps: 30.0,
        relative: false,
    };
    let d = a.decide(2 * S, &sample(DjiDrc, yaw, 2 * S), &v);
    assert_eq!(executed(&d), yaw);
    assert_eq!(target_brakes(&d.effects), [ShotEngine]);
    assert_eq!(authority_changes(&d.effects), [AuthorityChange::Preempted]);
    // ... or by an explicit grab.
    let mut a = Arbiter::new(settings());
    a.decide(
        S,
        &sample(SwarmQueue, Command::Takeoff { alt_rel_m: 10.0 }, S),
        &v,
    );
    let d = a.decide(
        2 * S,
        &sample(Operator, Command::GrabFlightAuthority, 2 * S),
        &v,
    );
    assert_eq!(target_brakes(&d.effects), [SwarmQueue]);
    // Pre-empted by a new target: that replaces it, no brake.
    let mut a = Arbiter::new(settings());
    a.decide(S, &sample(ShotEngine, goto_ne(40.0, 0.0, 10.0), S), &v);
    let d = a.decide(2 * S, &sample(DjiDrc, goto_ne(0.0, 40.0, 10.0), 2 * S), &v);
    assert!(target_brakes(&d.effects).is_empty());
    // The new holder times out (5 s): braked.
    assert!(a.poll(6 * S).is_empty());
    assert_eq!(
        target_brakes(&a.poll(7 * S)),
        [DjiDrc],
        "authority timed out with a target flying"
    );
    assert!(target_brakes(&a.poll(20 * S)).is_empty(), "once");
    // A target ended by the holder's own Brake is not braked again at the timeout.
    let mut a = Arbiter::new(settings());
    a.decide(S, &sample(Imc, goto_ne(40.0, 0.0, 10.0), S), &v);
    a.decide(2 * S, &sample(Imc, Command::Brake, 2 * S), &v);
    let fx = a.poll(8 * S);
    assert_eq!(authority_changes(&fx), [AuthorityChange::Timeout]);
    assert!(target_brakes(&fx).is_empty());
    // A voluntary release leaves the target to finish.
    let mut a = Arbiter::new(settings());
    a.decide(S, &sample(Imc, goto_ne(40.0, 0.0, 10.0), S), &v);
    let d = a.decide(
        2 * S,
        &sample(Imc, Command::ReleaseFlightAuthority, 2 * S),
        &v,
    );
    assert!(target_brakes(&d.effects).is_empty());
}

#[test]
fn an_autopilot_failsafe_is_held_against_sources_below_manual_rc() {
    let mut a = Arbiter::new(settings());
    let mut rtl = flying(0.0, 0.0, [2.0, 0.0, 0.0]);
    rtl.mode = FlightMode::Rtl;
    a.decide(S, &sample(Operator, Command::GrabFlightAuthority, S), &rtl);
    let motion = [
        Command::SetMode(FlightMode::Guided),
        Command::Brake,
        goto_ne(10.0, 0.0, 10.0),
        vel(1.0, 0.0, 0.0),
        Command::Takeoff { alt_rel_m: 5.0 },
        Command::SetYaw {
            yaw_deg: 10.0,
            rate_dps: 10.0,
            relative: true,
        },
        home_at(5.0, 0.0, HOME_ALT_MSL),
    ];
    for (i, cmd) in motion.iter().enumerate() {
        let d = a.decide(2 * S, &sample(Operator, *cmd, 2 * S), &rtl);
        let (reason, detail) = refusal(&d);
        assert_eq!(reason, RefusalReason::AutopilotFailsafe, "{cmd:?}");
        assert_eq!(detail, "rtl failsafe held: manual RC only");
        // One FailsafeHeld event per source and failsafe, not one per command.
        let expect: &[ArbiterEventKind] = if i == 0 {
            &[ArbiterEventKind::FailsafeHeld]
        } else {
            &[]
        };
        assert_eq!(event_kinds(&d.effects), expect, "{cmd:?}");
    }
    let d = a.decide(2 * S, &sample(DjiDrc, Command::Brake, 2 * S), &rtl);
    assert_eq!(event_kinds(&d.effects), [ArbiterEventKind::FailsafeHeld]);
    assert_eq!(
        a.authority().state(1).flight(),
        Some(Operator),
        "a refusal pre-empts nobody"
    );
    // RTL during RTL, Land, payload and an emergency stop pass.
    for cmd in [
        Command::ReturnToLaunch,
        Command::Land,
        Command::CameraCapture,
    ] {
        let d = a.decide(3 * S, &sample(Operator, cmd, 3 * S), &rtl);
        assert_eq!(executed(&d), cmd);
    }
    // Manual RC and safety may take over.
    let d = a.decide(
        4 * S,
        &sample(ManualRc, Command::SetMode(FlightMode::Loiter), 4 * S),
        &rtl,
    );
    assert_eq!(executed(&d), Command::SetMode(FlightMode::Loiter));
    let d = a.decide(4 * S, &sample(Safety, Command::Brake, 4 * S), &rtl);
    assert_eq!(executed(&d), Command::Brake);
    // In LAND (a battery failsafe, often) RTL is refused too; in SmartRTL as RTL.
    let mut a = Arbiter::new(settings());
    let land = VehicleView {
        mode: FlightMode::Land,
        ..rtl
    };
    let d = a.decide(
        5 * S,
        &sample(DjiDrc, Command::ReturnToLaunch, 5 * S),
        &land,
    );
    assert_eq!(refusal(&d).0, RefusalReason::AutopilotFailsafe);
    let smart = VehicleView {
        mode: FlightMode::SmartRtl,
        ..rtl
    };
    let d = a.decide(5 * S, &sample(DjiDrc, vel(0.0, 1.0, 0.0), 5 * S), &smart);
    assert_eq!(refusal(&d).0, RefusalReason::AutopilotFailsafe);
    let d = stop_by(&mut a, DjiDrc, 1, 6 * S, &land);
    assert_eq!(executed(&d), Command::EmergencyStop);
    // Out of the failsafe, the same commands are decided as usual.
    let mut a = Arbiter::new(settings());
    let guided = flying(0.0, 0.0, [0.0; 3]);
    a.decide(7 * S, &sample(DjiDrc, Command::Brake, 7 * S), &land);
    let d = a.decide(8 * S, &sample(DjiDrc, Command::Brake, 8 * S), &guided);
    assert_eq!(executed(&d), Command::Brake);
    // ... and a new failsafe tells the source again.
    let d = a.decide(9 * S, &sample(DjiDrc, Command::Brake, 9 * S), &land);
    assert_eq!(event_kinds(&d.effects), [ArbiterEventKind::FailsafeHeld]);
}
