//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are
//! `deploy/groundcontrol-gateway.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::{finite, in_range, socket_addr};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::privilege::{AddrSet, IpNet};

/// GroundControl's `liveness` byte of every pose record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveness {
    Undecided = 0,
    Live = 1,
    Simulated = 2,
}

impl Liveness {
    pub fn to_wire(self) -> u8 {
        self as u8
    }
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// TCP address of the state server (GroundControl's port is 8000).
    pub listen: SocketAddr,
    /// Clients connected at once; one more is closed at accept.
    pub max_clients: usize,
    /// Records waiting to be written to one client; a full queue closes it.
    pub outgoing_queue: usize,
    /// Records per second one client may send (sustained); the excess is dropped
    /// and counted (`rate_limited`).
    pub max_records_per_s: u32,
    /// Records one client may send at once above the sustained rate.
    pub record_burst: u32,
    /// A record whose bytes started arriving this long ago and is still incomplete
    /// closes the connection (`partial_record_timeout`: a slow-loris client).
    pub partial_record_timeout: Duration,
    /// Clients allowed every command; the others send only `CMD_EXT_*` and PING.
    pub privileged: AddrSet,
    /// Where each pose datagram goes.
    pub broadcast_destinations: Vec<SocketAddr>,
    /// The local address the broadcast is sent from.
    pub broadcast_bind: SocketAddr,
    /// Pose datagrams per second.
    pub broadcast_period: Duration,
    /// The liveness byte of every pose record.
    pub liveness: Liveness,
    /// No `SwarmState` for this long: the broadcast pauses until the next one.
    pub state_timeout: Duration,
    /// How long a command waits for the swarm queue to read the bus before the
    /// gateway answers it ACK_CMD_TIMEOUT itself.
    pub backend_wait: Duration,
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub listen: String,
    pub max_clients: i64,
    pub outgoing_queue: i64,
    pub max_records_per_s: i64,
    pub record_burst: i64,
    pub partial_record_timeout_s: f64,
    pub privileged: Vec<String>,
    pub broadcast_destinations: Vec<String>,
    pub broadcast_bind: String,
    pub broadcast_hz: f64,
    pub liveness: String,
    pub state_timeout_s: f64,
    pub backend_wait_ms: i64,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            listen: "127.0.0.1:8000".to_string(),
            max_clients: 64,
            outgoing_queue: 1024,
            max_records_per_s: 200,
            record_burst: 400,
            partial_record_timeout_s: 10.0,
            privileged: vec!["127.0.0.1".to_string()],
            broadcast_destinations: vec!["127.0.0.1:6666".to_string()],
            broadcast_bind: "0.0.0.0:0".to_string(),
            broadcast_hz: 30.0,
            liveness: "simulated".to_string(),
            state_timeout_s: 2.0,
            backend_wait_ms: 2000,
        }
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/groundcontrol-gateway.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        let listen = socket_addr("listen", &self.listen)?;
        let privileged = self
            .privileged
            .iter()
            .map(|s| {
                s.parse::<IpNet>()
                    .map_err(|e| ConfigError::invalid("privileged", format!("`{s}`: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let broadcast_bind = socket_addr("broadcast_bind", &self.broadcast_bind)?;
        if self.broadcast_destinations.is_empty() {
            return Err(ConfigError::invalid(
                "broadcast_destinations",
                "needs at least one ip:port (the pose broadcast is the interface's other half)",
            ));
        }
        let mut broadcast_destinations = Vec::new();
        for d in &self.broadcast_destinations {
            let addr = socket_addr("broadcast_destinations", d)?;
            if addr.is_ipv4() != broadcast_bind.is_ipv4() {
                return Err(ConfigError::invalid(
                    "broadcast_destinations",
                    format!(
                        "`{d}` is not of the address family of broadcast_bind `{broadcast_bind}`"
                    ),
                ));
            }
            if addr.port() == 0 {
                return Err(ConfigError::invalid(
                    "broadcast_destinations",
                    format!("`{d}` needs a port"),
                ));
            }
            broadcast_destinations.push(addr);
        }
        let hz = in_range(
            "broadcast_hz",
            finite("broadcast_hz", self.broadcast_hz)?,
            0.1,
            200.0,
        )?;
        let liveness = match self.liveness.as_str() {
            "undecided" => Liveness::Undecided,
            "live" => Liveness::Live,
            "simulated" => Liveness::Simulated,
            other => {
                return Err(ConfigError::invalid(
                    "liveness",
                    format!("`{other}` is not one of live, simulated, undecided"),
                ))
            }
        };
        let state_timeout = in_range(
            "state_timeout_s",
            finite("state_timeout_s", self.state_timeout_s)?,
            0.1,
            600.0,
        )?;
        let partial_record_timeout = in_range(
            "partial_record_timeout_s",
            finite("partial_record_timeout_s", self.partial_record_timeout_s)?,
            0.01,
            600.0,
        )?;
        Ok(Settings {
            listen,
            max_clients: in_range("max_clients", self.max_clients, 1, 4096)? as usize,
            outgoing_queue: in_range("outgoing_queue", self.outgoing_queue, 16, 65_536)? as usize,
            max_records_per_s: in_range("max_records_per_s", self.max_records_per_s, 1, 100_000)?
                as u32,
            record_burst: in_range("record_burst", self.record_burst, 1, 100_000)? as u32,
            partial_record_timeout: Duration::from_secs_f64(partial_record_timeout),
            privileged: AddrSet::new(privileged),
            broadcast_destinations,
            broadcast_bind,
            broadcast_period: Duration::from_secs_f64(1.0 / hz),
            liveness,
            state_timeout: Duration::from_secs_f64(state_timeout),
            backend_wait: Duration::from_millis(in_range(
                "backend_wait_ms",
                self.backend_wait_ms,
                0,
                10_000,
            )? as u64),
        })
    }
}

impl Default for Settings {
    fn default() -> Self {
        // The built-in defaults are valid by construction (checked by a test).
        RawConfig::default()
            .validate()
            .expect("the built-in defaults are valid")
    }
}

impl Settings {
    /// The defaults with the state server on `127.0.0.1:0` and the broadcast sent to
    /// `broadcast_to` (tests, embedding).
    pub fn loopback_any_port(broadcast_to: SocketAddr) -> Settings {
        Settings {
            listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            broadcast_destinations: vec![broadcast_to],
            broadcast_bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            ..Settings::default()
        }
    }

    /// True if a client from `ip` may send every command.
    pub fn is_privileged(&self, ip: IpAddr) -> bool {
        self.privileged.contains(ip)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    #[test]
    fn shipped_file_parses_and_equals_the_defaults() {
        let shipped = parse::<RawConfig>(RawConfig::DEFAULT_TOML, "deploy").unwrap();
        assert_eq!(shipped, Settings::default());
        assert_eq!(
            parse::<RawConfig>("", "empty").unwrap(),
            Settings::default()
        );
        assert_eq!(shipped.listen, SocketAddr::from(([127, 0, 0, 1], 8000)));
        assert_eq!(shipped.max_clients, 64);
        assert_eq!(
            (shipped.max_records_per_s, shipped.record_burst),
            (200, 400)
        );
        assert_eq!(shipped.partial_record_timeout, Duration::from_secs(10));
        assert_eq!(
            shipped.broadcast_period,
            Duration::from_secs_f64(1.0 / 30.0)
        );
        assert!(shipped.is_privileged([127, 0, 0, 1].into()));
        assert!(!shipped.is_privileged([127, 0, 0, 2].into()));
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        let e = parse::<RawConfig>("listn = \"127.0.0.1:1\"", "t").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
        for (text, field) in [
            ("listen = \"localhost:8000\"", "listen"),
            ("max_clients = 0", "max_clients"),
            ("outgoing_queue = 2", "outgoing_queue"),
            ("privileged = [\"10.0.0.300\"]", "privileged"),
            ("privileged = [\"10.0.0.0/33\"]", "privileged"),
            ("broadcast_destinations = []", "broadcast_destinations"),
            (
                "broadcast_destinations = [\"192.168.0.255\"]",
                "broadcast_destinations",
            ),
            (
                "broadcast_destinations = [\"[::1]:6666\"]",
                "broadcast_destinations",
            ),
            (
                "broadcast_destinations = [\"127.0.0.1:0\"]",
                "broadcast_destinations",
            ),
            ("broadcast_hz = 0.0", "broadcast_hz"),
            ("broadcast_hz = nan", "broadcast_hz"),
            ("liveness = \"maybe\"", "liveness"),
            ("state_timeout_s = 0.0", "state_timeout_s"),
            ("backend_wait_ms = -1", "backend_wait_ms"),
            ("backend_wait_ms = 10001", "backend_wait_ms"),
            ("max_records_per_s = 0", "max_records_per_s"),
            ("max_records_per_s = 1000000", "max_records_per_s"),
            ("record_burst = -1", "record_burst"),
            ("partial_record_timeout_s = 0.0", "partial_record_timeout_s"),
            ("partial_record_timeout_s = inf", "partial_record_timeout_s"),
        ] {
            let e = parse::<RawConfig>(text, "t").unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn values_are_converted() {
        let s = parse::<RawConfig>(
            "listen = \"0.0.0.0:8000\"\nprivileged = [\"192.168.0.0/24\", \"10.1.2.3\"]\n\
             broadcast_destinations = [\"192.168.0.255:6666\", \"10.1.2.3:7000\"]\n\
             broadcast_hz = 10\nliveness = \"live\"\nbackend_wait_ms = 250",
            "t",
        )
        .unwrap();
        assert_eq!(s.listen, SocketAddr::from(([0, 0, 0, 0], 8000)));
        assert!(s.is_privileged([192, 168, 0, 77].into()));
        assert!(s.is_privileged([10, 1, 2, 3].into()));
        assert!(!s.is_privileged([10, 1, 2, 4].into()));
        assert!(!s.is_privileged([127, 0, 0, 1].into()));
        assert_eq!(s.broadcast_destinations.len(), 2);
        assert_eq!(s.broadcast_period, Duration::from_millis(100));
        assert_eq!(s.liveness, Liveness::Live);
        assert_eq!(s.backend_wait, Duration::from_millis(250));
    }
}
