//! The emergency stop and the retransmissions it overrides, end to end (issue 42,
//! findings 3, 4 and 5): real supervisor, vehicle-sim and autopilot-link, with a
//! [`FaultLink`] between the last two that drops chosen frames and logs what
//! autopilot-link sent.
//!
//! - a dropped BRAKE (and the first zero setpoints): the vehicle still stops, and
//!   the stop's ack says `accepted` only once the autopilot reported BRAKE or the
//!   vehicle was measured stopped, after frames that got through;
//! - a lost ARM, then an emergency stop: the ARM is answered `cancelled` and never
//!   goes out again; a lost servo command (payload) is decided again before its
//!   retransmission and refused `emergency`; a lost ARM whose source is pre-empted:
//!   `preempted`, never again;
//! - LAND flown by the autopilot: a low-priority `Brake` is refused
//!   `autopilot_failsafe`, an emergency stop holds the descent (no BRAKE sent) and
//!   the vehicle lands.

use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::{MavCmd, MavMessage};
use skymesh_e2e::bench::take_off;
use skymesh_e2e::fault_link::{start_faulty_mesh, Dir, FaultLink, Seen};
use skymesh_e2e::ground::{runtime, Ground, PATIENCE};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{
    AckResult, Command, CommandAck, CommandSource, FlightMode, RefusalReason, VehicleState,
};

/// autopilot-link's default `stop_confirm_timeout_s`.
const STOP_CONFIRM: Duration = Duration::from_secs(5);

fn faulty_mesh() -> (Mesh, FaultLink) {
    start_faulty_mesh(MeshOptions::default(), &["vehicle-sim", "autopilot-link"]).unwrap()
}

fn speed(s: &VehicleState) -> f32 {
    let [n, e, d] = s.vel_ned_mps;
    (n * n + e * e + d * d).sqrt()
}

fn is_brake(msg: &MavMessage) -> Option<u8> {
    match msg {
        MavMessage::COMMAND_LONG(c)
            if c.command == MavCmd::MAV_CMD_DO_SET_MODE && c.param2 == 17.0 =>
        {
            Some(c.confirmation)
        }
        _ => None,
    }
}

fn is_zero_setpoint(msg: &MavMessage) -> bool {
    matches!(msg, MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) if s.vx == 0.0 && s.vy == 0.0 && s.vz == 0.0)
}

fn is_servo(msg: &MavMessage) -> bool {
    matches!(msg, MavMessage::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_DO_SET_SERVO)
}

fn is_arm(msg: &MavMessage) -> bool {
    matches!(msg, MavMessage::COMMAND_LONG(c)
        if c.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM && c.param1 == 1.0)
}

fn assert_accepted(a: &CommandAck, what: &str) {
    assert_eq!(a.result(), Some(AckResult::Accepted), "{what}: {a:?}");
}

/// Finding 3: the first BRAKE and the first five zero setpoints are lost while the
/// vehicle flies at 5 m/s in GUIDED and its operator keeps pushing. The stop is
/// retried, the vehicle stops, and the ack waits for the autopilot's word.
#[test]
fn a_dropped_brake_is_retried_and_the_ack_waits_for_the_autopilot() {
    let (mesh, link) = faulty_mesh();
    runtime().block_on(async {
        take_off(&mesh, 8.0).await.unwrap();
        let mut g = Ground::new(&mesh, "safety-stop");
        let push = Command::VelocityNed {
            vel_ned_mps: [5.0, 0.0, 0.0],
            yaw_rate_dps: None,
        };
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        let started = Instant::now();
        loop {
            tick.tick().await;
            g.send(CommandSource::Operator, &push);
            // The interval's first tick is at once: no state may have come yet.
            let Some(s) = g.state.latest().unwrap() else {
                assert!(started.elapsed() < Duration::from_secs(5), "no vehicle state");
                continue;
            };
            if speed(&s) > 4.5 {
                break;
            }
            assert!(started.elapsed() < PATIENCE, "never reached 4.5 m/s: {s:?}");
        }
        let (mut brakes, mut zeros) = (0, 0);
        link.set_rule(move |dir, msg| {
            if dir != Dir::ToVehicle {
                return false;
            }
            if is_brake(msg).is_some() {
                brakes += 1;
                return brakes == 1;
            }
            if is_zero_setpoint(msg) {
                zeros += 1;
                return zeros <= 5;
            }
            false
        });
        // Taken before the send: the link may forward the BRAKE before `send` returns.
        let sent = Instant::now();
        let stop = g.send(CommandSource::DjiDrc, &Command::EmergencyStop);
        // The operator keeps pushing (10 Hz) while the stop waits for its answer.
        let deadline = sent + STOP_CONFIRM + Duration::from_secs(2);
        let mut pushed = sent;
        let (acked_at, ack) = loop {
            if let Some(i) = g.early.iter().position(|(_, a)| a.command_id == stop) {
                break g.early.remove(i);
            }
            if let Some(a) = g.acks.recv_timeout(Duration::from_millis(20)).await.unwrap() {
                g.early.push((Instant::now(), a));
            }
            if pushed.elapsed() >= Duration::from_millis(100) {
                pushed = Instant::now();
                g.send(CommandSource::Operator, &push);
            }
            assert!(Instant::now() < deadline, "no answer to the stop");
        };
        let status = g.status.latest().unwrap().expect("status");
        let state = g.state.latest().unwrap().expect("state");
        assert_accepted(&ack, "emergency stop");
        let detail = ack.detail.as_str().to_string();
        // The confirmation the ack names was true when it was read.
        if detail.starts_with("BRAKE") {
            assert_eq!(status.flight_mode(), FlightMode::Brake, "{detail}");
        } else {
            assert!(detail.starts_with("stopped"), "{detail}");
            assert!(speed(&state) < 0.5, "{detail}: {state:?}");
        }
        // Not answered from the lost frames: only after a stop frame got through.
        let lost = link.seen(|s| s.at >= sent && s.dropped);
        assert!(lost.iter().any(|s| is_brake(&s.msg) == Some(0)), "first BRAKE not dropped");
        let through: Vec<Seen> = link.seen(|s| {
            s.at >= sent && !s.dropped && (is_brake(&s.msg).is_some() || is_zero_setpoint(&s.msg))
        });
        let first_through = through.first().expect("no stop frame got through").at;
        assert!(
            acked_at > first_through,
            "acked {:?} after the stop, first frame through at {:?}",
            acked_at - sent,
            first_through - sent
        );
        // The operator's stream was refused all along; the vehicle is stopped and
        // in BRAKE (the retried BRAKE, confirmation 1, went through).
        g.wait_state("stopped", |s| speed(s) < 0.3).await;
        g.wait_status("BRAKE", |s| s.flight_mode() == FlightMode::Brake)
            .await;
        let retried = link.seen(|s| !s.dropped && is_brake(&s.msg).is_some_and(|c| c >= 1));
        assert!(!retried.is_empty(), "BRAKE was not retried");
        let refused = g
            .early
            .iter()
            .filter(|(_, a)| a.reason() == Some(RefusalReason::Emergency))
            .count();
        assert!(refused >= 3, "operator setpoints refused: {refused}");
        println!(
            "safety_stop: stop acked after {:.2} s ({detail}); BRAKE frames {} (dropped 1), zero setpoints dropped 5",
            (acked_at - sent).as_secs_f64(),
            link.seen(|s| s.at >= sent && is_brake(&s.msg).is_some()).len(),
        );
    });
}

/// Finding 5: a lost ARM, then an emergency stop: nothing the stop overrides goes
/// out again. And a lost ARM whose source is pre-empted is not retransmitted either.
#[test]
fn a_lost_arm_is_not_retransmitted_after_a_stop_or_a_preemption() {
    let (mesh, link) = faulty_mesh();
    runtime().block_on(async {
        let mut g = Ground::new(&mesh, "safety-stop");
        g.wait_status("EKF healthy", |s| s.ekf_healthy != 0).await;
        assert_accepted(
            &g.command(
                CommandSource::SwarmQueue,
                &Command::SetMode(FlightMode::Guided),
            )
            .await,
            "GUIDED",
        );
        // Every ARM and DO_SET_SERVO to the vehicle is lost: only a retransmission
        // could arm it or move the servo.
        link.set_rule(|dir, msg| dir == Dir::ToVehicle && (is_arm(msg) || is_servo(msg)));
        let arm = g.send(CommandSource::SwarmQueue, &Command::Arm { force: false });
        let servo = g.send(
            CommandSource::Imc,
            &Command::Servo {
                channel: 9,
                pwm_us: 1900,
            },
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
        let stop = g.send(CommandSource::SwarmQueue, &Command::EmergencyStop);
        let stopped_at = Instant::now();
        let (_, a) = g.ack_within(arm, Duration::from_secs(5)).await;
        assert_eq!(
            (a.result(), a.reason()),
            (Some(AckResult::Refused), Some(RefusalReason::Cancelled)),
            "{a:?}"
        );
        let (_, s) = g
            .ack_within(stop, STOP_CONFIRM + Duration::from_secs(2))
            .await;
        assert_accepted(&s, "emergency stop on the ground");
        // The servo is payload: not cancelled by the stop, but its retransmission is
        // decided again, and the arbiter refuses it now.
        let (_, a) = g.ack_within(servo, Duration::from_secs(5)).await;
        assert_eq!(
            (a.result(), a.reason()),
            (Some(AckResult::Refused), Some(RefusalReason::Emergency)),
            "{a:?}"
        );
        assert!(
            a.detail.as_str().starts_with("not retransmitted"),
            "{:?}",
            a.detail
        );
        // Past the retransmission (1.5 s) and the timeout (3 s) of the ARM.
        tokio::time::sleep(Duration::from_secs(4)).await;
        let arms = link.seen(|s| is_arm(&s.msg));
        assert_eq!(arms.len(), 1, "ARM frames: {arms:?}");
        assert!(arms.iter().all(|s| s.at < stopped_at));
        let servos = link.seen(|s| is_servo(&s.msg));
        assert_eq!(servos.len(), 1, "DO_SET_SERVO frames: {servos:?}");
        assert!(!g.status.latest().unwrap().expect("status").is_armed());
        println!(
            "safety_stop: lost ARM cancelled by the stop, lost servo re-decided and refused; \
             1 ARM and 1 DO_SET_SERVO frame, none in the 4 s after the stop"
        );
    });
    drop(mesh);

    // Pre-emption: the swarm queue's lost ARM, the operator takes flight authority.
    let (mesh, link) = faulty_mesh();
    runtime().block_on(async {
        let mut g = Ground::new(&mesh, "safety-stop");
        g.wait_status("EKF healthy", |s| s.ekf_healthy != 0).await;
        assert_accepted(
            &g.command(
                CommandSource::SwarmQueue,
                &Command::SetMode(FlightMode::Guided),
            )
            .await,
            "GUIDED",
        );
        link.set_rule(|dir, msg| dir == Dir::ToVehicle && is_arm(msg));
        let arm = g.send(CommandSource::SwarmQueue, &Command::Arm { force: false });
        tokio::time::sleep(Duration::from_millis(300)).await;
        assert_accepted(
            &g.command(CommandSource::Operator, &Command::GrabFlightAuthority)
                .await,
            "operator grab",
        );
        let grabbed_at = Instant::now();
        let (_, a) = g.ack_within(arm, Duration::from_secs(5)).await;
        assert_eq!(
            (a.result(), a.reason()),
            (Some(AckResult::Refused), Some(RefusalReason::Preempted)),
            "{a:?}"
        );
        tokio::time::sleep(Duration::from_secs(4)).await;
        let arms = link.seen(|s| is_arm(&s.msg));
        assert_eq!(arms.len(), 1, "ARM frames: {arms:?}");
        assert!(arms.iter().all(|s| s.at < grabbed_at));
        assert!(!g.status.latest().unwrap().expect("status").is_armed());
    });
}

/// Finding 4: LAND flown by the autopilot (as its battery failsafe would). A `Brake`
/// from the swarm queue (GroundControl's EXT_HALT) is refused `autopilot_failsafe`;
/// its emergency stop holds the descent, sends no BRAKE, and the vehicle lands.
#[test]
fn a_failsafe_landing_is_held_not_braked() {
    let (mesh, link) = faulty_mesh();
    runtime().block_on(async {
        take_off(&mesh, 6.0).await.unwrap();
        let mut g = Ground::new(&mesh, "safety-stop");
        assert_accepted(
            &g.command(CommandSource::Operator, &Command::SetMode(FlightMode::Land))
                .await,
            "LAND",
        );
        assert_accepted(
            &g.command(CommandSource::Operator, &Command::ReleaseFlightAuthority)
                .await,
            "release",
        );
        g.wait_status("LAND", |s| s.flight_mode() == FlightMode::Land)
            .await;
        let from = Instant::now();
        let halt = g.command(CommandSource::SwarmQueue, &Command::Brake).await;
        assert_eq!(
            (halt.result(), halt.reason()),
            (
                Some(AckResult::Refused),
                Some(RefusalReason::AutopilotFailsafe)
            ),
            "{halt:?}"
        );
        let stop = g
            .command(CommandSource::SwarmQueue, &Command::EmergencyStop)
            .await;
        assert_accepted(&stop, "emergency stop during LAND");
        assert_eq!(stop.detail.as_str(), "failsafe descent held (land)");
        let landed = g.wait_state("landed", |s| s.alt_rel_m < 0.3).await;
        let status = g.status.latest().unwrap().expect("status");
        assert_eq!(status.flight_mode(), FlightMode::Land, "{status:?}");
        let brakes = link.seen(|s| s.at >= from && is_brake(&s.msg).is_some());
        assert!(brakes.is_empty(), "BRAKE sent over the landing: {brakes:?}");
        println!(
            "safety_stop: landed {:.1} s after the held stop ({:.2} m)",
            from.elapsed().as_secs_f64(),
            landed.alt_rel_m
        );
    });
}
