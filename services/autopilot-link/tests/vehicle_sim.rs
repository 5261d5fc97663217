//! autopilot-link against vehicle-sim, in-process: real TCP on 127.0.0.1, real
//! iceoryx2 shared memory in a domain of its own per test.
//!
//! Timeouts are generous (the machine may be slow and busy); nothing asserts on
//! tight timing.

mod common;

use std::time::{Duration, Instant};

use common::sim::Sim;
use common::{assert_accepted, Mesh, PATIENCE, VEHICLE};
use skymesh_ipc_types::{
    AckResult, Command, CommandAck, CommandSource, FlightMode, RefusalReason, ServiceStats,
    VehicleCommand, VehicleStatus,
};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn state_flows_at_about_the_requested_attitude_rate() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    let status = mesh.wait_link_up().await;
    assert_eq!(status.vehicle_id, VEHICLE);
    assert!(
        status.heartbeat_age_ms < 10_000,
        "{}",
        status.heartbeat_age_ms
    );
    assert_eq!(status.autopilot, 3, "ArduPilot");

    // The sim starts at 10 Hz; autopilot-link asks for 50 Hz. Measure by sequence
    // numbers, so samples a slow reader missed still count.
    let first = mesh
        .wait_state("a position", PATIENCE, |s| s.position_valid == 1)
        .await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    let last = mesh
        .state
        .latest()
        .expect("state")
        .expect("states keep flowing");
    let dt = (last.header.stamp_ns - first.header.stamp_ns) as f64 / 1e9;
    let rate = (last.header.seq - first.header.seq) as f64 / dt;
    assert!(
        (30.0..=70.0).contains(&rate),
        "VehicleState rate {rate:.1} Hz, expected about 50"
    );
    assert_eq!(last.vehicle_id, VEHICLE);
    assert_eq!(last.attitude_valid, 1);
    assert!((last.lat_deg + 35.363261).abs() < 0.001, "{}", last.lat_deg);
    assert!(
        (last.lon_deg - 149.165230).abs() < 0.001,
        "{}",
        last.lon_deg
    );
    assert!(
        last.alt_rel_m.abs() < 1.0,
        "on the ground: {}",
        last.alt_rel_m
    );
    let q = last.attitude_q;
    let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    assert!((norm - 1.0).abs() < 1e-3, "unit quaternion {q:?}");

    let status = mesh
        .wait_status("home, EKF and GPS", |s| {
            s.home_valid == 1 && s.ekf_healthy == 1 && s.satellites > 0
        })
        .await;
    assert_eq!(
        status.flight_mode(),
        FlightMode::from_copter_custom_mode(status.custom_mode)
    );
    assert!(!status.is_armed());
    assert!(
        status.battery_voltage_v > 10.0,
        "{}",
        status.battery_voltage_v
    );
    assert!((status.home_lat_deg + 35.363261).abs() < 0.001);

    assert_eq!(mesh.metric("skymesh_autopilot_link_up", ""), 1.0);
    let rx = "skymesh_autopilot_mavlink_messages_received_total";
    assert!(mesh.metric(rx, "msg=ATTITUDE") > 50.0);
    assert!(mesh.metric(rx, "msg=HEARTBEAT") >= 1.0);
    assert!(
        mesh.metric(
            "skymesh_autopilot_mavlink_messages_sent_total",
            "msg=HEARTBEAT"
        ) >= 1.0
    );

    // The autopilot's HEARTBEAT (the flight mode) is asked for at 5 Hz, a tenth of
    // ATTITUDE's 50: counted against ATTITUDE over the same stretch, so a stalled
    // machine that delays both does not change the answer. ArduPilot's own 1 Hz
    // would be a fiftieth (the sim's gimbal sends no HEARTBEAT of its own).
    let ratio = {
        let count = |m: &Mesh, msg: &str| m.metric(rx, &format!("msg={msg}"));
        let (hb0, att0) = (count(&mesh, "HEARTBEAT"), count(&mesh, "ATTITUDE"));
        let deadline = Instant::now() + PATIENCE;
        while count(&mesh, "ATTITUDE") - att0 < 300.0 {
            assert!(Instant::now() < deadline, "ATTITUDE stopped");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        (count(&mesh, "HEARTBEAT") - hb0) / (count(&mesh, "ATTITUDE") - att0)
    };
    eprintln!("heartbeats per ATTITUDE: {ratio:.3}");
    assert!(
        (0.06..=0.16).contains(&ratio),
        "heartbeats per ATTITUDE {ratio:.3}: expected about 0.1 (5 Hz against 50 Hz)"
    );
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn guided_arm_takeoff_climbs_to_10_m() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    mesh.wait_status("a healthy EKF", |s| s.ekf_healthy == 1)
        .await;

    let ack = mesh.command(Command::SetMode(FlightMode::Guided)).await;
    assert_accepted(&ack, "GUIDED");
    assert_eq!(ack.mav_result, 0);
    mesh.wait_status("GUIDED", |s| s.flight_mode() == FlightMode::Guided)
        .await;
    assert_accepted(&mesh.command(Command::Arm { force: false }).await, "arm");
    mesh.wait_status("armed", VehicleStatus::is_armed).await;
    assert_accepted(
        &mesh.command(Command::Takeoff { alt_rel_m: 10.0 }).await,
        "takeoff",
    );

    let reached = mesh
        .wait_state("alt_rel ≥ 9 m", Duration::from_secs(90), |s| {
            s.alt_rel_m >= 9.0
        })
        .await;
    assert!(reached.alt_rel_m <= 11.0, "{}", reached.alt_rel_m);
    // It settles at 10 ± 1 m rather than flying through.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let settled = mesh.state.latest().expect("state").expect("state");
    assert!(
        (9.0..=11.0).contains(&settled.alt_rel_m),
        "alt_rel {} m",
        settled.alt_rel_m
    );
    assert!(
        mesh.metric(
            "skymesh_autopilot_commands_total",
            "kind=takeoff,result=accepted"
        ) >= 1.0
    );
    let latency = {
        let mut out = Box::<ServiceStats>::default();
        mesh.stats.snapshot_into(&mut out);
        out.entries()
            .iter()
            .find(|e| e.name.as_str() == "skymesh_autopilot_command_latency_seconds")
            .map_or(0, |e| e.count)
    };
    assert!(latency >= 3, "latency observed per COMMAND_ACK: {latency}");
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn invalid_and_misaddressed_commands_are_refused_before_mavlink() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    // Let the start-up requests (stream rates, home) be answered first.
    mesh.wait_status("home", |s| s.home_valid == 1).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let sent = "skymesh_autopilot_mavlink_messages_sent_total";
    let commands_before = mesh.metric(sent, "msg=COMMAND_LONG");
    let sim_before = sim.stats.snapshot().frames_in;
    let heartbeats_before = mesh.metric(sent, "msg=HEARTBEAT");

    // A corrupt sample, written without the validating constructor.
    let mut nan = VehicleCommand::new(
        VEHICLE,
        CommandSource::Vision,
        0,
        &Command::Takeoff { alt_rel_m: 5.0 },
    )
    .unwrap();
    nan.f[0] = f32::NAN;
    let id = mesh.send(nan);
    let ack = mesh.answer_to(id).await;
    assert_eq!(ack.result(), Some(AckResult::Refused));
    assert_eq!(ack.reason(), Some(RefusalReason::InvalidParameter));
    assert_eq!(ack.mav_result, CommandAck::NO_MAV_RESULT);
    assert!(
        ack.detail.as_str().contains("alt_rel_m"),
        "{:?}",
        ack.detail
    );
    assert_eq!(ack.source, CommandSource::Vision.to_wire());

    let mut unknown_kind =
        VehicleCommand::new(VEHICLE, CommandSource::Operator, 0, &Command::Land).unwrap();
    unknown_kind.kind = 200;
    let id = mesh.send(unknown_kind);
    let ack = mesh.answer_to(id).await;
    assert_eq!(ack.reason(), Some(RefusalReason::InvalidParameter));
    assert_eq!(ack.kind, 200);

    let other_vehicle = VehicleCommand::new(9, CommandSource::Operator, 0, &Command::Land).unwrap();
    let id = mesh.send(other_vehicle);
    let ack = mesh.answer_to(id).await;
    assert_eq!(ack.reason(), Some(RefusalReason::WrongVehicle));

    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(
        mesh.metric(sent, "msg=COMMAND_LONG"),
        commands_before,
        "nothing reached MAVLink"
    );
    // The sim only heard our heartbeats meanwhile.
    let heartbeats = mesh.metric(sent, "msg=HEARTBEAT") - heartbeats_before;
    let sim_heard = sim.stats.snapshot().frames_in - sim_before;
    assert!(
        sim_heard as f64 <= heartbeats + 1.0,
        "sim heard {sim_heard}, heartbeats {heartbeats}"
    );
    assert_eq!(
        mesh.metric(
            "skymesh_autopilot_commands_total",
            "kind=takeoff,result=refused"
        ),
        1.0
    );
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn arming_in_land_mode_is_denied_with_the_reason() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    assert_accepted(
        &mesh.command(Command::SetMode(FlightMode::Land)).await,
        "LAND",
    );
    mesh.wait_status("LAND", |s| s.flight_mode() == FlightMode::Land)
        .await;
    let ack = mesh.command(Command::Arm { force: false }).await;
    assert_eq!(ack.result(), Some(AckResult::Refused));
    assert_eq!(
        ack.reason(),
        Some(RefusalReason::Denied),
        "{:?}",
        ack.detail
    );
    assert_eq!(ack.mav_result, 2, "MAV_RESULT_DENIED");
    // The STATUSTEXT that came with the denial explains it.
    assert!(ack.detail.as_str().contains("armable"), "{:?}", ack.detail);
    // The autopilot's explanation is surfaced in VehicleStatus too.
    let status = mesh
        .wait_status("the arming STATUSTEXT", |s| {
            s.status_text.as_str().contains("Arm")
        })
        .await;
    assert!(!status.is_armed());
    assert_eq!(
        mesh.metric(
            "skymesh_autopilot_commands_total",
            "kind=arm,result=refused"
        ),
        1.0
    );
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn link_goes_down_when_the_autopilot_stops_and_recovers_when_it_returns() {
    let sim = Sim::start(0).await;
    let port = sim.port;
    let mut mesh = Mesh::start(port).await;
    mesh.wait_link_up().await;
    mesh.wait_state("attitude", PATIENCE, |s| s.attitude_valid == 1)
        .await;

    let stopped = Instant::now();
    sim.stop().await;
    mesh.wait_status("link down", |s| !s.is_link_up()).await;
    let took = stopped.elapsed();
    assert!(took < Duration::from_secs(10), "link down after {took:?}");
    assert_eq!(mesh.metric("skymesh_autopilot_link_up", ""), 0.0);
    // Commands are refused while the link is down.
    let ack = mesh.command(Command::Land).await;
    assert_eq!(ack.reason(), Some(RefusalReason::LinkDown));

    // Same port again, as a restarted SITL or sim would be.
    let sim = Sim::start(port).await;
    let up = mesh.wait_link_up().await;
    assert!(up.heartbeat_age_ms < 10_000);
    let _ = mesh.state.latest().expect("state");
    let fresh = mesh
        .wait_state("fresh state", PATIENCE, |s| s.attitude_valid == 1)
        .await;
    assert_eq!(fresh.vehicle_id, VEHICLE);
    assert!(mesh.metric("skymesh_autopilot_reconnects_total", "") >= 1.0);
    assert_eq!(mesh.metric("skymesh_autopilot_link_up", ""), 1.0);
    // The restarted sim streams at 50 Hz again: the rates were requested anew.
    let a = mesh.state.latest().expect("state").unwrap_or(fresh);
    tokio::time::sleep(Duration::from_secs(2)).await;
    let b = mesh
        .state
        .latest()
        .expect("state")
        .expect("states keep flowing");
    let rate = (b.header.seq - a.header.seq) as f64
        / ((b.header.stamp_ns - a.header.stamp_ns) as f64 / 1e9);
    assert!(
        rate > 30.0,
        "VehicleState rate after reconnect {rate:.1} Hz"
    );
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_absent_autopilot_means_link_down_and_a_prompt_shutdown() {
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let mut mesh = Mesh::start(port).await;
    let s = mesh.wait_status("any status", |_| true).await;
    assert!(!s.is_link_up());
    assert_eq!(s.heartbeat_age_ms, u32::MAX);
    let ack = mesh.command(Command::Arm { force: false }).await;
    assert_eq!(ack.reason(), Some(RefusalReason::LinkDown));
    mesh.stop().await;
}
