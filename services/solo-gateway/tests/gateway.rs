//! solo-gateway in-process: app ↔ bus forwarding, sessions and the one-app rule.

mod common;

use std::time::Duration;

use common::{localhost, other_host, value_of, Gateway, PATIENCE};
use skymesh_ipc_types::ShotEvent;
use skymesh_ipc_types::{topics, AppSession, ServiceId};
use skymesh_runtime::{Bus, Stats};
use skymesh_solo_gateway::client::AppClient;
use skymesh_solo_gateway::Settings;
use solo_proto::{ids, GeofenceData, Location, SoloMessage};

#[tokio::test]
async fn app_messages_reach_the_bus_exactly() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let sent = [
        SoloMessage::SetCurrentShot(1),
        SoloMessage::Location(Location {
            lat_deg: -35.363261,
            lon_deg: 149.16523,
            alt_m: 12.5,
        }),
        SoloMessage::ShotOptions { cruise_speed: -3.0 },
        SoloMessage::RecordPosition,
    ];
    for m in &sent {
        app.send(m).await.expect("send");
    }
    for m in &sent {
        let got = gw.next_from_app().await;
        let value = value_of(m);
        assert_eq!(got.session, 1);
        assert_eq!(got.msg_type, m.msg_type());
        assert_eq!(got.len as usize, value.len());
        assert_eq!(got.value(), value.as_slice());
        assert_eq!(got.flags, 0);
        assert!(!got.is_follow_stream());
        assert_eq!(got.header.service_id(), Ok(ServiceId::SoloGateway));
        assert_eq!(
            SoloMessage::decode(got.msg_type, got.value()).as_ref(),
            Ok(m)
        );
    }
    gw.wait_metric(
        "skymesh_solo_messages_total",
        "direction=in,type=set_current_shot",
        1.0,
    )
    .await;
    gw.wait_metric(
        "skymesh_solo_messages_total",
        "direction=in,type=location",
        1.0,
    )
    .await;
    gw.stop().await;
}

#[tokio::test]
async fn a_geofence_is_translated_for_the_engine() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    // The spec's example: one keep-in polygon and its sub-polygon (JSON > 240 bytes).
    let coord = vec![
        [37.873_391_778_802, -122.301_244_403_242],
        [37.873_425_469_262, -122.300_884_203_791],
        [37.872_895_782_932, -122.300_712_401_129],
        [37.872_942_621_198, -122.301_244_403_242],
    ];
    let sub = vec![
        [37.873_405_777_181, -122.300_901_311_238],
        [37.872_916_521_332, -122.300_742_618_658],
        [37.872_958_695_064, -122.301_221_642_913],
        [37.873_375_815_652, -122.301_221_642_913],
    ];
    let fence = SoloMessage::GeofenceSetData(GeofenceData {
        coord: vec![coord.clone(), coord[..3].to_vec()],
        sub_coord: vec![sub.clone(), sub[..3].to_vec()],
        kinds: vec![0, 1],
    });
    app.send(&fence).await.expect("send");
    app.send(&SoloMessage::GeofenceClear).await.expect("send");
    let g = gw.next_geofence().await;
    assert_eq!(g.session, 1);
    assert_eq!(g.header.service_id(), Ok(ServiceId::SoloGateway));
    assert_eq!(g.polygons().len(), 2);
    assert_eq!(g.polygons()[0].kind, 0);
    assert_eq!(g.polygons()[0].vertices(), coord.as_slice());
    assert_eq!(g.polygons()[0].sub_vertices(), sub.as_slice());
    assert_eq!(g.polygons()[1].kind, 1);
    assert_eq!(g.polygons()[1].vertices(), &coord[..3]);
    // The CLEAR after it goes the usual way, stamped later (the engine keeps order).
    let clear = gw.next_from_app().await;
    assert_eq!(clear.msg_type, ids::GEOFENCE_CLEAR);
    assert!(clear.header.stamp_ns > g.header.stamp_ns);
    gw.wait_metric(
        "skymesh_solo_messages_total",
        "direction=in,type=geofence_set_data",
        1.0,
    )
    .await;
    assert_eq!(
        gw.metric("skymesh_solo_malformed_total", "kind=too_large_for_bus"),
        None
    );
    gw.stop().await;
}

#[tokio::test]
async fn engine_messages_reach_the_app_by_session() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;

    gw.send_to_app(0, &ShotEvent::CurrentShot(1));
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::GetCurrentShot(1))
    );

    // Addressed to an earlier session: dropped; the next one (this session) arrives first.
    gw.send_to_app(99, &ShotEvent::CurrentShot(2));
    gw.send_to_app(1, &ShotEvent::ShotOptions { cruise_speed: 4.0 });
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::ShotOptions { cruise_speed: 4.0 })
    );
    gw.wait_metric(
        "skymesh_solo_to_app_dropped_total",
        "reason=stale_session",
        1.0,
    )
    .await;
    gw.wait_metric(
        "skymesh_solo_messages_total",
        "direction=out,type=shot_options",
        1.0,
    )
    .await;

    // Nobody connected: counted, not queued for the next app.
    drop(app);
    gw.wait_session("session 1 disconnected", |s| {
        s.session == 1 && s.connected == 0
    })
    .await;
    gw.send_to_app(0, &ShotEvent::CurrentShot(5));
    gw.wait_metric("skymesh_solo_to_app_dropped_total", "reason=no_app", 1.0)
        .await;
    let mut app = AppClient::connect(gw.tcp).await.expect("reconnect");
    gw.wait_connected(2).await;
    gw.send_to_app(0, &ShotEvent::CurrentShot(-1));
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::GetCurrentShot(-1))
    );
    gw.stop().await;
}

#[tokio::test]
async fn app_session_on_connect_disconnect_and_periodically() {
    let mut settings = Settings::loopback_any_port();
    settings.session_publish = Duration::from_millis(100);
    let mut gw = Gateway::start_with(settings).await;
    gw.wait_session("the initial state", |s| s.session == 0 && s.connected == 0)
        .await;
    let app = AppClient::connect(gw.tcp).await.expect("connect");
    let s = gw.wait_connected(1).await;
    assert_eq!(s.peer.as_str(), app.local_addr().to_string());
    assert_eq!(gw.metric("skymesh_solo_clients_connected", ""), Some(1.0));
    // Republished: an engine that starts now learns the state from the next sample.
    gw.wait_connected(1).await;
    let late_bus =
        Bus::open(&gw.domain, "late-engine", ServiceId::Tool, 0, Stats::new()).expect("bus");
    let mut late = late_bus
        .subscriber::<AppSession>(&topics::shot_app_session())
        .expect("subscriber");
    let s = late
        .recv_timeout(PATIENCE)
        .await
        .expect("recv")
        .expect("a sample");
    assert_eq!((s.session, s.connected), (1, 1));

    drop(app);
    let s = gw
        .wait_session("session 1 disconnected", |s| {
            s.session == 1 && s.connected == 0
        })
        .await;
    assert!(s.peer.as_str().starts_with("127.0.0.1:"), "{}", s.peer);
    assert_eq!(gw.metric("skymesh_solo_clients_connected", ""), Some(0.0));
    gw.wait_metric("skymesh_solo_connections_total", "result=accepted", 1.0)
        .await;

    // Stopping with an app connected closes it and says so.
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(2).await;
    gw.halt().await;
    assert!(
        app.wait_closed(PATIENCE).await,
        "closed when the gateway stops"
    );
    let last = late
        .latest()
        .expect("recv")
        .expect("a final session sample");
    assert_eq!((last.session, last.connected), (2, 0));
    drop((late, late_bus));
    gw.stop().await;
}

#[tokio::test]
async fn a_second_phone_from_another_address_is_rejected() {
    let mut gw = Gateway::start().await;
    let mut first = AppClient::connect_from(localhost(), gw.tcp)
        .await
        .expect("connect");
    gw.wait_connected(1).await;

    let mut second = AppClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect");
    assert_eq!(
        second.recv(PATIENCE).await,
        Some(SoloMessage::SecondPhoneNotification)
    );
    assert!(
        second.wait_closed(PATIENCE).await,
        "the second phone is closed"
    );
    gw.wait_metric(
        "skymesh_solo_connections_total",
        "result=rejected_second_phone",
        1.0,
    )
    .await;

    // The first app keeps working both ways, same session.
    first
        .send(&SoloMessage::SetCurrentShot(2))
        .await
        .expect("send");
    let got = gw.next_from_app().await;
    assert_eq!(
        (got.session, got.msg_type),
        (1, solo_proto::ids::SET_CURRENT_SHOT)
    );
    gw.send_to_app(0, &ShotEvent::CurrentShot(2));
    assert_eq!(
        first.recv(PATIENCE).await,
        Some(SoloMessage::GetCurrentShot(2))
    );
    assert!(!first.is_closed());
    gw.stop().await;
}

#[tokio::test]
async fn the_same_address_replaces_the_connection() {
    let mut gw = Gateway::start().await;
    let mut old = AppClient::connect_from(localhost(), gw.tcp)
        .await
        .expect("connect");
    gw.wait_connected(1).await;

    let mut new = AppClient::connect_from(localhost(), gw.tcp)
        .await
        .expect("connect");
    gw.wait_session("session 1 disconnected", |s| {
        s.session == 1 && s.connected == 0
    })
    .await;
    gw.wait_connected(2).await;
    assert!(
        old.wait_closed(PATIENCE).await,
        "the old connection is closed"
    );
    gw.wait_metric("skymesh_solo_connections_total", "result=replaced", 1.0)
        .await;

    new.send(&SoloMessage::Pause).await.expect("send");
    let got = gw.next_from_app().await;
    assert_eq!((got.session, got.msg_type), (2, solo_proto::ids::PAUSE));
    gw.send_to_app(2, &ShotEvent::CurrentShot(1));
    assert_eq!(
        new.recv(PATIENCE).await,
        Some(SoloMessage::GetCurrentShot(1))
    );
    gw.stop().await;
}

#[tokio::test]
async fn an_app_that_stops_reading_is_closed_not_buffered() {
    let mut settings = Settings::loopback_any_port();
    settings.outgoing_queue = 4;
    let mut gw = Gateway::start_with(settings).await;
    let socket = tokio::net::TcpSocket::new_v4().expect("socket");
    socket.set_recv_buffer_size(4096).expect("rcvbuf");
    let stream = socket.connect(gw.tcp).await.expect("connect");
    let mut app = AppClient::from_stream(stream).expect("client");
    gw.wait_connected(1).await;

    // The app reads nothing; the engine keeps talking until the gateway gives up.
    let text = "x".repeat(200);
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        if gw.metric("skymesh_solo_malformed_total", "kind=overflow") == Some(1.0) {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no overflow within {PATIENCE:?}"
        );
        for _ in 0..32 {
            gw.send_to_app(0, &ShotEvent::Error(text.clone()));
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    gw.wait_session("session 1 disconnected", |s| {
        s.session == 1 && s.connected == 0
    })
    .await;
    assert!(app.wait_closed(PATIENCE).await, "closed after the overflow");
    gw.stop().await;
}
