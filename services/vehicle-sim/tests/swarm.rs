//! Swarm mode: one `run_all` serving several vehicles, each on its own endpoint
//! with its own system id and home, flying independently. The tokio clock is
//! paused, as in `server.rs`.

mod common;

use std::time::Duration;

use common::{Gcs, Swarm, GCS_HEADER, WAIT};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, GLOBAL_POSITION_INT_DATA,
    HEARTBEAT_DATA,
};
use mavlink_frame::{self as codec, FrameDecoder, Inbound};
use skymesh_vehicle_sim::{RawConfig, RawSwarm};

/// Metres per degree of latitude (as the sim's flat-earth frame).
const M_PER_DEG: f64 = 111_318.845_021_450_34;

fn swarm(count: u32) -> RawConfig {
    RawConfig {
        swarm: RawSwarm {
            count,
            spacing_m: 3.0,
            ..RawSwarm::default()
        },
        ..RawConfig::default()
    }
}

async fn position(gcs: &mut Gcs) -> GLOBAL_POSITION_INT_DATA {
    gcs.wait_for(WAIT, "GLOBAL_POSITION_INT", |m| match m {
        MavMessage::GLOBAL_POSITION_INT(g) => Some(g.clone()),
        _ => None,
    })
    .await
}

/// North and east of `home`, metres.
fn ne_from(home: &GLOBAL_POSITION_INT_DATA, p: &GLOBAL_POSITION_INT_DATA) -> (f64, f64) {
    let lat = f64::from(home.lat) / 1e7;
    let north = f64::from(p.lat - home.lat) / 1e7 * M_PER_DEG;
    let east = f64::from(p.lon - home.lon) / 1e7 * M_PER_DEG * lat.to_radians().cos();
    (north, east)
}

#[tokio::test(start_paused = true)]
async fn three_vehicles_on_three_ports_fly_independently() {
    let sim = Swarm::start(RawConfig {
        // Per vehicle: one client each must not exhaust a shared budget.
        max_clients: 1,
        ..swarm(3)
    })
    .await;
    assert_eq!(sim.addrs.len(), 3);
    let mut ports: Vec<u16> = sim.addrs.iter().map(|a| a.port()).collect();
    ports.dedup();
    assert_eq!(ports.len(), 3, "three distinct endpoints: {:?}", sim.addrs);

    let mut gcs = Vec::new();
    for (i, addr) in sim.addrs.iter().enumerate() {
        let mut g = Gcs::connect(*addr).await;
        g.target_system = i as u8 + 1;
        // Each endpoint speaks for its own vehicle: system id 1 + i, component 1.
        let (header, hb) = loop {
            if let (h, MavMessage::HEARTBEAT(hb)) = g.recv_with_header().await {
                break (h, hb);
            }
        };
        assert_eq!((header.system_id, header.component_id), (i as u32 + 1, 1));
        assert_eq!(hb.mavtype, MavType::MAV_TYPE_QUADROTOR);
        assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
        gcs.push(g);
    }

    // Homes on a 2-column grid 3 m apart: vehicle 2 east of vehicle 1, vehicle 3 north.
    let mut homes = Vec::new();
    for g in &mut gcs {
        homes.push(position(g).await);
    }
    for (i, want) in [(0.0, 0.0), (0.0, 3.0), (3.0, 0.0)].iter().enumerate() {
        let (n, e) = ne_from(&homes[0], &homes[i]);
        assert!(
            (n - want.0).abs() < 0.05 && (e - want.1).abs() < 0.05,
            "vehicle {} home is {n:.2} m north, {e:.2} m east of vehicle 1's",
            i + 1
        );
    }

    // Take vehicle 2 off; 1 and 3 stay disarmed on the ground where they were.
    gcs[1].airborne(5.0).await;
    let p2 = position(&mut gcs[1]).await;
    assert!((p2.relative_alt - 5000).abs() < 100, "{}", p2.relative_alt);
    for i in [0, 2] {
        let hb: HEARTBEAT_DATA = gcs[i].heartbeat().await;
        assert!(
            !hb.base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
            "vehicle {} armed",
            i + 1
        );
        assert_eq!(hb.system_status, MavState::MAV_STATE_STANDBY);
        assert_eq!(hb.custom_mode, 0, "vehicle {} still in STABILIZE", i + 1);
        let p = position(&mut gcs[i]).await;
        assert!(
            p.relative_alt.abs() < 50,
            "vehicle {} rose: {}",
            i + 1,
            p.relative_alt
        );
        let (n, e) = ne_from(&homes[i], &p);
        assert!(n.abs() < 0.05 && e.abs() < 0.05, "vehicle {} moved", i + 1);
    }
    let hb = gcs[1].heartbeat().await;
    assert!(hb
        .base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED));

    let s = sim.stats.snapshot();
    assert_eq!((s.vehicles, s.vehicles_linked, s.vehicles_armed), (3, 3, 1));
    assert_eq!((s.clients_connected, s.clients_rejected), (3, 0));

    // max_clients is per endpoint: a second client of vehicle 1 is refused.
    let mut extra = Gcs::connect(sim.addrs[0]).await;
    let closed = tokio::time::timeout(WAIT, async {
        use tokio::io::AsyncReadExt;
        let mut buf = [0u8; 64];
        matches!(extra.stream_mut().read(&mut buf).await, Ok(0) | Err(_))
    })
    .await;
    assert_eq!(closed, Ok(true));
    assert_eq!(sim.stats.snapshot().clients_rejected, 1);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn a_command_for_another_system_is_ignored() {
    let sim = Swarm::start(swarm(2)).await;
    let mut one = Gcs::connect(sim.addrs[0]).await;
    let mut two = Gcs::connect(sim.addrs[1]).await;
    one.heartbeat().await;
    two.heartbeat().await;
    // Vehicle 1's link carries a mode change addressed to system 2: vehicle 1 does
    // not obey it and vehicle 2 (another endpoint) never sees it.
    one.target_system = 2;
    one.send(&MavMessage::COMMAND_LONG(
        mavlink::dialects::ardupilotmega::COMMAND_LONG_DATA {
            param1: 1.0,
            param2: 4.0,
            command: mavlink::dialects::ardupilotmega::MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 2,
            target_component: 1,
            ..Default::default()
        },
    ))
    .await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(one.heartbeat().await.custom_mode, 0);
    assert_eq!(two.heartbeat().await.custom_mode, 0);
    assert_eq!(sim.stats.snapshot().commands_accepted, 0);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn udp_swarm_answers_with_each_vehicles_id() {
    let sim = Swarm::start(RawConfig {
        endpoint: "udp:127.0.0.1:0".to_owned(),
        ..swarm(2)
    })
    .await;
    let sock = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let mut hb = Vec::new();
    codec::encode(
        GCS_HEADER,
        &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_GCS,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            ..Default::default()
        }),
        &mut hb,
    );
    for (i, addr) in sim.addrs.iter().enumerate() {
        sock.send_to(&hb, addr).await.expect("send");
        let system_id = tokio::time::timeout(WAIT, async {
            let mut buf = [0u8; 512];
            loop {
                let (n, from) = sock.recv_from(&mut buf).await.expect("recv");
                if from != *addr {
                    continue;
                }
                let mut d = FrameDecoder::new();
                d.push(&buf[..n]);
                if let Some(Ok(Inbound::Message {
                    header,
                    msg: MavMessage::HEARTBEAT(_),
                    ..
                })) = d.next_frame()
                {
                    return header.system_id;
                }
            }
        })
        .await
        .expect("heartbeat over udp");
        assert_eq!(system_id, i as u32 + 1);
    }
    sim.stop().await;
}
