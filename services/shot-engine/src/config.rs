//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are
//! `deploy/shot-engine.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::in_range;
use skymesh_runtime::ipc::{DEFAULT_DOMAIN, DOMAIN_ENV};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::shots::Limits;

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../deploy/shot-engine.toml");

/// Name of the state file inside the state directory.
pub const STATE_FILE_NAME: &str = "shot-engine.json";

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The `{id}` of the vehicle topics.
    pub vehicle_id: u8,
    /// One control-loop tick.
    pub loop_period: Duration,
    /// `max_age_ms` of every velocity setpoint.
    pub setpoint_max_age_ms: u32,
    /// What every shot obeys.
    pub limits: Limits,
    pub selfie_cruise_speed: f32,
    pub orbit_initial_speed: f32,
    pub cable_initial_speed: f32,
    pub follow_cruise_speed: f32,
    /// No follow target for this long → hover and tell the app.
    pub follow_lost: Duration,
    /// Entry is refused at or below this battery percentage; 0 = never.
    pub battery_critical_pct: u8,
    /// No `AppSession` for this long → the app counts as disconnected.
    pub app_session_timeout: Duration,
    /// The JSON state file.
    pub state_file: PathBuf,
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub vehicle_id: i64,
    pub loop_hz: f64,
    pub setpoint_max_age_ms: i64,
    pub max_speed_mps: f64,
    pub max_accel_mps2: f64,
    pub max_climb_mps: f64,
    pub position_gain: f64,
    pub selfie_cruise_speed: f64,
    pub orbit_initial_speed: f64,
    pub cable_initial_speed: f64,
    pub follow_cruise_speed: f64,
    pub follow_lost_s: f64,
    pub battery_critical_pct: i64,
    pub app_session_timeout_s: f64,
    /// Empty → [`default_state_file`].
    pub state_file: String,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            vehicle_id: 1,
            loop_hz: 25.0,
            setpoint_max_age_ms: 500,
            max_speed_mps: 6.0,
            max_accel_mps2: 2.0,
            max_climb_mps: 1.5,
            position_gain: 0.5,
            selfie_cruise_speed: 2.0,
            orbit_initial_speed: 0.0,
            cable_initial_speed: 0.0,
            follow_cruise_speed: 0.0,
            follow_lost_s: 3.0,
            battery_critical_pct: 10,
            app_session_timeout_s: 3.0,
            state_file: String::new(),
        }
    }
}

/// Where the state file lives when `state_file` is empty: under systemd's
/// `STATE_DIRECTORY` (the first entry if it lists several), else under
/// `/tmp/skymesh-<domain>/`.
pub fn default_state_file(state_directory: Option<&str>, domain: Option<&str>) -> PathBuf {
    if let Some(dir) = state_directory
        .and_then(|d| d.split(':').next())
        .filter(|d| !d.is_empty())
    {
        return Path::new(dir).join(STATE_FILE_NAME);
    }
    let domain = domain.filter(|d| !d.is_empty()).unwrap_or(DEFAULT_DOMAIN);
    PathBuf::from(format!("/tmp/skymesh-{domain}")).join(STATE_FILE_NAME)
}

fn finite(field: &str, v: f64) -> Result<f64, ConfigError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ConfigError::invalid(
            field,
            format!("{v} is not a finite number"),
        ))
    }
}

fn range_f(field: &str, v: f64, min: f64, max: f64) -> Result<f64, ConfigError> {
    in_range(field, finite(field, v)?, min, max)
}

fn seconds(field: &str, v: f64, min: f64, max: f64) -> Result<Duration, ConfigError> {
    Ok(Duration::from_secs_f64(range_f(field, v, min, max)?))
}

impl RawConfig {
    /// Checks ranges and resolves the state file against the environment.
    pub fn validate_with_env(
        self,
        state_directory: Option<&str>,
        domain: Option<&str>,
    ) -> Result<Settings, ConfigError> {
        let vehicle_id = in_range("vehicle_id", self.vehicle_id, 1, 255)? as u8;
        let loop_hz = range_f("loop_hz", self.loop_hz, 1.0, 100.0)?;
        let setpoint_max_age_ms =
            in_range("setpoint_max_age_ms", self.setpoint_max_age_ms, 20, 2000)? as u32;
        let loop_period = Duration::from_secs_f64(1.0 / loop_hz);
        if Duration::from_millis(setpoint_max_age_ms.into()) <= loop_period {
            return Err(ConfigError::invalid(
                "setpoint_max_age_ms",
                format!(
                    "{setpoint_max_age_ms} ms is not longer than one loop tick ({loop_period:?}): every setpoint would expire before the next"
                ),
            ));
        }
        let max_speed = range_f("max_speed_mps", self.max_speed_mps, 0.5, 20.0)?;
        let limits = Limits {
            max_speed_mps: max_speed as f32,
            max_accel_mps2: range_f("max_accel_mps2", self.max_accel_mps2, 0.1, 10.0)? as f32,
            max_climb_mps: range_f("max_climb_mps", self.max_climb_mps, 0.1, 10.0)? as f32,
            position_gain: range_f("position_gain", self.position_gain, 0.05, 5.0)? as f32,
        };
        let speed = |field: &str, v: f64, min: f64| -> Result<f32, ConfigError> {
            Ok(range_f(field, v, min, max_speed)? as f32)
        };
        let state_file = if self.state_file.trim().is_empty() {
            default_state_file(state_directory, domain)
        } else {
            PathBuf::from(self.state_file.trim())
        };
        if state_file.file_name().is_none() {
            return Err(ConfigError::invalid(
                "state_file",
                format!("`{}` does not name a file", state_file.display()),
            ));
        }
        Ok(Settings {
            vehicle_id,
            loop_period,
            setpoint_max_age_ms,
            limits,
            selfie_cruise_speed: speed("selfie_cruise_speed", self.selfie_cruise_speed, 0.0)?,
            orbit_initial_speed: speed(
                "orbit_initial_speed",
                self.orbit_initial_speed,
                -max_speed,
            )?,
            cable_initial_speed: speed(
                "cable_initial_speed",
                self.cable_initial_speed,
                -max_speed,
            )?,
            follow_cruise_speed: speed(
                "follow_cruise_speed",
                self.follow_cruise_speed,
                -max_speed,
            )?,
            follow_lost: seconds("follow_lost_s", self.follow_lost_s, 0.5, 60.0)?,
            battery_critical_pct: in_range(
                "battery_critical_pct",
                self.battery_critical_pct,
                0,
                100,
            )? as u8,
            app_session_timeout: seconds(
                "app_session_timeout_s",
                self.app_session_timeout_s,
                1.0,
                60.0,
            )?,
            state_file,
        })
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = DEFAULT_CONFIG_TOML;

    fn validate(self) -> Result<Settings, ConfigError> {
        let state_directory = std::env::var("STATE_DIRECTORY").ok();
        let domain = std::env::var(DOMAIN_ENV).ok();
        self.validate_with_env(state_directory.as_deref(), domain.as_deref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Settings, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: "test".into(),
            message: e.to_string(),
        })?;
        raw.validate_with_env(None, Some("testdomain"))
    }

    #[test]
    fn shipped_defaults_parse_and_match_the_code_defaults() {
        let shipped = parse(DEFAULT_CONFIG_TOML).unwrap();
        let code = RawConfig::default()
            .validate_with_env(None, Some("testdomain"))
            .unwrap();
        assert_eq!(shipped, code);
        assert_eq!(shipped.vehicle_id, 1);
        assert_eq!(shipped.loop_period, Duration::from_millis(40));
        assert_eq!(shipped.setpoint_max_age_ms, 500);
        assert_eq!(shipped.follow_lost, Duration::from_secs(3));
        assert_eq!(
            shipped.state_file,
            PathBuf::from("/tmp/skymesh-testdomain/shot-engine.json")
        );
    }

    #[test]
    fn every_shipped_key_is_known() {
        // deny_unknown_fields: the shipped file parses, so every key in it is one of ours;
        // and a typo is refused.
        let e = parse("loop_hzz = 10").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    }

    #[test]
    fn out_of_range_values_name_their_field() {
        for (text, field) in [
            ("vehicle_id = 0", "vehicle_id"),
            ("loop_hz = 0.5", "loop_hz"),
            ("loop_hz = nan", "loop_hz"),
            ("setpoint_max_age_ms = 10", "setpoint_max_age_ms"),
            (
                "loop_hz = 1\nsetpoint_max_age_ms = 900",
                "setpoint_max_age_ms",
            ),
            ("max_speed_mps = 50", "max_speed_mps"),
            ("selfie_cruise_speed = 7", "selfie_cruise_speed"),
            ("orbit_initial_speed = -7", "orbit_initial_speed"),
            ("follow_lost_s = 0", "follow_lost_s"),
            ("battery_critical_pct = 101", "battery_critical_pct"),
            ("app_session_timeout_s = 0.1", "app_session_timeout_s"),
            ("state_file = \"/\"", "state_file"),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn state_file_defaults_follow_systemd_then_the_domain() {
        assert_eq!(
            default_state_file(Some("/var/lib/skymesh"), Some("x")),
            PathBuf::from("/var/lib/skymesh/shot-engine.json")
        );
        assert_eq!(
            default_state_file(Some("/var/lib/a:/var/lib/b"), None),
            PathBuf::from("/var/lib/a/shot-engine.json")
        );
        assert_eq!(
            default_state_file(None, None),
            PathBuf::from("/tmp/skymesh-skymesh/shot-engine.json")
        );
        assert_eq!(
            default_state_file(Some(""), Some("")),
            PathBuf::from("/tmp/skymesh-skymesh/shot-engine.json")
        );
        let s = parse("state_file = \"/srv/x.json\"").unwrap();
        assert_eq!(s.state_file, PathBuf::from("/srv/x.json"));
    }
}
