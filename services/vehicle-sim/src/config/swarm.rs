//! Swarm mode: one process serving several vehicles, each with its own system
//! id, port and home laid out around the configured one.

use nalgebra::Vector3;
use serde::Deserialize;

use super::{range, ConfigError, Endpoint, Settings};
use crate::model::{LocalFrame, VehicleParams};

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

pub(super) fn validate_swarm(
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

#[cfg(test)]
mod tests {
    use std::net::SocketAddr;

    use super::super::*;
    use super::*;

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
}
