//! The `skymesh-vision` binary from outside: its shipped config passes
//! `--check-config`, bad configs exit 64 naming the key, SIGTERM stops it cleanly.

use std::time::Duration;

use skymesh_test_support::{shipped_config, text, Ready, ServiceCli};

fn vision() -> ServiceCli {
    ServiceCli::new(env!("CARGO_BIN_EXE_skymesh-vision"), "viscli")
        .with_patience(Duration::from_secs(30))
}

fn shipped() -> std::path::PathBuf {
    shipped_config("vision-pipeline.toml")
}

#[tokio::test]
async fn the_shipped_config_passes_its_check() {
    vision().expect_config_ok(&shipped()).await;
}

#[tokio::test]
async fn help_names_the_options() {
    let out = vision().run(&shipped(), &["--help"]).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("--check-config"), "{help}");
}

#[tokio::test]
async fn bad_configs_exit_64_naming_the_key() {
    vision()
        .expect_config_errors(&[
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
        ])
        .await;
}

#[tokio::test]
async fn sigterm_stops_it_while_no_camera_publishes() {
    // Ready once it logs "ready" (stderr).
    vision()
        .sigterm_exits_cleanly(
            "thermal_zone = \"none\"\n[[streams]]\nname = \"clitest\"\n",
            Ready::StderrContains("ready"),
        )
        .await;
}
