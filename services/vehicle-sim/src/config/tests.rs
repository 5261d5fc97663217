//! Parsing and validating the whole file: defaults, the shipped file, field errors.

use std::net::SocketAddr;
use std::time::Duration;

use super::*;

#[test]
fn defaults_validate() {
    let s = RawConfig::default().validate().expect("defaults are valid");
    assert_eq!(
        s.endpoint,
        Endpoint::Tcp(SocketAddr::from(([127, 0, 0, 1], 5760)))
    );
    assert_eq!(s.system_id, 1);
    assert_eq!(s.streams.attitude, Some(Duration::from_millis(100)));
    assert_eq!(s.streams.gimbal_attitude, Some(Duration::from_millis(100)));
    assert_eq!(s.streams.gopro_heartbeat, Some(Duration::from_secs(1)));
    assert_eq!(s.streams.servo_output, Some(Duration::from_millis(500)));
    assert!(s.vehicle.gopro);
    let off = RawConfig::from_toml("servo_output_hz = 0")
        .and_then(RawConfig::validate)
        .expect("valid");
    assert_eq!(off.streams.servo_output, None);
    let e = RawConfig::from_toml("servo_output_hz = 101")
        .and_then(RawConfig::validate)
        .unwrap_err();
    assert!(e.to_string().contains("servo_output_hz"), "{e}");
}

#[test]
fn gopro_off_and_gimbal_keys() {
    let s = RawConfig::from_toml("gopro = false\ngimbal_attitude_hz = 0\n")
        .and_then(RawConfig::validate)
        .expect("valid");
    assert!(!s.vehicle.gopro);
    assert_eq!(s.streams.gopro_heartbeat, None);
    assert_eq!(s.streams.gimbal_attitude, None);
    let e = RawConfig {
        gimbal_slew_rate_dps: 0.0,
        ..RawConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(e.to_string().contains("gimbal_slew_rate_dps"), "{e}");
}

#[test]
fn shipped_file_parses_and_matches_defaults() {
    let raw = RawConfig::from_toml(DEFAULT_CONFIG_TOML).expect("shipped config parses");
    let s = raw.validate().expect("shipped config validates");
    let d = RawConfig::default().validate().expect("defaults are valid");
    assert_eq!(s.endpoint, d.endpoint);
    assert_eq!(s.system_id, d.system_id);
    assert_eq!(s.vehicle, d.vehicle);
    assert_eq!(s.streams, d.streams);
    assert_eq!(s.max_clients, d.max_clients);
    assert_eq!(s.swarm, d.swarm);
}

#[test]
fn raw_defaults_match_model_defaults() {
    let s = RawConfig::default().validate().expect("defaults are valid");
    let m = VehicleParams::default();
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    assert!(close(s.vehicle.max_yaw_rate, m.max_yaw_rate));
    assert!(close(s.vehicle.initial_heading_rad, m.initial_heading_rad));
    assert!(close(s.vehicle.gimbal_slew_rate, m.gimbal_slew_rate));
    let (mut a, mut b) = (s.vehicle, m);
    (a.max_yaw_rate, a.initial_heading_rad, a.gimbal_slew_rate) = (0.0, 0.0, 0.0);
    (b.max_yaw_rate, b.initial_heading_rad, b.gimbal_slew_rate) = (0.0, 0.0, 0.0);
    assert_eq!(a, b);
}

#[test]
fn empty_file_is_defaults() {
    let s = RawConfig::from_toml("").and_then(RawConfig::validate);
    assert!(s.is_ok());
}

#[test]
fn unknown_key_is_rejected() {
    let e = RawConfig::from_toml("sysid = 3").unwrap_err();
    assert!(matches!(e, ConfigError::Toml(m) if m.contains("sysid")));
}

#[test]
fn bad_values_are_reported_with_field_names() {
    let e = RawConfig {
        system_id: 0,
        ..RawConfig::default()
    }
    .validate()
    .unwrap_err();
    assert_eq!(e, ConfigError::SystemId(0));
    assert!(e.to_string().contains("1..=255"));

    let e = RawConfig {
        home_lat: 91.0,
        ..RawConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(e.to_string().contains("home_lat"), "{e}");

    let e = RawConfig {
        max_speed_mps: f64::NAN,
        ..RawConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(e.to_string().contains("max_speed_mps"), "{e}");

    let e = RawConfig {
        land_speed_mps: 2.0,
        ..RawConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(matches!(e, ConfigError::Inconsistent(_)));
}
