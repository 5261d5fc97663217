//! The `skymesh-dji-gateway` binary from outside: its shipped config, bad configs
//! refused with exit 64 naming the key, and a graceful SIGTERM while the cloud
//! broker is unreachable (the gateway keeps retrying, never exits on its own).

use std::io::Write;
use std::process::{Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use skymesh_runtime::Domain;
use tokio::process::{Child, Command};

/// How long a test waits for something that should happen (never a timing claim).
const PATIENCE: Duration = Duration::from_secs(20);

fn unique_domain() -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "djicli{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

fn config_file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().expect("temp file");
    f.write_all(text.as_bytes()).expect("write config");
    f
}

fn gateway(domain: &str, config: &std::path::Path, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_skymesh-dji-gateway"))
        .arg("--config")
        .arg(config)
        .args(extra)
        .env("SKYMESH_DOMAIN", domain)
        .env_remove("SKYMESH_IPC_CONFIG")
        .env_remove("SKYMESH_CONFIG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("spawn skymesh-dji-gateway")
}

async fn finish(child: Child, domain: &str) -> Output {
    let out = tokio::time::timeout(PATIENCE, child.wait_with_output())
        .await
        .expect("the gateway exits within patience")
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

fn shipped() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/dji-gateway.toml")
}

#[tokio::test]
async fn the_shipped_config_passes_its_check() {
    let domain = unique_domain();
    let out = finish(gateway(&domain, &shipped(), &["--check-config"]), &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
}

#[tokio::test]
async fn bad_configs_exit_64_naming_the_key() {
    let cases = [
        ("gateway_sn = \"\"\n", "gateway_sn"),
        ("gateway_sn = \"dock 1/#\"\n", "gateway_sn"),
        ("[broker]\naddress = \"no-port\"\n", "address"),
        ("[broker]\ntls = true\n", "ca_file"),
        (
            "[broker]\nreconnect_initial_ms = 5000\nreconnect_max_ms = 100\n",
            "reconnect",
        ),
        ("[drc]\nstick_max_age_ms = 5\n", "stick_max_age_ms"),
        ("[drc]\nheartbeat_timeout_s = 0\n", "heartbeat_timeout_s"),
        (
            "[poi]\nmax_circle_speed_mps = -1.0\n",
            "max_circle_speed_mps",
        ),
        ("[payload]\npayload_index = \"camera\"\n", "payload_index"),
        ("unknown_key = 1\n", "unknown_key"),
    ];
    for (toml, key) in cases {
        let domain = unique_domain();
        let f = config_file(toml);
        let out = finish(gateway(&domain, f.path(), &["--check-config"]), &domain).await;
        assert_eq!(out.status.code(), Some(64), "{toml:?}\n{}", text(&out));
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(key),
            "{toml:?} should name {key}\n{}",
            text(&out)
        );
    }
}

#[tokio::test]
async fn sigterm_stops_it_while_the_broker_is_unreachable() {
    // A port nothing listens on: the gateway retries with backoff, forever.
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind port 0");
        l.local_addr().expect("addr").port()
    };
    let domain = unique_domain();
    let f = config_file(&format!(
        "gateway_sn = \"CLI-TEST\"\n[broker]\naddress = \"127.0.0.1:{port}\"\nreconnect_initial_ms = 50\nreconnect_max_ms = 200\n"
    ));
    let mut child = gateway(&domain, f.path(), &[]);
    // Let it start and fail a few connection attempts.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    assert!(
        matches!(child.try_wait(), Ok(None)),
        "the gateway must keep running without a broker"
    );
    let pid = child.id().expect("pid") as i32;
    kill(Pid::from_raw(pid), Signal::SIGTERM).expect("SIGTERM");
    let out = finish(child, &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
}
