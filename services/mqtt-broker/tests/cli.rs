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
