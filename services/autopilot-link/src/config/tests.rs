//! Tests of the configuration: the shipped file, defaults, each table's checks.

use super::*;
use skymesh_runtime::config::parse;

fn parse_str(text: &str) -> Result<Settings, ConfigError> {
    parse::<RawConfig>(text, "test")
}

#[test]
fn the_shipped_file_parses_and_matches_the_built_in_defaults() {
    let shipped = parse_str(RawConfig::DEFAULT_TOML).unwrap();
    let mut built_in = RawConfig::default().validate().unwrap();
    // The one difference: the shipped (embedded mesh) config serves the vision
    // pipeline's virtual cameras; a config without `[vision]` does not (a fleet's
    // other links have no pipeline).
    assert!(shipped.vision.enabled && !built_in.vision.enabled);
    built_in.vision.enabled = true;
    assert_eq!(shipped, built_in);
    assert_eq!(
        shipped.connection,
        Endpoint::TcpOut {
            host: "127.0.0.1".into(),
            port: 5760
        }
    );
    assert_eq!(shipped.system_id, shipped.vehicle_id);
    assert_eq!(shipped.command_timeout, Duration::from_millis(1500));
    assert_eq!(shipped.stop_confirm_timeout, Duration::from_secs(5));
    assert_eq!(shipped.rates.attitude_hz, 50.0);
    assert_eq!(shipped.rates.ground_attitude_hz, Some(10.0));
    assert_eq!(shipped.rates.gimbal_attitude_hz, Some(10.0));
    assert_eq!(shipped.rates.heartbeat_hz, Some(5.0));
}

#[test]
fn an_empty_file_is_the_defaults() {
    assert_eq!(
        parse_str("").unwrap(),
        RawConfig::default().validate().unwrap()
    );
}

#[test]
fn router_endpoints_default_to_a_local_ground_station_and_are_checked() {
    let s = parse_str("").unwrap();
    assert_eq!(
        s.endpoints,
        vec![Endpoint::UdpOut {
            host: "127.0.0.1".into(),
            port: 14550
        }]
    );
    let s = parse_str(
        r#"endpoints = ["udpout:127.0.0.1:14550", "udpin:127.0.0.1:14560", "tcpin:127.0.0.1:5790", "tcpout:gcs.local:5760"]"#,
    )
    .unwrap();
    assert_eq!(s.endpoints.len(), 4);
    assert_eq!(
        s.endpoints[2],
        Endpoint::TcpIn("127.0.0.1:5790".parse().unwrap())
    );
    assert!(parse_str("endpoints = []").unwrap().endpoints.is_empty());
    assert!(Settings::with_connection(s.connection.clone())
        .endpoints
        .is_empty());
    for bad in [
        r#"endpoints = ["udp:127.0.0.1:14550"]"#,
        r#"endpoints = ["udpout:127.0.0.1:0"]"#,
        r#"endpoints = ["serial:/dev/ttyUSB0:57600"]"#,
        r#"endpoints = ["udpin:127.0.0.1:14560", "udpin:127.0.0.1:14560"]"#,
        r#"endpoints = ["tcpout:127.0.0.1:5760"]"#,
        r#"endpoints = ["udpin:127.0.0.1:1", "udpin:127.0.0.1:2", "udpin:127.0.0.1:3", "udpin:127.0.0.1:4", "udpin:127.0.0.1:5", "udpin:127.0.0.1:6", "udpin:127.0.0.1:7", "udpin:127.0.0.1:8", "udpin:127.0.0.1:9"]"#,
    ] {
        let e = parse_str(bad).unwrap_err();
        assert!(e.to_string().contains("endpoints"), "{bad}: {e}");
    }
}

/// A key file in the temp dir, removed on drop.
struct KeyFile(std::path::PathBuf);

impl KeyFile {
    fn new(content: &str) -> KeyFile {
        use std::sync::atomic::{AtomicU32, Ordering};
        static N: AtomicU32 = AtomicU32::new(0);
        let path = std::env::temp_dir().join(format!(
            "apl-signing-{}-{}.key",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::write(&path, content).unwrap();
        KeyFile(path)
    }
}

impl Drop for KeyFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

const HEX_KEY: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

#[test]
fn signing_is_off_by_default_and_its_keys_are_checked() {
    assert_eq!(parse_str("").unwrap().signing, None);
    assert_eq!(parse_str(RawConfig::DEFAULT_TOML).unwrap().signing, None);
    let good = KeyFile::new(&format!("{HEX_KEY}\n"));
    let config = |key_file: &str, signed: &str| {
        format!(
            "endpoints = [\"udpout:127.0.0.1:14550\", \"udpin:0.0.0.0:14560\", \"tcpin:127.0.0.1:5790\"]\n\
             [signing]\nkey_file = \"{key_file}\"\nendpoints = [{signed}]\n"
        )
    };
    let path = good.0.display().to_string();
    let s = parse_str(&config(
        &path,
        r#""udpin:0.0.0.0:14560", "tcpin:127.0.0.1:5790""#,
    ))
    .unwrap();
    let signing = s.signing.unwrap();
    assert_eq!(signing.endpoints, vec![1, 2]);
    assert_eq!(
        signing.key,
        mavlink_frame::signing::SigningKey::from_hex(HEX_KEY).unwrap()
    );
    // Refused with the key named, and never with the key's bytes in the message.
    let short = KeyFile::new(&HEX_KEY[..40]);
    let not_hex = KeyFile::new(&HEX_KEY.replace('a', "x"));
    let zero = KeyFile::new(&"0".repeat(64));
    for (text, field) in [
        (
            config(&short.0.display().to_string(), r#""udpin:0.0.0.0:14560""#),
            "signing.key_file",
        ),
        (
            config(&not_hex.0.display().to_string(), r#""udpin:0.0.0.0:14560""#),
            "signing.key_file",
        ),
        (
            config(&zero.0.display().to_string(), r#""udpin:0.0.0.0:14560""#),
            "signing.key_file",
        ),
        (
            config("/nonexistent/skymesh.key", r#""udpin:0.0.0.0:14560""#),
            "signing.key_file",
        ),
        (config("", r#""udpin:0.0.0.0:14560""#), "signing.key_file"),
        (config(&path, ""), "signing.endpoints"),
        (
            config(&path, r#""udpin:0.0.0.0:14561""#),
            "signing.endpoints",
        ),
        (
            config(&path, r#""udpin:0.0.0.0:14560", "udpin:0.0.0.0:14560""#),
            "signing.endpoints",
        ),
        (config(&path, r#""bogus""#), "signing.endpoints"),
        (
            "[signing]\nendpoints = [\"udpout:127.0.0.1:14550\"]".to_string(),
            "signing.key_file",
        ),
    ] {
        let e = parse_str(&text).unwrap_err();
        assert!(e.to_string().contains(field), "{text}: {e}");
        assert!(!e.to_string().contains("0a0b0c"), "{e}");
    }
    assert!(matches!(
        parse_str("[signing]\nkey = \"00\"").unwrap_err(),
        ConfigError::Parse { .. }
    ));
}

#[test]
fn connection_strings_parse() {
    let p = |s: &str| Endpoint::parse("connection", s);
    assert_eq!(
        p("serial:/dev/ttyACM0:115200").unwrap(),
        Endpoint::Serial {
            device: "/dev/ttyACM0".into(),
            baud: 115200
        }
    );
    assert_eq!(
        p("tcpout:sitl.local:5762").unwrap(),
        Endpoint::TcpOut {
            host: "sitl.local".into(),
            port: 5762
        }
    );
    assert_eq!(
        p("udpin:0.0.0.0:14550").unwrap(),
        Endpoint::UdpIn("0.0.0.0:14550".parse().unwrap())
    );
    assert!(matches!(
        p("udpout:127.0.0.1:14555").unwrap(),
        Endpoint::UdpOut { port: 14555, .. }
    ));
    assert!(matches!(
        p("tcpin:127.0.0.1:5770").unwrap(),
        Endpoint::TcpIn(_)
    ));
    let v6 = p("tcpout:[::1]:5760").unwrap();
    assert_eq!(
        v6,
        Endpoint::TcpOut {
            host: "::1".into(),
            port: 5760
        }
    );
    assert_eq!(v6.to_string(), "tcpout:[::1]:5760");
    for bad in [
        "",
        "tcp:127.0.0.1:5760",
        "tcpout:127.0.0.1",
        "tcpout::5760",
        "tcpout:127.0.0.1:0",
        "tcpout:127.0.0.1:99999",
        "udpin:nohost:14550",
        "serial:/dev/ttyACM0",
        "serial::57600",
        "serial:/dev/ttyACM0:fast",
        "file:/tmp/x.tlog",
    ] {
        let e = p(bad).unwrap_err();
        assert!(e.to_string().contains("connection"), "{bad}: {e}");
    }
}

#[test]
fn out_of_range_values_are_refused_with_the_field_named() {
    for (text, field) in [
        ("vehicle_id = 0", "vehicle_id"),
        ("vehicle_id = 256", "vehicle_id"),
        ("system_id = 300", "system_id"),
        ("link_timeout_s = 0.1", "link_timeout_s"),
        ("command_timeout_s = nan", "command_timeout_s"),
        ("command_retries = 9", "command_retries"),
        ("stop_confirm_timeout_s = 0.5", "stop_confirm_timeout_s"),
        (
            "reconnect_min_s = 2.0\nreconnect_max_s = 1.0",
            "reconnect_max_s",
        ),
        ("silence_reconnect_s = 0.5", "silence_reconnect_s"),
        ("attitude_hz = 500.0", "attitude_hz"),
        ("ground_attitude_hz = 500.0", "ground_attitude_hz"),
        ("ground_attitude_hz = -1", "ground_attitude_hz"),
        ("ekf_status_hz = 0.01", "ekf_status_hz"),
        ("gps_raw_hz = inf", "gps_raw_hz"),
        ("gimbal_attitude_hz = 0.05", "gimbal_attitude_hz"),
        ("gimbal_attitude_hz = -1", "gimbal_attitude_hz"),
        ("heartbeat_hz = 0.5", "heartbeat_hz"),
        ("heartbeat_hz = 60", "heartbeat_hz"),
        ("heartbeat_hz = nan", "heartbeat_hz"),
        (
            "[arbiter]\nsetpoint_max_age_ms = 5",
            "arbiter.setpoint_max_age_ms",
        ),
        (
            "[arbiter]\nsetpoint_max_age_ms = 3000",
            "arbiter.setpoint_max_age_ms",
        ),
        (
            "[arbiter]\nfence_deceleration_mps2 = nan",
            "arbiter.fence_deceleration_mps2",
        ),
        (
            "[arbiter.setpoint_max_age_by_source]\ndrone = 100",
            "arbiter.setpoint_max_age_by_source.drone",
        ),
        (
            "[arbiter]\nservo_channels_in_flight = [0]",
            "arbiter.servo_channels_in_flight",
        ),
        (
            "[arbiter]\nservo_channels_in_flight = [33]",
            "arbiter.servo_channels_in_flight",
        ),
        (
            "[arbiter]\nservo_channels_in_flight = [9, 10, 9]",
            "arbiter.servo_channels_in_flight",
        ),
    ] {
        let e = parse_str(text).unwrap_err();
        assert!(e.to_string().contains(field), "{text}: {e}");
    }
    assert!(matches!(
        parse_str("bogus = 1").unwrap_err(),
        ConfigError::Parse { .. }
    ));
    // Integers are fine where seconds and rates are expected.
    let s = parse_str("system_id = 42\nsilence_reconnect_s = 0\nattitude_hz = 20").unwrap();
    assert_eq!(s.system_id, 42);
    assert_eq!(s.rates.attitude_hz, 20.0);
    assert_eq!(s.silence_reconnect, None);
    assert_eq!(
        parse_str("gimbal_attitude_hz = 0")
            .unwrap()
            .rates
            .gimbal_attitude_hz,
        None,
        "0 = not requested"
    );
    assert_eq!(
        parse_str("heartbeat_hz = 0").unwrap().rates.heartbeat_hz,
        None,
        "0 = the autopilot's own rate"
    );
    assert!(parse_str("")
        .unwrap()
        .arbiter
        .servo_channels_in_flight
        .is_empty());
    assert_eq!(
        parse_str("[arbiter]\nservo_channels_in_flight = [32, 9, 1]")
            .unwrap()
            .arbiter
            .servo_channels_in_flight,
        [1, 9, 32],
        "sorted"
    );
    let s = parse_str(
        "[arbiter]\nauthority_timeout_s = 2\n[arbiter.setpoint_max_age_by_source]\nvision = 200",
    )
    .unwrap();
    assert_eq!(s.arbiter.authority_timeout, Duration::from_secs(2));
    assert_eq!(
        s.arbiter.setpoint_max_age_by_source,
        vec![(
            skymesh_ipc_types::CommandSource::Vision,
            Duration::from_millis(200)
        )]
    );
}

#[test]
fn the_state_file_defaults_per_vehicle_under_the_state_directory_or_tmp() {
    assert_eq!(
        default_state_file(Some("/var/lib/skymesh:/other"), Some("d"), 3),
        PathBuf::from("/var/lib/skymesh/autopilot-link-3.json")
    );
    assert_eq!(
        default_state_file(None, Some("e2e1"), 1),
        PathBuf::from("/tmp/skymesh-e2e1/autopilot-link-1.json")
    );
    assert_eq!(
        default_state_file(Some(""), None, 2),
        PathBuf::from("/tmp/skymesh-skymesh/autopilot-link-2.json")
    );
    let s = parse_str("state_file = \"/x/link.json\"\n[arbiter]\nmax_home_move_m = 20").unwrap();
    assert_eq!(s.state_file, PathBuf::from("/x/link.json"));
    assert_eq!(s.arbiter.max_home_move_m, 20.0);
    let e = parse_str("state_file = \"/\"").unwrap_err();
    assert!(e.to_string().contains("state_file"), "{e}");
    let e = parse_str("[arbiter]\nmax_home_alt_change_m = -1").unwrap_err();
    assert!(
        e.to_string().contains("arbiter.max_home_alt_change_m"),
        "{e}"
    );
}

#[test]
fn flight_logs_are_off_unless_a_tlog_table_is_given_and_its_values_are_checked() {
    assert_eq!(parse_str("").unwrap().tlog, None);
    assert_eq!(parse_str(RawConfig::DEFAULT_TOML).unwrap().tlog, None);
    let s = parse_str("vehicle_id = 4\n[tlog]\ndir = \"/var/log/skymesh/tlog\"")
        .unwrap()
        .tlog
        .unwrap();
    assert_eq!(s.dir, PathBuf::from("/var/log/skymesh/tlog"));
    assert_eq!(s.mode, crate::tlog::TlogMode::Arming);
    assert_eq!(s.vehicle_id, 4);
    assert_eq!(s.limits.max_files, 100);
    assert_eq!(s.limits.max_total, 2_000_000_000);
    assert_eq!(s.limits.min_free, 500_000_000);
    assert_eq!(s.max_file_bytes, 500_000_000);
    assert_eq!(s.queue_frames, 4096);
    assert_eq!(s.flush_interval, Duration::from_secs(1));
    let s = parse_str("[tlog]\nmode = \"connection\"\nmax_files = 3\nmin_free_mb = 0")
        .unwrap()
        .tlog
        .unwrap();
    assert_eq!(s.mode, crate::tlog::TlogMode::Connection);
    assert_eq!((s.limits.max_files, s.limits.min_free), (3, 0));
    assert_eq!(
        default_tlog_dir(Some("/var/log/skymesh:/x"), Some("d")),
        PathBuf::from("/var/log/skymesh/tlog")
    );
    assert_eq!(
        default_tlog_dir(None, Some("e2e7")),
        PathBuf::from("/tmp/skymesh-e2e7/tlog")
    );
    let file = tempfile::NamedTempFile::new().unwrap();
    let not_a_dir = format!("[tlog]\ndir = \"{}\"", file.path().display());
    for (bad, field) in [
        ("[tlog]\nmode = \"always\"", "tlog.mode"),
        ("[tlog]\ndir = \"relative/logs\"", "tlog.dir"),
        (not_a_dir.as_str(), "tlog.dir"),
        ("[tlog]\nmax_files = 0", "tlog.max_files"),
        ("[tlog]\nmax_total_mb = 0", "tlog.max_total_mb"),
        (
            "[tlog]\nmax_total_mb = 10\nmax_file_mb = 11",
            "tlog.max_file_mb",
        ),
        ("[tlog]\nmin_free_mb = -1", "tlog.min_free_mb"),
        ("[tlog]\nqueue_frames = 8", "tlog.queue_frames"),
        ("[tlog]\nflush_s = 0", "tlog.flush_s"),
        ("[tlog]\nflush_s = nan", "tlog.flush_s"),
        ("[tlog]\nrotate = true", "rotate"),
    ] {
        let e = parse_str(bad).unwrap_err();
        assert!(e.to_string().contains(field), "{bad}: {e}");
    }
}

#[test]
fn the_shipped_commented_tlog_table_parses_to_the_defaults() {
    let shipped = RawConfig::DEFAULT_TOML;
    let at = shipped
        .find("\n# [tlog]\n")
        .expect("a commented [tlog] table");
    let mut text = shipped[..at].to_string();
    text.push_str("\n[tlog]\n");
    // Its commented `key = value` lines, uncommented.
    for line in shipped[at..].lines().filter_map(|l| l.strip_prefix("# ")) {
        if line
            .split_once(" = ")
            .is_some_and(|(k, _)| !k.contains(' '))
        {
            text.push_str(line);
            text.push('\n');
        }
    }
    let s = parse_str(&text).unwrap().tlog.unwrap();
    let defaults = RawTlog {
        dir: "/var/log/skymesh/tlog".into(),
        ..RawTlog::default()
    };
    assert_eq!(s, defaults.validate(1).unwrap());
}
