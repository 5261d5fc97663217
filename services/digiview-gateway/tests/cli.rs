//! The `skymesh-digiview` binary from outside: its shipped config, bad configs
//! refused with exit 64 naming the key, and a graceful SIGTERM.

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
        "dvcli{}x{}",
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
    Command::new(env!("CARGO_BIN_EXE_skymesh-digiview"))
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
        .expect("spawn skymesh-digiview")
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
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/digiview-gateway.toml")
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
        ("listen = \"nowhere\"\n", "listen"),
        ("write_allowed = [\"300.1.1.1\"]\n", "write_allowed"),
        ("max_clients = 0\n", "max_clients"),
        ("roi_rel_frame = 7\n", "roi_rel_frame"),
        ("set_timeout_ms = -1\n", "set_timeout_ms"),
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
async fn sigterm_stops_it_cleanly() {
    let domain = unique_domain();
    let f = config_file("listen = \"127.0.0.1:0\"\n");
    let mut child = gateway(&domain, f.path(), &[]);
    // Let it start (it runs without a pipeline: GETs would be UNKNOWN).
    tokio::time::sleep(Duration::from_millis(1000)).await;
    assert!(
        matches!(child.try_wait(), Ok(None)),
        "the gateway must keep running without a pipeline"
    );
    let pid = child.id().expect("pid") as i32;
    kill(Pid::from_raw(pid), Signal::SIGTERM).expect("SIGTERM");
    let out = finish(child, &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
}
