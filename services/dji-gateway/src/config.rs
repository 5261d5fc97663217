//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented file is `deploy/dji-gateway.toml`
//! (embedded as [`ServiceConfig::DEFAULT_TOML`]) and equals the built-in defaults.

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::in_range;
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::drc::DrcConfig;

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Serial number of the dock/gateway we play: `thing/product/{gateway_sn}/...`.
    pub gateway_sn: String,
    /// MAVLink system id of the vehicle flown.
    pub vehicle_id: u8,
    pub broker: BrokerSettings,
    pub limits: LimitSettings,
    pub commands: CommandSettings,
    pub flight: FlightSettings,
    pub poi: PoiSettings,
    pub payload: PayloadSettings,
    pub drc: DrcConfig,
}

/// The cloud's broker (services, events).
#[derive(Debug, Clone, PartialEq)]
pub struct BrokerSettings {
    /// Host name or IP (IPv6 without brackets).
    pub host: String,
    pub port: u16,
    /// `address` as written, for logs.
    pub address: String,
    pub client_id: String,
    /// Empty: connect without credentials.
    pub username: String,
    pub password: String,
    /// `Some(ca_file)` when TLS is on.
    pub tls_ca_file: Option<PathBuf>,
    pub keep_alive: Duration,
    pub reconnect_initial: Duration,
    pub reconnect_max: Duration,
}

#[derive(Debug, Clone, PartialEq)]
pub struct LimitSettings {
    /// Larger inbound payloads are dropped before parsing.
    pub max_payload_bytes: usize,
    /// Per inbound topic and second; the excess is dropped and counted.
    pub max_messages_per_s: u32,
    /// Outbound messages kept while the broker is unreachable (oldest dropped first).
    pub max_queued_messages: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct CommandSettings {
    /// How long a `VehicleCommand` may wait for its `CommandAck`.
    pub ack_timeout: Duration,
    /// How long an emergency stop may wait for its `CommandAck`: autopilot-link
    /// answers it once the autopilot confirmed the stop, which may take up to its
    /// `stop_confirm_timeout_s` (5 s by default).
    pub stop_ack_timeout: Duration,
    /// While the cloud holds an authority it grabbed and no command of that domain
    /// went out for this long, the grab is re-sent (the arbiter drops a silent holder
    /// after its `authority_timeout_s`). Zero: never.
    pub authority_keepalive: Duration,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FlightSettings {
    /// A target counts as reached within this 3-D distance, metres.
    pub arrival_radius_m: f64,
    /// Ellipsoid height − MSL height here, metres (DJI heights are ellipsoidal):
    /// used only while the autopilot reports no `alt_ellipsoid` of its own.
    pub geoid_undulation_m: f64,
    /// Progress events while a task runs.
    pub progress_interval: Duration,
    /// A task whose remaining distance has not shrunk by a metre for this long fails.
    pub stall_timeout: Duration,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PoiSettings {
    /// Largest |circle_speed|, m/s (reported as `max_circle_speed`).
    pub max_circle_speed_mps: f64,
    /// Speed the orbit starts with on poi_mode_enter (sign = direction, positive
    /// counter-clockwise as DJI has it), |v| ≤ max.
    pub initial_circle_speed_mps: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PayloadSettings {
    /// The aircraft's camera/gimbal as the cloud names it (`type-subtype-gimbalindex`).
    pub payload_index: String,
    /// MAVLink camera id (0 = all cameras).
    pub camera: u8,
    pub hfov_deg: f64,
    pub vfov_deg: f64,
    /// zoom_factor 2..=this maps to CameraZoom Range 0..=100 %.
    pub zoom_max_factor: f64,
    /// Panorama: photos per full circle (stations `360/n`° apart in yaw).
    pub pano_stations: usize,
    /// Panorama: the stations' gimbal pitch, degrees (down negative).
    pub pano_pitch_deg: f64,
    /// Panorama: the gimbal must reach each station within this, else it fails.
    pub pano_settle_timeout: Duration,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawBroker {
    pub address: String,
    pub client_id: String,
    pub username: String,
    pub password: String,
    pub tls: bool,
    pub ca_file: String,
    pub keep_alive_s: i64,
    pub reconnect_initial_ms: i64,
    pub reconnect_max_ms: i64,
}

impl Default for RawBroker {
    fn default() -> Self {
        RawBroker {
            address: "127.0.0.1:1883".to_string(),
            client_id: String::new(),
            username: String::new(),
            password: String::new(),
            tls: false,
            ca_file: String::new(),
            keep_alive_s: 30,
            reconnect_initial_ms: 200,
            reconnect_max_ms: 10_000,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawLimits {
    pub max_payload_bytes: i64,
    pub max_messages_per_s: i64,
    pub max_queued_messages: i64,
}

impl Default for RawLimits {
    fn default() -> Self {
        RawLimits {
            max_payload_bytes: 65_536,
            max_messages_per_s: 200,
            max_queued_messages: 1000,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawCommands {
    pub ack_timeout_ms: i64,
    pub stop_ack_timeout_ms: i64,
    pub authority_keepalive_ms: i64,
}

impl Default for RawCommands {
    fn default() -> Self {
        RawCommands {
            ack_timeout_ms: 3000,
            stop_ack_timeout_ms: 6000,
            authority_keepalive_ms: 2000,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawFlight {
    pub arrival_radius_m: f64,
    pub geoid_undulation_m: f64,
    pub progress_interval_ms: i64,
    pub stall_timeout_s: f64,
}

impl Default for RawFlight {
    fn default() -> Self {
        RawFlight {
            arrival_radius_m: 1.5,
            geoid_undulation_m: 0.0,
            progress_interval_ms: 1000,
            stall_timeout_s: 30.0,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawPoi {
    pub max_circle_speed_mps: f64,
    pub initial_circle_speed_mps: f64,
}

impl Default for RawPoi {
    fn default() -> Self {
        RawPoi {
            max_circle_speed_mps: 5.0,
            initial_circle_speed_mps: 2.0,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawPayload {
    pub payload_index: String,
    pub camera: i64,
    pub hfov_deg: f64,
    pub vfov_deg: f64,
    pub zoom_max_factor: f64,
    pub pano_stations: i64,
    pub pano_pitch_deg: f64,
    pub pano_settle_timeout_ms: i64,
}

impl Default for RawPayload {
    fn default() -> Self {
        RawPayload {
            payload_index: "39-0-7".to_string(),
            camera: 1,
            hfov_deg: 82.0,
            vfov_deg: 52.0,
            zoom_max_factor: 10.0,
            pano_stations: 8,
            pano_pitch_deg: 0.0,
            pano_settle_timeout_ms: 10_000,
        }
    }
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub gateway_sn: String,
    pub vehicle_id: i64,
    pub broker: RawBroker,
    pub limits: RawLimits,
    pub commands: RawCommands,
    pub flight: RawFlight,
    pub poi: RawPoi,
    pub payload: RawPayload,
    pub drc: DrcConfig,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            gateway_sn: "SKYMESH-DOCK-1".to_string(),
            vehicle_id: 1,
            broker: RawBroker::default(),
            limits: RawLimits::default(),
            commands: RawCommands::default(),
            flight: RawFlight::default(),
            poi: RawPoi::default(),
            payload: RawPayload::default(),
            drc: DrcConfig::default(),
        }
    }
}

fn number(field: &str, v: f64, min: f64, max: f64) -> Result<f64, ConfigError> {
    if !v.is_finite() {
        return Err(ConfigError::invalid(field, "must be a finite number"));
    }
    in_range(field, v, min, max)
}

fn millis(field: &str, v: i64, min: i64, max: i64) -> Result<Duration, ConfigError> {
    in_range(field, v, min, max).map(|v| Duration::from_millis(v as u64))
}

/// `[A-Za-z0-9_-]{1,64}`: it becomes part of every topic name.
pub fn is_valid_gateway_sn(sn: &str) -> bool {
    (1..=64).contains(&sn.len())
        && sn
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// `host:port` (IPv6 host in brackets) → (host, port).
pub fn parse_host_port(field: &str, value: &str) -> Result<(String, u16), ConfigError> {
    let bad = |why: &str| ConfigError::invalid(field, format!("`{value}`: {why}"));
    let (host, port) = value
        .rsplit_once(':')
        .ok_or_else(|| bad("expected host:port"))?;
    let host = match host.strip_prefix('[') {
        Some(h) => h
            .strip_suffix(']')
            .ok_or_else(|| bad("unclosed [ in the host"))?,
        None if host.contains(':') => return Err(bad("an IPv6 host must be in brackets")),
        None => host,
    };
    if host.is_empty() || host.chars().any(|c| c.is_whitespace() || c == '/') {
        return Err(bad("expected a host name or IP address before the port"));
    }
    let port: u16 = port
        .parse()
        .map_err(|_| bad("the port must be a number 1..=65535"))?;
    if port == 0 {
        return Err(bad("the port must be 1..=65535"));
    }
    Ok((host.to_string(), port))
}

/// `type-subtype-gimbalindex`, three decimal integers.
fn is_payload_index(s: &str) -> bool {
    let parts: Vec<&str> = s.split('-').collect();
    parts.len() == 3
        && parts
            .iter()
            .all(|p| !p.is_empty() && p.len() <= 10 && p.parse::<u32>().is_ok())
}

impl RawConfig {
    fn broker(&self) -> Result<BrokerSettings, ConfigError> {
        let b = &self.broker;
        let (host, port) = parse_host_port("broker.address", &b.address)?;
        let client_id = if b.client_id.is_empty() {
            format!("skymesh-dji-{}", self.gateway_sn)
        } else {
            b.client_id.clone()
        };
        if client_id.len() > 256 {
            return Err(ConfigError::invalid(
                "broker.client_id",
                "at most 256 bytes",
            ));
        }
        if b.username.is_empty() && !b.password.is_empty() {
            return Err(ConfigError::invalid(
                "broker.password",
                "a password needs a username (MQTT 3.1.1)",
            ));
        }
        let tls_ca_file = if b.tls {
            if b.ca_file.is_empty() {
                return Err(ConfigError::invalid(
                    "broker.ca_file",
                    "required when tls = true (a PEM CA bundle)",
                ));
            }
            let path = PathBuf::from(&b.ca_file);
            // Read and parsed here so a bad bundle is a configuration error (exit 64).
            crate::tls::load_roots(&path)
                .map_err(|e| ConfigError::invalid("broker.ca_file", e.to_string()))?;
            Some(path)
        } else {
            None
        };
        let reconnect_initial = millis(
            "broker.reconnect_initial_ms",
            b.reconnect_initial_ms,
            10,
            60_000,
        )?;
        let reconnect_max = millis("broker.reconnect_max_ms", b.reconnect_max_ms, 10, 600_000)?;
        if reconnect_max < reconnect_initial {
            return Err(ConfigError::invalid(
                "broker.reconnect_max_ms",
                "must be at least reconnect_initial_ms",
            ));
        }
        Ok(BrokerSettings {
            host,
            port,
            address: b.address.clone(),
            client_id,
            username: b.username.clone(),
            password: b.password.clone(),
            tls_ca_file,
            keep_alive: Duration::from_secs(in_range(
                "broker.keep_alive_s",
                b.keep_alive_s,
                5,
                3600,
            )? as u64),
            reconnect_initial,
            reconnect_max,
        })
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/dji-gateway.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        if !is_valid_gateway_sn(&self.gateway_sn) {
            return Err(ConfigError::invalid(
                "gateway_sn",
                format!(
                    "`{}` must be 1-64 characters of [A-Za-z0-9_-]",
                    self.gateway_sn
                ),
            ));
        }
        let vehicle_id = in_range("vehicle_id", self.vehicle_id, 1, 255)? as u8;
        let broker = self.broker()?;
        let l = &self.limits;
        let limits = LimitSettings {
            max_payload_bytes: in_range(
                "limits.max_payload_bytes",
                l.max_payload_bytes,
                256,
                dji_proto::MAX_PAYLOAD_BYTES as i64,
            )? as usize,
            max_messages_per_s: in_range(
                "limits.max_messages_per_s",
                l.max_messages_per_s,
                1,
                100_000,
            )? as u32,
            max_queued_messages: in_range(
                "limits.max_queued_messages",
                l.max_queued_messages,
                1,
                100_000,
            )? as usize,
        };
        let c = &self.commands;
        let commands = CommandSettings {
            ack_timeout: millis("commands.ack_timeout_ms", c.ack_timeout_ms, 100, 60_000)?,
            stop_ack_timeout: millis(
                "commands.stop_ack_timeout_ms",
                c.stop_ack_timeout_ms,
                100,
                60_000,
            )?,
            authority_keepalive: millis(
                "commands.authority_keepalive_ms",
                c.authority_keepalive_ms,
                0,
                60_000,
            )?,
        };
        let f = &self.flight;
        let flight = FlightSettings {
            arrival_radius_m: number("flight.arrival_radius_m", f.arrival_radius_m, 0.1, 100.0)?,
            geoid_undulation_m: number(
                "flight.geoid_undulation_m",
                f.geoid_undulation_m,
                -150.0,
                150.0,
            )?,
            progress_interval: millis(
                "flight.progress_interval_ms",
                f.progress_interval_ms,
                100,
                60_000,
            )?,
            stall_timeout: Duration::from_secs_f64(number(
                "flight.stall_timeout_s",
                f.stall_timeout_s,
                1.0,
                3600.0,
            )?),
        };
        let p = &self.poi;
        let max = number(
            "poi.max_circle_speed_mps",
            p.max_circle_speed_mps,
            0.1,
            15.0,
        )?;
        let poi = PoiSettings {
            max_circle_speed_mps: max,
            initial_circle_speed_mps: number(
                "poi.initial_circle_speed_mps",
                p.initial_circle_speed_mps,
                -max,
                max,
            )?,
        };
        let pl = &self.payload;
        if !is_payload_index(&pl.payload_index) {
            return Err(ConfigError::invalid(
                "payload.payload_index",
                format!(
                    "`{}` must be type-subtype-gimbalindex (three integers)",
                    pl.payload_index
                ),
            ));
        }
        let payload = PayloadSettings {
            payload_index: pl.payload_index.clone(),
            camera: in_range("payload.camera", pl.camera, 0, 255)? as u8,
            hfov_deg: number("payload.hfov_deg", pl.hfov_deg, 1.0, 179.0)?,
            vfov_deg: number("payload.vfov_deg", pl.vfov_deg, 1.0, 179.0)?,
            zoom_max_factor: number("payload.zoom_max_factor", pl.zoom_max_factor, 2.1, 200.0)?,
            pano_stations: in_range("payload.pano_stations", pl.pano_stations, 2, 72)? as usize,
            pano_pitch_deg: number("payload.pano_pitch_deg", pl.pano_pitch_deg, -80.0, 30.0)?,
            pano_settle_timeout: millis(
                "payload.pano_settle_timeout_ms",
                pl.pano_settle_timeout_ms,
                500,
                120_000,
            )?,
        };
        self.drc
            .validate()
            .map_err(|e| ConfigError::invalid("drc", e))?;
        Ok(Settings {
            gateway_sn: self.gateway_sn,
            vehicle_id,
            broker,
            limits,
            commands,
            flight,
            poi,
            payload,
            drc: self.drc,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    fn ok(text: &str) -> Settings {
        parse::<RawConfig>(text, "test").unwrap_or_else(|e| panic!("{text}: {e}"))
    }

    fn err(text: &str) -> String {
        match parse::<RawConfig>(text, "test") {
            Ok(s) => panic!("{text}: accepted as {s:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn the_shipped_file_is_the_defaults() {
        let shipped = skymesh_runtime::config::load::<RawConfig>(None).unwrap();
        assert_eq!(shipped, ok(""));
        assert_eq!(shipped.gateway_sn, "SKYMESH-DOCK-1");
        assert_eq!(shipped.broker.client_id, "skymesh-dji-SKYMESH-DOCK-1");
        assert_eq!(
            (shipped.broker.host.as_str(), shipped.broker.port),
            ("127.0.0.1", 1883)
        );
        assert_eq!(shipped.broker.tls_ca_file, None);
        assert_eq!(shipped.limits.max_payload_bytes, 65_536);
        assert_eq!(shipped.commands.ack_timeout, Duration::from_secs(3));
        assert_eq!(shipped.commands.stop_ack_timeout, Duration::from_secs(6));
        assert_eq!(shipped.payload.payload_index, "39-0-7");
        assert_eq!(shipped.payload.pano_stations, 8);
        assert_eq!(shipped.payload.pano_pitch_deg, 0.0);
        assert_eq!(shipped.drc, DrcConfig::default());
    }

    #[test]
    fn the_test_authors_keys_parse() {
        let s = ok(r#"
gateway_sn = "SN_1-a"
vehicle_id = 3
[broker]
address = "[::1]:1884"
client_id = "me"
username = "u"
password = "p"
tls = false
ca_file = ""
keep_alive_s = 10
reconnect_initial_ms = 100
reconnect_max_ms = 1000
[limits]
max_payload_bytes = 4096
max_messages_per_s = 20
[commands]
ack_timeout_ms = 500
[flight]
arrival_radius_m = 2.0
geoid_undulation_m = 20.5
progress_interval_ms = 200
[poi]
max_circle_speed_mps = 3.0
[payload]
payload_index = "1-2-3"
camera = 0
hfov_deg = 60.0
vfov_deg = 40.0
zoom_max_factor = 5.0
pano_stations = 6
pano_pitch_deg = -20.0
pano_settle_timeout_ms = 4000
[drc]
"#);
        assert_eq!((s.broker.host.as_str(), s.broker.port), ("::1", 1884));
        assert_eq!(s.broker.client_id, "me");
        assert_eq!(s.vehicle_id, 3);
        assert_eq!(s.flight.geoid_undulation_m, 20.5);
        assert_eq!(s.poi.initial_circle_speed_mps, 2.0);
        assert_eq!(s.payload.camera, 0);
        assert_eq!(s.payload.pano_stations, 6);
        assert_eq!(s.payload.pano_pitch_deg, -20.0);
        assert_eq!(s.payload.pano_settle_timeout, Duration::from_secs(4));
    }

    #[test]
    fn bad_values_name_their_key() {
        assert!(err(r#"gateway_sn = """#).contains("gateway_sn"));
        assert!(err(r#"gateway_sn = "a/b""#).contains("gateway_sn"));
        assert!(err(&format!("gateway_sn = \"{}\"", "x".repeat(65))).contains("gateway_sn"));
        assert!(err("vehicle_id = 0").contains("vehicle_id"));
        for a in [
            "1883",
            "host:",
            ":1883",
            "host:0",
            "host:70000",
            "::1:1883",
            "[::1:1883",
        ] {
            assert!(
                err(&format!("[broker]\naddress = \"{a}\"")).contains("broker.address"),
                "{a}"
            );
        }
        assert!(err("[broker]\ntls = true").contains("broker.ca_file"));
        assert!(err("[broker]\ntls = true\nca_file = \"/nonexistent.pem\"").contains("ca_file"));
        assert!(err("[broker]\npassword = \"x\"").contains("broker.password"));
        assert!(
            err("[broker]\nreconnect_initial_ms = 5000\nreconnect_max_ms = 1000")
                .contains("reconnect_max_ms")
        );
        assert!(err("[limits]\nmax_payload_bytes = 1000000").contains("max_payload_bytes"));
        assert!(err("[limits]\nmax_messages_per_s = 0").contains("max_messages_per_s"));
        assert!(err("[commands]\nack_timeout_ms = 0").contains("ack_timeout_ms"));
        assert!(err("[flight]\narrival_radius_m = nan").contains("arrival_radius_m"));
        assert!(err("[poi]\nmax_circle_speed_mps = 0").contains("max_circle_speed_mps"));
        assert!(err("[poi]\ninitial_circle_speed_mps = -6").contains("initial_circle_speed_mps"));
        assert!(err("[payload]\npayload_index = \"39-0\"").contains("payload_index"));
        assert!(err("[payload]\nzoom_max_factor = 2").contains("zoom_max_factor"));
        assert!(err("[payload]\nhfov_deg = 180").contains("hfov_deg"));
        assert!(err("[payload]\npano_stations = 1").contains("pano_stations"));
        assert!(err("[payload]\npano_pitch_deg = -90").contains("pano_pitch_deg"));
        assert!(err("[payload]\npano_settle_timeout_ms = 0").contains("pano_settle_timeout_ms"));
        // Unknown keys anywhere are refused.
        assert!(err("bogus = 1").contains("bogus"));
        assert!(err("[flight]\nbogus = 1").contains("bogus"));
    }

    #[test]
    fn tls_needs_a_readable_ca_bundle() {
        let dir = tempfile::tempdir().unwrap();
        let empty = dir.path().join("empty.pem");
        std::fs::write(&empty, "no certificates here\n").unwrap();
        let e = err(&format!(
            "[broker]\ntls = true\nca_file = \"{}\"",
            empty.display()
        ));
        assert!(e.contains("no certificate"), "{e}");
        let good = dir.path().join("ca.pem");
        std::fs::write(&good, crate::tls::TEST_CA_PEM).unwrap();
        let s = ok(&format!(
            "[broker]\ntls = true\nca_file = \"{}\"",
            good.display()
        ));
        assert_eq!(s.broker.tls_ca_file.as_deref(), Some(good.as_path()));
    }
}
