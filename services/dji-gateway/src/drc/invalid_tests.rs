//! Tests of [`super::invalid`].

use std::time::{Duration, Instant};

use dji_proto::JoystickInvalidReason;
use skymesh_ipc_types::{
    ArbiterEvent, ArbiterEventKind, AuthorityState, CommandSource, FixedStr, FlightMode,
    VehicleStatus, NO_HOLDER,
};

use super::invalid::*;
use crate::link::{Snapshot, SOURCE};

const NOW_NS: u64 = 100_000_000_000;

fn status(mode: FlightMode, pct: i8, text: &str) -> VehicleStatus {
    let mut s = VehicleStatus {
        link_up: 1,
        armed: 1,
        mode: mode.to_wire(),
        battery_remaining_pct: pct,
        status_text: FixedStr::new(text),
        ..Default::default()
    };
    s.header.stamp_ns = NOW_NS;
    s
}

fn held_by(source: Option<CommandSource>) -> AuthorityState {
    AuthorityState {
        flight_holder: source.map_or(NO_HOLDER, |s| s.to_wire()),
        ..Default::default()
    }
}

fn snap(status: VehicleStatus, holder: Option<CommandSource>) -> Snapshot {
    Snapshot {
        status: Some(status),
        authority: Some(held_by(holder)),
        ..Default::default()
    }
}

fn event(kind: ArbiterEventKind, source: u8) -> ArbiterEvent {
    ArbiterEvent {
        kind: kind.to_wire(),
        source,
        ..Default::default()
    }
}

use JoystickInvalidReason as R;

#[test]
fn link_loss_is_reported_once_per_onset() {
    let t = Instant::now();
    let mut w = InvalidWatch::new(20);
    let ok = snap(status(FlightMode::Guided, 80, ""), Some(SOURCE));
    assert_eq!(w.on_vehicle(t, &ok, NOW_NS), vec![]);
    let mut down = ok;
    down.status.as_mut().unwrap().link_up = 0;
    assert_eq!(w.on_vehicle(t, &down, NOW_NS), vec![R::RcLost]);
    assert_eq!(w.on_vehicle(t, &down, NOW_NS), vec![], "once");
    assert_eq!(w.on_vehicle(t, &ok, NOW_NS), vec![]);
    // A status that stopped coming is a lost link too.
    assert_eq!(
        w.on_vehicle(t, &ok, NOW_NS + 3_500_000_000),
        vec![R::RcLost]
    );
    // The arbiter's event reports at once and holds until it is restored.
    let mut w = InvalidWatch::new(20);
    w.on_vehicle(t, &ok, NOW_NS);
    assert_eq!(
        w.on_arbiter_event(t, &event(ArbiterEventKind::LinkLost, NO_HOLDER)),
        Some(R::RcLost)
    );
    assert_eq!(w.on_vehicle(t, &down, NOW_NS), vec![], "the same onset");
    assert_eq!(
        w.on_vehicle(t, &ok, NOW_NS),
        vec![],
        "still down for the arbiter"
    );
    assert_eq!(
        w.on_arbiter_event(t, &event(ArbiterEventKind::LinkRestored, NO_HOLDER)),
        None
    );
    assert_eq!(w.on_vehicle(t, &ok, NOW_NS), vec![]);
    assert_eq!(w.on_vehicle(t, &down, NOW_NS), vec![R::RcLost]);
}

#[test]
fn no_status_at_entry_is_a_lost_link() {
    let mut w = InvalidWatch::new(20);
    assert_eq!(
        w.on_vehicle(Instant::now(), &Snapshot::default(), NOW_NS),
        vec![R::RcLost]
    );
}

#[test]
fn battery_failsafe_modes_are_told_apart_from_other_returns() {
    let t = Instant::now();
    let case = |mode, pct, text: &str| {
        let mut w = InvalidWatch::new(20);
        w.on_vehicle(
            t,
            &snap(status(FlightMode::Guided, 80, ""), Some(SOURCE)),
            NOW_NS,
        );
        w.on_vehicle(t, &snap(status(mode, pct, text), Some(SOURCE)), NOW_NS)
    };
    assert_eq!(case(FlightMode::Rtl, 15, ""), vec![R::LowBatteryReturn]);
    assert_eq!(
        case(
            FlightMode::SmartRtl,
            -1,
            "Battery 1 is low 10.50V used 1234 mAh"
        ),
        vec![R::LowBatteryReturn]
    );
    assert_eq!(
        case(FlightMode::Land, 50, "Battery 1 is critical 9.9V"),
        vec![R::LowBatteryLanding]
    );
    assert_eq!(
        case(FlightMode::Land, 50, "Battery failsafe"),
        vec![R::LowBatteryLanding]
    );
    assert_eq!(
        case(FlightMode::Rtl, 50, ""),
        vec![R::RcTakeover],
        "someone triggered a return"
    );
    assert_eq!(
        case(
            FlightMode::Rtl,
            50,
            "PreArm: Battery 1 below minimum arming capacity"
        ),
        vec![R::RcTakeover],
        "'below' is not 'low'"
    );
    assert_eq!(
        case(FlightMode::Loiter, 5, "Battery 1 is low"),
        vec![],
        "no return, no notice"
    );
    // Disarmed on the ground in LAND: nothing to tell.
    let mut landed = status(FlightMode::Land, 5, "");
    landed.armed = 0;
    assert_eq!(
        InvalidWatch::new(20).on_vehicle(t, &snap(landed, None), NOW_NS),
        vec![]
    );
}

#[test]
fn authority_taken_by_a_higher_source_but_not_by_our_own_estop() {
    let t = Instant::now();
    let st = status(FlightMode::Guided, 80, "");
    let mut w = InvalidWatch::new(20);
    assert_eq!(w.on_vehicle(t, &snap(st, Some(SOURCE)), NOW_NS), vec![]);
    assert_eq!(
        w.on_vehicle(t, &snap(st, Some(CommandSource::ManualRc)), NOW_NS),
        vec![R::RcTakeover]
    );
    assert_eq!(
        w.on_vehicle(t, &snap(st, Some(CommandSource::Operator)), NOW_NS),
        vec![],
        "still taken"
    );
    assert_eq!(
        w.on_vehicle(t, &snap(st, Some(CommandSource::ShotEngine)), NOW_NS),
        vec![],
        "lower sources: no"
    );
    assert_eq!(
        w.on_vehicle(t, &snap(st, Some(CommandSource::Safety)), NOW_NS),
        vec![R::RcTakeover]
    );

    let mut w = InvalidWatch::new(20);
    w.on_vehicle(t, &snap(st, Some(SOURCE)), NOW_NS);
    w.emergency_stop_sent(t);
    // Before the arbiter has acted, we still hold it: the grace keeps the mark.
    assert_eq!(w.on_vehicle(t, &snap(st, Some(SOURCE)), NOW_NS), vec![]);
    assert_eq!(
        w.on_vehicle(t, &snap(st, Some(CommandSource::Safety)), NOW_NS),
        vec![],
        "our own stop"
    );
    let later = t + Duration::from_secs(60);
    assert_eq!(
        w.on_vehicle(later, &snap(st, Some(CommandSource::Safety)), NOW_NS),
        vec![],
        "still ours"
    );
    assert_eq!(w.on_vehicle(later, &snap(st, None), NOW_NS), vec![]);
    assert_eq!(
        w.on_vehicle(later, &snap(st, Some(CommandSource::Safety)), NOW_NS),
        vec![R::RcTakeover],
        "a new safety hold"
    );
}

#[test]
fn a_safety_hold_is_ours_while_the_arbiter_counts_our_stop_among_its_engagers() {
    let t = Instant::now();
    let st = status(FlightMode::Guided, 80, "");
    let stopped_by = |sources: &[CommandSource]| {
        let mut s = snap(st, Some(CommandSource::Safety));
        let a = s.authority.as_mut().unwrap();
        for source in sources {
            a.emergency = 1;
            a.emergency_sources |= 1 << source.to_wire();
        }
        s
    };
    // Our stop (from an earlier session: no grace here), with another's: ours.
    let mut w = InvalidWatch::new(20);
    assert_eq!(
        w.on_vehicle(t, &stopped_by(&[SOURCE, CommandSource::SwarmQueue]), NOW_NS),
        vec![]
    );
    // We released ours; GroundControl's stop holds the vehicle: taken from us.
    assert_eq!(
        w.on_vehicle(t, &stopped_by(&[CommandSource::SwarmQueue]), NOW_NS),
        vec![R::RcTakeover]
    );
}

#[test]
fn geofence_events_of_ours_start_a_condition_after_a_quiet_period() {
    let t = Instant::now();
    let mut w = InvalidWatch::new(20);
    let ours = |k| event(k, SOURCE.to_wire());
    assert_eq!(
        w.on_arbiter_event(t, &ours(ArbiterEventKind::GeofenceLimited)),
        Some(R::NearRestrictedZone)
    );
    assert_eq!(
        w.on_arbiter_event(
            t + Duration::from_secs(2),
            &ours(ArbiterEventKind::GeofenceRefused)
        ),
        None
    );
    assert_eq!(
        w.on_arbiter_event(
            t + Duration::from_secs(6),
            &ours(ArbiterEventKind::GeofenceLimited)
        ),
        None,
        "events kept coming"
    );
    assert_eq!(
        w.on_arbiter_event(
            t + Duration::from_secs(12),
            &ours(ArbiterEventKind::GeofenceLimited)
        ),
        Some(R::NearRestrictedZone)
    );
    let theirs = event(
        ArbiterEventKind::GeofenceLimited,
        CommandSource::ShotEngine.to_wire(),
    );
    assert_eq!(InvalidWatch::new(20).on_arbiter_event(t, &theirs), None);
    assert_eq!(
        InvalidWatch::new(20).on_arbiter_event(t, &ours(ArbiterEventKind::StaleBrake)),
        None
    );
}
