//! The `skymesh-mqtt-broker` binary: config checks, a port in use, SIGTERM.

mod common;

use common::*;
use skymesh_test_support::{text, ServiceCli};
use tokio::process::Command;

fn broker() -> ServiceCli {
    ServiceCli::new(env!("CARGO_BIN_EXE_skymesh-mqtt-broker"), "mqtt")
}

#[tokio::test]
async fn check_config_accepts_good_and_refuses_bad_with_64() {
    let out = broker()
        .run_toml("listen = \"127.0.0.1:1883\"\n", &["--check-config"])
        .await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));

    broker()
        .expect_config_error("max_connections = 0\n", "max_connections")
        .await;
}

#[tokio::test]
async fn a_listener_reachable_from_elsewhere_needs_logins() {
    // Anonymous clients on every address: refused (64) with the reason.
    let out = broker()
        .run_toml("listen = \"0.0.0.0:1883\"\n", &["--check-config"])
        .await;
    assert_eq!(out.status.code(), Some(64), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("listen") && stderr.contains("no [[user]] is configured"),
        "{}",
        text(&out)
    );
    // With a login (and its ACL) it is accepted.
    let out = broker()
        .run_toml(
            "listen = \"0.0.0.0:1883\"\n[[user]]\nname = \"gw\"\npassword = \"p\"\n\
             publish = [\"thing/product/SN1/services_reply\"]\n\
             subscribe = [\"thing/product/SN1/services\"]\n",
            &["--check-config"],
        )
        .await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
}

/// MQTT 3.1.1 CONNECT (clean session, keep-alive 60 s, no login) for `id`.
fn connect_packet(id: &str) -> Vec<u8> {
    let mut body = vec![0, 4, b'M', b'Q', b'T', b'T', 4, 0x02, 0, 60];
    body.extend_from_slice(&(id.len() as u16).to_be_bytes());
    body.extend_from_slice(id.as_bytes());
    let mut p = vec![0x10, body.len() as u8];
    p.extend(body);
    p
}

/// Connects `id`, reads CONNACK (retrying while the broker is not up yet), returns
/// the connection.
async fn raw_client(addr: std::net::SocketAddr, id: &str) -> tokio::net::TcpStream {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    tokio::time::timeout(PATIENCE, async {
        loop {
            let Ok(mut s) = tokio::net::TcpStream::connect(addr).await else {
                tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                continue;
            };
            s.write_all(&connect_packet(id)).await.expect("CONNECT");
            let mut ack = [0u8; 4];
            s.read_exact(&mut ack).await.expect("CONNACK");
            assert_eq!(ack, [0x20, 2, 0, 0], "CONNACK accepted");
            return s;
        }
    })
    .await
    .expect("connected within patience")
}

/// A client that says DISCONNECT and a SIGTERM: a correct start and stop logs no
/// WARN or ERROR. (rumqttd 0.20 logs `no-connection id 0 is already gone` or
/// `router-drop` at ERROR for every DISCONNECT it is sent; the gate closes instead.)
#[tokio::test]
async fn a_clean_disconnect_and_stop_log_no_error() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let addr = free_addr();
    let running = broker().spawn_toml(&config_toml(addr, ""), &[]);
    for id in ["first", "second"] {
        let mut c = raw_client(addr, id).await;
        c.write_all(&[0xE0, 0]).await.expect("DISCONNECT");
        // The broker closes the connection once rumqttd has let it go.
        let mut rest = Vec::new();
        tokio::time::timeout(PATIENCE, c.read_to_end(&mut rest))
            .await
            .expect("closed within patience")
            .expect("clean close");
        assert!(rest.is_empty(), "{rest:?}");
    }
    // rumqttd's router handles events in order: this CONNACK comes after it
    // handled both disconnections (and logged whatever it logs about them).
    let _last = raw_client(addr, "last").await;
    running.sigterm();
    let out = running.finish().await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let bad: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("ERROR") || l.contains("WARN"))
        .collect();
    assert!(bad.is_empty(), "a clean run logged:\n{}", bad.join("\n"));
    assert!(stderr.contains("ready"), "{}", text(&out));
}

#[tokio::test]
async fn the_default_config_is_printed() {
    let out = Command::new(env!("CARGO_BIN_EXE_skymesh-mqtt-broker"))
        .arg("--print-default-config")
        .output()
        .await
        .expect("run");
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        skymesh_mqtt_broker::config::DEFAULT_CONFIG_TOML
    );
}

#[tokio::test]
async fn a_port_in_use_is_a_clear_failure() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = taken.local_addr().expect("addr");
    let out = broker().run_toml(&config_toml(addr, ""), &[]).await;
    // 75 (`exit::ADDR_IN_USE`): not a bad config, retried with backoff.
    assert_eq!(
        out.status.code(),
        Some(i32::from(skymesh_runtime::exit::ADDR_IN_USE)),
        "{}",
        text(&out)
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("cannot listen on")
            && stderr.contains(&addr.to_string())
            && stderr.matches("Address already in use").count() == 1,
        "{}",
        text(&out)
    );
    assert!(!stderr.contains("panicked"), "{}", text(&out));
}

#[tokio::test]
async fn sigterm_stops_the_broker_and_closes_connections() {
    let addr = free_addr();
    let running = broker().spawn_toml(&config_toml(addr, ""), &[]);
    let (_client, mut ev) = connect(addr, "watcher", None).await;

    running.sigterm();
    let out = running.finish().await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    // The process is gone, so the client's connection is closed.
    until_error(&mut ev, "client of the stopped broker").await;
}
