//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are
//! `deploy/digiview-gateway.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::{finite, in_range, socket_addr};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::privilege::{AddrSet, IpNet};

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// TCP address DigiView clients connect to (DigiView's port is 8555).
    pub listen: SocketAddr,
    /// Clients connected at once; one more is closed at accept.
    pub max_clients: usize,
    /// Clients allowed to SET; everyone else's SET is answered FORBIDDEN (GETs are
    /// open to every client).
    pub write_allowed: AddrSet,
    /// Frames waiting to be written to one client; a full queue closes it.
    pub outgoing_queue: usize,
    /// Frames per second one client may send (burst of the same size); the excess is
    /// dropped unanswered, counted and logged.
    pub max_frames_per_s: u32,
    /// A frame begun but not completed within this long closes the connection
    /// (slow-loris protection).
    pub partial_frame_timeout: Duration,
    /// How long a SET waits for the pipeline's `VisionReply` (then UNKNOWN).
    pub set_timeout: Duration,
    /// A `VisionState` older than this means the pipeline is down (GETs: UNKNOWN);
    /// also the longest wait at start for the first state before reporting ready.
    pub state_timeout: Duration,
    /// DETECTED_ROI `rel_frame_of_reference` of the replies' relative angles:
    /// 0 global, 1 vehicle heading, 2 camera axis.
    pub roi_rel_frame: u8,
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub listen: String,
    pub max_clients: i64,
    pub write_allowed: Vec<String>,
    pub outgoing_queue: i64,
    pub max_frames_per_s: i64,
    pub partial_frame_timeout_s: f64,
    pub set_timeout_ms: i64,
    pub state_timeout_s: f64,
    pub roi_rel_frame: i64,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            listen: "127.0.0.1:8555".to_string(),
            max_clients: 16,
            write_allowed: vec!["127.0.0.1".to_string(), "::1".to_string()],
            outgoing_queue: 1024,
            max_frames_per_s: 200,
            partial_frame_timeout_s: 5.0,
            set_timeout_ms: 1000,
            state_timeout_s: 2.0,
            roi_rel_frame: 2,
        }
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/digiview-gateway.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        let listen = socket_addr("listen", &self.listen)?;
        let write_allowed = self
            .write_allowed
            .iter()
            .map(|s| {
                s.parse::<IpNet>()
                    .map_err(|e| ConfigError::invalid("write_allowed", format!("`{s}`: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let partial = in_range(
            "partial_frame_timeout_s",
            finite("partial_frame_timeout_s", self.partial_frame_timeout_s)?,
            0.1,
            600.0,
        )?;
        let state_timeout = in_range(
            "state_timeout_s",
            finite("state_timeout_s", self.state_timeout_s)?,
            0.1,
            600.0,
        )?;
        Ok(Settings {
            listen,
            max_clients: in_range("max_clients", self.max_clients, 1, 1024)? as usize,
            write_allowed: AddrSet::new(write_allowed),
            outgoing_queue: in_range("outgoing_queue", self.outgoing_queue, 16, 65_536)? as usize,
            max_frames_per_s: in_range("max_frames_per_s", self.max_frames_per_s, 1, 100_000)?
                as u32,
            partial_frame_timeout: Duration::from_secs_f64(partial),
            set_timeout: Duration::from_millis(in_range(
                "set_timeout_ms",
                self.set_timeout_ms,
                10,
                60_000,
            )? as u64),
            state_timeout: Duration::from_secs_f64(state_timeout),
            roi_rel_frame: in_range("roi_rel_frame", self.roi_rel_frame, 0, 2)? as u8,
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
    /// The defaults listening on `127.0.0.1:0` (tests, embedding).
    pub fn loopback_any_port() -> Settings {
        Settings {
            listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            ..Settings::default()
        }
    }

    /// True if a client from `ip` may SET.
    pub fn may_set(&self, ip: IpAddr) -> bool {
        self.write_allowed.contains(ip)
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
        assert_eq!(shipped.listen, SocketAddr::from(([127, 0, 0, 1], 8555)));
        assert!(shipped.may_set([127, 0, 0, 1].into()));
        assert!(shipped.may_set("::1".parse().unwrap()));
        assert!(!shipped.may_set([127, 0, 0, 2].into()));
        assert_eq!(shipped.set_timeout, Duration::from_secs(1));
        assert_eq!(shipped.roi_rel_frame, 2);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        let e = parse::<RawConfig>("listn = \"127.0.0.1:1\"", "t").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
        for (text, field) in [
            ("listen = \"localhost:8555\"", "listen"),
            ("max_clients = 0", "max_clients"),
            ("write_allowed = [\"10.0.0.300\"]", "write_allowed"),
            ("write_allowed = [\"10.0.0.0/33\"]", "write_allowed"),
            ("outgoing_queue = 2", "outgoing_queue"),
            ("max_frames_per_s = 0", "max_frames_per_s"),
            ("partial_frame_timeout_s = nan", "partial_frame_timeout_s"),
            ("set_timeout_ms = 0", "set_timeout_ms"),
            ("state_timeout_s = 0.0", "state_timeout_s"),
            ("roi_rel_frame = 3", "roi_rel_frame"),
        ] {
            let e = parse::<RawConfig>(text, "t").unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn networks_are_accepted() {
        let s = parse::<RawConfig>(
            "listen = \"0.0.0.0:8555\"\nwrite_allowed = [\"192.168.0.0/24\"]",
            "t",
        )
        .unwrap();
        assert!(s.may_set([192, 168, 0, 9].into()));
        assert!(!s.may_set([127, 0, 0, 1].into()));
    }
}
