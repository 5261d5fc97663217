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
        let version = run(bin, &["--version"]);
        let printed = String::from_utf8_lossy(&version.stdout);
        assert!(
            version.status.success() && printed.contains(env!("CARGO_PKG_VERSION")),
            "{bin} --version: {version:?}"
        );
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
        // So is a worker count out of range, a real-time priority outside
        // SCHED_FIFO's 1..=99 (0 = normal scheduling) or a CPU list that is not one;
        // an explicit good value checks, and a refusal names the variable.
        let env_cases: &[(&str, &[(&str, u8)])] = &[
            (
                "SKYMESH_TOKIO_WORKERS",
                &[("0", 64), ("17", 64), ("two", 64), ("2", 0)],
            ),
            (
                "SKYMESH_REALTIME_PRIORITY",
                &[("100", 64), ("-1", 64), ("fifo", 64), ("0", 0), ("20", 0)],
            ),
            (
                "SKYMESH_CPU_AFFINITY",
                &[("1-3", 64), ("x", 64), ("4096", 64), ("0", 0), ("0, 1", 0)],
            ),
        ];
        for (var, values) in env_cases {
            for (value, code) in *values {
                let out = Command::new(binary(bin))
                    .arg("--check-config")
                    .env("SKYMESH_DOMAIN", format!("cli{}", std::process::id()))
                    .env_remove("SKYMESH_CONFIG")
                    .env(var, value)
                    .output()
                    .unwrap();
                let err = String::from_utf8_lossy(&out.stderr);
                assert_eq!(
                    out.status.code(),
                    Some(i32::from(*code)),
                    "{bin} with {var}={value}: {err}"
                );
                if *code == 64 {
                    assert!(err.contains(var), "{bin} with {var}={value}: {err}");
                }
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
