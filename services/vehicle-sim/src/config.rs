//! Configuration: the raw TOML shape (`RawConfig`) and the validated `Settings`
//! the rest of the crate sees.
//!
//! Every field has a default so an empty file is a valid configuration; the
//! shipped, commented defaults live in `deploy/vehicle-sim.toml` and are embedded
//! as [`DEFAULT_CONFIG_TOML`].

use std::net::SocketAddr;
use std::time::Duration;

use nalgebra::Vector3;
use serde::Deserialize;

use crate::model::{GeoPoint, LocalFrame, VehicleParams, CMAC_GEOID_UNDULATION_M};

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../deploy/vehicle-sim.toml");

/// MAVLink component id of the simulated autopilot (MAV_COMP_ID_AUTOPILOT1).
pub const COMPONENT_ID: u8 = 1;

/// MAVLink component id of the simulated gimbal (MAV_COMP_ID_GIMBAL), which
/// bridges the GoPro as the Solo gimbal does: GOPRO_* messages come from it.
pub const GIMBAL_COMPONENT_ID: u8 = 154;

/// The gimbal sends GOPRO_HEARTBEAT once a second while a GoPro is fitted.
pub const GOPRO_HEARTBEAT_INTERVAL: Duration = Duration::from_secs(1);

/// The physics tick: the model is always stepped with this fixed dt, and
/// telemetry streams are evaluated once per tick, so no stream can run faster.
pub const PHYSICS_HZ: u32 = 100;

/// The configuration file as written. Unknown keys are an error so typos don't
/// silently fall back to defaults.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    /// `tcp:IP:PORT` (any number of clients) or `udp:IP:PORT` (replies to every peer).
    pub endpoint: String,
    /// MAVLink system id of the vehicle (1..=255).
    pub system_id: u32,
    /// Home / EKF origin latitude, degrees.
    pub home_lat: f64,
    /// Home / EKF origin longitude, degrees.
    pub home_lon: f64,
    /// Home / ground altitude above mean sea level, metres.
    pub home_alt_msl: f64,
    /// Height of the geoid above the WGS-84 ellipsoid at home, metres (GPS_RAW_INT
    /// `alt_ellipsoid` = MSL altitude + this); the default suits the default home.
    pub geoid_undulation_m: f64,
    /// Initial heading, degrees clockwise from north.
    pub home_heading_deg: f64,
    /// Seconds after start until the EKF reports a good position (arming is refused before).
    pub ekf_ready_after_s: f64,
    /// Battery capacity, mAh.
    pub battery_capacity_mah: f64,
    /// Number of LiPo cells in series.
    pub battery_cells: u32,
    /// State of charge at start, percent.
    pub battery_initial_percent: f64,
    /// Arming is refused below this state of charge, percent.
    pub battery_arm_min_percent: f64,
    /// Battery current while hovering, amperes.
    pub hover_current_a: f64,
    /// Horizontal speed limit (ArduCopter WPNAV_SPEED), m/s.
    pub max_speed_mps: f64,
    /// Climb rate limit (WPNAV_SPEED_UP), m/s.
    pub max_climb_mps: f64,
    /// Descent rate limit (WPNAV_SPEED_DN), m/s.
    pub max_descent_mps: f64,
    /// Acceleration limit, horizontal and vertical, m/s².
    pub max_accel_mps2: f64,
    /// Yaw rate limit, degrees/s.
    pub max_yaw_rate_dps: f64,
    /// Final descent speed in LAND (LAND_SPEED), m/s.
    pub land_speed_mps: f64,
    /// RTL climbs to at least this altitude above home (RTL_ALT), metres.
    pub rtl_alt_m: f64,
    /// Landed and armed for this long disarms the motors (DISARM_DELAY), seconds.
    pub disarm_delay_s: f64,
    /// Guided velocity/yaw-rate setpoints expire after this long, seconds.
    pub velocity_timeout_s: f64,
    /// Default ATTITUDE rate per link, Hz (0 = off).
    pub default_attitude_hz: f64,
    /// Default rate of the other periodic telemetry per link, Hz (0 = off).
    pub default_stream_hz: f64,
    /// Default GIMBAL_DEVICE_ATTITUDE_STATUS rate per link, Hz (0 = off).
    pub gimbal_attitude_hz: f64,
    /// Default SERVO_OUTPUT_RAW rate per link, Hz (0 = off).
    pub servo_output_hz: f64,
    /// Gimbal slew rate, degrees/s.
    pub gimbal_slew_rate_dps: f64,
    /// A GoPro HERO4 Black sits behind the gimbal's MAVLink GoPro bridge.
    pub gopro: bool,
    /// Maximum simultaneous TCP clients (further connections are refused) or
    /// remembered UDP peers (the oldest is forgotten), per vehicle.
    pub max_clients: u32,
    /// Swarm mode: one process serving several vehicles (`count` 0 = one vehicle).
    pub swarm: RawSwarm,
}

/// The `[swarm]` table as written.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawSwarm {
    /// Vehicles served by this process, 0..=[`MAX_SWARM`] (0 = swarm mode off).
    pub count: u32,
    /// Vehicle `i` (0-based) listens on the configured port + `i × port_step`.
    pub port_step: u32,
    /// Distance between neighbouring vehicles' homes, metres.
    pub spacing_m: f64,
    /// `"grid"` (rows of ⌈√count⌉ vehicles going east, rows stacked north) or
    /// `"line"` (one row going east).
    pub layout: String,
}

impl Default for RawSwarm {
    fn default() -> Self {
        Self {
            count: 0,
            port_step: 1,
            spacing_m: 3.0,
            layout: "grid".to_owned(),
        }
    }
}

/// Most vehicles one process may serve.
pub const MAX_SWARM: u32 = 250;

impl Default for RawConfig {
    fn default() -> Self {
        Self {
            endpoint: "tcp:127.0.0.1:5760".to_owned(),
            system_id: 1,
            home_lat: -35.363_261,
            home_lon: 149.165_230,
            home_alt_msl: 584.0,
            geoid_undulation_m: CMAC_GEOID_UNDULATION_M,
            home_heading_deg: 353.0,
            ekf_ready_after_s: 0.0,
            battery_capacity_mah: 5200.0,
            battery_cells: 4,
            battery_initial_percent: 100.0,
            battery_arm_min_percent: 20.0,
            hover_current_a: 15.0,
            max_speed_mps: 5.0,
            max_climb_mps: 2.5,
            max_descent_mps: 1.5,
            max_accel_mps2: 2.5,
            max_yaw_rate_dps: 90.0,
            land_speed_mps: 0.5,
            rtl_alt_m: 15.0,
            disarm_delay_s: 10.0,
            velocity_timeout_s: 3.0,
            default_attitude_hz: 10.0,
            default_stream_hz: 1.0,
            gimbal_attitude_hz: 10.0,
            servo_output_hz: 2.0,
            gimbal_slew_rate_dps: 90.0,
            gopro: true,
            max_clients: 16,
            swarm: RawSwarm::default(),
        }
    }
}

/// Where the simulator listens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endpoint {
    /// Serve MAVLink over TCP; every accepted client is its own link.
    Tcp(SocketAddr),
    /// Serve MAVLink over UDP; every peer that has sent a packet gets the telemetry.
    Udp(SocketAddr),
}

impl Endpoint {
    /// The socket address to bind.
    pub fn addr(&self) -> SocketAddr {
        match self {
            Endpoint::Tcp(a) | Endpoint::Udp(a) => *a,
        }
    }
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Endpoint::Tcp(a) => write!(f, "tcp:{a}"),
            Endpoint::Udp(a) => write!(f, "udp:{a}"),
        }
    }
}

/// Default per-link stream intervals (`None` = not sent until asked).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamDefaults {
    /// ATTITUDE.
    pub attitude: Option<Duration>,
    /// SYS_STATUS, GPS_RAW_INT, GLOBAL_POSITION_INT, LOCAL_POSITION_NED, VFR_HUD,
    /// BATTERY_STATUS, EKF_STATUS_REPORT.
    pub telemetry: Option<Duration>,
    /// GIMBAL_DEVICE_ATTITUDE_STATUS.
    pub gimbal_attitude: Option<Duration>,
    /// SERVO_OUTPUT_RAW.
    pub servo_output: Option<Duration>,
    /// GOPRO_HEARTBEAT (1 s with a GoPro, `None` without).
    pub gopro_heartbeat: Option<Duration>,
}

/// How a swarm's homes are laid out around the configured home.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwarmLayout {
    /// Rows of ⌈√count⌉ vehicles: vehicle `i` stands `(i mod cols) × spacing`
    /// east and `(i div cols) × spacing` north of the configured home.
    Grid,
    /// One row: vehicle `i` stands `i × spacing` east of the configured home.
    Line,
}

/// Validated `[swarm]` settings (present only when `count` ≥ 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwarmSettings {
    /// Vehicles served, 1..=[`MAX_SWARM`].
    pub count: u8,
    /// Port increment per vehicle.
    pub port_step: u16,
    /// Metres between neighbouring homes.
    pub spacing_m: f64,
    /// Where the homes are.
    pub layout: SwarmLayout,
}

impl SwarmSettings {
    /// Vehicle `index`'s home offset from the configured home: (north, east), metres.
    pub fn offset_ne(&self, index: usize) -> (f64, f64) {
        match self.layout {
            SwarmLayout::Line => (0.0, index as f64 * self.spacing_m),
            SwarmLayout::Grid => {
                let cols = grid_columns(usize::from(self.count));
                (
                    (index / cols) as f64 * self.spacing_m,
                    (index % cols) as f64 * self.spacing_m,
                )
            }
        }
    }
}

/// Columns of a grid of `count` vehicles: ⌈√count⌉ (at least 1).
fn grid_columns(count: usize) -> usize {
    let mut cols = 1;
    while cols * cols < count {
        cols += 1;
    }
    cols
}

/// Validated settings: parsed addresses, durations and ranges.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Where to listen (vehicle 0's endpoint in swarm mode).
    pub endpoint: Endpoint,
    /// MAVLink system id (vehicle 0's in swarm mode).
    pub system_id: u8,
    /// Vehicle model parameters (home, limits, battery); vehicle 0's in swarm mode.
    pub vehicle: VehicleParams,
    /// Default stream rates for a new link.
    pub streams: StreamDefaults,
    /// Maximum simultaneous TCP clients / remembered UDP peers, per vehicle.
    pub max_clients: usize,
    /// Swarm mode: `None` serves the one vehicle above.
    pub swarm: Option<SwarmSettings>,
}

/// One vehicle of the process: its id, endpoint and model parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleSpec {
    /// 0-based index in the swarm (0 without swarm mode).
    pub index: usize,
    /// MAVLink system id: `system_id + index`.
    pub system_id: u8,
    /// Where it listens: the configured port + `index × port_step` (port 0
    /// stays 0: every vehicle gets its own ephemeral port).
    pub endpoint: Endpoint,
    /// Model parameters, home moved by the layout's offset.
    pub vehicle: VehicleParams,
}

impl Settings {
    /// Number of vehicles served (1 without swarm mode).
    pub fn vehicle_count(&self) -> usize {
        self.swarm.map_or(1, |s| usize::from(s.count))
    }

    /// Every vehicle this process serves, in index order.
    pub fn vehicles(&self) -> Vec<VehicleSpec> {
        let Some(swarm) = self.swarm else {
            return vec![VehicleSpec {
                index: 0,
                system_id: self.system_id,
                endpoint: self.endpoint,
                vehicle: self.vehicle.clone(),
            }];
        };
        let frame = LocalFrame::new(self.vehicle.home);
        (0..usize::from(swarm.count))
            .map(|i| {
                let (north, east) = swarm.offset_ne(i);
                let mut vehicle = self.vehicle.clone();
                vehicle.home = frame.to_geo(&Vector3::new(north, east, 0.0));
                let mut addr = self.endpoint.addr();
                if addr.port() != 0 {
                    // Validated: every port fits in u16.
                    addr.set_port(addr.port() + i as u16 * swarm.port_step);
                }
                VehicleSpec {
                    index: i,
                    // Validated: system_id + count - 1 ≤ 255.
                    system_id: self.system_id + i as u8,
                    endpoint: match self.endpoint {
                        Endpoint::Tcp(_) => Endpoint::Tcp(addr),
                        Endpoint::Udp(_) => Endpoint::Udp(addr),
                    },
                    vehicle,
                }
            })
            .collect()
    }
}

/// Why a configuration was rejected.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ConfigError {
    /// The TOML did not parse or had unknown keys.
    #[error("config is not valid TOML for vehicle-sim: {0}")]
    Toml(String),
    /// `endpoint` is malformed.
    #[error(
        "endpoint {value:?} is invalid: {reason} (expected \"tcp:IP:PORT\" or \"udp:IP:PORT\")"
    )]
    Endpoint {
        /// The configured value.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
    /// `system_id` outside 1..=255.
    #[error("system_id {0} is out of range: MAVLink system ids are 1..=255 (0 is broadcast)")]
    SystemId(u32),
    /// A number outside its allowed range (or not finite).
    #[error("{field} = {value} is out of range: must be within {min}..={max}")]
    OutOfRange {
        /// The key.
        field: &'static str,
        /// The configured value.
        value: f64,
        /// Inclusive lower bound.
        min: f64,
        /// Inclusive upper bound.
        max: f64,
    },
    /// A cross-field constraint failed.
    #[error("{0}")]
    Inconsistent(String),
}

impl RawConfig {
    /// Parse a TOML document (unknown keys are rejected).
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        toml::from_str(text).map_err(|e| ConfigError::Toml(e.to_string()))
    }

    /// Check every field and convert to [`Settings`].
    pub fn validate(self) -> Result<Settings, ConfigError> {
        let endpoint = parse_endpoint(&self.endpoint)?;
        let system_id = match u8::try_from(self.system_id) {
            Ok(id) if id != 0 => id,
            _ => return Err(ConfigError::SystemId(self.system_id)),
        };
        range("home_lat", self.home_lat, -90.0, 90.0)?;
        range("home_lon", self.home_lon, -180.0, 180.0)?;
        range("home_alt_msl", self.home_alt_msl, -500.0, 10_000.0)?;
        // The geoid lies within about -107..+86 m of the ellipsoid everywhere.
        range("geoid_undulation_m", self.geoid_undulation_m, -120.0, 100.0)?;
        range("home_heading_deg", self.home_heading_deg, 0.0, 360.0)?;
        range("ekf_ready_after_s", self.ekf_ready_after_s, 0.0, 3600.0)?;
        range(
            "battery_capacity_mah",
            self.battery_capacity_mah,
            100.0,
            1.0e6,
        )?;
        range("battery_cells", f64::from(self.battery_cells), 1.0, 14.0)?;
        range(
            "battery_initial_percent",
            self.battery_initial_percent,
            0.0,
            100.0,
        )?;
        range(
            "battery_arm_min_percent",
            self.battery_arm_min_percent,
            0.0,
            100.0,
        )?;
        range("hover_current_a", self.hover_current_a, 0.0, 1000.0)?;
        range("max_speed_mps", self.max_speed_mps, 0.1, 50.0)?;
        range("max_climb_mps", self.max_climb_mps, 0.1, 20.0)?;
        range("max_descent_mps", self.max_descent_mps, 0.1, 20.0)?;
        range("max_accel_mps2", self.max_accel_mps2, 0.1, 20.0)?;
        range("max_yaw_rate_dps", self.max_yaw_rate_dps, 1.0, 720.0)?;
        range("land_speed_mps", self.land_speed_mps, 0.1, 5.0)?;
        range("rtl_alt_m", self.rtl_alt_m, 0.0, 1000.0)?;
        range("disarm_delay_s", self.disarm_delay_s, 0.0, 600.0)?;
        range("velocity_timeout_s", self.velocity_timeout_s, 0.1, 60.0)?;
        let max_hz = f64::from(PHYSICS_HZ);
        range("default_attitude_hz", self.default_attitude_hz, 0.0, max_hz)?;
        range("default_stream_hz", self.default_stream_hz, 0.0, max_hz)?;
        range("gimbal_attitude_hz", self.gimbal_attitude_hz, 0.0, max_hz)?;
        range("servo_output_hz", self.servo_output_hz, 0.0, max_hz)?;
        range(
            "gimbal_slew_rate_dps",
            self.gimbal_slew_rate_dps,
            1.0,
            720.0,
        )?;
        range("max_clients", f64::from(self.max_clients), 1.0, 1024.0)?;
        let swarm = validate_swarm(&self.swarm, system_id, endpoint)?;
        if self.land_speed_mps > self.max_descent_mps {
            return Err(ConfigError::Inconsistent(format!(
                "land_speed_mps ({}) must not exceed max_descent_mps ({})",
                self.land_speed_mps, self.max_descent_mps
            )));
        }

        let vehicle = VehicleParams {
            home: GeoPoint {
                lat_deg: self.home_lat,
                lon_deg: self.home_lon,
                alt_msl_m: self.home_alt_msl,
            },
            geoid_undulation_m: self.geoid_undulation_m,
            initial_heading_rad: self.home_heading_deg.to_radians(),
            ekf_ready_after_s: self.ekf_ready_after_s,
            battery_capacity_mah: self.battery_capacity_mah,
            battery_cells: self.battery_cells,
            battery_initial_fraction: self.battery_initial_percent / 100.0,
            battery_arm_min_fraction: self.battery_arm_min_percent / 100.0,
            hover_current_a: self.hover_current_a,
            max_speed_xy: self.max_speed_mps,
            max_speed_up: self.max_climb_mps,
            max_speed_down: self.max_descent_mps,
            max_accel: self.max_accel_mps2,
            max_yaw_rate: self.max_yaw_rate_dps.to_radians(),
            land_speed: self.land_speed_mps,
            rtl_alt_m: self.rtl_alt_m,
            disarm_delay_s: self.disarm_delay_s,
            velocity_timeout_s: self.velocity_timeout_s,
            gimbal_slew_rate: self.gimbal_slew_rate_dps.to_radians(),
            gopro: self.gopro,
        };
        Ok(Settings {
            endpoint,
            system_id,
            vehicle,
            streams: StreamDefaults {
                attitude: hz_to_interval(self.default_attitude_hz),
                telemetry: hz_to_interval(self.default_stream_hz),
                gimbal_attitude: hz_to_interval(self.gimbal_attitude_hz),
                servo_output: hz_to_interval(self.servo_output_hz),
                gopro_heartbeat: self.gopro.then_some(GOPRO_HEARTBEAT_INTERVAL),
            },
            max_clients: self.max_clients as usize,
            swarm,
        })
    }
}

fn validate_swarm(
    raw: &RawSwarm,
    system_id: u8,
    endpoint: Endpoint,
) -> Result<Option<SwarmSettings>, ConfigError> {
    range(
        "swarm.count",
        f64::from(raw.count),
        0.0,
        f64::from(MAX_SWARM),
    )?;
    range("swarm.port_step", f64::from(raw.port_step), 1.0, 1000.0)?;
    range("swarm.spacing_m", raw.spacing_m, 0.5, 1000.0)?;
    let layout = match raw.layout.as_str() {
        "grid" => SwarmLayout::Grid,
        "line" => SwarmLayout::Line,
        other => {
            return Err(ConfigError::Inconsistent(format!(
                "swarm.layout {other:?} is unknown: expected \"grid\" or \"line\""
            )))
        }
    };
    if raw.count == 0 {
        return Ok(None);
    }
    let last = raw.count - 1;
    if u32::from(system_id) + last > 255 {
        return Err(ConfigError::Inconsistent(format!(
            "swarm.count = {} from system_id {system_id} needs system ids up to {}: \
             MAVLink system ids end at 255",
            raw.count,
            u32::from(system_id) + last
        )));
    }
    let port = u32::from(endpoint.addr().port());
    if port != 0 && port + last * raw.port_step > u32::from(u16::MAX) {
        return Err(ConfigError::Inconsistent(format!(
            "swarm.count = {} with swarm.port_step = {} from port {port} needs ports up to {}: \
             ports end at 65535",
            raw.count,
            raw.port_step,
            port + last * raw.port_step
        )));
    }
    Ok(Some(SwarmSettings {
        // Checked above: count ≤ 250.
        count: raw.count as u8,
        port_step: raw.port_step as u16,
        spacing_m: raw.spacing_m,
        layout,
    }))
}

fn range(field: &'static str, value: f64, min: f64, max: f64) -> Result<(), ConfigError> {
    // `contains` is false for NaN, so non-finite values are rejected here too.
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ConfigError::OutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}

fn hz_to_interval(hz: f64) -> Option<Duration> {
    (hz > 0.0).then(|| Duration::from_secs_f64(1.0 / hz))
}

/// Parse `tcp:IP:PORT` / `udp:IP:PORT` (`tcpin:`/`udpin:` accepted as synonyms,
/// as the mavlink crate spells listening endpoints).
pub fn parse_endpoint(value: &str) -> Result<Endpoint, ConfigError> {
    let err = |reason: &str| ConfigError::Endpoint {
        value: value.to_owned(),
        reason: reason.to_owned(),
    };
    let (scheme, rest) = value.split_once(':').ok_or_else(|| err("missing scheme"))?;
    let addr: SocketAddr = rest
        .parse()
        .map_err(|_| err("address must be a literal IP:PORT"))?;
    match scheme {
        "tcp" | "tcpin" => Ok(Endpoint::Tcp(addr)),
        "udp" | "udpin" => Ok(Endpoint::Udp(addr)),
        "tcpout" | "udpout" => Err(err("the simulator listens; use tcp: or udp:")),
        _ => Err(err("unknown scheme")),
    }
}

#[cfg(test)]
mod tests {
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
    fn swarm_off_by_default_is_one_vehicle() {
        let s = RawConfig::default().validate().expect("valid");
        assert_eq!(s.swarm, None);
        let v = s.vehicles();
        assert_eq!(v.len(), 1);
        assert_eq!(s.vehicle_count(), 1);
        assert_eq!(
            (v[0].index, v[0].system_id, v[0].endpoint),
            (0, 1, s.endpoint)
        );
        assert_eq!(v[0].vehicle, s.vehicle);
        let zero = RawConfig::from_toml("[swarm]\ncount = 0\n")
            .and_then(RawConfig::validate)
            .expect("valid");
        assert_eq!(zero.swarm, None);
    }

    #[test]
    fn swarm_ids_ports_and_grid_homes() {
        let s = RawConfig::from_toml(
            "endpoint = \"tcp:127.0.0.1:5760\"\nsystem_id = 10\n\
             [swarm]\ncount = 5\nport_step = 10\nspacing_m = 3.0\nlayout = \"grid\"\n",
        )
        .and_then(RawConfig::validate)
        .expect("valid");
        assert_eq!(s.vehicle_count(), 5);
        let v = s.vehicles();
        let ids: Vec<u8> = v.iter().map(|v| v.system_id).collect();
        assert_eq!(ids, [10, 11, 12, 13, 14]);
        let ports: Vec<u16> = v.iter().map(|v| v.endpoint.addr().port()).collect();
        assert_eq!(ports, [5760, 5770, 5780, 5790, 5800]);
        assert!(v.iter().all(|v| matches!(v.endpoint, Endpoint::Tcp(_))));
        // 5 vehicles: rows of ⌈√5⌉ = 3, going east, the second row 3 m north.
        let frame = LocalFrame::new(s.vehicle.home);
        let ne: Vec<(f64, f64)> = v
            .iter()
            .map(|v| {
                let p = frame.to_ned(&v.vehicle.home);
                assert!(p.z.abs() < 1e-9, "same ground altitude");
                ((p.x * 100.0).round() / 100.0, (p.y * 100.0).round() / 100.0)
            })
            .collect();
        assert_eq!(
            ne,
            [(0.0, 0.0), (0.0, 3.0), (0.0, 6.0), (3.0, 0.0), (3.0, 3.0)]
        );
        assert_eq!(v[0].vehicle, s.vehicle, "vehicle 0 is the configured one");
        // Everything else is shared.
        assert!(v
            .iter()
            .all(|x| x.vehicle.max_speed_xy == s.vehicle.max_speed_xy));
    }

    #[test]
    fn swarm_line_layout_udp_and_ephemeral_ports() {
        let s = RawConfig::from_toml(
            "endpoint = \"udp:127.0.0.1:0\"\n[swarm]\ncount = 3\nlayout = \"line\"\nspacing_m = 5\n",
        )
        .and_then(RawConfig::validate)
        .expect("valid");
        let v = s.vehicles();
        assert!(v
            .iter()
            .all(|v| v.endpoint == Endpoint::Udp(SocketAddr::from(([127, 0, 0, 1], 0)))));
        let frame = LocalFrame::new(s.vehicle.home);
        let east: Vec<f64> = v
            .iter()
            .map(|v| (frame.to_ned(&v.vehicle.home).y * 100.0).round() / 100.0)
            .collect();
        assert_eq!(east, [0.0, 5.0, 10.0]);
        assert_eq!(grid_columns(1), 1);
        assert_eq!(grid_columns(4), 2);
        assert_eq!(grid_columns(5), 3);
        assert_eq!(grid_columns(250), 16);
    }

    #[test]
    fn shipped_swarm_example_parses_when_uncommented() {
        let start = DEFAULT_CONFIG_TOML
            .find("# [swarm]")
            .expect("the shipped file documents [swarm]");
        let table: String = DEFAULT_CONFIG_TOML[start..]
            .lines()
            .filter_map(|l| l.strip_prefix("# "))
            .filter(|l| !l.trim_start().starts_with('#'))
            .map(|l| format!("{l}\n"))
            .collect();
        let raw = RawConfig::from_toml(&table).expect("uncommented [swarm] parses");
        assert_eq!(
            raw.swarm,
            RawSwarm::default(),
            "documented values are the defaults"
        );
        let raw = RawConfig::from_toml(&table.replace("count = 0", "count = 4"))
            .and_then(RawConfig::validate)
            .expect("valid");
        assert_eq!(raw.vehicle_count(), 4);
    }

    #[test]
    fn swarm_limits() {
        let check = |toml: &str| RawConfig::from_toml(toml).and_then(RawConfig::validate);
        // 250 vehicles fit with the defaults.
        let s = check("[swarm]\ncount = 250\n").expect("250 vehicles");
        let v = s.vehicles();
        assert_eq!(v.len(), 250);
        assert_eq!(v[249].system_id, 250);
        assert_eq!(v[249].endpoint.addr().port(), 5760 + 249);
        for (toml, needle) in [
            ("[swarm]\ncount = 251\n", "swarm.count"),
            ("system_id = 7\n[swarm]\ncount = 250\n", "255"),
            ("system_id = 206\n[swarm]\ncount = 51\n", "256"),
            (
                "endpoint = \"tcp:127.0.0.1:65000\"\n[swarm]\ncount = 10\nport_step = 100\n",
                "65535",
            ),
            ("[swarm]\ncount = 2\nport_step = 0\n", "swarm.port_step"),
            ("[swarm]\ncount = 2\nspacing_m = 0\n", "swarm.spacing_m"),
            ("[swarm]\ncount = 2\nspacing_m = nan\n", "swarm.spacing_m"),
            ("[swarm]\ncount = 2\nlayout = \"circle\"\n", "swarm.layout"),
            ("[swarm]\ncount = 2\nsize = 3\n", "size"),
        ] {
            let e = check(toml).expect_err(toml);
            assert!(e.to_string().contains(needle), "{toml}: {e}");
        }
        // The last id and port exactly at their limits are fine.
        let s = check("system_id = 206\nendpoint = \"tcp:127.0.0.1:65486\"\n[swarm]\ncount = 50\n")
            .expect("ids up to 255, ports up to 65535");
        let v = s.vehicles();
        assert_eq!(v[49].system_id, 255);
        assert_eq!(v[49].endpoint.addr().port(), 65535);
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
    fn endpoints() {
        assert_eq!(
            parse_endpoint("udp:127.0.0.1:14560"),
            Ok(Endpoint::Udp(SocketAddr::from(([127, 0, 0, 1], 14560))))
        );
        assert!(matches!(
            parse_endpoint("tcpin:[::1]:5760"),
            Ok(Endpoint::Tcp(_))
        ));
        for bad in [
            "127.0.0.1:5760",
            "tcp:localhost:5760",
            "udpout:1.2.3.4:5",
            "serial:/dev/tty",
            "tcp:127.0.0.1",
        ] {
            assert!(parse_endpoint(bad).is_err(), "{bad} should be rejected");
        }
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
}
