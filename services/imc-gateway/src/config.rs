//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented file is `deploy/imc-gateway.toml`
//! (embedded as [`ServiceConfig::DEFAULT_TOML`]). It equals the built-in defaults
//! except `announce_destinations`, which it turns off.

use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use imc_proto::{parse_tuple_list, ADDR_NONE, ENTITY_ANY};
use serde::Deserialize;
use skymesh_ipc_types::command::limits;
use skymesh_ipc_types::Button;
use skymesh_runtime::addresses::{AddressList, IpNet};
use skymesh_runtime::config::{in_range, socket_addr};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::actuators::{Actuators, PwmMap, ServoMap, SurfaceMap, ThrusterMap};
use crate::teleop::{ActionKind, TeleopSettings};

/// IMC's discovery group and ports: where Announce goes unless configured otherwise.
pub const ANNOUNCE_GROUP: [u8; 4] = [224, 0, 75, 69];
pub const ANNOUNCE_PORTS: std::ops::RangeInclusive<u16> = 30100..=30104;

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// UDP address IMC peers send to.
    pub listen: SocketAddr,
    /// The peers whose datagrams are read at all (addresses and networks); a
    /// datagram from anyone else is dropped (`not_allowed`) before it is decoded.
    /// Empty: nobody.
    pub allowed_peers: AddressList,
    /// Our IMC system address (header `src`).
    pub address: u16,
    /// Our IMC entity (header `src_ent`).
    pub entity: u8,
    /// `sys_name` of our Announce.
    pub system_name: String,
    /// MAVLink system id of the vehicle commanded and reported.
    pub vehicle_id: u8,
    /// The address in our Announce's services string.
    pub advertise_address: IpAddr,
    /// Peers that always get heartbeats.
    pub static_peers: Vec<SocketAddr>,
    /// Where Announce goes (empty: no Announce).
    pub announce_destinations: Vec<SocketAddr>,
    pub heartbeat_interval: Duration,
    pub announce_interval: Duration,
    /// A peer silent for this long gets no more heartbeats.
    pub peer_timeout: Duration,
    /// A hardware request unanswered for this long is dropped; also the longest
    /// wait at start for the hardware state before the gateway reports ready.
    pub hardware_timeout: Duration,
    pub actuators: Actuators,
    /// IMC button id → skymesh button.
    pub buttons: BTreeMap<u8, Button>,
    pub teleop: TeleopSettings,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawServo {
    pub id: i64,
    pub channel: i64,
    #[serde(default = "pwm_min")]
    pub pwm_min: i64,
    #[serde(default = "pwm_max")]
    pub pwm_max: i64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSurface {
    pub id: i64,
    pub channel: i64,
    #[serde(default = "max_angle")]
    pub max_angle_rad: f64,
    #[serde(default = "pwm_min")]
    pub pwm_min: i64,
    #[serde(default = "pwm_max")]
    pub pwm_max: i64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPwm {
    pub id: i64,
    pub channel: i64,
    #[serde(default = "period")]
    pub period_us: i64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawThruster {
    pub id: i64,
    pub motor: i64,
    #[serde(default = "max_throttle")]
    pub max_throttle_pct: f64,
    #[serde(default = "duration")]
    pub duration_s: f64,
}

fn pwm_min() -> i64 {
    1000
}
fn pwm_max() -> i64 {
    2000
}
fn max_angle() -> f64 {
    0.5
}
fn period() -> i64 {
    20_000
}
fn max_throttle() -> f64 {
    15.0
}
fn duration() -> f64 {
    2.0
}

/// `[teleop]` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawTeleop {
    pub actions: String,
    pub forward: String,
    pub right: String,
    pub up: String,
    pub yaw: String,
    pub max_speed_mps: f64,
    pub max_climb_mps: f64,
    pub max_yaw_rate_dps: f64,
    pub max_age_ms: i64,
    pub switch_to_guided: bool,
    /// Button action → skymesh button name.
    pub buttons: BTreeMap<String, String>,
}

impl Default for RawTeleop {
    fn default() -> Self {
        RawTeleop {
            actions:
                "Forward=Axis;Right=Axis;Up=Axis;Yaw=Axis;Fly=Button;A=Button;B=Button;Pause=Button"
                    .to_string(),
            forward: "Forward".to_string(),
            right: "Right".to_string(),
            up: "Up".to_string(),
            yaw: "Yaw".to_string(),
            max_speed_mps: 2.0,
            max_climb_mps: 1.0,
            max_yaw_rate_dps: 45.0,
            max_age_ms: 500,
            switch_to_guided: false,
            buttons: [("Fly", "fly"), ("A", "a"), ("B", "b"), ("Pause", "pause")]
                .into_iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
        }
    }
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub listen: String,
    pub allowed_peers: Vec<String>,
    pub address: i64,
    pub entity: i64,
    pub system_name: String,
    pub vehicle_id: i64,
    pub advertise_address: Option<String>,
    pub static_peers: Vec<String>,
    pub announce_destinations: Vec<String>,
    pub heartbeat_interval_ms: i64,
    pub announce_interval_s: f64,
    pub peer_timeout_s: f64,
    pub hardware_timeout_ms: i64,
    pub servo: Vec<RawServo>,
    pub surface: Vec<RawSurface>,
    pub pwm: Vec<RawPwm>,
    pub thruster: Vec<RawThruster>,
    /// IMC button id (a TOML key, so a string) → skymesh button name.
    pub buttons: BTreeMap<String, String>,
    pub teleop: RawTeleop,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            listen: "127.0.0.1:6002".to_string(),
            allowed_peers: vec!["127.0.0.1".to_string(), "::1".to_string()],
            address: 0x2c01,
            entity: 0,
            system_name: "skymesh-1".to_string(),
            vehicle_id: 1,
            advertise_address: None,
            static_peers: Vec::new(),
            announce_destinations: ANNOUNCE_PORTS
                .map(|p| SocketAddr::from((ANNOUNCE_GROUP, p)).to_string())
                .collect(),
            heartbeat_interval_ms: 1000,
            announce_interval_s: 10.0,
            peer_timeout_s: 30.0,
            hardware_timeout_ms: 2000,
            servo: vec![RawServo {
                id: 0,
                channel: 9,
                pwm_min: pwm_min(),
                pwm_max: pwm_max(),
            }],
            surface: Vec::new(),
            pwm: vec![RawPwm {
                id: 0,
                channel: 10,
                period_us: period(),
            }],
            thruster: (0..4)
                .map(|i| RawThruster {
                    id: i,
                    motor: i + 1,
                    max_throttle_pct: max_throttle(),
                    duration_s: duration(),
                })
                .collect(),
            buttons: Button::ALL
                .iter()
                .map(|b| (b.to_wire().to_string(), b.as_str().to_string()))
                .collect(),
            teleop: RawTeleop::default(),
        }
    }
}

fn number(field: &str, v: f64, min: f64, max: f64) -> Result<f64, ConfigError> {
    if !v.is_finite() {
        return Err(ConfigError::invalid(field, "must be a finite number"));
    }
    in_range(field, v, min, max)
}

fn secs(field: &str, v: f64, min: f64, max: f64) -> Result<Duration, ConfigError> {
    number(field, v, min, max).map(Duration::from_secs_f64)
}

fn millis(field: &str, v: i64, min: i64, max: i64) -> Result<Duration, ConfigError> {
    in_range(field, v, min, max).map(|v| Duration::from_millis(v as u64))
}

fn byte(field: &str, v: i64, min: u8, max: u8) -> Result<u8, ConfigError> {
    in_range(field, v, i64::from(min), i64::from(max)).map(|v| v as u8)
}

fn pulse(field: &str, v: i64) -> Result<u16, ConfigError> {
    let r = limits::PWM_US;
    in_range(field, v, i64::from(*r.start()), i64::from(*r.end())).map(|v| v as u16)
}

fn pulse_range(table: &str, i: usize, min: i64, max: i64) -> Result<(u16, u16), ConfigError> {
    let lo = pulse(&format!("{table}[{i}].pwm_min"), min)?;
    let hi = pulse(&format!("{table}[{i}].pwm_max"), max)?;
    if lo >= hi {
        return Err(ConfigError::invalid(
            format!("{table}[{i}].pwm_max"),
            format!("must be above pwm_min ({lo})"),
        ));
    }
    Ok((lo, hi))
}

fn channel(table: &str, i: usize, v: i64) -> Result<u8, ConfigError> {
    let r = limits::SERVO_CHANNELS;
    byte(&format!("{table}[{i}].channel"), v, *r.start(), *r.end())
}

/// Each id at most once per table.
fn unique_ids(table: &str, ids: impl Iterator<Item = u8>) -> Result<(), ConfigError> {
    let mut seen = std::collections::BTreeSet::new();
    for id in ids {
        if !seen.insert(id) {
            return Err(ConfigError::invalid(
                table,
                format!("id {id} is mapped twice"),
            ));
        }
    }
    Ok(())
}

fn button(field: &str, name: &str) -> Result<Button, ConfigError> {
    Button::ALL
        .iter()
        .find(|b| b.as_str() == name)
        .copied()
        .ok_or_else(|| {
            let names: Vec<&str> = Button::ALL.iter().map(|b| b.as_str()).collect();
            ConfigError::invalid(
                field,
                format!("`{name}` is not a button ({})", names.join(", ")),
            )
        })
}

fn actuators(raw: &RawConfig) -> Result<Actuators, ConfigError> {
    let servos = raw
        .servo
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let (pwm_min, pwm_max) = pulse_range("servo", i, s.pwm_min, s.pwm_max)?;
            Ok(ServoMap {
                id: byte(&format!("servo[{i}].id"), s.id, 0, 255)?,
                channel: channel("servo", i, s.channel)?,
                pwm_min,
                pwm_max,
            })
        })
        .collect::<Result<Vec<_>, ConfigError>>()?;
    let surfaces = raw
        .surface
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let (pwm_min, pwm_max) = pulse_range("surface", i, s.pwm_min, s.pwm_max)?;
            let max = number(
                &format!("surface[{i}].max_angle_rad"),
                s.max_angle_rad,
                0.01,
                std::f64::consts::PI,
            )?;
            Ok(SurfaceMap {
                id: byte(&format!("surface[{i}].id"), s.id, 0, 255)?,
                channel: channel("surface", i, s.channel)?,
                max_angle_rad: max as f32,
                pwm_min,
                pwm_max,
            })
        })
        .collect::<Result<Vec<_>, ConfigError>>()?;
    let pwms = raw
        .pwm
        .iter()
        .enumerate()
        .map(|(i, p)| {
            Ok(PwmMap {
                id: byte(&format!("pwm[{i}].id"), p.id, 0, 255)?,
                channel: channel("pwm", i, p.channel)?,
                period_us: in_range(&format!("pwm[{i}].period_us"), p.period_us, 2_500, 100_000)?
                    as u32,
            })
        })
        .collect::<Result<Vec<_>, ConfigError>>()?;
    let motors = limits::MOTORS;
    let thrusters = raw
        .thruster
        .iter()
        .enumerate()
        .map(|(i, t)| {
            Ok(ThrusterMap {
                id: byte(&format!("thruster[{i}].id"), t.id, 0, 255)?,
                motor: byte(
                    &format!("thruster[{i}].motor"),
                    t.motor,
                    *motors.start(),
                    *motors.end(),
                )?,
                max_throttle_pct: number(
                    &format!("thruster[{i}].max_throttle_pct"),
                    t.max_throttle_pct,
                    0.1,
                    100.0,
                )? as f32,
                duration_s: number(
                    &format!("thruster[{i}].duration_s"),
                    t.duration_s,
                    0.1,
                    f64::from(limits::MAX_MOTOR_TEST_S),
                )? as f32,
            })
        })
        .collect::<Result<Vec<_>, ConfigError>>()?;
    unique_ids("servo", servos.iter().map(|s| s.id))?;
    unique_ids("surface", surfaces.iter().map(|s| s.id))?;
    unique_ids("pwm", pwms.iter().map(|p| p.id))?;
    unique_ids("thruster", thrusters.iter().map(|t| t.id))?;
    Ok(Actuators {
        servos,
        surfaces,
        pwms,
        thrusters,
    })
}

fn teleop(raw: RawTeleop) -> Result<TeleopSettings, ConfigError> {
    let pairs = parse_tuple_list(&raw.actions)
        .map_err(|e| ConfigError::invalid("teleop.actions", e.to_string()))?;
    let mut actions: Vec<(String, ActionKind)> = Vec::new();
    for (name, kind) in pairs {
        let kind = ActionKind::parse(&kind).ok_or_else(|| {
            ConfigError::invalid(
                "teleop.actions",
                format!("action {name}: type `{kind}` is not Axis, Hat or Button"),
            )
        })?;
        if actions.iter().any(|(n, _)| *n == name) {
            return Err(ConfigError::invalid(
                "teleop.actions",
                format!("action {name} is listed twice"),
            ));
        }
        actions.push((name, kind));
    }
    let kind_of = |name: &str| actions.iter().find(|(n, _)| n == name).map(|(_, k)| *k);
    let role = |field: &str, name: String| -> Result<Option<String>, ConfigError> {
        if name.is_empty() {
            return Ok(None);
        }
        match kind_of(&name) {
            Some(ActionKind::Axis) => Ok(Some(name)),
            _ => Err(ConfigError::invalid(
                field,
                format!("`{name}` is not an Axis action of teleop.actions"),
            )),
        }
    };
    let mut buttons = Vec::new();
    for (action, name) in raw.buttons {
        let field = format!("teleop.buttons.{action}");
        if kind_of(&action) != Some(ActionKind::Button) {
            return Err(ConfigError::invalid(
                field,
                format!("`{action}` is not a Button action of teleop.actions"),
            ));
        }
        buttons.push((action, button(&field, &name)?));
    }
    // The configured order, so events of one message come out in a stable order.
    buttons.sort_by_key(|(a, _)| actions.iter().position(|(n, _)| n == a));
    Ok(TeleopSettings {
        forward: role("teleop.forward", raw.forward)?,
        right: role("teleop.right", raw.right)?,
        up: role("teleop.up", raw.up)?,
        yaw: role("teleop.yaw", raw.yaw)?,
        max_speed_mps: number("teleop.max_speed_mps", raw.max_speed_mps, 0.1, 20.0)? as f32,
        max_climb_mps: number("teleop.max_climb_mps", raw.max_climb_mps, 0.1, 10.0)? as f32,
        max_yaw_rate_dps: number("teleop.max_yaw_rate_dps", raw.max_yaw_rate_dps, 1.0, 360.0)?
            as f32,
        max_age_ms: in_range("teleop.max_age_ms", raw.max_age_ms, 50, 5000)? as u32,
        switch_to_guided: raw.switch_to_guided,
        actions,
        buttons,
    })
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/imc-gateway.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        let listen = socket_addr("listen", &self.listen)?;
        let allowed_peers = self
            .allowed_peers
            .iter()
            .enumerate()
            .map(|(i, s)| {
                s.parse::<IpNet>().map_err(|e| {
                    ConfigError::invalid(
                        format!("allowed_peers[{i}]"),
                        format!("`{s}`: {e} (an IP address or a network such as 10.0.0.0/24)"),
                    )
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let address = in_range("address", self.address, 0, i64::from(ADDR_NONE) - 1)? as u16;
        let entity = byte("entity", self.entity, 0, ENTITY_ANY - 1)?;
        if self.system_name.is_empty() || self.system_name.len() > 64 {
            return Err(ConfigError::invalid("system_name", "must be 1..=64 bytes"));
        }
        let advertise_address = match &self.advertise_address {
            None => listen.ip(),
            Some(a) => a.parse().map_err(|e| {
                ConfigError::invalid(
                    "advertise_address",
                    format!("`{a}` is not an IP address ({e})"),
                )
            })?,
        };
        let addrs = |field: &str, list: &[String]| -> Result<Vec<SocketAddr>, ConfigError> {
            list.iter()
                .enumerate()
                .map(|(i, a)| socket_addr(&format!("{field}[{i}]"), a))
                .collect()
        };
        let mut buttons = BTreeMap::new();
        for (id, name) in &self.buttons {
            let field = format!("buttons.{id}");
            let imc_id: u8 = id.parse().map_err(|_| {
                ConfigError::invalid(&field, format!("`{id}` is not a button id 0..=255"))
            })?;
            buttons.insert(imc_id, button(&field, name)?);
        }
        Ok(Settings {
            listen,
            allowed_peers: AddressList::new(allowed_peers),
            address,
            entity,
            vehicle_id: byte("vehicle_id", self.vehicle_id, 1, 255)?,
            advertise_address,
            static_peers: addrs("static_peers", &self.static_peers)?,
            announce_destinations: addrs("announce_destinations", &self.announce_destinations)?,
            heartbeat_interval: millis(
                "heartbeat_interval_ms",
                self.heartbeat_interval_ms,
                100,
                60_000,
            )?,
            announce_interval: secs("announce_interval_s", self.announce_interval_s, 1.0, 600.0)?,
            peer_timeout: secs("peer_timeout_s", self.peer_timeout_s, 1.0, 3600.0)?,
            hardware_timeout: millis("hardware_timeout_ms", self.hardware_timeout_ms, 100, 60_000)?,
            actuators: actuators(&self)?,
            buttons,
            teleop: teleop(self.teleop)?,
            system_name: self.system_name,
        })
    }
}

impl Settings {
    /// The built-in defaults (announce to IMC's multicast group).
    pub fn defaults() -> Result<Settings, ConfigError> {
        RawConfig::default().validate()
    }

    /// The built-in defaults on `127.0.0.1:0`, without Announce (tests, embedding).
    pub fn loopback_any_port() -> Result<Settings, ConfigError> {
        let mut s = Settings::defaults()?;
        s.listen = SocketAddr::from(([127, 0, 0, 1], 0));
        s.advertise_address = s.listen.ip();
        s.announce_destinations.clear();
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    #[test]
    fn shipped_file_parses_and_equals_the_defaults_but_for_announce() {
        let shipped = parse::<RawConfig>(RawConfig::DEFAULT_TOML, "deploy").unwrap();
        let mut defaults = Settings::defaults().unwrap();
        assert_eq!(defaults.announce_destinations.len(), 5);
        assert_eq!(
            defaults.announce_destinations[0],
            SocketAddr::from(([224, 0, 75, 69], 30100))
        );
        defaults.announce_destinations.clear();
        assert_eq!(shipped, defaults);
        assert_eq!(
            parse::<RawConfig>("", "empty").unwrap(),
            Settings::defaults().unwrap()
        );
    }

    #[test]
    fn the_shipped_mapping_is_the_documented_one() {
        let s = parse::<RawConfig>(RawConfig::DEFAULT_TOML, "deploy").unwrap();
        assert_eq!(s.address, 0x2c01);
        assert_eq!(s.listen, SocketAddr::from(([127, 0, 0, 1], 6002)));
        assert_eq!(s.advertise_address, s.listen.ip());
        let a = &s.actuators;
        assert_eq!((a.servos[0].id, a.servos[0].channel), (0, 9));
        assert_eq!(
            (a.pwms[0].id, a.pwms[0].channel, a.pwms[0].period_us),
            (0, 10, 20_000)
        );
        let motors: Vec<(u8, u8)> = a.thrusters.iter().map(|t| (t.id, t.motor)).collect();
        assert_eq!(motors, vec![(0, 1), (1, 2), (2, 3), (3, 4)]);
        assert!(a.surfaces.is_empty());
        assert_eq!(s.buttons.len(), Button::ALL.len());
        for b in Button::ALL {
            assert_eq!(s.buttons.get(&b.to_wire()), Some(b), "identity mapping");
        }
        let t = &s.teleop;
        assert_eq!(t.actions.len(), 8);
        assert_eq!(t.forward.as_deref(), Some("Forward"));
        assert_eq!(
            t.buttons,
            vec![
                ("Fly".to_string(), Button::Fly),
                ("A".to_string(), Button::A),
                ("B".to_string(), Button::B),
                ("Pause".to_string(), Button::Pause)
            ]
        );
        assert!(!t.switch_to_guided);
    }

    #[test]
    fn tables_replace_the_defaults() {
        let s = parse::<RawConfig>(
            "servo = []\n[[surface]]\nid = 4\nchannel = 11\n[buttons]\n20 = \"a\"\n[teleop]\nyaw = \"\"\n[teleop.buttons]\nFly = \"fly\"\n",
            "t",
        )
        .unwrap();
        assert!(s.actuators.servos.is_empty());
        assert_eq!(
            s.actuators.surfaces,
            vec![SurfaceMap {
                id: 4,
                channel: 11,
                max_angle_rad: 0.5,
                pwm_min: 1000,
                pwm_max: 2000
            }]
        );
        assert_eq!(s.buttons.len(), 1);
        assert_eq!(s.buttons.get(&20), Some(&Button::A));
        assert_eq!(s.teleop.yaw, None);
        assert_eq!(s.teleop.buttons.len(), 1);
        assert_eq!(
            s.actuators.thrusters.len(),
            4,
            "untouched tables keep their defaults"
        );
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        let e = parse::<RawConfig>("lisen = \"127.0.0.1:1\"", "t").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
        let e = parse::<RawConfig>("[[servo]]\nid = 1\nchannel = 9\nspeed = 3\n", "t").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
        for (text, field) in [
            ("listen = \"localhost:6002\"", "listen"),
            ("address = 65535", "address"),
            ("entity = 255", "entity"),
            ("system_name = \"\"", "system_name"),
            ("vehicle_id = 0", "vehicle_id"),
            ("advertise_address = \"example.org\"", "advertise_address"),
            ("static_peers = [\"1.2.3.4\"]", "static_peers[0]"),
            ("allowed_peers = [\"10.0.0.0/33\"]", "allowed_peers[0]"),
            (
                "allowed_peers = [\"127.0.0.1\", \"neptus.local\"]",
                "allowed_peers[1]",
            ),
            (
                "announce_destinations = [\"x\"]",
                "announce_destinations[0]",
            ),
            ("heartbeat_interval_ms = 10", "heartbeat_interval_ms"),
            ("announce_interval_s = nan", "announce_interval_s"),
            ("peer_timeout_s = 0", "peer_timeout_s"),
            ("hardware_timeout_ms = 0", "hardware_timeout_ms"),
            ("[[servo]]\nid = 1\nchannel = 33", "servo[0].channel"),
            (
                "[[servo]]\nid = 1\nchannel = 9\npwm_min = 2000",
                "servo[0].pwm_max",
            ),
            ("[[servo]]\nid = 256\nchannel = 9", "servo[0].id"),
            (
                "[[servo]]\nid = 1\nchannel = 9\n[[servo]]\nid = 1\nchannel = 10",
                "servo",
            ),
            (
                "[[surface]]\nid = 1\nchannel = 9\nmax_angle_rad = 4.0",
                "surface[0].max_angle_rad",
            ),
            (
                "[[pwm]]\nid = 1\nchannel = 9\nperiod_us = 100",
                "pwm[0].period_us",
            ),
            ("[[thruster]]\nid = 1\nmotor = 13", "thruster[0].motor"),
            (
                "[[thruster]]\nid = 1\nmotor = 1\nmax_throttle_pct = 150.0",
                "thruster[0].max_throttle_pct",
            ),
            (
                "[[thruster]]\nid = 1\nmotor = 1\nduration_s = 60.0",
                "thruster[0].duration_s",
            ),
            ("[buttons]\nx = \"a\"", "buttons.x"),
            ("[buttons]\n1 = \"jump\"", "buttons.1"),
            ("[teleop]\nactions = \"Go=Slider\"", "teleop.actions"),
            ("[teleop]\nactions = \"Go\"", "teleop.actions"),
            ("[teleop]\nactions = \"A=Axis;A=Button\"", "teleop.actions"),
            ("[teleop]\nforward = \"Fly\"", "teleop.forward"),
            ("[teleop]\nmax_speed_mps = 100.0", "teleop.max_speed_mps"),
            ("[teleop]\nmax_age_ms = 10", "teleop.max_age_ms"),
            (
                "[teleop.buttons]\nForward = \"a\"",
                "teleop.buttons.Forward",
            ),
            ("[teleop.buttons]\nFly = \"jump\"", "teleop.buttons.Fly"),
        ] {
            let e = parse::<RawConfig>(text, "t").unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn values_are_converted() {
        let s = parse::<RawConfig>(
            "listen = \"0.0.0.0:6002\"\nadvertise_address = \"10.0.0.5\"\naddress = 0x0c10\nentity = 7\nstatic_peers = [\"10.0.0.2:6001\"]\nheartbeat_interval_ms = 250\nannounce_interval_s = 2.5",
            "t",
        )
        .unwrap();
        assert_eq!(s.advertise_address, IpAddr::from([10, 0, 0, 5]));
        assert_eq!((s.address, s.entity), (0x0c10, 7));
        assert_eq!(
            s.static_peers,
            vec![SocketAddr::from(([10, 0, 0, 2], 6001))]
        );
        assert_eq!(s.heartbeat_interval, Duration::from_millis(250));
        assert_eq!(s.announce_interval, Duration::from_millis(2500));
        let t = Settings::loopback_any_port().unwrap();
        assert_eq!(t.listen.port(), 0);
        assert!(t.announce_destinations.is_empty());
        assert_eq!(t.allowed_peers.to_string(), "[127.0.0.1, ::1]");
    }

    #[test]
    fn allowed_peers_default_to_loopback_and_take_networks() {
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        let d = Settings::defaults().unwrap().allowed_peers;
        for ok in ["127.0.0.1", "::1", "::ffff:127.0.0.1"] {
            assert!(d.contains(ip(ok)), "{ok}");
        }
        for no in ["127.0.0.2", "10.0.0.2", "0.0.0.0", "::2"] {
            assert!(!d.contains(ip(no)), "{no}");
        }
        let s = parse::<RawConfig>(
            "listen = \"0.0.0.0:6002\"\nallowed_peers = [\"10.0.0.0/24\", \"192.168.1.7\"]",
            "t",
        )
        .unwrap();
        assert!(s.allowed_peers.contains(ip("10.0.0.200")));
        assert!(s.allowed_peers.contains(ip("192.168.1.7")));
        assert!(!s.allowed_peers.contains(ip("192.168.1.8")));
        assert!(
            !s.allowed_peers.contains(ip("127.0.0.1")),
            "replaced, not added"
        );
        let none = parse::<RawConfig>("allowed_peers = []", "t").unwrap();
        assert!(none.allowed_peers.entries().is_empty());
        assert!(
            !none.allowed_peers.contains(ip("127.0.0.1")),
            "empty: nobody"
        );
    }
}
