//! The `skymesh-mqtt-broker` binary: config checks, a port in use, SIGTERM.

mod common;

use std::io::Write;
use std::process::{Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};

use common::*;
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use skymesh_runtime::Domain;
use tokio::process::{Child, Command};

fn unique_domain() -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "mqtt{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

fn config_file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().expect("temp file");
    f.write_all(text.as_bytes()).expect("write config");
    f
}

fn broker(domain: &str, config: &tempfile::NamedTempFile, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_skymesh-mqtt-broker"))
        .arg("--config")
        .arg(config.path())
        .args(extra)
        .env("SKYMESH_DOMAIN", domain)
        .env_remove("SKYMESH_IPC_CONFIG")
        .env_remove("SKYMESH_CONFIG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("spawn skymesh-mqtt-broker")
}

async fn finish(child: Child, domain: &str) -> Output {
    let out = tokio::time::timeout(PATIENCE, child.wait_with_output())
        .await
        .expect("the broker exits within patience")
        .expect("output");
    if let Ok(d) = Domain::load(domain, None) {
        d.remove_leftover_files();
    }
    out
}

fn text(out: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[tokio::test]
async fn check_config_accepts_good_and_refuses_bad_with_64() {
    let domain = unique_domain();
    let good = config_file("listen = \"127.0.0.1:1883\"\n");
    let out = finish(broker(&domain, &good, &["--check-config"]), &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));

    let bad = config_file("max_connections = 0\n");
    let out = finish(broker(&domain, &bad, &["--check-config"]), &domain).await;
    assert_eq!(out.status.code(), Some(64), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("max_connections"),
        "{}",
        text(&out)
    );
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
    let domain = unique_domain();
    let cfg = config_file(&config_toml(addr, ""));
    let out = finish(broker(&domain, &cfg, &[]), &domain).await;
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("cannot listen on") && stderr.contains(&addr.to_string()),
        "{}",
        text(&out)
    );
    assert!(!stderr.contains("panicked"), "{}", text(&out));
}

#[tokio::test]
async fn sigterm_stops_the_broker_and_closes_connections() {
    let addr = free_addr();
    let domain = unique_domain();
    let cfg = config_file(&config_toml(addr, ""));
    let child = broker(&domain, &cfg, &[]);
    let (_client, mut ev) = connect(addr, "watcher", None).await;

    let pid = child.id().expect("running");
    kill(
        Pid::from_raw(i32::try_from(pid).expect("pid")),
        Signal::SIGTERM,
    )
    .expect("SIGTERM");
    let out = finish(child, &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    // The process is gone, so the client's connection is closed.
    until_error(&mut ev, "client of the stopped broker").await;
}
