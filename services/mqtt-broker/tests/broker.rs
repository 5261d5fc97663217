//! The embedded broker in-process ([`serve`]) against `rumqttc` clients.
//!
//! rumqttd cannot be stopped inside a process: after `serve` returns, its threads
//! keep listening until the test process ends. Every test uses its own port.

mod common;

use std::net::SocketAddr;

use common::*;
use rumqttc::{Packet, QoS};
use skymesh_mqtt_broker::{serve, BrokerError, RawConfig};
use skymesh_runtime::config::parse;
use skymesh_runtime::{CancellationToken, Stats};

/// The in-process broker and its plain listener.
struct Broker {
    addr: SocketAddr,
    run: Running,
}

impl std::ops::Deref for Broker {
    type Target = Running;
    fn deref(&self) -> &Running {
        &self.run
    }
}

impl Broker {
    async fn stop(self) {
        self.run.stop().await;
    }
}

/// The broker on a free port with `extra` TOML.
async fn start(extra: &str) -> Broker {
    let (run, [addr]) = Running::start_on_free_ports(|[addr]| config_toml(addr, extra)).await;
    Broker { addr, run }
}

#[tokio::test]
async fn a_publish_reaches_a_subscriber_and_is_metered() {
    let broker = start("").await;
    let (sub, mut sub_ev) = connect(broker.addr, "sub", None).await;
    sub.subscribe("thing/product/sn1/drc/down", QoS::AtLeastOnce)
        .await
        .expect("subscribe");
    until_incoming(&mut sub_ev, "suback", |p| matches!(p, Packet::SubAck(_))).await;

    let (publ, pub_ev) = connect(broker.addr, "pub", None).await;
    let _pub_task = drive(pub_ev);
    publ.publish(
        "thing/product/sn1/drc/down",
        QoS::AtLeastOnce,
        false,
        &b"{\"method\":\"heart_beat\"}"[..],
    )
    .await
    .expect("publish");
    let got = next_publish(&mut sub_ev, "the published message").await;
    assert_eq!(got.topic, "thing/product/sn1/drc/down");
    assert_eq!(&got.payload[..], b"{\"method\":\"heart_beat\"}");

    // rumqttd's meters reach the service's stats.
    broker
        .until_metric("skymesh_mqtt_publishes_total", "", 1.0)
        .await;
    assert_eq!(
        broker.stats.value("skymesh_mqtt_connections", ""),
        Some(2.0)
    );
    assert!(broker.stats.value("skymesh_mqtt_meters_total", "") >= Some(1.0));
    drop((sub, publ));
    broker.stop().await;
}

#[tokio::test]
async fn an_oversized_publish_closes_the_connection_and_is_not_delivered() {
    let broker = start("max_payload_size = 1024").await;
    let (sub, mut sub_ev) = connect(broker.addr, "sub", None).await;
    sub.subscribe("big/#", QoS::AtMostOnce)
        .await
        .expect("subscribe");
    until_incoming(&mut sub_ev, "suback", |p| matches!(p, Packet::SubAck(_))).await;

    let (big, mut big_ev) = connect(broker.addr, "big", None).await;
    big.publish("big/one", QoS::AtMostOnce, false, vec![0x55; 4096])
        .await
        .expect("queue publish");
    until_error(&mut big_ev, "oversized publish").await;

    // A small message sent afterwards is the first one the subscriber sees.
    let (small, small_ev) = connect(broker.addr, "small", None).await;
    let _small_task = drive(small_ev);
    small
        .publish("big/two", QoS::AtMostOnce, false, &b"ok"[..])
        .await
        .expect("publish");
    let got = next_publish(&mut sub_ev, "the small message").await;
    assert_eq!(got.topic, "big/two");
    assert_eq!(&got.payload[..], b"ok");
    drop((sub, big, small));
    broker.stop().await;
}

#[tokio::test]
async fn only_configured_users_may_connect() {
    let broker = start("[[user]]\nname = \"cloud\"\npassword = \"s3cret\"").await;
    // The right credentials work (and prove the broker is listening).
    let (_ok, _ok_ev) = connect(broker.addr, "good", Some(("cloud", "s3cret"))).await;

    for (id, login) in [
        ("wrong-password", Some(("cloud", "nope"))),
        ("unknown-user", Some(("mallory", "s3cret"))),
        ("no-login", None),
    ] {
        let (_c, mut ev) = rumqttc::AsyncClient::new(options(broker.addr, id, login), 4);
        match tokio::time::timeout(PATIENCE, ev.poll()).await {
            Ok(Err(_refused)) => {}
            Ok(Ok(event)) => panic!("{id}: the broker must refuse the connection, got {event:?}"),
            Err(_) => panic!("{id}: no answer within {PATIENCE:?}"),
        }
    }
    broker.stop().await;
}

#[tokio::test]
async fn a_port_in_use_is_a_clear_error() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = taken.local_addr().expect("addr");
    let settings = parse::<RawConfig>(&config_toml(addr, ""), "test").expect("config");
    let r = serve(settings, Stats::new(), CancellationToken::new(), || {
        panic!("must not report ready")
    })
    .await;
    let e = r.expect_err("the port is taken");
    assert!(matches!(e, BrokerError::Listen { .. }), "{e:?}");
    assert!(e.to_string().contains(&addr.to_string()), "{e}");
}

#[tokio::test]
async fn serve_returns_on_shutdown() {
    let broker = start("").await;
    let (_c, _ev) = connect(broker.addr, "c", None).await;
    broker.stop().await;
}
