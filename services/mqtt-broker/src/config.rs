//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees. The shipped, commented defaults are
//! `deploy/mqtt-broker.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::{in_range, socket_addr};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::tls::TlsSettings;

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../deploy/mqtt-broker.toml");

/// The largest "remaining length" MQTT can encode.
pub const MQTT_MAX_PACKET: usize = 268_435_455;

/// The validated configuration.
#[derive(Clone, PartialEq, Eq)]
pub struct Settings {
    /// Plain TCP MQTT 3.1.1 listener.
    pub listen: SocketAddr,
    pub max_connections: usize,
    /// Largest packet (remaining length) a client may send, bytes.
    pub max_payload_size: usize,
    pub max_inflight: usize,
    /// Time to receive CONNECT on a new connection.
    pub connection_timeout: Duration,
    /// How often rumqttd's meters are pushed into the service's metrics.
    pub meters_interval: Duration,
    /// username → password and topic ACL; empty = anonymous clients (only allowed
    /// when every listener is on the loopback or TLS requires client certificates).
    pub users: BTreeMap<String, User>,
    /// Topic names and subscription filters the broker may know at once (rumqttd
    /// keeps a log per filter and an entry per topic until it restarts).
    pub max_topics: usize,
    /// The TLS listener (a terminator forwarding to `listen`), if configured.
    pub tls: Option<TlsSettings>,
}

impl fmt::Debug for Settings {
    /// Passwords are not printed.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Settings")
            .field("listen", &self.listen)
            .field("max_connections", &self.max_connections)
            .field("max_payload_size", &self.max_payload_size)
            .field("max_inflight", &self.max_inflight)
            .field("connection_timeout", &self.connection_timeout)
            .field("meters_interval", &self.meters_interval)
            .field("users", &self.users)
            .field("max_topics", &self.max_topics)
            .field("tls", &self.tls)
            .finish()
    }
}

/// One validated `[[user]]`: its password and the topic filters it may use.
#[derive(Clone, PartialEq, Eq)]
pub struct User {
    pub password: String,
    /// A PUBLISH (and the CONNECT's will) is allowed on a topic matching one of these.
    pub publish: Vec<String>,
    /// A SUBSCRIBE filter is allowed when every topic it matches is matched by one
    /// of these (`crate::acl::covers`).
    pub subscribe: Vec<String>,
}

impl fmt::Debug for User {
    /// The password is not printed.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("User")
            .field("publish", &self.publish)
            .field("subscribe", &self.subscribe)
            .finish_non_exhaustive()
    }
}

/// One `[[user]]` entry.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawUser {
    pub name: String,
    pub password: String,
    /// Topic filters the user may publish to; required (`["#"]` = every topic).
    pub publish: Option<Vec<String>>,
    /// Topic filters the user may subscribe within; required.
    pub subscribe: Option<Vec<String>>,
}

/// `[tls]` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawTls {
    #[serde(default = "d_tls_listen")]
    pub listen: String,
    #[serde(default)]
    pub cert_file: String,
    #[serde(default)]
    pub key_file: String,
    #[serde(default)]
    pub client_ca_file: String,
}

fn d_tls_listen() -> String {
    "127.0.0.1:8883".into()
}

/// The TOML file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    #[serde(default = "d_listen")]
    pub listen: String,
    #[serde(default = "d_max_connections")]
    pub max_connections: u32,
    #[serde(default = "d_max_payload_size")]
    pub max_payload_size: u64,
    #[serde(default = "d_max_inflight")]
    pub max_inflight: u32,
    #[serde(default = "d_connection_timeout_ms")]
    pub connection_timeout_ms: u32,
    #[serde(default = "d_meters_interval_s")]
    pub meters_interval_s: u32,
    #[serde(default = "d_max_topics")]
    pub max_topics: u32,
    #[serde(default)]
    pub user: Vec<RawUser>,
    #[serde(default)]
    pub tls: Option<RawTls>,
}

fn d_listen() -> String {
    "127.0.0.1:1883".into()
}
fn d_max_connections() -> u32 {
    100
}
fn d_max_payload_size() -> u64 {
    1_048_576
}
fn d_max_inflight() -> u32 {
    100
}
fn d_connection_timeout_ms() -> u32 {
    5000
}
fn d_meters_interval_s() -> u32 {
    1
}
fn d_max_topics() -> u32 {
    256
}

/// The topic filters of `user[i].<key>`, each checked ([`crate::acl::valid_filter`]).
fn acl_list(field: &str, list: Option<Vec<String>>) -> Result<Vec<String>, ConfigError> {
    let Some(list) = list else {
        return Err(ConfigError::invalid(
            field,
            "required: the topic filters this user may use, e.g. \
             [\"thing/product/+/services_reply\"] ([\"#\"] = every topic, [] = none)",
        ));
    };
    for (j, f) in list.iter().enumerate() {
        if let Err(why) = crate::acl::valid_filter(f) {
            return Err(ConfigError::invalid(
                format!("{field}[{j}]"),
                format!("`{f}` is not an MQTT topic filter: {why}"),
            ));
        }
    }
    Ok(list)
}

/// Clients elsewhere can reach `addr`.
fn reachable_from_elsewhere(addr: SocketAddr) -> bool {
    !addr.ip().is_loopback()
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = DEFAULT_CONFIG_TOML;

    fn validate(self) -> Result<Settings, ConfigError> {
        let listen = socket_addr("listen", &self.listen)?;
        if listen.port() == 0 {
            return Err(ConfigError::invalid(
                "listen",
                "port 0 is not allowed: clients need a fixed port",
            ));
        }
        let max_connections = in_range("max_connections", self.max_connections, 1, 10_000)?;
        let max_payload_size = in_range(
            "max_payload_size",
            self.max_payload_size,
            1,
            MQTT_MAX_PACKET as u64,
        )?;
        let max_inflight = in_range("max_inflight", self.max_inflight, 1, 65_535)?;
        let timeout_ms = in_range(
            "connection_timeout_ms",
            self.connection_timeout_ms,
            1,
            u32::from(u16::MAX),
        )?;
        let meters_s = in_range("meters_interval_s", self.meters_interval_s, 1, 60)?;
        let max_topics = in_range("max_topics", self.max_topics, 1, 1_000_000)?;
        let mut users = BTreeMap::new();
        let mut seen = HashSet::new();
        for (i, u) in self.user.into_iter().enumerate() {
            let field = format!("user[{i}]");
            if u.name.is_empty() || u.name.len() > 256 {
                return Err(ConfigError::invalid(
                    format!("{field}.name"),
                    "must be 1-256 bytes",
                ));
            }
            if u.password.is_empty() || u.password.len() > 256 {
                return Err(ConfigError::invalid(
                    format!("{field}.password"),
                    "must be 1-256 bytes",
                ));
            }
            if !seen.insert(u.name.clone()) {
                return Err(ConfigError::invalid(
                    format!("{field}.name"),
                    format!("user `{}` is listed twice", u.name),
                ));
            }
            let publish = acl_list(&format!("{field}.publish"), u.publish)?;
            let subscribe = acl_list(&format!("{field}.subscribe"), u.subscribe)?;
            users.insert(
                u.name,
                User {
                    password: u.password,
                    publish,
                    subscribe,
                },
            );
        }
        let tls = match self.tls {
            None => None,
            Some(raw) => Some(tls(raw, listen)?),
        };
        // Anonymous clients drive the DJI gateway at DRC priority: only local ones.
        if users.is_empty() && reachable_from_elsewhere(listen) {
            return Err(ConfigError::invalid(
                "listen",
                format!(
                    "{listen} is reachable from other hosts and no [[user]] is configured: \
                     anyone who reaches it could publish DJI commands. Configure [[user]]s \
                     (each with publish/subscribe topic filters) or listen on 127.0.0.1"
                ),
            ));
        }
        if let Some(t) = &tls {
            if users.is_empty() && t.client_ca_file.is_none() && reachable_from_elsewhere(t.listen)
            {
                return Err(ConfigError::invalid(
                    "tls.listen",
                    format!(
                        "{} is reachable from other hosts and neither [[user]]s nor \
                         tls.client_ca_file (client certificates) are configured: anyone who \
                         reaches it could publish DJI commands",
                        t.listen
                    ),
                ));
            }
        }
        Ok(Settings {
            tls,
            listen,
            max_connections: max_connections as usize,
            max_payload_size: usize::try_from(max_payload_size).unwrap_or(MQTT_MAX_PACKET),
            max_inflight: max_inflight as usize,
            connection_timeout: Duration::from_millis(u64::from(timeout_ms)),
            meters_interval: Duration::from_secs(u64::from(meters_s)),
            users,
            max_topics: max_topics as usize,
        })
    }
}

fn required_path(field: &str, v: &str) -> Result<PathBuf, ConfigError> {
    if v.is_empty() {
        return Err(ConfigError::invalid(
            field,
            "required in [tls] (a path to a PEM file)",
        ));
    }
    Ok(PathBuf::from(v))
}

/// `[tls]`: addresses checked against the plain listener, and every file read,
/// parsed and matched (the key belongs to the certificate) as at start.
fn tls(raw: RawTls, plain: SocketAddr) -> Result<TlsSettings, ConfigError> {
    let listen = socket_addr("tls.listen", &raw.listen)?;
    if listen.port() == 0 {
        return Err(ConfigError::invalid(
            "tls.listen",
            "port 0 is not allowed: clients need a fixed port",
        ));
    }
    if listen.port() == plain.port()
        && (listen.ip() == plain.ip()
            || listen.ip().is_unspecified()
            || plain.ip().is_unspecified())
    {
        return Err(ConfigError::invalid(
            "tls.listen",
            format!("overlaps the plain listener `listen` ({plain})"),
        ));
    }
    let client_ca_file = if raw.client_ca_file.is_empty() {
        None
    } else {
        // Client certificates mean nothing if the plain listener, which the TLS
        // listener forwards to, is reachable from elsewhere without one.
        if !plain.ip().is_loopback() {
            return Err(ConfigError::invalid(
                "tls.client_ca_file",
                format!(
                    "requires the plain listener `listen` on the loopback (it is {plain}): \
                     clients without a certificate could use it"
                ),
            ));
        }
        Some(PathBuf::from(&raw.client_ca_file))
    };
    let settings = TlsSettings {
        listen,
        cert_file: required_path("tls.cert_file", &raw.cert_file)?,
        key_file: required_path("tls.key_file", &raw.key_file)?,
        client_ca_file,
    };
    crate::tls::server_config(&settings)
        .map_err(|e| ConfigError::invalid(e.key(), e.to_string()))?;
    Ok(settings)
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    #[test]
    fn the_shipped_defaults_parse() {
        let s = parse::<RawConfig>(DEFAULT_CONFIG_TOML, "default").expect("defaults");
        assert_eq!(s.listen, "127.0.0.1:1883".parse().expect("addr"));
        assert_eq!(s.max_connections, 100);
        assert_eq!(s.max_payload_size, 1_048_576);
        assert_eq!(s.max_inflight, 100);
        assert_eq!(s.connection_timeout, Duration::from_secs(5));
        assert!(s.users.is_empty());
        assert_eq!(s.max_topics, 256);
        assert_eq!(s.tls, None, "TLS is off unless [tls] is configured");
    }

    #[test]
    fn users_are_read_and_passwords_not_printed() {
        let s = parse::<RawConfig>(
            "[[user]]\nname = \"cloud\"\npassword = \"secret\"\n\
             publish = [\"thing/product/+/services\"]\nsubscribe = [\"thing/product/#\"]\n",
            "t",
        )
        .expect("users");
        let cloud = s.users.get("cloud").expect("cloud");
        assert_eq!(cloud.password, "secret");
        assert_eq!(cloud.publish, ["thing/product/+/services"]);
        assert_eq!(cloud.subscribe, ["thing/product/#"]);
        assert!(!format!("{s:?}").contains("secret"));
    }

    #[test]
    fn bad_values_name_the_field() {
        for (text, field) in [
            ("listen = \"localhost\"", "listen"),
            ("listen = \"127.0.0.1:0\"", "listen"),
            ("max_connections = 0", "max_connections"),
            ("max_payload_size = 0", "max_payload_size"),
            ("max_payload_size = 268435456", "max_payload_size"),
            ("max_inflight = 70000", "max_inflight"),
            ("connection_timeout_ms = 70000", "connection_timeout_ms"),
            ("meters_interval_s = 0", "meters_interval_s"),
            ("max_topics = 0", "max_topics"),
            ("[[user]]\nname = \"\"\npassword = \"p\"", "user[0].name"),
            ("[[user]]\nname = \"a\"\npassword = \"\"", "user[0].password"),
            (
                "[[user]]\nname = \"a\"\npassword = \"p\"\npublish = []\nsubscribe = []\n\
                 [[user]]\nname = \"a\"\npassword = \"q\"",
                "user[1].name",
            ),
            (
                "[[user]]\nname = \"a\"\npassword = \"p\"\nsubscribe = []",
                "user[0].publish",
            ),
            (
                "[[user]]\nname = \"a\"\npassword = \"p\"\npublish = []",
                "user[0].subscribe",
            ),
            (
                "[[user]]\nname = \"a\"\npassword = \"p\"\npublish = [\"a/#/b\"]\nsubscribe = []",
                "user[0].publish[0]",
            ),
            (
                "[[user]]\nname = \"a\"\npassword = \"p\"\npublish = []\nsubscribe = [\"ok\", \"a+\"]",
                "user[0].subscribe[1]",
            ),
            // Anonymous clients only on the loopback.
            ("listen = \"0.0.0.0:1883\"", "listen"),
            ("listen = \"192.168.1.5:1883\"", "listen"),
            ("listen = \"[::]:1883\"", "listen"),
        ] {
            let e = parse::<RawConfig>(text, "t").expect_err(text);
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
        let e = parse::<RawConfig>("listen = \"0.0.0.0:1883\"", "t").expect_err("anonymous");
        assert!(e.to_string().contains("no [[user]]"), "{e}");
        let e = parse::<RawConfig>("bogus = 1", "t").expect_err("unknown key");
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    }
}

#[cfg(test)]
mod exposure_tests {
    use super::*;
    use skymesh_runtime::config::parse;

    #[test]
    fn a_reachable_listener_with_users_is_accepted() {
        let s = parse::<RawConfig>(
            "listen = \"0.0.0.0:1883\"\n[[user]]\nname = \"u\"\npassword = \"p\"\n\
             publish = [\"#\"]\nsubscribe = [\"#\"]\n",
            "t",
        )
        .expect("users make it safe");
        assert_eq!(s.users.len(), 1);
        parse::<RawConfig>("listen = \"[::1]:1883\"", "t").expect("loopback v6");
    }

    /// The DJI ACL documented in the shipped config parses, and gives the gateway
    /// its side of the six topics and the cloud the other.
    #[test]
    fn the_documented_dji_acl_parses() {
        let start = DEFAULT_CONFIG_TOML
            .find("# [[user]]\n# name = \"dji-gateway\"")
            .expect("the example is in the shipped config");
        let example: String = DEFAULT_CONFIG_TOML[start..]
            .lines()
            .take_while(|l| l.starts_with('#'))
            .map(|l| format!("{}\n", l.trim_start_matches('#').trim_start()))
            .collect();
        let s = parse::<RawConfig>(&example, "example").expect("the example parses");
        let gw = &s.users["dji-gateway"];
        let cloud = &s.users["cloud"];
        for t in ["services_reply", "events", "drc/up"] {
            let topic = format!("thing/product/SN1/{t}");
            assert!(crate::acl::any_matches(&gw.publish, &topic), "{topic}");
            assert!(!crate::acl::any_matches(&cloud.publish, &topic), "{topic}");
            assert!(crate::acl::any_covers(&cloud.subscribe, &topic), "{topic}");
        }
        for t in ["services", "events_reply", "drc/down"] {
            let topic = format!("thing/product/SN1/{t}");
            assert!(crate::acl::any_matches(&cloud.publish, &topic), "{topic}");
            assert!(!crate::acl::any_matches(&gw.publish, &topic), "{topic}");
            assert!(crate::acl::any_covers(&gw.subscribe, &topic), "{topic}");
        }
    }
}
