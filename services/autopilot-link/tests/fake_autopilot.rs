//! autopilot-link against a scripted fake autopilot built on the same MAVLink codec:
//! the cases vehicle-sim does not produce on demand (silence, IN_PROGRESS, an
//! explanation after the ack, a foreign system) and what goes out on the wire.

mod common;

use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use common::{Mesh, PATIENCE, VEHICLE};
use mavlink::dialects::ardupilotmega::{
    GimbalDeviceFlags, GoproCaptureMode, GoproCommand, GoproHeartbeatFlags, GoproHeartbeatStatus,
    GoproRequestStatus, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavSeverity,
    MavState, MavType, ATTITUDE_DATA, COMMAND_ACK_DATA, COMMAND_LONG_DATA,
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, GOPRO_HEARTBEAT_DATA, GOPRO_SET_RESPONSE_DATA,
    HEARTBEAT_DATA, STATUSTEXT_DATA,
};
use mavlink::{Connectable, Connection, MavConnection, MavHeader, TcpConfig};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::Settings;
use skymesh_ipc_types::{AckResult, Command, FlightMode, GoProStatus, RefusalReason};
use tokio::sync::mpsc;

type Conn = Connection<MavMessage>;
/// Decides the replies to each message the fake receives.
type Responder = Box<dyn Fn(&MavMessage) -> Vec<Reply> + Send + Sync>;

/// What the fake sends back, optionally after a pause.
enum Reply {
    Now(MavMessage),
    After(Duration, MavMessage),
}

fn ack(command: MavCmd, result: MavResult) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        ..Default::default()
    })
}

fn text(s: &str) -> MavMessage {
    MavMessage::STATUSTEXT(STATUSTEXT_DATA {
        severity: MavSeverity::MAV_SEVERITY_CRITICAL,
        text: s.into(),
        ..Default::default()
    })
}

/// A TCP "autopilot": heartbeats (GUIDED, disarmed) and ATTITUDE at 5 Hz from
/// `system`/1, replies from `responder`, and everything it receives on `received`.
struct Fake {
    port: u16,
    received: mpsc::UnboundedReceiver<(MavHeader, MavMessage)>,
    stop: Arc<AtomicBool>,
}

impl Fake {
    fn start(system: u8, responder: Responder) -> Fake {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let (tx, received) = mpsc::unbounded_channel();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        std::thread::spawn(move || {
            let (stream, _) = listener.accept().unwrap();
            serve(stream, system, responder, tx, flag);
        });
        Fake {
            port,
            received,
            stop,
        }
    }

    /// The next received message matching `pred` (others are skipped).
    async fn expect(
        &mut self,
        what: &str,
        pred: impl Fn(&MavHeader, &MavMessage) -> bool,
    ) -> (MavHeader, MavMessage) {
        let deadline = tokio::time::Instant::now() + PATIENCE;
        loop {
            match tokio::time::timeout_at(deadline, self.received.recv()).await {
                Ok(Some((h, m))) if pred(&h, &m) => return (h, m),
                Ok(Some(_)) => {}
                Ok(None) => panic!("fake autopilot stopped while waiting for {what}"),
                Err(_) => panic!("the fake autopilot received no {what} within {PATIENCE:?}"),
            }
        }
    }

    /// The next SET_MESSAGE_INTERVAL for message id `id` (`name` for the failure).
    async fn expect_interval(&mut self, name: &str, id: u32) -> COMMAND_LONG_DATA {
        let what = format!("{name}'s SET_MESSAGE_INTERVAL");
        let (_, m) = self
            .expect(&what, |_, m| {
                matches!(m, MavMessage::COMMAND_LONG(c)
                    if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL && c.param1 == id as f32)
            })
            .await;
        let MavMessage::COMMAND_LONG(c) = m else {
            unreachable!()
        };
        c
    }

    /// Every COMMAND_LONG with `command` received so far (without waiting).
    fn drain_commands(&mut self, command: MavCmd) -> Vec<COMMAND_LONG_DATA> {
        let mut out = Vec::new();
        while let Ok((_, m)) = self.received.try_recv() {
            if let MavMessage::COMMAND_LONG(c) = m {
                if c.command == command {
                    out.push(c);
                }
            }
        }
        out
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn serve(
    stream: TcpStream,
    system: u8,
    responder: Responder,
    received: mpsc::UnboundedSender<(MavHeader, MavMessage)>,
    stop: Arc<AtomicBool>,
) {
    stream
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let conn: Arc<Conn> = Arc::new(
        TcpConfig::from_stream(stream)
            .unwrap()
            .connect::<MavMessage>()
            .unwrap(),
    );
    let header = MavHeader {
        system_id: u32::from(system),
        component_id: 1,
        sequence: 0,
    };
    // Telemetry at 5 Hz.
    {
        let (conn, stop) = (conn.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut t = 0u32;
            while !stop.load(Ordering::Relaxed) {
                let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 4,
                    mavtype: MavType::MAV_TYPE_QUADROTOR,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                    base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                    system_status: MavState::MAV_STATE_STANDBY,
                    mavlink_version: 3,
                });
                let att = MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: t,
                    ..Default::default()
                });
                if conn.send(&header, &hb).is_err() || conn.send(&header, &att).is_err() {
                    return;
                }
                t += 200;
                std::thread::sleep(Duration::from_millis(200));
            }
        });
    }
    while !stop.load(Ordering::Relaxed) {
        match conn.recv() {
            Ok((h, m)) => {
                for reply in responder(&m) {
                    match reply {
                        Reply::Now(r) => {
                            let _ = conn.send(&header, &r);
                        }
                        Reply::After(pause, r) => {
                            let (conn, header) = (conn.clone(), header);
                            std::thread::spawn(move || {
                                std::thread::sleep(pause);
                                let _ = conn.send(&header, &r);
                            });
                        }
                    }
                }
                if received.send((h, m)).is_err() {
                    return;
                }
            }
            Err(mavlink::error::MessageReadError::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return,
        }
    }
}

fn settings(port: u16) -> Settings {
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    });
    s.command_timeout = Duration::from_millis(400);
    s.command_retries = 1;
    s
}

/// Answers `command` (COMMAND_LONG) with `result`, everything else not at all.
fn answering(
    command: MavCmd,
    replies: impl Fn(&COMMAND_LONG_DATA) -> Vec<Reply> + Send + Sync + 'static,
) -> Responder {
    Box::new(move |m| match m {
        MavMessage::COMMAND_LONG(c) if c.command == command => replies(c),
        _ => Vec::new(),
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn it_introduces_itself_and_asks_for_telemetry() {
    let mut fake = Fake::start(VEHICLE, Box::new(|_| Vec::new()));
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    let (h, m) = fake
        .expect("our HEARTBEAT", |_, m| {
            matches!(m, MavMessage::HEARTBEAT(_))
        })
        .await;
    assert_eq!((h.system_id, h.component_id), (u32::from(VEHICLE), 191));
    let MavMessage::HEARTBEAT(hb) = m else {
        unreachable!()
    };
    assert_eq!(hb.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
    assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);

    // A disarmed autopilot: ATTITUDE at the ground rate (`ground_attitude_hz`).
    let c = fake.expect_interval("ATTITUDE", 30).await;
    assert_eq!(c.param2, 100_000.0, "10 Hz on the ground");
    assert_eq!((c.target_system, c.target_component), (VEHICLE, 1));
    // The flight mode arrives with the autopilot's HEARTBEAT: asked for at 5 Hz, not
    // ArduPilot's own 1 Hz, so a pilot's mode switch is known within 200 ms.
    let c = fake.expect_interval("HEARTBEAT", 0).await;
    assert_eq!(c.param2, 200_000.0, "5 Hz");
    fake.expect("HOME_POSITION request", |_, m| {
        matches!(m, MavMessage::COMMAND_LONG(c)
            if c.command == MavCmd::MAV_CMD_REQUEST_MESSAGE && c.param1 == 242.0)
    })
    .await;
    let status = mesh.wait_link_up().await;
    assert_eq!(status.flight_mode(), FlightMode::Guided);
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refusal_carries_the_statustext_that_follows_its_ack() {
    // As ArduPilot does: the COMMAND_ACK at once, the queued explanation after it.
    let mut fake = Fake::start(
        VEHICLE,
        answering(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, |_| {
            vec![
                Reply::Now(ack(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    MavResult::MAV_RESULT_FAILED,
                )),
                Reply::After(
                    Duration::from_millis(20),
                    text("PreArm: Need Position Estimate"),
                ),
            ]
        }),
    );
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    mesh.wait_link_up().await;
    let a = mesh.command(Command::Arm { force: false }).await;
    assert_eq!(a.result(), Some(AckResult::Refused));
    assert_eq!(a.reason(), Some(RefusalReason::Failed));
    assert_eq!(a.mav_result, 4);
    assert_eq!(a.detail.as_str(), "PreArm: Need Position Estimate");
    fake.expect("the arm command", |_, m| matches!(m, MavMessage::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM)).await;
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn silence_means_one_retransmission_with_confirmation_then_timeout() {
    let mut fake = Fake::start(VEHICLE, Box::new(|_| Vec::new()));
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    mesh.wait_link_up().await;
    let a = mesh.command(Command::Land).await;
    assert_eq!(a.result(), Some(AckResult::Refused));
    assert_eq!(a.reason(), Some(RefusalReason::Timeout));
    assert_eq!(a.mav_result, 255);
    // Both transmissions were seen by the time the timeout was declared.
    fake.expect("the retransmission", |_, m| {
        matches!(m, MavMessage::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_NAV_LAND && c.confirmation == 1)
    })
    .await;
    let more = fake.drain_commands(MavCmd::MAV_CMD_NAV_LAND);
    assert!(more.is_empty(), "no third transmission: {more:?}");
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn in_progress_is_reported_and_the_final_answer_follows() {
    let fake = Fake::start(
        VEHICLE,
        answering(MavCmd::MAV_CMD_NAV_TAKEOFF, |_| {
            vec![
                Reply::Now(ack(
                    MavCmd::MAV_CMD_NAV_TAKEOFF,
                    MavResult::MAV_RESULT_IN_PROGRESS,
                )),
                // Longer than command_timeout: no retransmission once in progress.
                Reply::After(
                    Duration::from_millis(900),
                    ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
                ),
            ]
        }),
    );
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    mesh.wait_link_up().await;
    let sample = skymesh_ipc_types::VehicleCommand::new(
        VEHICLE,
        skymesh_ipc_types::CommandSource::Operator,
        0,
        &Command::Takeoff { alt_rel_m: 5.0 },
    )
    .unwrap();
    let id = mesh.send(sample);
    let first = loop {
        let a = mesh
            .acks
            .recv_timeout(PATIENCE)
            .await
            .unwrap()
            .expect("an ack");
        if a.command_id == id {
            break a;
        }
    };
    assert_eq!(first.result(), Some(AckResult::InProgress));
    assert_eq!(first.mav_result, 5);
    let last = mesh.answer_to(id).await;
    assert_eq!(last.result(), Some(AckResult::Accepted));
    assert_eq!(last.mav_result, 0);
    drop(fake);
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_newer_command_of_the_same_kind_cancels_the_older() {
    // Only disarm (param1 = 0) is answered.
    let fake = Fake::start(
        VEHICLE,
        answering(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, |c| {
            if c.param1 == 0.0 {
                vec![Reply::Now(ack(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    MavResult::MAV_RESULT_ACCEPTED,
                ))]
            } else {
                Vec::new()
            }
        }),
    );
    let mut settings = settings(fake.port);
    settings.command_timeout = Duration::from_secs(5);
    let mut mesh = Mesh::start_with(settings).await;
    mesh.wait_link_up().await;
    let arm = skymesh_ipc_types::VehicleCommand::new(
        VEHICLE,
        skymesh_ipc_types::CommandSource::Operator,
        0,
        &Command::Arm { force: false },
    )
    .unwrap();
    let arm_id = mesh.send(arm);
    // The same source: a higher one would pre-empt the operator, and its ARM would
    // be answered `preempted` instead (acks.rs: a pre-emption cancels).
    let disarm = skymesh_ipc_types::VehicleCommand::new(
        VEHICLE,
        skymesh_ipc_types::CommandSource::Operator,
        0,
        &Command::Disarm { force: false },
    )
    .unwrap();
    let disarm_id = mesh.send(disarm);
    let a = mesh.answer_to(arm_id).await;
    assert_eq!(a.reason(), Some(RefusalReason::Cancelled));
    let d = mesh.answer_to(disarm_id).await;
    assert_eq!(d.result(), Some(AckResult::Accepted));
    drop(fake);
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn setpoints_are_accepted_when_written() {
    let mut fake = Fake::start(VEHICLE, Box::new(|_| Vec::new()));
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    mesh.wait_link_up().await;
    let a = mesh
        .command(Command::VelocityNed {
            vel_ned_mps: [1.0, -0.5, 0.0],
            yaw_rate_dps: Some(30.0),
        })
        .await;
    common::assert_accepted(&a, "velocity");
    assert_eq!(a.mav_result, 255);
    let (h, m) = fake
        .expect("the velocity setpoint", |_, m| {
            matches!(m, MavMessage::SET_POSITION_TARGET_LOCAL_NED(_))
        })
        .await;
    assert_eq!(h.component_id, 191);
    let MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp) = m else {
        unreachable!()
    };
    assert_eq!((sp.vx, sp.vy, sp.vz), (1.0, -0.5, 0.0));
    assert!((sp.yaw_rate - 30f32.to_radians()).abs() < 1e-6);
    assert_eq!((sp.target_system, sp.target_component), (VEHICLE, 1));
    // In GUIDED, Brake is a zero-velocity setpoint too.
    common::assert_accepted(&mesh.command(Command::Brake).await, "brake");
    let (_, m) = fake
        .expect(
            "the brake setpoint",
            |_, m| matches!(m, MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp) if sp.vx == 0.0),
        )
        .await;
    let MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp) = m else {
        unreachable!()
    };
    assert_eq!((sp.vx, sp.vy, sp.vz), (0.0, 0.0, 0.0));
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_autopilot_with_another_system_id_is_ignored() {
    let fake = Fake::start(7, Box::new(|_| Vec::new()));
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    // Connected, heartbeats flowing, but not ours: the link stays down.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let s = mesh.status.latest().unwrap().expect("status at 1 Hz");
    assert!(!s.is_link_up());
    assert!(
        mesh.state.latest().unwrap().is_none(),
        "no state from system 7"
    );
    let a = mesh.command(Command::Land).await;
    assert_eq!(a.reason(), Some(RefusalReason::LinkDown));
    drop(fake);
    mesh.stop().await;
}

/// The GoPro bridge of a Solo gimbal: capture mode 0..=6 succeeds, other values fail;
/// the shutter is never answered.
fn gopro_bridge(m: &MavMessage) -> Vec<Reply> {
    let MavMessage::GOPRO_SET_REQUEST(r) = m else {
        return Vec::new();
    };
    let status = match r.cmd_id {
        GoproCommand::GOPRO_COMMAND_CAPTURE_MODE if r.value[0] <= 6 => {
            GoproRequestStatus::GOPRO_REQUEST_SUCCESS
        }
        GoproCommand::GOPRO_COMMAND_CAPTURE_MODE => GoproRequestStatus::GOPRO_REQUEST_FAILED,
        _ => return Vec::new(),
    };
    vec![Reply::Now(MavMessage::GOPRO_SET_RESPONSE(
        GOPRO_SET_RESPONSE_DATA {
            cmd_id: r.cmd_id,
            status,
        },
    ))]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gopro_requests_go_to_the_gimbal_and_are_answered_by_the_matching_response() {
    let mut fake = Fake::start(VEHICLE, Box::new(gopro_bridge));
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    mesh.wait_link_up().await;

    let a = mesh
        .command(Command::GoProSet {
            command: 1,
            value: [1, 0, 0, 0],
        })
        .await;
    common::assert_accepted(&a, "capture mode photo");
    assert_eq!(a.mav_result, 255, "a GoPro answer is no MAV_RESULT");
    let (h, m) = fake
        .expect("the GOPRO_SET_REQUEST", |_, m| {
            matches!(m, MavMessage::GOPRO_SET_REQUEST(_))
        })
        .await;
    assert_eq!((h.system_id, h.component_id), (u32::from(VEHICLE), 191));
    let MavMessage::GOPRO_SET_REQUEST(r) = m else {
        unreachable!()
    };
    assert_eq!((r.target_system, r.target_component), (VEHICLE, 154));
    assert_eq!(r.cmd_id, GoproCommand::GOPRO_COMMAND_CAPTURE_MODE);
    assert_eq!(r.value, [1, 0, 0, 0]);

    let a = mesh
        .command(Command::GoProSet {
            command: 1,
            value: [9, 0, 0, 0],
        })
        .await;
    assert_eq!(a.result(), Some(AckResult::Refused));
    assert_eq!(a.reason(), Some(RefusalReason::Failed));
    assert_eq!(a.detail.as_str(), "GoPro: request failed");

    // Unanswered: refused after command_timeout, and never sent twice.
    let a = mesh
        .command(Command::GoProSet {
            command: 2,
            value: [1, 0, 0, 0],
        })
        .await;
    assert_eq!(a.result(), Some(AckResult::Refused));
    assert_eq!(a.reason(), Some(RefusalReason::Timeout));
    assert_eq!(a.detail.as_str(), "no GOPRO_SET_RESPONSE from the gimbal");
    fake.expect("the shutter request", |_, m| {
        matches!(m, MavMessage::GOPRO_SET_REQUEST(r) if r.cmd_id == GoproCommand::GOPRO_COMMAND_SHUTTER)
    })
    .await;
    let mut again = 0;
    while let Ok((_, m)) = fake.received.try_recv() {
        again += usize::from(matches!(m, MavMessage::GOPRO_SET_REQUEST(_)));
    }
    assert_eq!(again, 0, "no retransmission of a GoPro request");

    // A command id the dialect has no GOPRO_COMMAND for cannot even be built.
    assert!(skymesh_ipc_types::VehicleCommand::new(
        1,
        skymesh_ipc_types::CommandSource::Operator,
        1,
        &Command::GoProSet {
            command: 20,
            value: [0; 4],
        },
    )
    .is_err());

    let gopro = "skymesh_autopilot_gopro_responses_total";
    assert_eq!(mesh.metric(gopro, "status=success"), 1.0);
    assert_eq!(mesh.metric(gopro, "status=failed"), 1.0);
    assert_eq!(
        mesh.metric(
            "skymesh_autopilot_mavlink_messages_sent_total",
            "msg=GOPRO_SET_REQUEST"
        ),
        3.0
    );
    let cmds = "skymesh_autopilot_commands_total";
    assert_eq!(mesh.metric(cmds, "kind=gopro_set,result=accepted"), 1.0);
    assert_eq!(mesh.metric(cmds, "kind=gopro_set,result=refused"), 2.0);
    mesh.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gimbal_attitude_and_gopro_heartbeat_become_payload_state_until_they_stop() {
    // One gimbal attitude (30° down, 20° right, vehicle frame: yaw then pitch, roll 0)
    // and one GoPro heartbeat, sent when the gimbal stream is asked for; then silence.
    let half_pitch = (-30f32).to_radians() / 2.0;
    let half_yaw = 20f32.to_radians() / 2.0;
    let q = [
        half_pitch.cos() * half_yaw.cos(),
        -half_pitch.sin() * half_yaw.sin(),
        half_pitch.sin() * half_yaw.cos(),
        half_pitch.cos() * half_yaw.sin(),
    ];
    let mut fake = Fake::start(
        VEHICLE,
        Box::new(move |m| match m {
            MavMessage::COMMAND_LONG(c)
                if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL && c.param1 == 285.0 =>
            {
                vec![
                    Reply::Now(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(
                        GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
                            q,
                            flags: GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
                            ..Default::default()
                        },
                    )),
                    Reply::Now(MavMessage::GOPRO_HEARTBEAT(GOPRO_HEARTBEAT_DATA {
                        status: GoproHeartbeatStatus::GOPRO_HEARTBEAT_STATUS_CONNECTED,
                        capture_mode: GoproCaptureMode::GOPRO_CAPTURE_MODE_VIDEO,
                        flags: GoproHeartbeatFlags::GOPRO_FLAG_RECORDING,
                    })),
                ]
            }
            _ => Vec::new(),
        }),
    );
    let mut mesh = Mesh::start_with(settings(fake.port)).await;
    let c = fake
        .expect_interval("GIMBAL_DEVICE_ATTITUDE_STATUS", 285)
        .await;
    assert_eq!(c.param2, 100_000.0, "10 Hz by default");
    assert_eq!((c.target_system, c.target_component), (VEHICLE, 1));

    let p = mesh
        .wait_payload("a gimbal attitude", |p| p.is_gimbal_valid())
        .await;
    assert_eq!(p.vehicle_id, VEHICLE);
    assert!((p.gimbal_pitch_deg + 30.0).abs() < 0.1, "{p:?}");
    assert!((p.gimbal_yaw_deg - 20.0).abs() < 0.1, "{p:?}");
    assert!(p.gimbal_roll_deg.abs() < 0.1, "{p:?}");
    assert!(p.gimbal_stamp_ns > 0 && p.gimbal_stamp_ns <= p.header.stamp_ns);
    let p = mesh
        .wait_payload("the GoPro", |p| p.gopro_status() == GoProStatus::Connected)
        .await;
    assert_eq!((p.gopro_capture_mode, p.gopro_recording), (0, 1));

    // Nothing more arrives: invalid after 2 s, disconnected after 3 s.
    let p = mesh
        .wait_payload("the gimbal invalid", |p| !p.is_gimbal_valid())
        .await;
    assert!(p.header.stamp_ns - p.gimbal_stamp_ns >= 2_000_000_000);
    let p = mesh
        .wait_payload("the GoPro disconnected", |p| {
            p.gopro_status() == GoProStatus::Disconnected
        })
        .await;
    assert!(p.header.stamp_ns - p.gopro_stamp_ns >= 3_000_000_000);
    assert_eq!((p.gopro_capture_mode, p.gopro_recording), (255, 0));
    let rx = "skymesh_autopilot_mavlink_messages_received_total";
    assert!(mesh.metric(rx, "msg=GIMBAL_DEVICE_ATTITUDE_STATUS") >= 1.0);
    assert!(mesh.metric(rx, "msg=GOPRO_HEARTBEAT") >= 1.0);
    mesh.stop().await;
}
