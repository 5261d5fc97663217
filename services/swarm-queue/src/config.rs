//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key but the drone list is optional; the shipped, commented defaults are
//! `deploy/swarm-queue.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]). Unknown
//! keys and out-of-range values are refused (exit code 64).
//!
//! `animations_dir` is relative to the directory of the config file given with
//! `--config` (or `$SKYMESH_CONFIG`); with the embedded default it is relative to the
//! current directory. The runtime hands `validate` no path, so `main` records the
//! config file's directory first ([`set_config_dir_from_args`]).

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use serde::Deserialize;
use skymesh_ipc_types::SWARM_MAX_DRONES;
use skymesh_runtime::config::finite;
use skymesh_runtime::config::in_range;
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::site::SiteFrame;

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../deploy/swarm-queue.toml");

/// What happens to a waypoint outside the drone's bounding box.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoxPolicy {
    /// Moved to the nearest point inside the box (logged); the command runs.
    Clamp,
    /// Refused ("outside the bounding box"); nothing is flown.
    Refuse,
}

/// One drone: GroundControl id ↔ vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DroneConfig {
    /// GroundControl drone id (`context`), 0..=65534.
    pub id: u16,
    /// MAVLink system id of its vehicle (the `{id}` of `skymesh/vehicle/{id}/...`).
    pub vehicle_id: u8,
    /// The "setup" home in the site frame (`RESET_HOME_TO_SETUP`); `None` = the
    /// autopilot's own home as first reported.
    pub home: Option<[f32; 3]>,
}

/// How long commands may run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timeouts {
    /// `GO_EXTERNAL`: from the first command until the takeoff altitude is reached.
    pub takeoff: Duration,
    /// `GO_HOME_AT_POSITION`, and the landing part of `GO_HOME`.
    pub land: Duration,
    /// `WAYPOINT`: `waypoint_base + waypoint_factor × distance / speed`.
    pub waypoint_base: Duration,
    pub waypoint_factor: f32,
    /// A command answered only by the vehicle (home, motors, rotation, emergency):
    /// no acknowledgement in this time → `Timeout`.
    pub ack: Duration,
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The site frame's origin (x east, y north, z up metres around it).
    pub site: SiteFrame,
    /// Every drone served, in configuration order (also the order in `SwarmState`).
    pub drones: Vec<DroneConfig>,
    /// Queue tick: drains the vehicle topics, steps every drone, publishes `SwarmState`.
    pub tick_period: Duration,
    /// A waypoint (and takeoff altitude, and home) counts as reached this close, m.
    pub waypoint_tolerance_m: f32,
    /// Waypoint speed when a command gives 0, m/s.
    pub default_speed_mps: f32,
    /// `GO_EXTERNAL` climbs to this height above home, m.
    pub takeoff_alt_m: f32,
    pub bounding_box: BoxPolicy,
    /// Where `drone_<id>.csv` animations are read from (absolute once validated).
    pub animations_dir: PathBuf,
    pub timeouts: Timeouts,
    /// The drone whose LEDs and LCD are on this computer's hardware service.
    pub hardware_drone: Option<u16>,
    /// Characters per LCD line: a longer `TEXT` continues on line 1.
    pub lcd_width: usize,
    /// Commands waiting per drone; more are refused "queue full".
    pub queue_capacity: usize,
    /// Replies published per tick at most (the rest wait for the next tick), so
    /// bursts never overrun the reply topic's subscriber buffer.
    pub max_replies_per_tick: usize,
    /// Highest rate of position targets per drone while following or animating.
    pub setpoint_period: Duration,
    /// A drone this low above home (m) and slower vertically than 0.3 m/s is landed.
    pub landed_alt_m: f32,
    /// A position older than this is not valid (POSE_VALID cleared, no new motion).
    pub pose_timeout: Duration,
    /// No `VehicleStatus` for this long (or `link_up = 0`) → LINK_DOWN.
    pub link_timeout: Duration,
    /// While a drone's current command flies a position target (`GoTo`, `Takeoff`),
    /// a flight command goes to its vehicle at least this often (a
    /// `GrabFlightAuthority` when nothing else was sent): the arbiter brakes a
    /// position target whose source fell silent for its authority timeout.
    pub authority_keepalive: Duration,
}

/// `[site_origin]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawOrigin {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_msl_m: f64,
}

/// `[drones]`: `count` drones numbered from `first_id`, vehicles from `first_vehicle_id`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawDroneRange {
    pub first_id: i64,
    pub count: i64,
    pub first_vehicle_id: i64,
}

/// One `[[drone]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawDrone {
    pub id: i64,
    pub vehicle_id: i64,
    #[serde(default)]
    pub home: Option<[f64; 3]>,
}

/// `[timeouts]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawTimeouts {
    pub takeoff_s: f64,
    pub land_s: f64,
    pub waypoint_base_s: f64,
    pub waypoint_factor: f64,
    pub ack_s: f64,
}

impl Default for RawTimeouts {
    fn default() -> Self {
        RawTimeouts {
            takeoff_s: 30.0,
            land_s: 90.0,
            waypoint_base_s: 10.0,
            waypoint_factor: 3.0,
            ack_s: 5.0,
        }
    }
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub site_origin: Option<RawOrigin>,
    pub drones: Option<RawDroneRange>,
    pub drone: Vec<RawDrone>,
    pub tick_hz: f64,
    pub waypoint_tolerance_m: f64,
    pub default_speed_mps: f64,
    pub takeoff_alt_m: f64,
    pub bounding_box: String,
    pub animations_dir: String,
    pub timeouts: RawTimeouts,
    pub hardware_drone: Option<i64>,
    pub lcd_width: i64,
    pub queue_capacity: i64,
    pub max_replies_per_tick: i64,
    pub setpoint_hz: f64,
    pub landed_alt_m: f64,
    pub pose_timeout_s: f64,
    pub link_timeout_s: f64,
    pub authority_keepalive_ms: i64,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            site_origin: None,
            drones: None,
            drone: Vec::new(),
            tick_hz: 30.0,
            waypoint_tolerance_m: 0.5,
            default_speed_mps: 2.0,
            takeoff_alt_m: 2.5,
            bounding_box: "clamp".into(),
            animations_dir: "animations".into(),
            timeouts: RawTimeouts::default(),
            hardware_drone: None,
            lcd_width: 16,
            queue_capacity: 256,
            max_replies_per_tick: 256,
            setpoint_hz: 10.0,
            landed_alt_m: 0.3,
            pose_timeout_s: 1.0,
            link_timeout_s: 3.0,
            authority_keepalive_ms: 1_000,
        }
    }
}

fn range_f(field: &str, v: f64, min: f64, max: f64) -> Result<f64, ConfigError> {
    in_range(field, finite(field, v)?, min, max)
}

fn seconds(field: &str, v: f64, min: f64, max: f64) -> Result<Duration, ConfigError> {
    Ok(Duration::from_secs_f64(range_f(field, v, min, max)?))
}

/// The directory relative paths of the config are resolved against.
static CONFIG_DIR: OnceLock<PathBuf> = OnceLock::new();

/// Records the directory of the config file named on the command line (`--config
/// FILE`, `--config=FILE`, `-c FILE`) or in `$SKYMESH_CONFIG`, for
/// [`ServiceConfig::validate`]. Called by `main` before the runtime parses the
/// arguments (which it does identically).
pub fn set_config_dir_from_args() {
    let mut args = std::env::args_os().skip(1);
    let mut path: Option<PathBuf> = None;
    while let Some(a) = args.next() {
        let s = a.to_string_lossy();
        if s == "--config" || s == "-c" {
            path = args.next().map(PathBuf::from);
        } else if let Some(v) = s.strip_prefix("--config=") {
            path = Some(PathBuf::from(v));
        } else if let Some(v) = s.strip_prefix("-c").filter(|v| !v.is_empty()) {
            path = Some(PathBuf::from(v));
        }
    }
    let path = path.or_else(|| std::env::var_os("SKYMESH_CONFIG").map(PathBuf::from));
    if let Some(dir) = path.as_deref().and_then(Path::parent) {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let _ = CONFIG_DIR.set(dir.to_path_buf());
    }
}

fn config_dir() -> PathBuf {
    CONFIG_DIR
        .get()
        .cloned()
        .unwrap_or_else(|| PathBuf::from("."))
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = DEFAULT_CONFIG_TOML;

    fn validate(self) -> Result<Settings, ConfigError> {
        self.validate_in(&config_dir())
    }
}

impl RawConfig {
    /// Checks every value; a relative `animations_dir` is resolved against `base`.
    pub fn validate_in(self, base: &Path) -> Result<Settings, ConfigError> {
        let origin = self.site_origin.as_ref().ok_or_else(|| {
            ConfigError::invalid(
                "site_origin",
                "missing: give { lat_deg, lon_deg, alt_msl_m }",
            )
        })?;
        let site = SiteFrame::new(
            range_f("site_origin.lat_deg", origin.lat_deg, -89.0, 89.0)?,
            range_f("site_origin.lon_deg", origin.lon_deg, -180.0, 180.0)?,
            range_f("site_origin.alt_msl_m", origin.alt_msl_m, -1_000.0, 9_000.0)?,
        );
        let drones = self.drones()?;
        let tick_hz = range_f("tick_hz", self.tick_hz, 1.0, 200.0)?;
        let setpoint_hz = range_f("setpoint_hz", self.setpoint_hz, 0.5, 10.0)?;
        let box_policy = match self.bounding_box.as_str() {
            "clamp" => BoxPolicy::Clamp,
            "refuse" => BoxPolicy::Refuse,
            other => {
                return Err(ConfigError::invalid(
                    "bounding_box",
                    format!("`{other}`: use \"clamp\" or \"refuse\""),
                ))
            }
        };
        let dir = self.animations_dir.trim();
        if dir.is_empty() {
            return Err(ConfigError::invalid("animations_dir", "empty"));
        }
        let animations_dir = if Path::new(dir).is_absolute() {
            PathBuf::from(dir)
        } else {
            base.join(dir)
        };
        let t = &self.timeouts;
        let timeouts = Timeouts {
            takeoff: seconds("timeouts.takeoff_s", t.takeoff_s, 1.0, 600.0)?,
            land: seconds("timeouts.land_s", t.land_s, 1.0, 1_800.0)?,
            waypoint_base: seconds("timeouts.waypoint_base_s", t.waypoint_base_s, 0.5, 600.0)?,
            waypoint_factor: range_f("timeouts.waypoint_factor", t.waypoint_factor, 1.0, 100.0)?
                as f32,
            ack: seconds("timeouts.ack_s", t.ack_s, 0.5, 60.0)?,
        };
        let hardware_drone = match self.hardware_drone {
            None => None,
            Some(id) => {
                if !drones.iter().any(|d| i64::from(d.id) == id) {
                    return Err(ConfigError::invalid(
                        "hardware_drone",
                        format!("{id} is not one of the configured drones"),
                    ));
                }
                Some(id as u16)
            }
        };
        Ok(Settings {
            site,
            drones,
            tick_period: Duration::from_secs_f64(1.0 / tick_hz),
            waypoint_tolerance_m: range_f(
                "waypoint_tolerance_m",
                self.waypoint_tolerance_m,
                0.05,
                10.0,
            )? as f32,
            default_speed_mps: range_f("default_speed_mps", self.default_speed_mps, 0.1, 20.0)?
                as f32,
            takeoff_alt_m: range_f("takeoff_alt_m", self.takeoff_alt_m, 0.5, 100.0)? as f32,
            bounding_box: box_policy,
            animations_dir,
            timeouts,
            hardware_drone,
            lcd_width: in_range("lcd_width", self.lcd_width, 1, 40)? as usize,
            queue_capacity: in_range("queue_capacity", self.queue_capacity, 1, 65_535)? as usize,
            max_replies_per_tick: in_range(
                "max_replies_per_tick",
                self.max_replies_per_tick,
                1,
                skymesh_ipc_types::topics::swarm_reply().qos.buffer as i64,
            )? as usize,
            setpoint_period: Duration::from_secs_f64(1.0 / setpoint_hz),
            landed_alt_m: range_f("landed_alt_m", self.landed_alt_m, 0.05, 2.0)? as f32,
            pose_timeout: seconds("pose_timeout_s", self.pose_timeout_s, 0.1, 60.0)?,
            link_timeout: seconds("link_timeout_s", self.link_timeout_s, 0.5, 60.0)?,
            authority_keepalive: Duration::from_millis(in_range(
                "authority_keepalive_ms",
                self.authority_keepalive_ms,
                100,
                2_500,
            )? as u64),
        })
    }

    fn drones(&self) -> Result<Vec<DroneConfig>, ConfigError> {
        let list: Vec<DroneConfig> = match (&self.drones, self.drone.is_empty()) {
            (Some(_), false) => {
                return Err(ConfigError::invalid(
                    "drones",
                    "give either `drones = { first_id, count, first_vehicle_id }` or [[drone]] tables, not both",
                ))
            }
            (None, true) => {
                return Err(ConfigError::invalid(
                    "drones",
                    "no drones: give `drones = { first_id, count, first_vehicle_id }` or [[drone]] tables",
                ))
            }
            (Some(r), true) => {
                let max = SWARM_MAX_DRONES.min(255) as i64;
                let count = in_range("drones.count", r.count, 1, max)?;
                let first_id = in_range("drones.first_id", r.first_id, 0, 65_534 - (count - 1))?;
                let first_vehicle =
                    in_range("drones.first_vehicle_id", r.first_vehicle_id, 1, 256 - count)?;
                (0..count)
                    .map(|i| DroneConfig {
                        id: (first_id + i) as u16,
                        vehicle_id: (first_vehicle + i) as u8,
                        home: None,
                    })
                    .collect()
            }
            (None, false) => self
                .drone
                .iter()
                .enumerate()
                .map(|(i, d)| {
                    let home = match d.home {
                        None => None,
                        Some(h) => {
                            let mut out = [0f32; 3];
                            for (k, v) in h.iter().enumerate() {
                                out[k] = range_f(&format!("drone[{i}].home"), *v, -10_000.0, 10_000.0)?
                                    as f32;
                            }
                            Some(out)
                        }
                    };
                    Ok(DroneConfig {
                        id: in_range(&format!("drone[{i}].id"), d.id, 0, 65_534)? as u16,
                        vehicle_id: in_range(&format!("drone[{i}].vehicle_id"), d.vehicle_id, 1, 255)?
                            as u8,
                        home,
                    })
                })
                .collect::<Result<_, ConfigError>>()?,
        };
        if list.len() > SWARM_MAX_DRONES {
            return Err(ConfigError::invalid(
                "drone",
                format!("{} drones, at most {SWARM_MAX_DRONES}", list.len()),
            ));
        }
        let mut ids = HashSet::new();
        let mut vehicles = HashSet::new();
        for d in &list {
            if !ids.insert(d.id) {
                return Err(ConfigError::invalid(
                    "drone",
                    format!("drone id {} appears twice", d.id),
                ));
            }
            if !vehicles.insert(d.vehicle_id) {
                return Err(ConfigError::invalid(
                    "drone",
                    format!("vehicle_id {} is given to two drones", d.vehicle_id),
                ));
            }
        }
        Ok(list)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    fn parse_in(text: &str) -> Result<Settings, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: "test".into(),
            message: e.to_string(),
        })?;
        raw.validate_in(Path::new("/etc/skymesh"))
    }

    const ORIGIN: &str =
        "site_origin = { lat_deg = -35.36, lon_deg = 149.16, alt_msl_m = 584.0 }\n";

    #[test]
    fn the_shipped_default_is_valid() {
        let s = parse::<RawConfig>(DEFAULT_CONFIG_TOML, "default").expect("default config");
        assert_eq!(s.drones.len(), 1);
        assert_eq!(s.drones[0].id, 1);
        assert_eq!(s.drones[0].vehicle_id, 1);
        assert_eq!(s.tick_period, Duration::from_secs_f64(1.0 / 30.0));
        assert_eq!(s.bounding_box, BoxPolicy::Clamp);
        assert_eq!(s.hardware_drone, Some(1));
        assert_eq!(s.authority_keepalive, Duration::from_secs(1));
        assert!((s.site.origin().0 - -35.363261).abs() < 1e-9);
    }

    #[test]
    fn a_compact_range_expands_and_a_list_keeps_its_order() {
        let s = parse_in(&format!(
            "{ORIGIN}drones = {{ first_id = 10, count = 250, first_vehicle_id = 2 }}\n"
        ))
        .unwrap();
        assert_eq!(s.drones.len(), 250);
        assert_eq!((s.drones[0].id, s.drones[0].vehicle_id), (10, 2));
        assert_eq!((s.drones[249].id, s.drones[249].vehicle_id), (259, 251));
        assert_eq!(s.animations_dir, Path::new("/etc/skymesh/animations"));

        let s = parse_in(&format!(
            "{ORIGIN}[[drone]]\nid = 7\nvehicle_id = 3\nhome = [1.0, 2.0, 0.0]\n[[drone]]\nid = 2\nvehicle_id = 4\n"
        ))
        .unwrap();
        assert_eq!(s.drones.iter().map(|d| d.id).collect::<Vec<_>>(), [7, 2]);
        assert_eq!(s.drones[0].home, Some([1.0, 2.0, 0.0]));
    }

    #[test]
    fn bad_drone_lists_name_the_problem() {
        for (text, field) in [
            ("", "drones"),
            ("drones = { first_id = 1, count = 300, first_vehicle_id = 1 }", "drones.count"),
            ("drones = { first_id = 1, count = 10, first_vehicle_id = 250 }", "drones.first_vehicle_id"),
            ("[[drone]]\nid = 1\nvehicle_id = 1\n[[drone]]\nid = 1\nvehicle_id = 2", "drone"),
            ("[[drone]]\nid = 1\nvehicle_id = 1\n[[drone]]\nid = 2\nvehicle_id = 1", "drone"),
            ("[[drone]]\nid = 1\nvehicle_id = 0", "drone[0].vehicle_id"),
            (
                "drones = { first_id = 1, count = 1, first_vehicle_id = 1 }\n[[drone]]\nid = 1\nvehicle_id = 1",
                "drones",
            ),
        ] {
            let e = parse_in(&format!("{ORIGIN}{text}\n")).unwrap_err();
            match e {
                ConfigError::Invalid { field: f, .. } => assert_eq!(f, field, "{text}"),
                other => panic!("{text}: {other}"),
            }
        }
    }

    #[test]
    fn ranges_and_enums_are_checked() {
        let base =
            format!("{ORIGIN}drones = {{ first_id = 1, count = 2, first_vehicle_id = 1 }}\n");
        assert!(parse_in(&base).is_ok());
        for (extra, field) in [
            ("tick_hz = 0", "tick_hz"),
            ("bounding_box = \"wrap\"", "bounding_box"),
            ("hardware_drone = 9", "hardware_drone"),
            ("takeoff_alt_m = nan", "takeoff_alt_m"),
            ("setpoint_hz = 50", "setpoint_hz"),
            ("[timeouts]\nack_s = 0", "timeouts.ack_s"),
            ("authority_keepalive_ms = 99", "authority_keepalive_ms"),
            ("authority_keepalive_ms = 2501", "authority_keepalive_ms"),
        ] {
            match parse_in(&format!("{base}{extra}\n")).unwrap_err() {
                ConfigError::Invalid { field: f, .. } => assert_eq!(f, field, "{extra}"),
                other => panic!("{extra}: {other}"),
            }
        }
        assert!(matches!(
            parse_in(&format!("{base}bogus = 1\n")).unwrap_err(),
            ConfigError::Parse { .. }
        ));
        let e =
            parse_in("drones = { first_id = 1, count = 1, first_vehicle_id = 1 }\n").unwrap_err();
        assert!(e.to_string().contains("site_origin"), "{e}");
        let s = parse_in(&format!(
            "{base}animations_dir = \"/srv/anim\"\nbounding_box = \"refuse\"\n"
        ))
        .unwrap();
        assert_eq!(s.animations_dir, Path::new("/srv/anim"));
        assert_eq!(s.bounding_box, BoxPolicy::Refuse);
    }
}
