//! Tests of [`super::session`].

use std::time::{Duration, Instant};

use dji_proto::{codes, DroneControl};
use skymesh_ipc_types::{Command, FlightMode};

use super::session::*;
use crate::link::Snapshot;

const LIMITS: SessionLimits = SessionLimits {
    stick_max_age: Duration::from_millis(500),
    heartbeat_timeout: Duration::from_secs(60),
};

fn stick(seq: i64, x: f64, y: f64, h: f64, w: f64) -> DroneControl {
    DroneControl { seq, x, y, h, w }
}

fn guided() -> VehicleView {
    VehicleView {
        holds_flight: true,
        available: true,
        mode: FlightMode::Guided,
        armed: true,
        yaw_rad: Some(0.0),
    }
}

fn velocity(d: StickDecision) -> ([f32; 3], f32) {
    match d {
        StickDecision::Fly {
            setpoint:
                Command::VelocityNed {
                    vel_ned_mps,
                    yaw_rate_dps: Some(w),
                },
            ..
        } => (vel_ned_mps, w),
        other => panic!("not flown: {other:?}"),
    }
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4)
}

#[test]
fn body_sticks_become_ned_rotated_by_yaw() {
    // Facing north: forward is north, LEFT (+x) is west.
    let (v, w) = velocity(StickDecision::Fly {
        set_guided: false,
        setpoint: stick_setpoint(&stick(0, 0.0, 2.0, 1.0, 30.0), 0.0),
    });
    assert!(close(v, [2.0, 0.0, -1.0]), "{v:?}");
    assert_eq!(w, 30.0);
    let v = |x, y, yaw_deg: f32| match stick_setpoint(
        &stick(0, x, y, 0.0, 0.0),
        yaw_deg.to_radians(),
    ) {
        Command::VelocityNed { vel_ned_mps, .. } => vel_ned_mps,
        other => panic!("{other:?}"),
    };
    assert!(close(v(3.0, 0.0, 0.0), [0.0, -3.0, 0.0]), "left = west");
    assert!(close(v(-3.0, 0.0, 0.0), [0.0, 3.0, 0.0]), "right = east");
    // Facing east: forward is east, left is north.
    assert!(close(v(0.0, 2.0, 90.0), [0.0, 2.0, 0.0]));
    assert!(close(v(2.0, 0.0, 90.0), [2.0, 0.0, 0.0]));
    // Facing south-west, forward 1: south-west.
    let h = std::f32::consts::FRAC_1_SQRT_2;
    assert!(close(v(0.0, 1.0, 225.0), [-h, -h, 0.0]));
}

#[test]
fn zero_stick_is_a_hold() {
    let mut s = Session::new(LIMITS, Instant::now());
    let (v, w) =
        velocity(s.drone_control(Instant::now(), &stick(1, 0.0, 0.0, 0.0, 0.0), &guided()));
    assert_eq!((v, w), ([0.0; 3], 0.0));
    assert!(!s.sticks_active());
}

#[test]
fn lower_seq_is_refused_and_zero_restarts() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    let v = guided();
    let fly = |s: &mut Session, seq| s.drone_control(t0, &stick(seq, 0.0, 1.0, 0.0, 0.0), &v);
    assert!(matches!(fly(&mut s, 5), StickDecision::Fly { .. }));
    assert_eq!(
        fly(&mut s, 4),
        StickDecision::Refuse(codes::SEQ_OUT_OF_ORDER)
    );
    assert!(
        matches!(fly(&mut s, 5), StickDecision::Fly { .. }),
        "equal: a duplicate"
    );
    assert!(
        matches!(fly(&mut s, 0), StickDecision::Fly { .. }),
        "0 restarts"
    );
    assert!(matches!(fly(&mut s, 1), StickDecision::Fly { .. }));
    assert_eq!(fly(&mut s, 0), fly(&mut s, 0));
    // A refused seq does not move the count.
    assert!(matches!(fly(&mut s, 9), StickDecision::Fly { .. }));
    assert_eq!(
        fly(&mut s, 3),
        StickDecision::Refuse(codes::SEQ_OUT_OF_ORDER)
    );
    assert!(matches!(fly(&mut s, 9), StickDecision::Fly { .. }));
}

#[test]
fn authority_comes_first() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    let mut v = guided();
    assert!(matches!(
        s.drone_control(t0, &stick(7, 0.0, 1.0, 0.0, 0.0), &v),
        StickDecision::Fly { .. }
    ));
    v.holds_flight = false;
    assert_eq!(
        s.drone_control(t0, &stick(1, 0.0, 1.0, 0.0, 0.0), &v),
        StickDecision::Refuse(codes::NO_FLIGHT_AUTHORITY),
        "no authority wins over a low seq"
    );
}

#[test]
fn a_stale_moving_stream_brakes_and_the_next_stick_is_refused() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    let v = guided();
    assert!(matches!(
        s.drone_control(t0, &stick(1, 0.0, 3.0, 0.0, 0.0), &v),
        StickDecision::Fly { .. }
    ));
    assert!(s.sticks_active());
    assert_eq!(s.next_deadline(), t0 + LIMITS.stick_max_age);
    assert_eq!(s.poll(t0 + Duration::from_millis(499)), None);
    assert_eq!(s.poll(t0 + LIMITS.stick_max_age), Some(Due::Brake));
    assert!(!s.sticks_active());
    assert_eq!(s.poll(t0 + Duration::from_secs(1)), None, "braked once");
    let t1 = t0 + Duration::from_secs(2);
    assert_eq!(
        s.drone_control(t1, &stick(2, 0.0, 3.0, 0.0, 0.0), &v),
        StickDecision::Refuse(codes::STICK_STALE)
    );
    assert!(matches!(
        s.drone_control(t1, &stick(3, 0.0, 3.0, 0.0, 0.0), &v),
        StickDecision::Fly { .. }
    ));
}

#[test]
fn a_pause_after_a_zero_stick_is_not_stale() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    let v = guided();
    s.drone_control(t0, &stick(1, 0.0, 0.0, 0.0, 0.0), &v);
    assert_eq!(s.next_deadline(), t0 + LIMITS.heartbeat_timeout);
    assert_eq!(s.poll(t0 + Duration::from_secs(5)), None);
    let later = t0 + Duration::from_secs(5);
    assert!(matches!(
        s.drone_control(later, &stick(2, 1.0, 0.0, 0.0, 0.0), &v),
        StickDecision::Fly { .. }
    ));
}

#[test]
fn emergency_stop_ends_the_stream_without_a_stale_answer() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    s.drone_control(t0, &stick(1, 0.0, 3.0, 0.0, 0.0), &guided());
    s.emergency_stop();
    assert!(!s.sticks_active());
    assert_eq!(s.poll(t0 + Duration::from_secs(1)), None);
}

#[test]
fn heartbeats_keep_the_session_and_silence_ends_it() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    assert_eq!(s.next_deadline(), t0 + LIMITS.heartbeat_timeout);
    s.heart_beat(t0 + Duration::from_secs(50));
    assert_eq!(s.poll(t0 + Duration::from_secs(100)), None);
    assert_eq!(
        s.poll(t0 + Duration::from_secs(110)),
        Some(Due::HeartbeatTimeout)
    );
}

#[test]
fn guided_is_requested_for_moving_sticks_at_most_every_period() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    let mut v = guided();
    v.mode = FlightMode::Loiter;
    let guided_asked = |d| {
        matches!(
            d,
            StickDecision::Fly {
                set_guided: true,
                ..
            }
        )
    };
    assert!(
        !guided_asked(s.drone_control(t0, &stick(1, 0.0, 0.0, 0.0, 0.0), &v)),
        "zero stick: no mode change"
    );
    assert!(guided_asked(s.drone_control(
        t0,
        &stick(2, 0.0, 1.0, 0.0, 0.0),
        &v
    )));
    let t1 = t0 + Duration::from_millis(100);
    assert!(!guided_asked(s.drone_control(
        t1,
        &stick(3, 0.0, 1.0, 0.0, 0.0),
        &v
    )));
    let t2 = t0 + GUIDED_REQUEST_EVERY;
    assert!(guided_asked(s.drone_control(
        t2,
        &stick(4, 0.0, 0.0, 1.0, 0.0),
        &v
    )));
    v.mode = FlightMode::Guided;
    let t3 = t2 + GUIDED_REQUEST_EVERY;
    assert!(!guided_asked(s.drone_control(
        t3,
        &stick(5, 0.0, 1.0, 0.0, 0.0),
        &v
    )));
}

#[test]
fn returning_landing_or_unreachable_vehicles_refuse_sticks() {
    let t0 = Instant::now();
    let mut s = Session::new(LIMITS, t0);
    for mode in [FlightMode::Rtl, FlightMode::SmartRtl, FlightMode::Land] {
        let v = VehicleView { mode, ..guided() };
        assert_eq!(
            s.drone_control(t0, &stick(1, 0.0, 1.0, 0.0, 0.0), &v),
            StickDecision::Refuse(codes::WRONG_STATE),
            "{mode:?}"
        );
    }
    let down = VehicleView {
        available: false,
        ..guided()
    };
    assert_eq!(
        s.drone_control(t0, &stick(1, 0.0, 1.0, 0.0, 0.0), &down),
        StickDecision::Refuse(codes::VEHICLE_UNAVAILABLE)
    );
    let no_yaw = VehicleView {
        yaw_rad: None,
        ..guided()
    };
    assert_eq!(
        s.drone_control(t0, &stick(1, 1.0, 0.0, 0.0, 0.0), &no_yaw),
        StickDecision::Refuse(codes::VEHICLE_UNAVAILABLE),
        "a horizontal stick needs the yaw"
    );
    let (v, w) = velocity(s.drone_control(t0, &stick(2, 0.0, 0.0, -2.0, 10.0), &no_yaw));
    assert_eq!((v, w), ([0.0, 0.0, 2.0], 10.0), "climb and turn need none");
}

#[test]
fn the_view_reads_the_snapshot() {
    use skymesh_ipc_types::{AuthorityState, CommandSource, VehicleState, VehicleStatus};
    let now_ns = 10_000_000_000;
    let mut status = VehicleStatus {
        link_up: 1,
        armed: 1,
        mode: FlightMode::Loiter.to_wire(),
        ..Default::default()
    };
    status.header.stamp_ns = now_ns - 1_000_000_000;
    let state = VehicleState {
        attitude_valid: 0,
        position_valid: 1,
        heading_deg: 90.0,
        ..Default::default()
    };
    let authority = AuthorityState {
        flight_holder: CommandSource::DjiDrc.to_wire(),
        ..Default::default()
    };
    let snap = Snapshot {
        state: Some(state),
        status: Some(status),
        payload: None,
        authority: Some(authority),
    };
    let v = VehicleView::from_snapshot(&snap, now_ns);
    assert!(v.holds_flight && v.available && v.armed);
    assert_eq!(v.mode, FlightMode::Loiter);
    assert!(
        (v.yaw_rad.unwrap() - std::f32::consts::FRAC_PI_2).abs() < 1e-6,
        "heading fallback"
    );
    let v = VehicleView::from_snapshot(&snap, now_ns + 3_000_000_000);
    assert!(!v.available, "status too old");
    assert!(!VehicleView::from_snapshot(&Snapshot::default(), now_ns).available);
}
