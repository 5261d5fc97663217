//! Heartbeat to the peers that talk to us and to static peers; Announce to the
//! configured destinations with our name, type and services string.

mod common;

use std::net::SocketAddr;
use std::time::Duration;

use common::{settings, Gateway, GATEWAY_ID, PATIENCE};
use imc_proto::{Message, SystemType};
use skymesh_imc_gateway::client::ImcClient;
use skymesh_ipc_types::VehicleState;

#[tokio::test]
async fn peers_that_talk_to_us_get_heartbeats() {
    let gw = Gateway::start().await;
    let peer = gw.peer().await;
    peer.send(&Message::Heartbeat).await.unwrap();
    let hb = peer
        .recv_until(PATIENCE, |p| p.message == Message::Heartbeat)
        .await
        .expect("a heartbeat from the gateway");
    assert_eq!(hb.header.src, GATEWAY_ID);
    assert_eq!(hb.header.dst, peer.identity.src, "addressed to the peer");
    // About once a second: a second one follows.
    peer.recv_until(PATIENCE, |p| p.message == Message::Heartbeat)
        .await
        .expect("another heartbeat");
    gw.wait_metric("skymesh_imc_peers", "", 1.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn static_peers_and_announce_destinations_are_served_unasked() {
    let listener = ImcClient::connect(SocketAddr::from(([127, 0, 0, 1], 9)))
        .await
        .unwrap();
    let group = ImcClient::connect(SocketAddr::from(([127, 0, 0, 1], 9)))
        .await
        .unwrap();
    let mut s = settings();
    s.static_peers = vec![listener.local_addr().unwrap()];
    s.announce_destinations = vec![group.local_addr().unwrap()];
    s.announce_interval = Duration::from_secs(1);
    s.system_name = "skymesh-test".into();
    let mut gw = Gateway::start_with(s).await;
    let state = VehicleState {
        vehicle_id: 1,
        position_valid: 1,
        lat_deg: -35.363261,
        lon_deg: 149.165230,
        alt_msl_m: 594.0,
        ..Default::default()
    };

    let hb = listener
        .recv_until(PATIENCE, |p| p.message == Message::Heartbeat)
        .await
        .expect("heartbeat to the static peer");
    assert_eq!(
        hb.header.dst,
        imc_proto::ADDR_NONE,
        "its id is not known yet"
    );

    // Announces before the first vehicle state carry zeros; the state streams as
    // autopilot-link's does until one with the position arrives.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let a = loop {
        gw.vehicle_state.publish(state).unwrap();
        let got = group
            .recv_message(Duration::from_millis(300), |m| {
                matches!(m, Message::Announce(_))
            })
            .await;
        match got {
            Some(Message::Announce(a)) if a.lat != 0.0 => break a,
            Some(Message::Announce(a)) => assert_eq!((a.lat, a.lon), (0.0, 0.0)),
            _ => {}
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no Announce with a position"
        );
    };
    assert_eq!(a.sys_name, "skymesh-test");
    assert_eq!(a.sys_type, SystemType::Uav);
    assert_eq!(a.owner, 0xFFFF);
    assert!((a.lat.to_degrees() + 35.363261).abs() < 1e-9);
    assert!((a.lon.to_degrees() - 149.165230).abs() < 1e-9);
    assert_eq!(a.height, 594.0);
    assert_eq!(a.services, format!("imc+udp://{}/", gw.addr));

    // An Announce from a peer names it (and makes it a peer).
    let peer = gw.peer().await;
    let mut own = a.clone();
    own.sys_name = "neptus-console".into();
    peer.send(&Message::Announce(own)).await.unwrap();
    peer.recv_until(PATIENCE, |p| p.message == Message::Heartbeat)
        .await
        .expect("the announcing peer gets heartbeats");
    gw.wait_metric("skymesh_imc_peers", "", 2.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn an_unreachable_announce_destination_is_not_fatal() {
    let mut s = settings();
    // An IPv6 destination from an IPv4 socket: every send fails, as multicast does
    // on a machine without a route for it.
    s.announce_destinations = vec!["[::1]:30100".parse().unwrap()];
    s.announce_interval = Duration::from_secs(1);
    let gw = Gateway::start_with(s).await;
    gw.wait_metric_at_least("skymesh_imc_send_errors_total", "message=Announce", 2.0)
        .await;
    // Still serving.
    let peer = gw.peer().await;
    common::barrier(&peer).await;
    gw.stop().await;
}
