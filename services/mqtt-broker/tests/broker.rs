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
    let broker =
        start("[[user]]\nname = \"cloud\"\npassword = \"s3cret\"\npublish = []\nsubscribe = []")
            .await;
    // The right credentials work (and prove the broker is listening).
    let (_ok, _ok_ev) = connect(broker.addr, "good", Some(("cloud", "s3cret"))).await;

    for (id, login) in [
        ("wrong-password", Some(("cloud", "nope"))),
        ("unknown-user", Some(("mallory", "s3cret"))),
        ("no-login", None),
    ] {
        let (_c, mut ev) = rumqttc::AsyncClient::new(options(broker.addr, id, login), 4);
        match tokio::time::timeout(PATIENCE, ev.poll()).await {
            Ok(Err(rumqttc::ConnectionError::ConnectionRefused(code))) => {
                assert_eq!(
                    code,
                    rumqttc::ConnectReturnCode::BadUserNamePassword,
                    "{id}"
                );
            }
            Ok(Ok(event)) => panic!("{id}: the broker must refuse the connection, got {event:?}"),
            Ok(Err(e)) => panic!("{id}: refused without CONNACK 4: {e}"),
            Err(_) => panic!("{id}: no answer within {PATIENCE:?}"),
        }
    }
    assert_eq!(
        broker
            .stats
            .value("skymesh_mqtt_refused_total", "reason=login"),
        Some(3.0)
    );
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

/// The DJI gateway's ACL (device side of `thing/product/SN1/...`), the cloud's
/// (the other side), and an auditor reading everything.
const DJI_USERS: &str = r##"
[[user]]
name = "gateway"
password = "g"
publish = ["thing/product/SN1/services_reply", "thing/product/SN1/events", "thing/product/SN1/drc/up"]
subscribe = ["thing/product/SN1/services", "thing/product/SN1/events_reply", "thing/product/SN1/drc/down"]
[[user]]
name = "cloud"
password = "c"
publish = ["thing/product/+/services", "thing/product/+/events_reply", "thing/product/+/drc/down"]
subscribe = ["thing/product/+/services_reply", "thing/product/+/events", "thing/product/+/drc/up"]
[[user]]
name = "auditor"
password = "a"
publish = []
subscribe = ["#"]
"##;

#[tokio::test]
async fn topic_acls_deliver_inside_and_disconnect_outside() {
    let broker = start(DJI_USERS).await;
    let (audit, mut audit_ev) = connect(broker.addr, "audit", Some(("auditor", "a"))).await;
    audit
        .subscribe("#", QoS::AtLeastOnce)
        .await
        .expect("subscribe");
    until_incoming(&mut audit_ev, "suback", |p| matches!(p, Packet::SubAck(_))).await;

    // Inside the ACL: the gateway's reply reaches the cloud.
    let (cloud, mut cloud_ev) = connect(broker.addr, "cloud", Some(("cloud", "c"))).await;
    cloud
        .subscribe("thing/product/+/services_reply", QoS::AtLeastOnce)
        .await
        .expect("subscribe");
    until_incoming(&mut cloud_ev, "suback", |p| matches!(p, Packet::SubAck(_))).await;
    let (gw, gw_ev) = connect(broker.addr, "gw", Some(("gateway", "g"))).await;
    let _gw_task = drive(gw_ev);
    gw.publish(
        "thing/product/SN1/services_reply",
        QoS::AtLeastOnce,
        false,
        &b"ok"[..],
    )
    .await
    .expect("publish");
    let got = next_publish(&mut cloud_ev, "the gateway's reply").await;
    assert_eq!(got.topic, "thing/product/SN1/services_reply");
    assert_eq!(
        next_publish(&mut audit_ev, "the reply, audited")
            .await
            .topic,
        "thing/product/SN1/services_reply"
    );

    // Another user reusing the gateway's client id neither takes over its
    // connection nor its session: the gateway's next reply still arrives.
    let (_imp, imp_ev) = connect(broker.addr, "gw", Some(("cloud", "c"))).await;
    let _imp_task = drive(imp_ev);
    gw.publish(
        "thing/product/SN1/services_reply",
        QoS::AtLeastOnce,
        false,
        &b"ok2"[..],
    )
    .await
    .expect("publish");
    let got = next_publish(&mut cloud_ev, "the gateway's second reply").await;
    assert_eq!(&got.payload[..], b"ok2");
    assert_eq!(
        &next_publish(&mut audit_ev, "audited").await.payload[..],
        b"ok2"
    );

    // Outside: a client of the gateway's login publishing a DRC command (the cloud's
    // topic) is disconnected and the command reaches nobody.
    let (rogue, mut rogue_ev) = connect(broker.addr, "rogue", Some(("gateway", "g"))).await;
    rogue
        .publish(
            "thing/product/SN1/drc/down",
            QoS::AtLeastOnce,
            false,
            &b"stick"[..],
        )
        .await
        .expect("queue");
    until_error(&mut rogue_ev, "publish outside the ACL").await;
    broker
        .until_metric("skymesh_mqtt_refused_total", "reason=publish_acl", 1.0)
        .await;
    // A subscription wider than the ACL: disconnected too.
    let (nosy, mut nosy_ev) = connect(broker.addr, "nosy", Some(("cloud", "c"))).await;
    nosy.subscribe("thing/product/#", QoS::AtMostOnce)
        .await
        .expect("queue");
    until_error(&mut nosy_ev, "subscribe outside the ACL").await;
    broker
        .until_metric("skymesh_mqtt_refused_total", "reason=subscribe_acl", 1.0)
        .await;

    // The next message the auditor sees is the cloud's allowed one, not the rogue's.
    let (c2, c2_ev) = connect(broker.addr, "cloud2", Some(("cloud", "c"))).await;
    let _c2_task = drive(c2_ev);
    c2.publish(
        "thing/product/SN1/services",
        QoS::AtLeastOnce,
        false,
        &b"go"[..],
    )
    .await
    .expect("publish");
    let next = next_publish(&mut audit_ev, "the cloud's request").await;
    assert_eq!(
        (next.topic.as_str(), &next.payload[..]),
        ("thing/product/SN1/services", &b"go"[..])
    );
    // Wills obey the publish ACL: refused at CONNECT (CONNACK 5).
    let mut o = options(broker.addr, "will", Some(("gateway", "g")));
    o.set_last_will(rumqttc::LastWill::new(
        "thing/product/SN1/drc/down",
        "x",
        QoS::AtMostOnce,
        false,
    ));
    let (_w, mut will_ev) = rumqttc::AsyncClient::new(o, 4);
    match tokio::time::timeout(PATIENCE, will_ev.poll()).await {
        Ok(Err(rumqttc::ConnectionError::ConnectionRefused(code))) => {
            assert_eq!(code, rumqttc::ConnectReturnCode::NotAuthorized)
        }
        other => panic!("a will outside the ACL must be refused, got {other:?}"),
    }
    broker
        .until_metric("skymesh_mqtt_refused_total", "reason=publish_acl", 2.0)
        .await;
    drop((audit, cloud, gw, c2));
    broker.stop().await;
}

#[tokio::test]
async fn topics_beyond_the_cap_are_refused_and_counted() {
    let broker = start("max_topics = 3").await;
    let (sub, mut sub_ev) = connect(broker.addr, "sub", None).await;
    sub.subscribe("cap/#", QoS::AtLeastOnce)
        .await
        .expect("subscribe");
    until_incoming(&mut sub_ev, "suback", |p| matches!(p, Packet::SubAck(_))).await;
    let (p, p_ev) = connect(broker.addr, "p", None).await;
    let _p_task = drive(p_ev);
    for t in ["cap/a", "cap/b"] {
        p.publish(t, QoS::AtLeastOnce, false, &b"x"[..])
            .await
            .expect("publish");
        assert_eq!(next_publish(&mut sub_ev, t).await.topic, t);
    }
    assert_eq!(broker.stats.value("skymesh_mqtt_topics", ""), Some(3.0));

    // A fourth topic: the publisher is disconnected, nothing delivered.
    let (over, mut over_ev) = connect(broker.addr, "over", None).await;
    over.publish("cap/c", QoS::AtLeastOnce, false, &b"x"[..])
        .await
        .expect("queue");
    until_error(&mut over_ev, "a topic beyond the cap").await;
    broker
        .until_metric("skymesh_mqtt_refused_total", "reason=topic_limit", 1.0)
        .await;
    assert_eq!(broker.stats.value("skymesh_mqtt_topics", ""), Some(3.0));
    // Known topics still flow.
    p.publish("cap/a", QoS::AtLeastOnce, false, &b"again"[..])
        .await
        .expect("publish");
    let got = next_publish(&mut sub_ev, "cap/a again").await;
    assert_eq!(
        (got.topic.as_str(), &got.payload[..]),
        ("cap/a", &b"again"[..])
    );
    drop((sub, p));
    broker.stop().await;
}
