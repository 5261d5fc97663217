//! The command arbiter against vehicle-sim, in-process: real TCP on 127.0.0.1, real
//! iceoryx2 shared memory in a domain of its own per test.
//!
//! Timeouts are generous; the only timing asserted is the braking bound
//! (speed below 0.3 m/s within 1.5 s of the last setpoint), and it is measured with
//! the samples' own `CLOCK_MONOTONIC` stamps.

mod common;

use std::time::{Duration, Instant};

use common::arbiter::{assert_result, ground_speed, ArbiterPorts};
use common::sim::Sim;
use common::{assert_accepted, Mesh, PATIENCE, VEHICLE};
use skymesh_autopilot_link::arbiter::authority::Engagement;
use skymesh_autopilot_link::arbiter::geofence::LocalFrame;
use skymesh_autopilot_link::arbiter::persist::{Persisted, Store};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::Settings;
use skymesh_ipc_types::{
    AckResult, ArbiterEventKind, AuthorityChange, Command, CommandSource, FenceKind, FlightMode,
    GeofenceSet, RefusalReason, VehicleCommand, VehicleStatus, NO_HOLDER,
};
use skymesh_runtime::clock::monotonic_ns;

/// vehicle-sim's home.
const HOME: (f64, f64) = (-35.363261, 149.165230);

fn settings(port: u16) -> Settings {
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    });
    s.reconnect_max = Duration::from_secs(1);
    // Finer velocity telemetry for the braking measurement.
    s.rates.global_position_hz = 25.0;
    s
}

fn velocity(n: f32, e: f32, d: f32) -> Command {
    Command::VelocityNed {
        vel_ned_mps: [n, e, d],
        yaw_rate_dps: None,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_sources_contend_for_authority() {
    use CommandSource::{Operator, ShotEngine, Vision};
    let sim = Sim::start(0).await;
    let mut s = settings(sim.port);
    s.arbiter.authority_timeout = Duration::from_millis(1500);
    let mut mesh = Mesh::start_with(s).await;
    let mut arb = ArbiterPorts::open(&mesh);
    mesh.wait_link_up().await;

    let ack = mesh
        .command_as(ShotEngine, Command::GrabFlightAuthority)
        .await;
    assert_accepted(&ack, "grab");
    assert_eq!(ack.detail.as_str(), "flight authority granted");
    arb.wait_authority("shot_engine holding", |a| {
        a.flight() == Some(ShotEngine) && a.flight_change == AuthorityChange::Granted.to_wire()
    })
    .await;

    // A lower source is refused, with the holder named.
    let ack = mesh.command_as(Vision, Command::Land).await;
    assert_result(&ack, AckResult::Refused, "vision lands");
    assert_eq!(ack.reason(), Some(RefusalReason::NoAuthority));
    assert!(
        ack.detail.as_str().contains("shot_engine"),
        "{:?}",
        ack.detail
    );
    let ack = mesh.command_as(Vision, Command::GrabFlightAuthority).await;
    assert_eq!(ack.reason(), Some(RefusalReason::NoAuthority));

    // A higher one pre-empts; the pre-empted holder is told.
    let ack = mesh
        .command_as(Operator, Command::GrabFlightAuthority)
        .await;
    assert_accepted(&ack, "operator grabs");
    let state = arb
        .wait_authority("operator holding", |a| a.flight() == Some(Operator))
        .await;
    assert_eq!(state.flight_previous, ShotEngine.to_wire());
    assert_eq!(state.flight_change, AuthorityChange::Preempted.to_wire());
    // The grant came first; the pre-emption event names the source that lost out.
    let event = loop {
        let e = arb.wait_event(ArbiterEventKind::AuthorityChanged).await;
        if e.detail.as_str().contains("preempted") {
            break e;
        }
    };
    assert_eq!(event.source, ShotEngine.to_wire(), "{:?}", event.detail);
    let ack = mesh
        .command_as(ShotEngine, Command::GrabFlightAuthority)
        .await;
    assert_eq!(ack.reason(), Some(RefusalReason::NoAuthority));

    // Silence: the operator loses authority after the quiet timeout.
    let quiet = Instant::now();
    let state = arb
        .wait_authority("nobody holding", |a| a.flight_holder == NO_HOLDER)
        .await;
    assert_eq!(state.flight_change, AuthorityChange::Timeout.to_wire());
    assert_eq!(state.flight_previous, Operator.to_wire());
    assert!(
        quiet.elapsed() >= Duration::from_millis(1000),
        "{:?}",
        quiet.elapsed()
    );

    // Free again: the lowest source may take it; payload authority is separate.
    assert_accepted(
        &mesh.command_as(Vision, Command::GrabFlightAuthority).await,
        "vision grabs",
    );
    assert_accepted(
        &mesh
            .command_as(ShotEngine, Command::GrabPayloadAuthority)
            .await,
        "shot engine grabs payload",
    );
    let state = arb
        .wait_authority("both held", |a| a.payload() == Some(ShotEngine))
        .await;
    assert_eq!(state.flight(), Some(Vision));

    let decisions = "skymesh_arbiter_decisions_total";
    assert_eq!(
        mesh.metric(
            decisions,
            "source=vision,decision=refused,reason=no_authority"
        ),
        2.0
    );
    assert_eq!(
        mesh.metric(
            decisions,
            "source=shot_engine,decision=accepted,reason=none"
        ),
        2.0
    );
    let holder = "skymesh_arbiter_authority_holder";
    assert_eq!(mesh.metric(holder, "vehicle=1,source=vision"), 1.0);
    assert_eq!(mesh.metric(holder, "vehicle=1,source=operator"), 0.0);
    drop(arb);
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_arbiter_brakes_when_a_velocity_stream_stops() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start_with(settings(sim.port)).await;
    let mut arb = ArbiterPorts::open(&mesh);
    mesh.wait_link_up().await;
    mesh.take_off(5.0).await;

    // 2 m/s north at 20 Hz; each setpoint is good for 200 ms. Expected stop: 0.2 s
    // until the stream counts as stopped + 0.8 s of braking at vehicle-sim's 2.5 m/s²
    // (about 1 s). Without the arbiter's brake, vehicle-sim's own 3 s velocity timeout
    // and the same braking would take 3.8 s: the 3 s bound tells the two apart with
    // room for a loaded machine. (With the default 500 ms max age the same holds up to
    // about 2.5 m/s.)
    let mut last_stamp = 0;
    let start = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    while start.elapsed() < Duration::from_secs(4) {
        tick.tick().await;
        mesh.send_as(CommandSource::Operator, velocity(2.0, 0.0, 0.0), 200);
        last_stamp = monotonic_ns();
    }
    let ack = mesh.acks.latest().expect("acks").expect("acks flowing");
    assert_accepted(&ack, "the last setpoint");
    let _ = mesh.state.latest();
    let moving = mesh
        .wait_state("flying north", PATIENCE, |s| s.position_valid == 1)
        .await;
    assert!(
        ground_speed(&moving) > 1.5,
        "the stream flew the vehicle: {:?}",
        moving.vel_ned_mps
    );

    // The stream stopped: the arbiter, not vehicle-sim's 3 s velocity timeout, stops it.
    let stopped = mesh
        .wait_state("< 0.3 m/s", PATIENCE, |s| ground_speed(s) < 0.3)
        .await;
    let took = Duration::from_nanos(stopped.header.stamp_ns.saturating_sub(last_stamp));
    println!("below 0.3 m/s {took:?} after the last setpoint");
    assert!(
        took < Duration::from_secs(3),
        "below 0.3 m/s after {took:?}"
    );
    let event = arb.wait_event(ArbiterEventKind::StaleBrake).await;
    assert_eq!(event.source, CommandSource::Operator.to_wire());
    assert!(
        event.detail.as_str().contains("braked"),
        "{:?}",
        event.detail
    );
    assert!(mesh.metric("skymesh_arbiter_stale_brakes_total", "source=operator") >= 1.0);

    drop(arb);
    mesh.stop().await;
    sim.stop().await;
}

/// A keep-in square of ±`half` metres around home, ceiling `ceiling_m`.
fn square_fence(half: f64, ceiling_m: f32) -> GeofenceSet {
    let frame = LocalFrame::new(HOME.0, HOME.1);
    let unit = frame.to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    let ll = |n: f64, e: f64| [HOME.0 + n / unit.x * 1e-3, HOME.1 + e / unit.y * 1e-3];
    let mut set = GeofenceSet {
        vehicle_id: VEHICLE,
        enabled: 1,
        source: CommandSource::Operator.to_wire(),
        ceiling_m,
        floor_m: -5.0,
        ..Default::default()
    };
    assert!(set.push_polygon(
        FenceKind::KeepIn,
        &[
            ll(-half, -half),
            ll(half, -half),
            ll(half, half),
            ll(-half, half)
        ],
    ));
    set
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_geofence_keeps_the_vehicle_inside() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start_with(settings(sim.port)).await;
    let mut arb = ArbiterPorts::open(&mesh);
    mesh.wait_link_up().await;

    // An invalid fence is refused; a valid one accepted.
    let mut bad = square_fence(20.0, 12.0);
    bad.polygons[0].vertex_count = 2;
    arb.geofence.publish(bad).unwrap();
    let e = arb.wait_event(ArbiterEventKind::GeofenceInvalid).await;
    assert!(e.detail.as_str().contains("vertices"), "{:?}", e.detail);
    arb.geofence.publish(square_fence(20.0, 12.0)).unwrap();
    arb.wait_event(ArbiterEventKind::GeofenceUpdated).await;

    let ack = mesh.command(Command::Takeoff { alt_rel_m: 30.0 }).await;
    assert_eq!(
        ack.reason(),
        Some(RefusalReason::Geofence),
        "{:?}",
        ack.detail
    );
    mesh.take_off(5.0).await;

    let frame = LocalFrame::new(HOME.0, HOME.1);
    let north_of_home = 100.0 / frame.to_local(HOME.0 + 1e-3, HOME.1).x * 1e-3;
    let ack = mesh
        .command(Command::GoTo {
            lat_deg: HOME.0 + north_of_home,
            lon_deg: HOME.1,
            alt_rel_m: 5.0,
            yaw_deg: None,
            speed_mps: None,
        })
        .await;
    assert_result(&ack, AckResult::Refused, "100 m north");
    assert_eq!(ack.reason(), Some(RefusalReason::Geofence));
    arb.wait_event(ArbiterEventKind::GeofenceRefused).await;

    // Push north-east and up at full speed for 8 s: limited, never outside.
    let (mut max_n, mut max_e, mut max_alt) = (f64::MIN, f64::MIN, f32::MIN);
    let mut limited = 0;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(10) {
        tick.tick().await;
        if start.elapsed() < Duration::from_secs(8) {
            mesh.send_as(CommandSource::Operator, velocity(5.0, 2.0, -2.5), 0);
        }
        while let Some(ack) = mesh.acks.try_recv().unwrap() {
            assert!(ack.is_accepted(), "{:?} {:?}", ack.reason(), ack.detail);
            if ack.result() == Some(AckResult::Limited) {
                limited += 1;
            }
        }
        while let Some(s) = mesh.state.try_recv().unwrap() {
            let p = frame.to_local(s.lat_deg, s.lon_deg);
            max_n = max_n.max(p.x);
            max_e = max_e.max(p.y);
            max_alt = max_alt.max(s.alt_rel_m);
        }
    }
    println!("pushing out: max north {max_n:.2} m, east {max_e:.2} m, alt {max_alt:.2} m; {limited} limited");
    assert!(limited > 10, "velocity setpoints limited: {limited}");
    assert!(max_n < 20.0, "north {max_n:.2} m: inside the 20 m keep-in");
    assert!(max_n > 12.0, "it did fly toward the edge: {max_n:.2} m");
    assert!(max_e < 20.0, "east {max_e:.2} m");
    assert!(
        max_alt < 12.0,
        "altitude {max_alt:.2} m under the 12 m ceiling"
    );
    arb.wait_event(ArbiterEventKind::GeofenceLimited).await;
    assert!(
        mesh.metric(
            "skymesh_arbiter_decisions_total",
            "source=operator,decision=limited,reason=none"
        ) > 10.0
    );
    drop(arb);
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nan_inf_and_out_of_range_values_are_refused_and_limits_applied() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start_with(settings(sim.port)).await;
    mesh.wait_link_up().await;
    let source = CommandSource::Vision;
    let valid = |cmd: &Command| VehicleCommand::new(VEHICLE, source, 0, cmd).unwrap();

    let mut nan = valid(&velocity(1.0, 0.0, 0.0));
    nan.f[2] = f32::NAN;
    let mut inf = valid(&Command::GoTo {
        lat_deg: HOME.0,
        lon_deg: HOME.1,
        alt_rel_m: 10.0,
        yaw_deg: None,
        speed_mps: None,
    });
    inf.lon_deg = f64::INFINITY;
    let mut fast = valid(&velocity(1.0, 0.0, 0.0));
    fast.f[0] = 60.0;
    let mut servo = valid(&Command::Servo {
        channel: 9,
        pwm_us: 1500,
    });
    servo.i[1] = 9000;
    for (what, sample, field) in [
        ("NaN", nan, "vd"),
        ("infinity", inf, "lon_deg"),
        ("60 m/s", fast, "vn"),
        ("9000 µs", servo, "pwm_us"),
    ] {
        let id = mesh.send(sample);
        let ack = mesh.answer_to(id).await;
        assert_eq!(
            ack.reason(),
            Some(RefusalReason::InvalidParameter),
            "{what}: {:?}",
            ack.detail
        );
        assert!(
            ack.detail.as_str().contains(field),
            "{what}: {:?}",
            ack.detail
        );
    }
    assert_eq!(
        mesh.metric(
            "skymesh_arbiter_decisions_total",
            "source=vision,decision=refused,reason=invalid_parameter"
        ),
        4.0
    );
    // Valid on the wire, above the configured limit: reduced, and said so.
    let ack = mesh.command_as(source, velocity(20.0, 0.0, 0.0)).await;
    assert_result(&ack, AckResult::Limited, "20 m/s");
    assert_eq!(ack.detail.as_str(), "speed 20.0->12.0 m/s");
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emergency_stop_brakes_and_holds_and_motor_kill_needs_the_emergency_flag_in_the_air() {
    use CommandSource::{Operator, Safety, ShotEngine, Vision};
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start_with(settings(sim.port)).await;
    let mut arb = ArbiterPorts::open(&mesh);
    mesh.wait_link_up().await;
    mesh.take_off(5.0).await;

    // The operator flies north; the shot engine (lower priority) hits the stop.
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    for _ in 0..25 {
        tick.tick().await;
        mesh.send_as(Operator, velocity(3.0, 0.0, 0.0), 0);
    }
    let _ = mesh.state.latest();
    let s = mesh
        .wait_state("moving", PATIENCE, |s| s.position_valid == 1)
        .await;
    assert!(ground_speed(&s) > 2.0, "{:?}", s.vel_ned_mps);
    let stop = mesh.send_as(ShotEngine, Command::EmergencyStop, 0);
    // The operator keeps pushing: refused, the vehicle stops anyway.
    let mut refused = 0;
    let started = Instant::now();
    loop {
        tick.tick().await;
        mesh.send_as(Operator, velocity(3.0, 0.0, 0.0), 0);
        while let Some(ack) = mesh.acks.try_recv().unwrap() {
            if ack.command_id == stop {
                assert_accepted(&ack, "emergency stop");
            } else if ack.reason() == Some(RefusalReason::Emergency) {
                refused += 1;
            }
        }
        let slow = mesh
            .state
            .latest()
            .unwrap()
            .is_some_and(|s| ground_speed(&s) < 0.3);
        if slow && refused >= 3 {
            break;
        }
        assert!(
            started.elapsed() < PATIENCE,
            "still moving or not refused ({refused})"
        );
    }
    let state = arb
        .wait_authority("the emergency", |a| a.emergency == 1)
        .await;
    assert_eq!(state.flight(), Some(Safety));
    assert_eq!(state.flight_previous, Operator.to_wire());
    assert_eq!(state.flight_change, AuthorityChange::Emergency.to_wire());
    assert!(
        state.emergency_by(ShotEngine),
        "{:#x}",
        state.emergency_sources
    );
    assert_eq!(state.emergency_sources, 1 << ShotEngine.to_wire());
    let e = arb.wait_event(ArbiterEventKind::EmergencyStop).await;
    assert_eq!(e.source, ShotEngine.to_wire());

    // In the air: a plain kill is refused, even from safety.
    let ack = mesh
        .command_as(Safety, Command::MotorKill { emergency: false })
        .await;
    assert_eq!(ack.reason(), Some(RefusalReason::InAir), "{:?}", ack.detail);
    // The stop is the shot engine's: safety releasing its flight authority, a
    // source that did not engage it releasing "its" stop, or a clear from below
    // operator/safety end nothing; the operator is still locked out.
    let _ = mesh
        .command_as(Safety, Command::ReleaseFlightAuthority)
        .await;
    let _ = mesh.command_as(Operator, Command::ReleaseEmergency).await;
    let ack = mesh.command_as(Vision, Command::ClearEmergency).await;
    assert_eq!(
        ack.reason(),
        Some(RefusalReason::Denied),
        "{:?}",
        ack.detail
    );
    let ack = mesh.command_as(Operator, velocity(1.0, 0.0, 0.0)).await;
    assert_eq!(
        ack.reason(),
        Some(RefusalReason::Emergency),
        "{:?}",
        ack.detail
    );
    let _ = arb.authority.latest();
    let state = arb.wait_authority("a fresh state", |_| true).await;
    assert_eq!(state.emergency, 1);
    assert_eq!(state.flight(), Some(Safety));
    assert_eq!(state.emergency_sources, 1 << ShotEngine.to_wire());
    // Its engager releases it: the stop ends, the operator may command again.
    assert_accepted(
        &mesh.command_as(ShotEngine, Command::ReleaseEmergency).await,
        "release emergency",
    );
    let e = arb.wait_event(ArbiterEventKind::EmergencyCleared).await;
    assert_eq!(e.source, ShotEngine.to_wire());
    let state = arb
        .wait_authority("no emergency", |a| a.emergency == 0)
        .await;
    assert_eq!(state.emergency_sources, 0);
    assert_eq!(state.flight(), None);
    let ack = mesh
        .command_as(Operator, Command::MotorKill { emergency: false })
        .await;
    assert_eq!(ack.reason(), Some(RefusalReason::InAir));
    let ack = mesh
        .command_as(Operator, Command::MotorKill { emergency: true })
        .await;
    assert_accepted(&ack, "emergency kill");
    mesh.wait_status("disarmed", |s| !s.is_armed()).await;
    drop(arb);
    mesh.stop().await;
    sim.stop().await;
}

/// Finding 2 + the stop driver: a run killed during a stop leaves the latch in its
/// state file; the next run restores it and, at link up, brakes the vehicle it
/// finds flying GUIDED (the latch alone would only refuse commands).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_latch_restored_at_start_brakes_the_vehicle_it_finds_flying() {
    use CommandSource::{DjiDrc, Operator};
    let sim = Sim::start(0).await;
    // A first run takes off and flies north, then goes away (no stop).
    let mut first = Mesh::start_with(settings(sim.port)).await;
    first.wait_link_up().await;
    first.take_off(3.0).await;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    for _ in 0..15 {
        tick.tick().await;
        first.send_as(Operator, velocity(3.0, 0.0, 0.0), 0);
    }
    first.stop().await;
    // The state file a run killed during the DJI pilot's stop leaves behind.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("autopilot-link-1.json");
    let (mut store, _) = Store::open(&path, VEHICLE);
    let engaged = Engagement {
        source: DjiDrc,
        command_id: 7,
    };
    store.save(&Persisted::of(&[engaged], &[])).unwrap();
    let mut s = settings(sim.port);
    s.state_file = path;
    let mut mesh = Mesh::start_with(s).await;
    let mut arb = ArbiterPorts::open(&mesh);
    // The link comes up on a vehicle still in GUIDED...
    let up = mesh.wait_link_up().await;
    assert_eq!(up.flight_mode(), FlightMode::Guided, "{up:?}");
    // ... and nobody but the restored latch puts it in BRAKE and stops it.
    mesh.wait_status("BRAKE", |s| s.flight_mode() == FlightMode::Brake)
        .await;
    let _ = mesh.state.latest();
    mesh.wait_state("stopped", PATIENCE, |s| {
        s.position_valid == 1 && ground_speed(s) < 0.3
    })
    .await;
    let a = arb
        .wait_authority("the restored stop", |a| a.emergency == 1)
        .await;
    assert_eq!(a.emergency_sources, 1 << DjiDrc.to_wire());
    let ack = mesh.command_as(Operator, velocity(1.0, 0.0, 0.0)).await;
    assert_eq!(ack.reason(), Some(RefusalReason::Emergency));
    drop(arb);
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn link_loss_clears_authority_and_recovery_resends_nothing() {
    let sim = Sim::start(0).await;
    let port = sim.port;
    let mut mesh = Mesh::start_with(settings(port)).await;
    let mut arb = ArbiterPorts::open(&mesh);
    mesh.wait_link_up().await;
    arb.wait_event(ArbiterEventKind::LinkRestored).await;
    assert_accepted(
        &mesh
            .command_as(CommandSource::DjiDrc, Command::GrabFlightAuthority)
            .await,
        "grab",
    );
    // On the ground, a plain kill is fine.
    mesh.wait_status("home", |s| s.home_valid == 1).await;
    let ack = mesh
        .command_as(
            CommandSource::DjiDrc,
            Command::MotorKill { emergency: false },
        )
        .await;
    assert_ne!(ack.reason(), Some(RefusalReason::InAir), "{:?}", ack.detail);

    sim.stop().await;
    arb.wait_event(ArbiterEventKind::LinkLost).await;
    let state = arb
        .wait_authority("cleared by the link loss", |a| {
            a.flight_change == AuthorityChange::LinkLost.to_wire()
        })
        .await;
    assert_eq!(state.flight_holder, NO_HOLDER);
    assert_eq!(state.flight_previous, CommandSource::DjiDrc.to_wire());
    let ack = mesh.command_as(CommandSource::DjiDrc, Command::Land).await;
    assert_eq!(ack.reason(), Some(RefusalReason::LinkDown));

    let sim = Sim::start(port).await;
    mesh.wait_link_up().await;
    arb.wait_event(ArbiterEventKind::LinkRestored).await;
    let before = sim.stats.snapshot().frames_in;
    tokio::time::sleep(Duration::from_secs(2)).await;
    // Only our heartbeats and telemetry requests: no command from before the loss.
    let status: Option<VehicleStatus> = mesh.status.latest().unwrap();
    assert!(status.is_some_and(|s| s.is_link_up()));
    let heard = sim.stats.snapshot().frames_in - before;
    assert!(heard < 20, "the sim heard {heard} frames in 2 s");
    drop(arb);
    mesh.stop().await;
    sim.stop().await;
}
