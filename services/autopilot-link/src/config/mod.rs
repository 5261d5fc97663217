//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are
//! `deploy/autopilot-link.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).
//!
//! | file | holds |
//! |---|---|
//! | `mod.rs` | [`RawConfig`] → [`Settings`], the top-level keys |
//! | `endpoint.rs` | connection and router endpoint strings ([`Endpoint`]) |
//! | `arbiter.rs` | the `[arbiter]` table |
//! | `signing.rs` | the `[signing]` table |
//! | `vision.rs` | the `[vision]` table |
//! | `tlog.rs` | the `[tlog]` table (flight logs) |

mod arbiter;
mod endpoint;
mod signing;
#[cfg(test)]
mod tests;
mod tlog;
mod vision;

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::in_range;
use skymesh_runtime::ipc::{DEFAULT_DOMAIN, DOMAIN_ENV};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::arbiter::ArbiterSettings;
use crate::gimbal_v2::VisionSettings;
use crate::signing::SigningSettings;
use crate::tlog::TlogSettings;

pub use arbiter::RawArbiter;
use endpoint::router_endpoints;
pub use endpoint::Endpoint;
pub use signing::RawSigning;
pub use tlog::{default_dir as default_tlog_dir, RawTlog};
pub use vision::RawVision;

/// Telemetry rates requested from the autopilot, Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamRates {
    /// ATTITUDE while the vehicle is armed (and before its armed state is known).
    pub attitude_hz: f32,
    /// ATTITUDE while the vehicle is disarmed; `None` = [`Self::attitude_hz`].
    pub ground_attitude_hz: Option<f32>,
    pub global_position_hz: f32,
    pub local_position_hz: f32,
    pub sys_status_hz: f32,
    pub battery_status_hz: f32,
    pub gps_raw_hz: f32,
    pub ekf_status_hz: f32,
    /// GIMBAL_DEVICE_ATTITUDE_STATUS → `PayloadState`; `None` = not requested.
    pub gimbal_attitude_hz: Option<f32>,
    /// The autopilot's HEARTBEAT (flight mode, armed) → `VehicleStatus`; `None` = not
    /// requested (the autopilot's own rate, 1 Hz on ArduPilot).
    pub heartbeat_hz: Option<f32>,
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub connection: Endpoint,
    /// MAVLink router endpoints (ground stations, other MAVLink programs), at most
    /// [`crate::router::MAX_ENDPOINTS`], no duplicates; see [`crate::endpoints`].
    pub endpoints: Vec<Endpoint>,
    /// MAVLink system id of the autopilot; also the `{id}` of the vehicle topics.
    pub vehicle_id: u8,
    /// Our own MAVLink system id (component is always 191, onboard computer).
    pub system_id: u8,
    /// No autopilot heartbeat for this long → link down.
    pub link_timeout: Duration,
    /// Wait this long for a COMMAND_ACK before retransmitting / giving up.
    pub command_timeout: Duration,
    /// Retransmissions (confirmation + 1 each) before a command is refused with `Timeout`.
    pub command_retries: u8,
    /// After MAV_RESULT_IN_PROGRESS, wait this long for the final answer.
    pub command_in_progress_timeout: Duration,
    /// An emergency stop not confirmed by the autopilot (BRAKE reported or the
    /// vehicle measured stopped) this long after it arrived is answered `failed`.
    pub stop_confirm_timeout: Duration,
    /// First reconnect delay; doubles per failed attempt up to `reconnect_max`.
    pub reconnect_min: Duration,
    pub reconnect_max: Duration,
    /// A TCP or serial connection that delivers no MAVLink for this long is reopened.
    pub silence_reconnect: Option<Duration>,
    pub rates: StreamRates,
    /// Also send REQUEST_DATA_STREAM (for firmware without SET_MESSAGE_INTERVAL).
    pub request_data_streams: bool,
    /// The command arbiter.
    pub arbiter: ArbiterSettings,
    /// The arbiter's state file (emergency stops and fences survive a restart;
    /// [`crate::arbiter::persist`]).
    pub state_file: PathBuf,
    /// Gimbal protocol v2 for the vision pipeline's virtual cameras.
    pub vision: VisionSettings,
    /// MAVLink 2 message signing on some endpoints; `None` = no signing.
    pub signing: Option<SigningSettings>,
    /// Flight logs of the autopilot link; `None` = none (no `[tlog]` table).
    pub tlog: Option<TlogSettings>,
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub connection: String,
    /// MAVLink router endpoints, same syntax as `connection` (no `serial:`).
    pub endpoints: Vec<String>,
    pub vehicle_id: i64,
    /// Absent → same as `vehicle_id`.
    pub system_id: Option<i64>,
    pub link_timeout_s: f64,
    pub command_timeout_s: f64,
    pub command_retries: i64,
    pub command_in_progress_timeout_s: f64,
    pub stop_confirm_timeout_s: f64,
    pub reconnect_min_s: f64,
    pub reconnect_max_s: f64,
    /// 0 disables.
    pub silence_reconnect_s: f64,
    pub request_data_streams: bool,
    /// Requested telemetry rates, Hz.
    pub attitude_hz: f64,
    /// 0 = `attitude_hz` on the ground too.
    pub ground_attitude_hz: f64,
    pub global_position_hz: f64,
    pub local_position_hz: f64,
    pub sys_status_hz: f64,
    pub battery_status_hz: f64,
    pub gps_raw_hz: f64,
    pub ekf_status_hz: f64,
    /// 0 = not requested.
    pub gimbal_attitude_hz: f64,
    /// 0 = not requested.
    pub heartbeat_hz: f64,
    /// Empty → [`default_state_file`].
    pub state_file: String,
    /// `[arbiter]`: authority, freshness, geofence envelope, limits.
    pub arbiter: RawArbiter,
    /// `[vision]`: the virtual cameras as MAVLink gimbals.
    pub vision: RawVision,
    /// `[signing]`: MAVLink 2 message signing on router endpoints.
    pub signing: RawSigning,
    /// `[tlog]`: flight logs; absent = off.
    pub tlog: Option<RawTlog>,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            connection: "tcpout:127.0.0.1:5760".to_string(),
            endpoints: vec!["udpout:127.0.0.1:14550".to_string()],
            vehicle_id: 1,
            system_id: None,
            link_timeout_s: 2.0,
            command_timeout_s: 1.5,
            command_retries: 1,
            command_in_progress_timeout_s: 30.0,
            stop_confirm_timeout_s: 5.0,
            reconnect_min_s: 0.5,
            reconnect_max_s: 5.0,
            silence_reconnect_s: 10.0,
            request_data_streams: true,
            attitude_hz: 50.0,
            ground_attitude_hz: 10.0,
            global_position_hz: 10.0,
            local_position_hz: 5.0,
            sys_status_hz: 2.0,
            battery_status_hz: 2.0,
            gps_raw_hz: 2.0,
            ekf_status_hz: 2.0,
            gimbal_attitude_hz: 10.0,
            heartbeat_hz: 5.0,
            state_file: String::new(),
            arbiter: RawArbiter::default(),
            vision: RawVision::default(),
            signing: RawSigning::default(),
            tlog: None,
        }
    }
}

/// A finite number of seconds within `min..=max`.
pub(super) fn seconds(
    field: &str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<Duration, ConfigError> {
    if !value.is_finite() {
        return Err(ConfigError::invalid(field, "must be a finite number"));
    }
    Ok(Duration::from_secs_f64(in_range(field, value, min, max)?))
}

/// A telemetry rate, Hz.
fn rate(field: &str, value: f64) -> Result<f32, ConfigError> {
    number(field, value, 0.1, 400.0)
}

fn mav_id(field: &str, value: i64) -> Result<u8, ConfigError> {
    Ok(in_range(field, value, 1, 255)? as u8)
}

/// Where the arbiter's state lives when `state_file` is empty:
/// `autopilot-link-<vehicle_id>.json` under systemd's `STATE_DIRECTORY` (its first
/// entry), else under `/tmp/skymesh-<domain>/` (writable without root).
pub fn default_state_file(
    state_directory: Option<&str>,
    domain: Option<&str>,
    vehicle_id: u8,
) -> PathBuf {
    let name = format!("autopilot-link-{vehicle_id}.json");
    if let Some(dir) = state_directory
        .and_then(|d| d.split(':').next())
        .filter(|d| !d.is_empty())
    {
        return Path::new(dir).join(name);
    }
    let domain = domain.filter(|d| !d.is_empty()).unwrap_or(DEFAULT_DOMAIN);
    PathBuf::from(format!("/tmp/skymesh-{domain}")).join(name)
}

fn state_file(raw: &str, vehicle_id: u8) -> Result<PathBuf, ConfigError> {
    let path = if raw.trim().is_empty() {
        let state_directory = std::env::var("STATE_DIRECTORY").ok();
        let domain = std::env::var(DOMAIN_ENV).ok();
        default_state_file(state_directory.as_deref(), domain.as_deref(), vehicle_id)
    } else {
        PathBuf::from(raw.trim())
    };
    if path.file_name().is_none() {
        return Err(ConfigError::invalid(
            "state_file",
            format!("`{}` does not name a file", path.display()),
        ));
    }
    Ok(path)
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../../deploy/autopilot-link.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        let vehicle_id = mav_id("vehicle_id", self.vehicle_id)?;
        let system_id = match self.system_id {
            Some(id) => mav_id("system_id", id)?,
            None => vehicle_id,
        };
        let reconnect_min = seconds("reconnect_min_s", self.reconnect_min_s, 0.05, 60.0)?;
        let reconnect_max = seconds("reconnect_max_s", self.reconnect_max_s, 0.05, 300.0)?;
        if reconnect_max < reconnect_min {
            return Err(ConfigError::invalid(
                "reconnect_max_s",
                "must not be smaller than reconnect_min_s",
            ));
        }
        let silence = self.silence_reconnect_s;
        let silence_reconnect = if silence == 0.0 {
            None
        } else {
            Some(seconds("silence_reconnect_s", silence, 1.0, 600.0)?)
        };
        let endpoints = router_endpoints(&self.endpoints, &self.connection)?;
        let signing = self.signing.validate(&endpoints)?;
        Ok(Settings {
            connection: Endpoint::parse("connection", &self.connection)?,
            endpoints,
            vehicle_id,
            system_id,
            link_timeout: seconds("link_timeout_s", self.link_timeout_s, 0.5, 60.0)?,
            command_timeout: seconds("command_timeout_s", self.command_timeout_s, 0.1, 30.0)?,
            command_retries: in_range("command_retries", self.command_retries, 0, 5)? as u8,
            command_in_progress_timeout: seconds(
                "command_in_progress_timeout_s",
                self.command_in_progress_timeout_s,
                1.0,
                600.0,
            )?,
            stop_confirm_timeout: seconds(
                "stop_confirm_timeout_s",
                self.stop_confirm_timeout_s,
                1.0,
                30.0,
            )?,
            reconnect_min,
            reconnect_max,
            silence_reconnect,
            rates: StreamRates {
                attitude_hz: rate("attitude_hz", self.attitude_hz)?,
                ground_attitude_hz: if self.ground_attitude_hz == 0.0 {
                    None
                } else {
                    Some(rate("ground_attitude_hz", self.ground_attitude_hz)?)
                },
                global_position_hz: rate("global_position_hz", self.global_position_hz)?,
                local_position_hz: rate("local_position_hz", self.local_position_hz)?,
                sys_status_hz: rate("sys_status_hz", self.sys_status_hz)?,
                battery_status_hz: rate("battery_status_hz", self.battery_status_hz)?,
                gps_raw_hz: rate("gps_raw_hz", self.gps_raw_hz)?,
                ekf_status_hz: rate("ekf_status_hz", self.ekf_status_hz)?,
                gimbal_attitude_hz: if self.gimbal_attitude_hz == 0.0 {
                    None
                } else {
                    Some(rate("gimbal_attitude_hz", self.gimbal_attitude_hz)?)
                },
                heartbeat_hz: if self.heartbeat_hz == 0.0 {
                    None
                } else {
                    // Slower than ArduPilot's own 1 Hz would only make the link
                    // look lost (link_timeout); faster than 50 Hz buys nothing.
                    Some(number("heartbeat_hz", self.heartbeat_hz, 1.0, 50.0)?)
                },
            },
            request_data_streams: self.request_data_streams,
            arbiter: self.arbiter.validate()?,
            state_file: state_file(&self.state_file, vehicle_id)?,
            vision: self.vision.validate()?,
            signing,
            tlog: self.tlog.map(|t| t.validate(vehicle_id)).transpose()?,
        })
    }
}
/// A finite number within `min..=max`, as f32.
pub(super) fn number(field: &str, value: f64, min: f64, max: f64) -> Result<f32, ConfigError> {
    if !value.is_finite() {
        return Err(ConfigError::invalid(field, "must be a finite number"));
    }
    Ok(in_range(field, value, min, max)? as f32)
}
impl Settings {
    /// The defaults with `connection` replaced and no router endpoints (a test must
    /// not send to a ground station on the developer's machine): what in-process
    /// tests start from.
    pub fn with_connection(connection: Endpoint) -> Settings {
        let mut s = RawConfig::default()
            .validate()
            .expect("the built-in defaults are valid");
        s.connection = connection;
        s.endpoints.clear();
        s
    }
}
