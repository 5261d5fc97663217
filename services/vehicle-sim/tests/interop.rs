//! Interoperability with the mavlink crate's own connection API (what
//! autopilot-link uses): `tcpout:`/`udpout:` clients in blocking threads,
//! against the simulator on real time.

mod common;

use std::time::Duration;

use common::Sim;
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType, COMMAND_LONG_DATA,
    HEARTBEAT_DATA,
};
use std::io::ErrorKind;

use mavlink::error::MessageReadError;
use mavlink::{MavConnection, MavHeader};
use skymesh_vehicle_sim::RawConfig;

/// Generous: these run on wall-clock time on a busy 2-core machine.
const LIMIT: Duration = Duration::from_secs(20);

const GCS: MavHeader = MavHeader {
    system_id: 255,
    component_id: 190,
    sequence: 0,
};

fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// `recv`, retrying the crate's idle timeouts: its `tcpout` socket has a
/// 100 ms read timeout, so a quiet moment surfaces as WouldBlock/TimedOut.
fn recv(conn: &impl MavConnection<MavMessage>) -> Result<(MavHeader, MavMessage), String> {
    let deadline = std::time::Instant::now() + LIMIT;
    loop {
        match conn.recv() {
            Ok(x) => return Ok(x),
            Err(MessageReadError::Io(e))
                if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut)
                    && std::time::Instant::now() < deadline => {}
            Err(e) => return Err(e.to_string()),
        }
    }
}

/// Read until `n` heartbeats from system 1 / component 1 have arrived.
fn heartbeats(conn: &impl MavConnection<MavMessage>, n: usize) -> Result<usize, String> {
    let mut seen = 0;
    while seen < n {
        let (h, m) = recv(conn)?;
        if let MavMessage::HEARTBEAT(hb) = m {
            if (h.system_id, h.component_id) == (1, 1) && hb.mavtype == MavType::MAV_TYPE_QUADROTOR
            {
                seen += 1;
            }
        }
    }
    Ok(seen)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_tcp_clients_both_receive_heartbeats() {
    let sim = Sim::tcp().await;
    let url = format!("tcpout:{}", sim.addr);
    let clients: Vec<_> = (0..2)
        .map(|_| {
            let url = url.clone();
            tokio::task::spawn_blocking(move || -> Result<usize, String> {
                let conn = mavlink::connect::<MavMessage>(&url).map_err(|e| e.to_string())?;
                heartbeats(&conn, 2)
            })
        })
        .collect();
    for c in clients {
        let got = tokio::time::timeout(LIMIT, c)
            .await
            .expect("heartbeats within the limit")
            .expect("client thread");
        assert_eq!(got, Ok(2));
    }
    assert_eq!(sim.stats.snapshot().clients_total, 2);
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mavlink_crate_client_sets_mode_and_arms() {
    let sim = Sim::tcp().await;
    let url = format!("tcpout:{}", sim.addr);
    let client = tokio::task::spawn_blocking(move || -> Result<Vec<MavResult>, String> {
        let conn = mavlink::connect::<MavMessage>(&url).map_err(|e| e.to_string())?;
        let mut results = Vec::new();
        for (command, p1, p2) in [
            (MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 4.0),
            (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0),
        ] {
            let cmd = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p1,
                param2: p2,
                command,
                target_system: 1,
                target_component: 1,
                ..COMMAND_LONG_DATA::DEFAULT
            });
            conn.send(&GCS, &cmd).map_err(|e| e.to_string())?;
            loop {
                if let (_, MavMessage::COMMAND_ACK(a)) = recv(&conn)? {
                    if a.command == command {
                        results.push(a.result);
                        break;
                    }
                }
            }
        }
        // The heartbeat now says GUIDED and armed.
        loop {
            if let (_, MavMessage::HEARTBEAT(hb)) = recv(&conn)? {
                if hb.custom_mode == 4
                    && hb
                        .base_mode
                        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
                {
                    return Ok(results);
                }
            }
        }
    });
    let results = tokio::time::timeout(LIMIT, client)
        .await
        .expect("within the limit")
        .expect("client thread");
    assert_eq!(
        results,
        Ok(vec![
            MavResult::MAV_RESULT_ACCEPTED,
            MavResult::MAV_RESULT_ACCEPTED
        ])
    );
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn udpout_client_gets_telemetry_after_its_first_packet() {
    let sim = Sim::start(RawConfig {
        endpoint: "udp:127.0.0.1:0".to_owned(),
        ..RawConfig::default()
    })
    .await;
    let url = format!("udpout:{}", sim.addr);
    let client = tokio::task::spawn_blocking(move || -> Result<usize, String> {
        let conn = mavlink::connect::<MavMessage>(&url).map_err(|e| e.to_string())?;
        // The simulator learns a UDP peer from its first packet.
        conn.send(&GCS, &gcs_heartbeat())
            .map_err(|e| e.to_string())?;
        heartbeats(&conn, 2)
    });
    let got = tokio::time::timeout(LIMIT, client)
        .await
        .expect("within the limit")
        .expect("client thread");
    assert_eq!(got, Ok(2));
    sim.stop().await;
}

/// The same rate check as the paused-clock test, on the wall clock: loose
/// bounds, since a busy machine may skip ticks.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn attitude_at_100_hz_on_the_wall_clock() {
    let sim = Sim::tcp().await;
    let mut gcs = common::Gcs::connect(sim.addr).await;
    assert_eq!(
        gcs.set_interval(30, 10_000.0).await,
        MavResult::MAV_RESULT_ACCEPTED
    );
    let until = tokio::time::Instant::now() + Duration::from_secs(1);
    let mut n = 0;
    while tokio::time::Instant::now() < until {
        if let MavMessage::ATTITUDE(_) = gcs.recv().await {
            n += 1;
        }
    }
    assert!((60..=140).contains(&n), "{n} ATTITUDE in 1 s");
    sim.stop().await;
}
