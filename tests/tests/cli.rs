//! Every process honours the command-line contract: `--help`, `--print-default-config`,
//! `--check-config` (0 good, 64 bad), and the shipped `deploy/` configs are valid.

use std::process::Command;

use skymesh_e2e::{binary, repo_root};

/// Services whose binaries `cargo test --workspace` builds (their packages have
/// integration tests of their own).
const SERVICES: &[&str] = &[
    "skymesh-vehicle-sim",
    "skymesh-autopilot-link",
    "skymesh-dji-gateway",
    "skymesh-camera",
    "skymesh-mqtt-broker",
    "skymesh-vision",
    "skymesh-digiview",
];

fn run(bin: &str, args: &[&str]) -> std::process::Output {
    Command::new(binary(bin))
        .args(args)
        .env("SKYMESH_DOMAIN", format!("cli{}", std::process::id()))
        .env_remove("SKYMESH_CONFIG")
        .output()
        .unwrap()
}

#[test]
fn every_service_has_help_and_a_default_config_that_checks() {
    let dir = tempfile::tempdir().unwrap();
    for bin in SERVICES {
        let help = run(bin, &["--help"]);
        assert!(help.status.success(), "{bin} --help");
        let text = String::from_utf8_lossy(&help.stdout);
        for flag in ["--config", "--check-config", "--print-default-config"] {
            assert!(text.contains(flag), "{bin} --help lacks {flag}:\n{text}");
        }

        let default = run(bin, &["--print-default-config"]);
        assert!(default.status.success());
        let path = dir.path().join(format!("{bin}.toml"));
        std::fs::write(&path, &default.stdout).unwrap();
        let check = run(bin, &["--config", path.to_str().unwrap(), "--check-config"]);
        assert_eq!(
            check.status.code(),
            Some(0),
            "{bin}: {}",
            String::from_utf8_lossy(&check.stderr)
        );

        // The shipped file under deploy/ is the same default and also checks.
        let name = match *bin {
            "skymesh-vision" => "vision-pipeline",
            "skymesh-digiview" => "digiview-gateway",
            other => other.trim_start_matches("skymesh-"),
        };
        let shipped = repo_root().join(format!("deploy/{name}.toml"));
        let check = run(
            bin,
            &["--config", shipped.to_str().unwrap(), "--check-config"],
        );
        assert_eq!(
            check.status.code(),
            Some(0),
            "{}: {}",
            shipped.display(),
            String::from_utf8_lossy(&check.stderr)
        );
    }
}

#[test]
fn bad_configuration_exits_64_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str)] = &[
        ("unknown key", "this_key_does_not_exist = 1\n"),
        ("not toml", "= = =\n"),
    ];
    for bin in SERVICES {
        for (what, text) in cases {
            let path = dir.path().join("bad.toml");
            std::fs::write(&path, text).unwrap();
            let out = run(bin, &["--config", path.to_str().unwrap(), "--check-config"]);
            assert_eq!(out.status.code(), Some(64), "{bin} with {what}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                err.contains("bad configuration"),
                "{bin} with {what}: {err}"
            );
        }
        let missing = run(
            bin,
            &["--config", "/nonexistent/skymesh.toml", "--check-config"],
        );
        assert_eq!(missing.status.code(), Some(64), "{bin} with a missing file");
        // An invalid domain is a configuration error too.
        let out = Command::new(binary(bin))
            .arg("--check-config")
            .env("SKYMESH_DOMAIN", "bad/domain")
            .output()
            .unwrap();
        assert_eq!(
            out.status.code(),
            Some(64),
            "{bin} with a bad SKYMESH_DOMAIN"
        );
        // So is a worker count out of range; an explicit good one checks.
        for (workers, code) in [("0", 64), ("17", 64), ("two", 64), ("2", 0)] {
            let out = Command::new(binary(bin))
                .arg("--check-config")
                .env("SKYMESH_DOMAIN", format!("cli{}", std::process::id()))
                .env_remove("SKYMESH_CONFIG")
                .env("SKYMESH_TOKIO_WORKERS", workers)
                .output()
                .unwrap();
            assert_eq!(
                out.status.code(),
                Some(code),
                "{bin} with SKYMESH_TOKIO_WORKERS={workers}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        // And a real-time priority outside SCHED_FIFO's 1..=99 (0 = normal scheduling).
        for (priority, code) in [("100", 64), ("-1", 64), ("fifo", 64), ("0", 0), ("20", 0)] {
            let out = Command::new(binary(bin))
                .arg("--check-config")
                .env("SKYMESH_DOMAIN", format!("cli{}", std::process::id()))
                .env_remove("SKYMESH_CONFIG")
                .env("SKYMESH_REALTIME_PRIORITY", priority)
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(
                out.status.code(),
                Some(code),
                "{bin} with SKYMESH_REALTIME_PRIORITY={priority}: {err}"
            );
            if code == 64 {
                assert!(err.contains("SKYMESH_REALTIME_PRIORITY"), "{bin}: {err}");
            }
        }
        for (cpus, code) in [("1-3", 64), ("x", 64), ("4096", 64), ("0", 0), ("0, 1", 0)] {
            let out = Command::new(binary(bin))
                .arg("--check-config")
                .env("SKYMESH_DOMAIN", format!("cli{}", std::process::id()))
                .env_remove("SKYMESH_CONFIG")
                .env("SKYMESH_CPU_AFFINITY", cpus)
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(
                out.status.code(),
                Some(code),
                "{bin} with SKYMESH_CPU_AFFINITY={cpus}: {err}"
            );
            if code == 64 {
                assert!(err.contains("SKYMESH_CPU_AFFINITY"), "{bin}: {err}");
            }
        }
    }
}

#[test]
fn supervisor_checks_its_config() {
    let shipped = repo_root().join("deploy/skymesh.toml");
    let out = run(
        "skymesh",
        &[
            "up",
            "--config",
            shipped.to_str().unwrap(),
            "--check-config",
        ],
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("skymesh.toml");
    std::fs::write(
        &bad,
        "[[service]]\nname = \"a\"\nbinary = \"x\"\nafter = [\"nobody\"]\n",
    )
    .unwrap();
    let out = run(
        "skymesh",
        &["up", "--config", bad.to_str().unwrap(), "--check-config"],
    );
    assert_eq!(
        out.status.code(),
        Some(64),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let help = run("skymesh", &["--help"]);
    assert!(help.status.success());
}
