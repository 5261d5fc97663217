//! The simulator over real loopback sockets, driven by a fake ground station.
//! The tokio clock is paused: the physics and streams run on virtual time, so
//! "10 s of flight" takes milliseconds and rates are measured exactly.

// REQUEST_DATA_STREAM is deprecated in MAVLink; ArduPilot and the sim honour it.
#![allow(deprecated)]

mod common;

use std::time::Duration;

use common::{Gcs, Sim, GCS_HEADER, WAIT};
use mavlink::dialects::ardupilotmega::{
    EkfStatusFlags, MavAutopilot, MavCmd, MavDataStream, MavFrame, MavMessage, MavModeFlag,
    MavResult, MavType, PositionTargetTypemask as Mask, COMMAND_LONG_DATA,
    REQUEST_DATA_STREAM_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use mavlink::MavHeader;
use skymesh_vehicle_sim::RawConfig;
use tokio::time::Instant;

const ACCEPTED: MavResult = MavResult::MAV_RESULT_ACCEPTED;

#[tokio::test(start_paused = true)]
async fn heartbeat_reports_guided_after_do_set_mode() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    let (header, hb) = loop {
        if let (h, MavMessage::HEARTBEAT(hb)) = gcs.recv_with_header().await {
            break (h, hb);
        }
    };
    assert_eq!((header.system_id, header.component_id), (1, 1));
    assert_eq!(hb.mavtype, MavType::MAV_TYPE_QUADROTOR);
    assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    assert_eq!(hb.custom_mode, 0, "boots in STABILIZE");

    assert_eq!(gcs.set_mode(4).await, ACCEPTED);
    let hb = gcs.heartbeat().await;
    assert_eq!(hb.custom_mode, 4);
    assert!(hb.base_mode.contains(
        MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED
    ));
    assert!(!hb
        .base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED));
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn arming_refused_in_land_with_reason() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    assert_eq!(gcs.set_mode(9).await, ACCEPTED);
    let (result, texts) = gcs
        .command_with_texts(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1., 0., 0., 0., 0., 0., 0.],
        )
        .await;
    assert_eq!(result, MavResult::MAV_RESULT_DENIED);
    assert!(
        texts.contains(&"Arm: Mode not armable".to_owned()),
        "{texts:?}"
    );
    assert_eq!(sim.stats.snapshot().commands_denied, 1);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn arming_refused_until_the_ekf_is_ready() {
    let sim = Sim::start(RawConfig {
        ekf_ready_after_s: 30.0,
        ..RawConfig::default()
    })
    .await;
    let mut gcs = Gcs::connect(sim.addr).await;
    assert_eq!(gcs.set_mode(4).await, ACCEPTED);
    let arm = [1., 0., 0., 0., 0., 0., 0.];
    let (result, texts) = gcs
        .command_with_texts(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm)
        .await;
    assert_eq!(result, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert!(texts.iter().any(|t| t.starts_with("PreArm")), "{texts:?}");
    // Like SITL: position reads zero until the EKF has one.
    let lat = gcs
        .wait_for(WAIT, "GLOBAL_POSITION_INT", |m| match m {
            MavMessage::GLOBAL_POSITION_INT(g) => Some(g.lat),
            _ => None,
        })
        .await;
    assert_eq!(lat, 0);
    gcs.wait_for(Duration::from_secs(40), "EKF ready", |m| match m {
        MavMessage::EKF_STATUS_REPORT(e) if e.flags.contains(EkfStatusFlags::EKF_POS_HORIZ_ABS) => {
            Some(())
        }
        _ => None,
    })
    .await;
    assert_eq!(
        gcs.command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm).await,
        ACCEPTED
    );
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn guided_takeoff_reaches_10m_and_holds() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    assert_eq!(gcs.set_mode(4).await, ACCEPTED);
    assert_eq!(
        gcs.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1., 0., 0., 0., 0., 0., 0.]
        )
        .await,
        ACCEPTED
    );
    assert!(gcs
        .heartbeat()
        .await
        .base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED));
    assert_eq!(gcs.set_interval(33, 100_000.0).await, ACCEPTED);
    assert_eq!(
        gcs.command(MavCmd::MAV_CMD_NAV_TAKEOFF, [0., 0., 0., 0., 0., 0., 10.])
            .await,
        ACCEPTED
    );
    let start = Instant::now();
    gcs.wait_for(Duration::from_secs(10), "10 m", |m| match m {
        MavMessage::GLOBAL_POSITION_INT(g) => {
            assert!(g.vz >= -251, "climb rate limited to 2.5 m/s: {}", g.vz);
            ((g.relative_alt - 10_000).abs() <= 500).then_some(())
        }
        _ => None,
    })
    .await;
    assert!(
        start.elapsed() > Duration::from_secs(4),
        "cannot climb 10 m faster than 2.5 m/s"
    );
    let hold_until = Instant::now() + Duration::from_secs(3);
    while Instant::now() < hold_until {
        if let MavMessage::GLOBAL_POSITION_INT(g) = gcs.recv().await {
            assert!(
                (g.relative_alt - 10_000).abs() <= 500,
                "holds: {}",
                g.relative_alt
            );
        }
    }
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn attitude_runs_at_100_hz_when_asked() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    assert_eq!(gcs.set_interval(30, 10_000.0).await, ACCEPTED);
    let until = Instant::now() + Duration::from_secs(1);
    let mut n = 0;
    while Instant::now() < until {
        if let MavMessage::ATTITUDE(_) = gcs.recv().await {
            n += 1;
        }
    }
    assert!((60..=140).contains(&n), "{n} ATTITUDE in 1 s");
    // -1 disables it.
    assert_eq!(gcs.set_interval(30, -1.0).await, ACCEPTED);
    let until = Instant::now() + Duration::from_secs(2);
    let mut late = 0;
    while Instant::now() < until {
        if let MavMessage::ATTITUDE(_) = gcs.recv().await {
            late += 1;
        }
    }
    assert!(late <= 1, "{late} ATTITUDE after disabling");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn request_data_stream_sets_a_group_rate() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    let req = MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
        req_message_rate: 25,
        target_system: 1,
        target_component: 1,
        req_stream_id: MavDataStream::MAV_DATA_STREAM_EXTRA1,
        start_stop: 1,
    });
    gcs.send(&req).await;
    // Let the request land, then count over two seconds.
    gcs.heartbeat().await;
    let until = Instant::now() + Duration::from_secs(2);
    let mut n = 0;
    while Instant::now() < until {
        if let MavMessage::ATTITUDE(_) = gcs.recv().await {
            n += 1;
        }
    }
    assert!((40..=60).contains(&n), "{n} ATTITUDE in 2 s at 25 Hz");
    sim.stop().await;
}

fn local_target(mask: Mask, pos: [f32; 3], vel: [f32; 3]) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        x: pos[0],
        y: pos[1],
        z: pos[2],
        vx: vel[0],
        vy: vel[1],
        vz: vel[2],
        type_mask: mask,
        target_system: 1,
        target_component: 1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::DEFAULT
    })
}

const IGNORE_ACC_YAW: Mask = Mask::POSITION_TARGET_TYPEMASK_AX_IGNORE
    .union(Mask::POSITION_TARGET_TYPEMASK_AY_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AZ_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE);
const IGNORE_POS: Mask = Mask::POSITION_TARGET_TYPEMASK_X_IGNORE
    .union(Mask::POSITION_TARGET_TYPEMASK_Y_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_Z_IGNORE);
const IGNORE_VEL: Mask = Mask::POSITION_TARGET_TYPEMASK_VX_IGNORE
    .union(Mask::POSITION_TARGET_TYPEMASK_VY_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_VZ_IGNORE);

/// (x, vx) from the next LOCAL_POSITION_NED.
async fn north(gcs: &mut Gcs) -> (f32, f32) {
    gcs.wait_for(WAIT, "LOCAL_POSITION_NED", |m| match m {
        MavMessage::LOCAL_POSITION_NED(p) => Some((p.x, p.vx)),
        _ => None,
    })
    .await
}

#[tokio::test(start_paused = true)]
async fn velocity_setpoint_flies_north_then_times_out() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    gcs.airborne(10.0).await;
    assert_eq!(gcs.set_interval(32, 50_000.0).await, ACCEPTED);
    let (x0, _) = north(&mut gcs).await;
    let sent = Instant::now();
    gcs.send(&local_target(
        IGNORE_POS | IGNORE_ACC_YAW,
        [0.; 3],
        [2., 0., 0.],
    ))
    .await;
    // Cruising at the commanded speed between ~1 s and the 3 s timeout.
    while sent.elapsed() < Duration::from_millis(2800) {
        let (_, vx) = north(&mut gcs).await;
        if sent.elapsed() > Duration::from_secs(1) {
            assert!((vx - 2.0).abs() < 0.1, "vx {vx} at {:?}", sent.elapsed());
        }
    }
    // Timed out at 3 s; stopped well within another 1.5 s.
    while sent.elapsed() < Duration::from_millis(4500) {
        north(&mut gcs).await;
    }
    let (x1, vx) = north(&mut gcs).await;
    assert!(vx.abs() < 0.05, "stopped: {vx}");
    let travelled = x1 - x0;
    assert!((4.5..6.5).contains(&travelled), "{travelled} m");
    while sent.elapsed() < Duration::from_millis(6000) {
        north(&mut gcs).await;
    }
    let (x2, _) = north(&mut gcs).await;
    assert!((x2 - x1).abs() < 0.05, "holds after the timeout");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn position_target_is_reached_without_overshoot() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    gcs.airborne(10.0).await;
    assert_eq!(gcs.set_interval(32, 20_000.0).await, ACCEPTED);
    gcs.send(&local_target(
        IGNORE_VEL | IGNORE_ACC_YAW,
        [20., 0., -10.],
        [0.; 3],
    ))
    .await;
    let start = Instant::now();
    let mut max_x = f32::MIN;
    let mut last = 0.0;
    while start.elapsed() < Duration::from_secs(15) {
        let (x, _) = north(&mut gcs).await;
        max_x = max_x.max(x);
        last = x;
    }
    assert!((last - 20.0).abs() < 0.1, "arrived: {last}");
    assert!(max_x <= 20.5, "overshoot: {max_x}");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn land_disarms_on_the_ground() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    gcs.airborne(5.0).await;
    assert_eq!(
        gcs.command(MavCmd::MAV_CMD_NAV_LAND, [0.; 7]).await,
        ACCEPTED
    );
    let mut disarm_text = false;
    let mut last_alt = i32::MAX;
    gcs.wait_for(Duration::from_secs(30), "disarmed heartbeat", |m| match m {
        MavMessage::STATUSTEXT(t) => {
            disarm_text |= t.text.to_str() == Ok("Disarming motors");
            None
        }
        MavMessage::GLOBAL_POSITION_INT(g) => {
            last_alt = g.relative_alt;
            None
        }
        MavMessage::HEARTBEAT(h) => (!h
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED))
        .then_some(()),
        _ => None,
    })
    .await;
    assert!(disarm_text);
    assert!(last_alt.abs() < 100, "on the ground: {last_alt} mm");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn rtl_returns_home_and_disarms() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    gcs.airborne(10.0).await;
    gcs.send(&local_target(
        IGNORE_VEL | IGNORE_ACC_YAW,
        [30., 10., -10.],
        [0.; 3],
    ))
    .await;
    assert_eq!(gcs.set_interval(32, 100_000.0).await, ACCEPTED);
    gcs.wait_for(Duration::from_secs(20), "arrival", |m| match m {
        MavMessage::LOCAL_POSITION_NED(p) if (p.x - 30.0).abs() < 0.2 => Some(()),
        _ => None,
    })
    .await;
    assert_eq!(gcs.set_mode(6).await, ACCEPTED);
    let mut max_alt = 0;
    let mut pos = (0.0, 0.0);
    gcs.wait_for(Duration::from_secs(60), "disarmed", |m| match m {
        MavMessage::GLOBAL_POSITION_INT(g) => {
            max_alt = max_alt.max(g.relative_alt);
            None
        }
        MavMessage::LOCAL_POSITION_NED(p) => {
            pos = (p.x, p.y);
            None
        }
        MavMessage::HEARTBEAT(h) => (!h
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED))
        .then_some(()),
        _ => None,
    })
    .await;
    assert!((max_alt - 15_000).abs() < 300, "RTL_ALT 15 m: {max_alt}");
    assert!(pos.0.abs() < 0.5 && pos.1.abs() < 0.5, "home: {pos:?}");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn garbage_then_a_valid_frame_is_still_handled() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    // Garbage without frame markers, then a command in the same write.
    let mut bytes: Vec<u8> = (0..200u32).map(|i| (i * 7 % 250) as u8).collect();
    let mut frame = Vec::new();
    mavlink_frame::encode(
        GCS_HEADER,
        &MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: 1.0,
            param2: 4.0,
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 1,
            target_component: 1,
            ..COMMAND_LONG_DATA::DEFAULT
        }),
        &mut frame,
    );
    bytes.extend(&frame);
    gcs.send_raw(&bytes).await;
    let result = gcs
        .wait_for(WAIT, "ACK after garbage", |m| match m {
            MavMessage::COMMAND_ACK(a) => Some(a.result),
            _ => None,
        })
        .await;
    assert_eq!(result, ACCEPTED);
    assert!(sim.stats.snapshot().garbage_bytes >= 200);

    // A fake marker claiming a long known message swallows the next frame;
    // the frame still comes out once the fake candidate fails its checksum.
    let mut bytes = vec![0xFD, 250, 0, 0, 0, 1, 1, 76, 0, 0];
    let mut loiter = frame.clone();
    // Same command, mode 5: patch param2 (payload offset 4..8) and re-checksum.
    loiter[10 + 4..10 + 8].copy_from_slice(&5.0f32.to_le_bytes());
    let crc_at = loiter.len() - 2;
    let crc = mavlink::calculate_crc(&loiter[1..crc_at], COMMAND_LONG_DATA_EXTRA_CRC);
    loiter[crc_at..].copy_from_slice(&crc.to_le_bytes());
    bytes.extend(&loiter);
    gcs.send_raw(&bytes).await;
    // A GCS keeps sending heartbeats (21 bytes each), which completes the
    // fake 262-byte candidate.
    for _ in 0..15 {
        gcs.send(&gcs_heartbeat()).await;
    }
    gcs.wait_for(WAIT, "LOITER heartbeat", |m| match m {
        MavMessage::HEARTBEAT(h) if h.custom_mode == 5 => Some(()),
        _ => None,
    })
    .await;
    assert!(sim.stats.snapshot().bad_frames >= 1);
    sim.stop().await;
}

const COMMAND_LONG_DATA_EXTRA_CRC: u8 = <COMMAND_LONG_DATA as mavlink::MessageData>::EXTRA_CRC;

fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(mavlink::dialects::ardupilotmega::HEARTBEAT_DATA {
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        ..mavlink::dialects::ardupilotmega::HEARTBEAT_DATA::DEFAULT
    })
}

#[tokio::test(start_paused = true)]
async fn unknown_commands_are_unsupported_and_mavlink1_is_accepted() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    assert_eq!(
        gcs.command(MavCmd::MAV_CMD_DO_FLIGHTTERMINATION, [1.; 7])
            .await,
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    // A command number no dialect has: the ACK carries the raw number, which
    // the typed decoder cannot represent, so count it on the sim side.
    let mut frame = Vec::new();
    mavlink_frame::encode(
        GCS_HEADER,
        &MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 1,
            target_component: 1,
            ..COMMAND_LONG_DATA::DEFAULT
        }),
        &mut frame,
    );
    frame[10 + 28..10 + 30].copy_from_slice(&65000u16.to_le_bytes());
    let crc_at = frame.len() - 2;
    let crc = mavlink::calculate_crc(&frame[1..crc_at], COMMAND_LONG_DATA_EXTRA_CRC);
    frame[crc_at..].copy_from_slice(&crc.to_le_bytes());
    gcs.send_raw(&frame).await;

    // MAVLink 1 in, MAVLink 2 out.
    let mut v1 = Vec::new();
    mavlink::write_v1_msg(
        &mut v1,
        MavHeader {
            sequence: 9,
            ..GCS_HEADER
        },
        &MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: 1.0,
            param2: 16.0,
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 1,
            target_component: 1,
            ..COMMAND_LONG_DATA::DEFAULT
        }),
    )
    .expect("encode v1");
    gcs.send_raw(&v1).await;
    let result = gcs
        .wait_for(WAIT, "POSHOLD ack", |m| match m {
            MavMessage::COMMAND_ACK(a) if a.command == MavCmd::MAV_CMD_DO_SET_MODE => {
                Some(a.result)
            }
            _ => None,
        })
        .await;
    assert_eq!(result, ACCEPTED);
    assert_eq!(gcs.heartbeat().await.custom_mode, 16);
    let s = sim.stats.snapshot();
    assert_eq!(s.commands_unsupported, 2);
    assert!(gcs.bad_frames >= 1, "the raw ACK reached the client");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn request_message_sends_ack_then_the_message() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    assert_eq!(
        gcs.command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [242., 0., 0., 0., 0., 0., 0.]
        )
        .await,
        ACCEPTED
    );
    let home = gcs
        .wait_for(WAIT, "HOME_POSITION", |m| match m {
            MavMessage::HOME_POSITION(h) => Some(h.clone()),
            _ => None,
        })
        .await;
    assert_eq!(home.latitude, -353_632_610);
    assert_eq!(home.altitude, 584_000);
    assert_eq!(
        gcs.command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [148., 0., 0., 0., 0., 0., 0.]
        )
        .await,
        ACCEPTED
    );
    gcs.wait_for(WAIT, "AUTOPILOT_VERSION", |m| match m {
        MavMessage::AUTOPILOT_VERSION(_) => Some(()),
        _ => None,
    })
    .await;
    assert_eq!(
        gcs.command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [65., 0., 0., 0., 0., 0., 0.]
        )
        .await,
        MavResult::MAV_RESULT_DENIED
    );
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn udp_endpoint_answers_every_peer() {
    let sim = Sim::start(RawConfig {
        endpoint: "udp:127.0.0.1:0".to_owned(),
        ..RawConfig::default()
    })
    .await;
    let a = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind a");
    let b = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind b");
    let mut hb = Vec::new();
    mavlink_frame::encode(GCS_HEADER, &gcs_heartbeat(), &mut hb);
    a.send_to(&hb, sim.addr).await.expect("send a");
    b.send_to(&hb, sim.addr).await.expect("send b");
    for sock in [&a, &b] {
        let got = tokio::time::timeout(WAIT, async {
            let mut buf = [0u8; 512];
            loop {
                let (n, from) = sock.recv_from(&mut buf).await.expect("recv");
                assert_eq!(from, sim.addr);
                let mut d = mavlink_frame::FrameDecoder::new();
                d.push(&buf[..n]);
                if let Some(Ok(mavlink_frame::Inbound::Message {
                    msg: MavMessage::HEARTBEAT(h),
                    ..
                })) = d.next_frame()
                {
                    return h;
                }
            }
        })
        .await
        .expect("heartbeat over udp");
        assert_eq!(got.mavtype, MavType::MAV_TYPE_QUADROTOR);
    }
    assert_eq!(sim.stats.snapshot().clients_total, 2);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn shutdown_closes_clients_and_run_returns_ok() {
    let sim = Sim::tcp().await;
    let mut one = Gcs::connect(sim.addr).await;
    let mut two = Gcs::connect(sim.addr).await;
    one.heartbeat().await;
    two.heartbeat().await;
    assert_eq!(sim.stats.snapshot().clients_connected, 2);
    let stats = sim.stats.clone();
    let addr = sim.addr;
    sim.stop().await;
    assert_eq!(stats.snapshot().clients_connected, 0);
    for gcs in [&mut one, &mut two] {
        let eof = tokio::time::timeout(WAIT, async {
            use tokio::io::AsyncReadExt;
            let mut buf = [0u8; 4096];
            loop {
                match gcs_stream(gcs).read(&mut buf).await {
                    Ok(0) | Err(_) => return,
                    Ok(_) => {}
                }
            }
        })
        .await;
        assert!(eof.is_ok(), "connection closed");
    }
    assert!(
        tokio::net::TcpStream::connect(addr).await.is_err(),
        "listener closed"
    );
}

fn gcs_stream(gcs: &mut Gcs) -> &mut tokio::net::TcpStream {
    gcs.stream_mut()
}

#[tokio::test(start_paused = true)]
async fn connections_beyond_max_clients_are_refused() {
    let sim = Sim::start(RawConfig {
        max_clients: 1,
        ..RawConfig::default()
    })
    .await;
    let mut first = Gcs::connect(sim.addr).await;
    first.heartbeat().await;
    let mut second = Gcs::connect(sim.addr).await;
    let closed = tokio::time::timeout(WAIT, async {
        use tokio::io::AsyncReadExt;
        let mut buf = [0u8; 64];
        matches!(second.stream_mut().read(&mut buf).await, Ok(0) | Err(_))
    })
    .await;
    assert_eq!(closed, Ok(true), "the second client is closed at once");
    assert_eq!(sim.stats.snapshot().clients_rejected, 1);
    // The first is unaffected.
    first.heartbeat().await;
    sim.stop().await;
}
