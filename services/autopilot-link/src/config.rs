//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are
//! `deploy/autopilot-link.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::fmt;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::{in_range, socket_addr};
use skymesh_runtime::ipc::{DEFAULT_DOMAIN, DOMAIN_ENV};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::arbiter::ArbiterSettings;
use crate::gimbal_v2::VisionSettings;
use crate::signing::{load_key, SigningSettings};

/// Where the autopilot is, as written in `connection`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// `tcpout:HOST:PORT`: we connect (ArduPilot SITL, vehicle-sim, a telemetry radio bridge).
    TcpOut { host: String, port: u16 },
    /// `tcpin:IP:PORT`: we listen and take one client at a time.
    TcpIn(SocketAddr),
    /// `udpin:IP:PORT`: we listen; replies go to whoever sent last.
    UdpIn(SocketAddr),
    /// `udpout:HOST:PORT`: we send to the autopilot and read its replies.
    UdpOut { host: String, port: u16 },
    /// `serial:DEVICE:BAUD`: a UART or USB CDC port of the flight controller.
    Serial { device: String, baud: u32 },
}

impl Endpoint {
    /// Parses a connection string, naming `field` in the error.
    pub fn parse(field: &str, s: &str) -> Result<Endpoint, ConfigError> {
        let bad = |msg: String| ConfigError::invalid(field, msg);
        let (scheme, rest) = s.split_once(':').ok_or_else(|| {
            bad(format!(
                "`{s}` has no scheme; use tcpout:, tcpin:, udpin:, udpout: or serial:"
            ))
        })?;
        let host_port = |rest: &str| -> Result<(String, u16), ConfigError> {
            let (host, port) = rest
                .rsplit_once(':')
                .ok_or_else(|| bad(format!("`{s}` needs HOST:PORT after `{scheme}:`")))?;
            let host = host.trim_start_matches('[').trim_end_matches(']');
            if host.is_empty() {
                return Err(bad(format!("`{s}` has an empty host")));
            }
            let port: u16 = port
                .parse()
                .map_err(|_| bad(format!("`{s}`: `{port}` is not a port number")))?;
            if port == 0 {
                return Err(bad(format!("`{s}`: port 0 cannot be connected to")));
            }
            Ok((host.to_string(), port))
        };
        match scheme {
            "tcpout" => {
                let (host, port) = host_port(rest)?;
                Ok(Endpoint::TcpOut { host, port })
            }
            "udpout" => {
                let (host, port) = host_port(rest)?;
                Ok(Endpoint::UdpOut { host, port })
            }
            "tcpin" => Ok(Endpoint::TcpIn(socket_addr(field, rest)?)),
            "udpin" => Ok(Endpoint::UdpIn(socket_addr(field, rest)?)),
            "serial" => {
                // Split at the last colon: device paths may contain colons, baud rates never do.
                let (device, baud) = rest
                    .rsplit_once(':')
                    .ok_or_else(|| bad(format!("`{s}` needs serial:DEVICE:BAUD")))?;
                if device.is_empty() {
                    return Err(bad(format!("`{s}` has an empty device path")));
                }
                let baud: u32 = baud
                    .parse()
                    .map_err(|_| bad(format!("`{s}`: `{baud}` is not a baud rate")))?;
                let baud = in_range(field, baud, 1200, 12_000_000)?;
                Ok(Endpoint::Serial {
                    device: device.to_string(),
                    baud,
                })
            }
            other => Err(bad(format!(
                "unknown scheme `{other}:`; use tcpout:, tcpin:, udpin:, udpout: or serial:"
            ))),
        }
    }

    /// Stream transports end with EOF or an error; datagram ones never do.
    pub fn is_stream(&self) -> bool {
        matches!(
            self,
            Endpoint::TcpOut { .. } | Endpoint::TcpIn(_) | Endpoint::Serial { .. }
        )
    }
}

/// `host:port`, with an IPv6 literal in brackets.
struct HostPort<'a>(&'a str, u16);

impl fmt::Display for HostPort<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.contains(':') {
            write!(f, "[{}]:{}", self.0, self.1)
        } else {
            write!(f, "{}:{}", self.0, self.1)
        }
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::TcpOut { host, port } => write!(f, "tcpout:{}", HostPort(host, *port)),
            Endpoint::TcpIn(a) => write!(f, "tcpin:{a}"),
            Endpoint::UdpIn(a) => write!(f, "udpin:{a}"),
            Endpoint::UdpOut { host, port } => write!(f, "udpout:{}", HostPort(host, *port)),
            Endpoint::Serial { device, baud } => write!(f, "serial:{device}:{baud}"),
        }
    }
}

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
        }
    }
}

/// A finite number of seconds within `min..=max`.
fn seconds(field: &str, value: f64, min: f64, max: f64) -> Result<Duration, ConfigError> {
    if !value.is_finite() {
        return Err(ConfigError::invalid(field, "must be a finite number"));
    }
    Ok(Duration::from_secs_f64(in_range(field, value, min, max)?))
}

/// A telemetry rate, Hz.
fn rate(field: &str, value: f64) -> Result<f32, ConfigError> {
    number(field, value, 0.1, 400.0)
}

/// The `endpoints` list: valid strings, no serial ports, no duplicates, not the
/// autopilot's own connection, at most [`crate::router::MAX_ENDPOINTS`].
fn router_endpoints(list: &[String], connection: &str) -> Result<Vec<Endpoint>, ConfigError> {
    const FIELD: &str = "endpoints";
    let max = crate::router::MAX_ENDPOINTS;
    if list.len() > max {
        return Err(ConfigError::invalid(
            FIELD,
            format!("{} endpoints; at most {max}", list.len()),
        ));
    }
    let connection = Endpoint::parse("connection", connection).ok();
    let mut out: Vec<Endpoint> = Vec::new();
    for s in list {
        let e = Endpoint::parse(FIELD, s)?;
        if matches!(e, Endpoint::Serial { .. }) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("`{s}`: serial router endpoints are not supported; use udpin/udpout/tcpin/tcpout"),
            ));
        }
        if out.contains(&e) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("`{s}` is listed twice"),
            ));
        }
        if connection.as_ref() == Some(&e) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("`{s}` is the autopilot connection itself"),
            ));
        }
        out.push(e);
    }
    Ok(out)
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
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/autopilot-link.toml");

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
        })
    }
}

/// The `[signing]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawSigning {
    /// A file holding the 32-byte secret key as 64 hex digits.
    pub key_file: Option<String>,
    /// Entries of `endpoints` (as written there) that require signing.
    pub endpoints: Vec<String>,
}

impl RawSigning {
    /// `endpoints` are the validated router endpoints the entries must name.
    fn validate(self, endpoints: &[Endpoint]) -> Result<Option<SigningSettings>, ConfigError> {
        const FIELD: &str = "signing.endpoints";
        let Some(path) = self.key_file else {
            if self.endpoints.is_empty() {
                return Ok(None);
            }
            return Err(ConfigError::invalid(
                "signing.key_file",
                "signing.endpoints are listed but no key_file is given",
            ));
        };
        if path.trim().is_empty() {
            return Err(ConfigError::invalid("signing.key_file", "is empty"));
        }
        if self.endpoints.is_empty() {
            return Err(ConfigError::invalid(
                FIELD,
                "a key_file is given but no endpoint requires signing; list them here",
            ));
        }
        let mut indices = Vec::new();
        for s in &self.endpoints {
            let e = Endpoint::parse(FIELD, s)?;
            let i = endpoints.iter().position(|x| *x == e).ok_or_else(|| {
                ConfigError::invalid(FIELD, format!("`{s}` is not one of `endpoints`"))
            })?;
            if indices.contains(&i) {
                return Err(ConfigError::invalid(
                    FIELD,
                    format!("`{s}` is listed twice"),
                ));
            }
            indices.push(i);
        }
        indices.sort_unstable();
        // The key's bytes never appear in an error.
        let key = load_key(std::path::Path::new(&path))
            .map_err(|e| ConfigError::invalid("signing.key_file", e.to_string()))?;
        Ok(Some(SigningSettings {
            key,
            endpoints: indices,
        }))
    }
}

/// The `[vision]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawVision {
    pub enabled: bool,
    pub stream: i64,
    pub components: Vec<i64>,
    pub forward_payload: bool,
}

impl Default for RawVision {
    fn default() -> Self {
        let d = VisionSettings::default();
        RawVision {
            enabled: d.enabled,
            stream: i64::from(d.stream),
            components: d.components.iter().map(|c| i64::from(*c)).collect(),
            forward_payload: d.forward_payload,
        }
    }
}

impl RawVision {
    fn validate(self) -> Result<VisionSettings, ConfigError> {
        let max_streams = skymesh_ipc_types::VISION_MAX_STREAMS as i64;
        let stream = in_range("vision.stream", self.stream, 0, max_streams - 1)? as u8;
        let max = skymesh_ipc_types::VISION_MAX_CAMS;
        if self.components.is_empty() || self.components.len() > max {
            return Err(ConfigError::invalid(
                "vision.components",
                format!("1 to {max} component ids (one per virtual camera)"),
            ));
        }
        let mut components: Vec<u8> = Vec::new();
        for c in &self.components {
            let c = in_range("vision.components", *c, 1, 255)? as u8;
            if c == crate::requests::OWN_COMPONENT {
                return Err(ConfigError::invalid(
                    "vision.components",
                    format!("{c} is autopilot-link's own component"),
                ));
            }
            if c == crate::telemetry::AUTOPILOT_COMPONENT {
                return Err(ConfigError::invalid(
                    "vision.components",
                    format!("{c} is the autopilot's component"),
                ));
            }
            if components.contains(&c) {
                return Err(ConfigError::invalid(
                    "vision.components",
                    format!("{c} is listed twice"),
                ));
            }
            components.push(c);
        }
        Ok(VisionSettings {
            enabled: self.enabled,
            stream,
            components,
            forward_payload: self.forward_payload,
        })
    }
}

/// The `[arbiter]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawArbiter {
    pub authority_timeout_s: f64,
    pub setpoint_max_age_ms: i64,
    pub setpoint_max_age_cap_ms: i64,
    /// Source name (`vision`, `shot_engine`, ...) → default maximum age, ms.
    pub setpoint_max_age_by_source: std::collections::BTreeMap<String, i64>,
    pub max_horizontal_speed_mps: f64,
    pub max_climb_mps: f64,
    pub max_descent_mps: f64,
    pub max_yaw_rate_dps: f64,
    pub fence_deceleration_mps2: f64,
    pub fence_margin_m: f64,
    pub fence_vertical_margin_m: f64,
    pub fence_response_s: f64,
    pub in_air_alt_m: f64,
    pub in_air_speed_mps: f64,
    /// Servo channels (1..=32) a `Servo` command may drive in the air.
    pub servo_channels_in_flight: Vec<i64>,
    pub max_home_move_m: f64,
    pub max_home_alt_change_m: f64,
}

impl Default for RawArbiter {
    fn default() -> Self {
        RawArbiter {
            authority_timeout_s: 5.0,
            setpoint_max_age_ms: 500,
            setpoint_max_age_cap_ms: 2000,
            setpoint_max_age_by_source: std::collections::BTreeMap::new(),
            max_horizontal_speed_mps: 12.0,
            max_climb_mps: 5.0,
            max_descent_mps: 3.0,
            max_yaw_rate_dps: 180.0,
            fence_deceleration_mps2: 1.5,
            fence_margin_m: 2.0,
            fence_vertical_margin_m: 1.0,
            fence_response_s: 0.3,
            in_air_alt_m: 0.5,
            in_air_speed_mps: 0.5,
            servo_channels_in_flight: Vec::new(),
            max_home_move_m: 50.0,
            max_home_alt_change_m: 1.0,
        }
    }
}

/// A finite number within `min..=max`, as f32.
fn number(field: &str, value: f64, min: f64, max: f64) -> Result<f32, ConfigError> {
    if !value.is_finite() {
        return Err(ConfigError::invalid(field, "must be a finite number"));
    }
    Ok(in_range(field, value, min, max)? as f32)
}

impl RawArbiter {
    fn validate(self) -> Result<ArbiterSettings, ConfigError> {
        let ms = |field: &str, v: i64, max: i64| -> Result<Duration, ConfigError> {
            Ok(Duration::from_millis(in_range(field, v, 20, max)? as u64))
        };
        let cap_ms = in_range(
            "arbiter.setpoint_max_age_cap_ms",
            self.setpoint_max_age_cap_ms,
            20,
            10_000,
        )?;
        let mut by_source = Vec::new();
        for (name, age) in &self.setpoint_max_age_by_source {
            let field = format!("arbiter.setpoint_max_age_by_source.{name}");
            let source = skymesh_ipc_types::CommandSource::ALL
                .iter()
                .copied()
                .find(|s| s.as_str() == name)
                .ok_or_else(|| ConfigError::invalid(&field, "not a command source name"))?;
            by_source.push((source, ms(&field, *age, cap_ms)?));
        }
        Ok(ArbiterSettings {
            authority_timeout: seconds(
                "arbiter.authority_timeout_s",
                self.authority_timeout_s,
                0.5,
                300.0,
            )?,
            setpoint_max_age: ms(
                "arbiter.setpoint_max_age_ms",
                self.setpoint_max_age_ms,
                cap_ms,
            )?,
            setpoint_max_age_cap: Duration::from_millis(cap_ms as u64),
            setpoint_max_age_by_source: by_source,
            max_horizontal_speed_mps: number(
                "arbiter.max_horizontal_speed_mps",
                self.max_horizontal_speed_mps,
                0.5,
                50.0,
            )?,
            max_climb_mps: number("arbiter.max_climb_mps", self.max_climb_mps, 0.1, 50.0)?,
            max_descent_mps: number("arbiter.max_descent_mps", self.max_descent_mps, 0.1, 50.0)?,
            max_yaw_rate_dps: number(
                "arbiter.max_yaw_rate_dps",
                self.max_yaw_rate_dps,
                1.0,
                720.0,
            )?,
            fence_deceleration_mps2: number(
                "arbiter.fence_deceleration_mps2",
                self.fence_deceleration_mps2,
                0.2,
                20.0,
            )?,
            fence_margin_m: number("arbiter.fence_margin_m", self.fence_margin_m, 0.0, 100.0)?,
            fence_vertical_margin_m: number(
                "arbiter.fence_vertical_margin_m",
                self.fence_vertical_margin_m,
                0.0,
                100.0,
            )?,
            fence_response_s: number("arbiter.fence_response_s", self.fence_response_s, 0.0, 5.0)?,
            in_air_alt_m: number("arbiter.in_air_alt_m", self.in_air_alt_m, 0.1, 10.0)?,
            in_air_speed_mps: number("arbiter.in_air_speed_mps", self.in_air_speed_mps, 0.1, 10.0)?,
            servo_channels_in_flight: servo_channels(&self.servo_channels_in_flight)?,
            max_home_move_m: number(
                "arbiter.max_home_move_m",
                self.max_home_move_m,
                0.0,
                10_000.0,
            )?,
            max_home_alt_change_m: number(
                "arbiter.max_home_alt_change_m",
                self.max_home_alt_change_m,
                0.0,
                100.0,
            )?,
        })
    }
}

/// `arbiter.servo_channels_in_flight`: each a servo channel (1..=32), none twice;
/// returned sorted.
fn servo_channels(list: &[i64]) -> Result<Vec<u8>, ConfigError> {
    const FIELD: &str = "arbiter.servo_channels_in_flight";
    let range = skymesh_ipc_types::command::limits::SERVO_CHANNELS;
    let mut out = Vec::with_capacity(list.len());
    for &channel in list {
        let channel = in_range(
            FIELD,
            channel,
            i64::from(*range.start()),
            i64::from(*range.end()),
        )? as u8;
        if out.contains(&channel) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("channel {channel} is listed twice"),
            ));
        }
        out.push(channel);
    }
    out.sort_unstable();
    Ok(out)
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

#[cfg(test)]
mod tests {
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
        let s = parse_str("[arbiter]\nauthority_timeout_s = 2\n[arbiter.setpoint_max_age_by_source]\nvision = 200").unwrap();
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
        let s =
            parse_str("state_file = \"/x/link.json\"\n[arbiter]\nmax_home_move_m = 20").unwrap();
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
}
