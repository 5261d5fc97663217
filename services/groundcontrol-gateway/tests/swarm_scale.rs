//! 250 drones through the state server: a command for every drone in one burst
//! reaches the queue whole, and 250 CHECK_ALL_IDLE answers reach the client whole.

mod common;

use std::time::Duration;

use common::{Gateway, PATIENCE};
use gc_proto::{NetCmdType, Record};
use skymesh_groundcontrol_gateway::client::GcClient;
use skymesh_ipc_types::{SwarmCommandKind, SwarmResult};

const DRONES: i32 = 250;

#[tokio::test]
async fn a_burst_for_every_drone_loses_nothing() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect(gw.tcp).await.expect("connect");
    let takeoff: Vec<Record> = (0..DRONES)
        .map(|d| Record::new(NetCmdType::CmdExtGoExternal, d))
        .collect();
    client.send_all(&takeoff).await.expect("send");
    let mut drones = Vec::new();
    while drones.len() < DRONES as usize {
        let c = gw
            .commands
            .recv_timeout(Duration::from_secs(2))
            .await
            .expect("swarm_command");
        let Some(c) = c else { break };
        assert_eq!(c.kind(), Ok(SwarmCommandKind::ExtGoExternal));
        drones.push(c.drone);
    }
    assert_eq!(
        drones,
        (0..DRONES as u16).collect::<Vec<_>>(),
        "{} of {DRONES} commands arrived",
        drones.len()
    );
    gw.stop().await;
}

#[tokio::test]
async fn check_all_idle_for_every_drone_loses_nothing() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect(gw.tcp).await.expect("connect");
    client
        .send(&Record::new(NetCmdType::CmdExtCheckAllIdle, 0))
        .await
        .expect("send");
    let c = gw.next_command().await;
    for d in 0..DRONES as u16 {
        gw.reply(&c, d, SwarmResult::IdleState, i32::from(d % 2 == 0));
    }
    let mut got = Vec::new();
    while got.len() < DRONES as usize {
        match client.recv(Duration::from_secs(2)).await.expect("open") {
            Some(r) => got.push((r.context, r.int1)),
            None => break,
        }
    }
    let expected: Vec<(i32, i32)> = (0..DRONES).map(|d| (d, i32::from(d % 2 == 0))).collect();
    assert_eq!(
        got.len(),
        expected.len(),
        "{} of {DRONES} answers arrived",
        got.len()
    );
    assert_eq!(got, expected);
    let _ = PATIENCE;
    gw.stop().await;
}
