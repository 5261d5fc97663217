//! Configuration: the raw TOML shape (`RawConfig`) and the validated `Settings`
//! the rest of the crate sees.
//!
//! Every field has a default so an empty file is a valid configuration; the
//! shipped, commented defaults live in `deploy/vehicle-sim.toml` and are embedded
//! as [`DEFAULT_CONFIG_TOML`].

use std::time::Duration;

use serde::Deserialize;

use crate::model::{GeoPoint, VehicleParams, CMAC_GEOID_UNDULATION_M};

mod endpoint;
mod swarm;
#[cfg(test)]
mod tests;

pub use endpoint::{parse_endpoint, Endpoint};
use swarm::validate_swarm;
pub use swarm::{RawSwarm, SwarmLayout, SwarmSettings, VehicleSpec, MAX_SWARM};

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../../deploy/vehicle-sim.toml");

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

pub(super) fn range(
    field: &'static str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<(), ConfigError> {
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
