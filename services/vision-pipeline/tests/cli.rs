//! The `skymesh-vision` binary from outside: its shipped config passes
//! `--check-config`, bad configs exit 64 naming the key, SIGTERM stops it cleanly.

use std::io::Write;
use std::process::{Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_runtime::Domain;
use tokio::process::{Child, Command};

/// How long a test waits for something that should happen (never a timing claim).
const PATIENCE: Duration = Duration::from_secs(30);

fn unique_domain() -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "viscli{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

fn config_file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().expect("temp file");
    f.write_all(text.as_bytes()).expect("write config");
    f
}

fn vision(domain: &str, config: &std::path::Path, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_skymesh-vision"))
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
        .expect("spawn skymesh-vision")
}

async fn finish(child: Child, domain: &str) -> Output {
    let out = tokio::time::timeout(PATIENCE, child.wait_with_output())
        .await
        .expect("skymesh-vision exits within patience")
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
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/vision-pipeline.toml")
}

#[tokio::test]
async fn the_shipped_config_passes_its_check() {
    let domain = unique_domain();
    let out = finish(vision(&domain, &shipped(), &["--check-config"]), &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
}

#[tokio::test]
async fn help_names_the_options() {
    let domain = unique_domain();
    let out = finish(vision(&domain, &shipped(), &["--help"]), &domain).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("--check-config"), "{help}");
}

#[tokio::test]
async fn bad_configs_exit_64_naming_the_key() {
    let cases = [
        ("[[streams]]\nname = \"far-too-long\"\n", "streams[0].name"),
        (
            "[[streams]]\nname = \"a\"\nwidth = 100\n",
            "streams[0].width",
        ),
        (
            "[[streams]]\nname = \"a\"\nlayout = 7\n",
            "streams[0].layout",
        ),
        ("streams = []\n", "streams"),
        ("[ai]\nscan_model = \"yolo\"\n", "ai.scan_model"),
        ("[capture]\ndir = \"relative\"\n", "capture.dir"),
        ("[capture]\nformat = \"gif\"\n", "capture.format"),
        (
            "[detection]\nscan_overlap = 1.5\n",
            "detection.scan_overlap",
        ),
        ("thermal_zone = \"zone0\"\n", "thermal_zone"),
        ("unknown_key = 1\n", "unknown_key"),
    ];
    for (toml, key) in cases {
        let domain = unique_domain();
        let f = config_file(toml);
        let out = finish(vision(&domain, f.path(), &["--check-config"]), &domain).await;
        assert_eq!(out.status.code(), Some(64), "{toml:?}\n{}", text(&out));
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(key),
            "{toml:?} should name {key}\n{}",
            text(&out)
        );
    }
}

#[tokio::test]
async fn sigterm_stops_it_while_no_camera_publishes() {
    let domain = unique_domain();
    let f = config_file("thermal_zone = \"none\"\n[[streams]]\nname = \"clitest\"\n");
    let mut child = vision(&domain, f.path(), &[]);
    let pid = child.id().expect("pid");
    // Ready once it logs "ready" (stderr); read until then.
    let mut stderr = child.stderr.take().expect("stderr");
    let mut seen = Vec::new();
    let ready = tokio::time::timeout(PATIENCE, async {
        use tokio::io::AsyncReadExt;
        let mut chunk = [0u8; 4096];
        loop {
            let n = stderr.read(&mut chunk).await.expect("read stderr");
            if n == 0 {
                return false;
            }
            seen.extend_from_slice(&chunk[..n]);
            if String::from_utf8_lossy(&seen).contains("ready") {
                return true;
            }
        }
    })
    .await;
    assert_eq!(ready, Ok(true), "{}", String::from_utf8_lossy(&seen));
    let status = std::process::Command::new("kill")
        .args(["-TERM", &pid.to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    let out = finish(child, &domain).await;
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}\n{}",
        text(&out),
        String::from_utf8_lossy(&seen)
    );
}
