//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are `deploy/solo-gateway.toml`
//! (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::net::SocketAddr;
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::{in_range, socket_addr};
use skymesh_runtime::{ConfigError, ServiceConfig};

/// The validated configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Settings {
    /// TCP address the Solo app connects to (ShotManager's port is 5507).
    pub listen: SocketAddr,
    /// UDP address of the follow stream (the app streams LOCATION datagrams to 14558).
    pub follow_listen: SocketAddr,
    /// A frame whose first byte arrived this long ago and is still incomplete closes
    /// the connection (`stalled`).
    pub frame_timeout: Duration,
    /// Frames waiting to be written to the app; a full queue closes the connection
    /// (`overflow`): the app stopped reading.
    pub outgoing_queue: usize,
    /// How often the `AppSession` sample is republished (besides every change).
    pub session_publish: Duration,
    /// Frames per second the app may send (sustained); the excess is dropped and
    /// counted (`rate_limited`).
    pub max_messages_per_s: u32,
    /// Frames the app may send at once above the sustained rate.
    pub message_burst: u32,
    /// Follow-stream datagrams per second (and burst) from the app's address; the
    /// excess is dropped and counted (`follow_rate_limited`).
    pub follow_max_per_s: u32,
    /// How long a request the shot engine answers waits for a shot engine to read
    /// the bus before the gateway answers it with the protocol's error.
    pub backend_wait: Duration,
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub listen: String,
    pub follow_listen: String,
    pub frame_timeout_s: f64,
    pub outgoing_queue: i64,
    pub session_publish_ms: i64,
    pub max_messages_per_s: i64,
    pub message_burst: i64,
    pub follow_max_per_s: i64,
    pub backend_wait_ms: i64,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            listen: "127.0.0.1:5507".to_string(),
            follow_listen: "127.0.0.1:14558".to_string(),
            frame_timeout_s: 10.0,
            outgoing_queue: 256,
            session_publish_ms: 1000,
            max_messages_per_s: 200,
            message_burst: 400,
            follow_max_per_s: 50,
            backend_wait_ms: 2000,
        }
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/solo-gateway.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        if !self.frame_timeout_s.is_finite() {
            return Err(ConfigError::invalid(
                "frame_timeout_s",
                "must be a finite number",
            ));
        }
        let frame_timeout = in_range("frame_timeout_s", self.frame_timeout_s, 0.01, 600.0)?;
        Ok(Settings {
            listen: socket_addr("listen", &self.listen)?,
            follow_listen: socket_addr("follow_listen", &self.follow_listen)?,
            frame_timeout: Duration::from_secs_f64(frame_timeout),
            outgoing_queue: in_range("outgoing_queue", self.outgoing_queue, 4, 65_536)? as usize,
            session_publish: Duration::from_millis(in_range(
                "session_publish_ms",
                self.session_publish_ms,
                50,
                10_000,
            )? as u64),
            max_messages_per_s: in_range("max_messages_per_s", self.max_messages_per_s, 1, 100_000)?
                as u32,
            message_burst: in_range("message_burst", self.message_burst, 1, 100_000)? as u32,
            follow_max_per_s: in_range("follow_max_per_s", self.follow_max_per_s, 1, 10_000)?
                as u32,
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
        let raw = RawConfig::default();
        Settings {
            listen: SocketAddr::from(([127, 0, 0, 1], 5507)),
            follow_listen: SocketAddr::from(([127, 0, 0, 1], 14558)),
            frame_timeout: Duration::from_secs_f64(raw.frame_timeout_s),
            outgoing_queue: raw.outgoing_queue as usize,
            session_publish: Duration::from_millis(raw.session_publish_ms as u64),
            max_messages_per_s: raw.max_messages_per_s as u32,
            message_burst: raw.message_burst as u32,
            follow_max_per_s: raw.follow_max_per_s as u32,
            backend_wait: Duration::from_millis(raw.backend_wait_ms as u64),
        }
    }
}

impl Settings {
    /// The defaults with both sockets on `127.0.0.1:0` (tests, embedding).
    pub fn loopback_any_port() -> Settings {
        Settings {
            listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            follow_listen: SocketAddr::from(([127, 0, 0, 1], 0)),
            ..Settings::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    #[test]
    fn shipped_file_parses_and_equals_the_defaults() {
        let shipped = parse::<RawConfig>(RawConfig::DEFAULT_TOML, "deploy").unwrap();
        assert_eq!(shipped, RawConfig::default().validate().unwrap());
        assert_eq!(shipped, Settings::default());
        assert_eq!(
            parse::<RawConfig>("", "empty").unwrap(),
            Settings::default()
        );
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        let e = parse::<RawConfig>("listn = \"127.0.0.1:1\"", "t").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
        for (text, field) in [
            ("listen = \"localhost:5507\"", "listen"),
            ("follow_listen = \"1.2.3.4\"", "follow_listen"),
            ("frame_timeout_s = 0.0", "frame_timeout_s"),
            ("frame_timeout_s = nan", "frame_timeout_s"),
            ("outgoing_queue = 1", "outgoing_queue"),
            ("session_publish_ms = 20000", "session_publish_ms"),
            ("max_messages_per_s = 0", "max_messages_per_s"),
            ("message_burst = 1000000", "message_burst"),
            ("follow_max_per_s = -5", "follow_max_per_s"),
            ("backend_wait_ms = -1", "backend_wait_ms"),
            ("backend_wait_ms = 10001", "backend_wait_ms"),
        ] {
            let e = parse::<RawConfig>(text, "t").unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn values_are_converted() {
        let s = parse::<RawConfig>(
            "listen = \"0.0.0.0:6000\"\nframe_timeout_s = 0.25\nsession_publish_ms = 200\nbackend_wait_ms = 0",
            "t",
        )
        .unwrap();
        assert_eq!(s.listen, SocketAddr::from(([0, 0, 0, 0], 6000)));
        assert_eq!(s.frame_timeout, Duration::from_millis(250));
        assert_eq!(s.session_publish, Duration::from_millis(200));
        assert_eq!(s.backend_wait, Duration::ZERO);
    }
}
