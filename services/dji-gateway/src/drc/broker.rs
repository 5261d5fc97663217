//! The DRC broker connection: the MQTT client options (address, credentials, TLS)
//! from drc_mode_enter, the first connect (CONNACK + SUBACK within the timeout),
//! and the driver task that owns the rumqttc `EventLoop` afterwards.
//!
//! The driver is the only code that polls the event loop (rumqttc's `poll` must not
//! be dropped half-way through a reconnect), so the DRC task can wait on timers
//! freely. It forwards `drc/down` messages stamped with their arrival, reconnects
//! with the gateway's jittered exponential backoff ([`crate::mqtt::RECONNECT_JITTER`]), subscribes again after every reconnect (clean
//! sessions), and says when the link goes down and comes back up.
//!
//! TLS: [`crate::tls`] (rustls, `ring`) with the roots of `[drc] ca_file` (PEM); the
//! server name is the host of `mqtt_broker.address` (an IPv6 literal cannot be a TLS
//! server name with rumqttc: use a host name). Without `ca_file` a TLS request is
//! refused at drc_mode_enter.

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use dji_proto::{topic, MqttBroker, TopicKind};
use rumqttc::{
    AsyncClient, Event, EventLoop, MqttOptions, NetworkOptions, Outgoing, Packet, QoS,
    SubscribeReasonCode,
};
use skymesh_runtime::CancellationToken;
use tokio::sync::mpsc;

use super::DrcConfig;
use skymesh_runtime::Backoff;

/// MQTT keep-alive of the DRC connection (a dead broker is noticed within ~1.5×).
pub const KEEP_ALIVE: Duration = Duration::from_secs(10);
/// Largest packet either way: bigger than any DRC message, so an oversized payload
/// from the cloud is dropped and counted by the parser rather than killing the link.
const MAX_PACKET_BYTES: usize = 1 << 20;
/// Requests (publishes) the client queues before `try_publish` refuses.
const REQUEST_CAPACITY: usize = 256;
/// How long a stopping driver waits for its DISCONNECT to go out.
const DISCONNECT_GRACE: Duration = Duration::from_millis(500);
/// An `expire_time` above this is a Unix time (the document's example is
/// 1672744922); at or below, seconds after drc_mode_enter.
const UNIX_TIME_THRESHOLD: i64 = 1_000_000_000;

/// Why drc_mode_enter could not connect.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConnectError {
    #[error("broker address `{0}` is not host:port")]
    BadAddress(String),
    #[error("enable_tls requested but [drc] ca_file is not configured")]
    NoCaFile,
    #[error("TLS setup: {0}")]
    Tls(String),
    #[error("the client would not queue the subscription: {0}")]
    Client(String),
    #[error("connection failed: {0}")]
    Connection(String),
    #[error("the broker refused the subscription to {0}")]
    SubscribeRefused(String),
    #[error("no CONNACK and SUBACK within {0:?}")]
    Timeout(Duration),
}

/// `host:port` or `[v6]:port` → (host for rumqttc, port). An IPv6 host keeps its
/// brackets: rumqttc joins host and port with `:` to connect.
pub fn parse_address(address: &str) -> Result<(String, u16), ConnectError> {
    let bad = || ConnectError::BadAddress(address.to_string());
    let (host, port) = address.rsplit_once(':').ok_or_else(bad)?;
    let port: u16 = port.parse().ok().filter(|p| *p != 0).ok_or_else(bad)?;
    let plain = !host.is_empty() && !host.contains([':', '[', ']', '/', ' ']);
    let bracketed = host.len() > 2
        && host.starts_with('[')
        && host.ends_with(']')
        && host[1..host.len() - 1]
            .parse::<std::net::Ipv6Addr>()
            .is_ok();
    if plain || bracketed {
        Ok((host.to_string(), port))
    } else {
        Err(bad())
    }
}

/// When the credentials of drc_mode_enter expire: `expire_time` above
/// [`UNIX_TIME_THRESHOLD`] is a Unix time in seconds (as in the document's example),
/// else seconds after `entered`. A connection that is up is not affected (the
/// document's words); once expired, a failed reconnect leaves DRC mode.
pub fn expiry(expire_time: i64, entered: Instant, now_unix: Duration) -> Instant {
    let secs = if expire_time > UNIX_TIME_THRESHOLD {
        (expire_time as u64).saturating_sub(now_unix.as_secs())
    } else {
        expire_time.max(0) as u64
    };
    entered
        .checked_add(Duration::from_secs(secs))
        .unwrap_or(entered + Duration::from_secs(100 * 365 * 86_400))
}

/// The wall clock as a duration since the Unix epoch (0 if the clock is before it).
pub fn unix_now() -> Duration {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
}

/// The client options for `broker`.
pub fn options(config: &DrcConfig, broker: &MqttBroker) -> Result<MqttOptions, ConnectError> {
    let (host, port) = parse_address(&broker.address)?;
    let mut o = MqttOptions::new(broker.client_id.clone(), host, port);
    o.set_keep_alive(KEEP_ALIVE)
        .set_clean_session(true)
        .set_max_packet_size(MAX_PACKET_BYTES, MAX_PACKET_BYTES);
    if !broker.username.is_empty() || !broker.password.is_empty() {
        o.set_credentials(broker.username.clone(), broker.password.clone());
    }
    if broker.enable_tls {
        let ca = config.ca_file.as_deref().ok_or(ConnectError::NoCaFile)?;
        o.set_transport(crate::tls::transport(ca).map_err(|e| ConnectError::Tls(e.to_string()))?);
    }
    Ok(o)
}

/// A connected, subscribed DRC link.
pub struct Connected {
    pub client: AsyncClient,
    pub events: EventLoop,
    /// `thing/product/{sn}/drc/down`
    pub down: String,
    /// `thing/product/{sn}/drc/up`
    pub up: String,
}

/// Connects and subscribes `drc/down` (QoS 1); done when both CONNACK and SUBACK
/// arrived within `connect_timeout_ms`.
pub async fn connect(
    config: &DrcConfig,
    gateway_sn: &str,
    broker: &MqttBroker,
) -> Result<Connected, ConnectError> {
    let (client, mut events) = AsyncClient::new(options(config, broker)?, REQUEST_CAPACITY);
    let mut network = NetworkOptions::new();
    // Small messages at 10 Hz: no Nagle delay.
    network.set_tcp_nodelay(true);
    network.set_connection_timeout(u64::from(config.connect_timeout_ms.div_ceil(1000)).max(1));
    events.set_network_options(network);
    let down = topic(gateway_sn, TopicKind::DrcDown);
    let up = topic(gateway_sn, TopicKind::DrcUp);
    client
        .try_subscribe(down.clone(), QoS::AtLeastOnce)
        .map_err(|e| ConnectError::Client(e.to_string()))?;
    let limit = Duration::from_millis(config.connect_timeout_ms.into());
    let handshake = async {
        let mut connack = false;
        loop {
            match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => connack = true,
                Ok(Event::Incoming(Packet::SubAck(ack))) if connack => {
                    return if subscribed(&ack.return_codes) {
                        Ok(())
                    } else {
                        Err(ConnectError::SubscribeRefused(down.clone()))
                    };
                }
                Ok(_) => {}
                Err(e) => return Err(ConnectError::Connection(e.to_string())),
            }
        }
    };
    tokio::time::timeout(limit, handshake)
        .await
        .map_err(|_| ConnectError::Timeout(limit))??;
    Ok(Connected {
        client,
        events,
        down,
        up,
    })
}

impl std::fmt::Debug for Connected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Connected")
            .field("down", &self.down)
            .field("up", &self.up)
            .finish_non_exhaustive()
    }
}

fn subscribed(codes: &[SubscribeReasonCode]) -> bool {
    !codes.is_empty()
        && codes
            .iter()
            .all(|c| matches!(c, SubscribeReasonCode::Success(_)))
}

/// What the driver tells the DRC task.
#[derive(Debug)]
pub enum LinkEvent {
    /// A `drc/down` message and when it arrived.
    Message {
        publish: rumqttc::Publish,
        at: Instant,
    },
    /// Connected and subscribed again after a drop.
    Up,
    /// The connection dropped (`failures` = 1) or a reconnect failed (≥ 2).
    Down { failures: u32, error: String },
    /// The broker accepted the connection but refused the subscription.
    SubscribeRefused,
}

/// Reconnect pacing of the driver (the gateway's jittered exponential backoff).
#[derive(Debug, Clone, Copy)]
pub struct BackoffLimits {
    pub initial: Duration,
    pub max: Duration,
}

/// Runs the event loop until `stop`, then sends DISCONNECT (briefly).
pub async fn drive(
    conn: Connected,
    limits: BackoffLimits,
    events_out: mpsc::Sender<LinkEvent>,
    stop: CancellationToken,
) {
    let Connected {
        client,
        mut events,
        down,
        ..
    } = conn;
    let mut backoff =
        Backoff::new(limits.initial, limits.max).with_jitter(crate::mqtt::RECONNECT_JITTER);
    let mut connected = true;
    loop {
        let polled = tokio::select! {
            _ = stop.cancelled() => break,
            r = events.poll() => r,
        };
        let out = match polled {
            Ok(Event::Incoming(Packet::Publish(p))) if p.topic == down => {
                let at = tokio::time::Instant::now().into_std();
                Some(LinkEvent::Message { publish: p, at })
            }
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                backoff.reset();
                connected = true;
                // Clean session: the subscription is gone with the old connection.
                if let Err(e) = client.try_subscribe(down.clone(), QoS::AtLeastOnce) {
                    tracing::warn!(error = %e, "DRC: cannot queue the subscription after reconnecting");
                }
                None
            }
            Ok(Event::Incoming(Packet::SubAck(ack))) => Some(if subscribed(&ack.return_codes) {
                LinkEvent::Up
            } else {
                LinkEvent::SubscribeRefused
            }),
            Ok(_) => None,
            Err(e) => {
                connected = false;
                let delay = backoff.next_delay(fastrand::f64());
                let report = LinkEvent::Down {
                    failures: backoff.failures(),
                    error: e.to_string(),
                };
                tokio::select! {
                    _ = stop.cancelled() => break,
                    r = events_out.send(report) => if r.is_err() { break },
                }
                tokio::select! {
                    _ = stop.cancelled() => break,
                    _ = tokio::time::sleep(delay) => {}
                }
                None
            }
        };
        if let Some(event) = out {
            tokio::select! {
                _ = stop.cancelled() => break,
                r = events_out.send(event) => if r.is_err() { break },
            }
        }
    }
    if connected && client.try_disconnect().is_ok() {
        let _ = tokio::time::timeout(DISCONNECT_GRACE, async {
            loop {
                match events.poll().await {
                    Ok(Event::Outgoing(Outgoing::Disconnect)) | Err(_) => break,
                    Ok(_) => {}
                }
            }
        })
        .await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses() {
        assert_eq!(
            parse_address("mqtt.dji.com:8883"),
            Ok(("mqtt.dji.com".into(), 8883))
        );
        assert_eq!(
            parse_address("192.0.2.1:1883"),
            Ok(("192.0.2.1".into(), 1883))
        );
        assert_eq!(parse_address("[::1]:1883"), Ok(("[::1]".into(), 1883)));
        for bad in [
            "",
            "host",
            "host:",
            ":1883",
            "host:0",
            "host:65536",
            "::1:1883",
            "[::1:1883",
            "[zz]:1",
            "a b:1",
            "tcp://h:1",
        ] {
            assert!(parse_address(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn expiry_reads_unix_times_and_relative_seconds() {
        let t0 = Instant::now();
        let now = Duration::from_secs(1_700_000_000);
        assert_eq!(expiry(600, t0, now), t0 + Duration::from_secs(600));
        assert_eq!(expiry(0, t0, now), t0);
        assert_eq!(expiry(-5, t0, now), t0);
        assert_eq!(expiry(1_700_000_060, t0, now), t0 + Duration::from_secs(60));
        assert_eq!(
            expiry(1_672_744_922, t0, now),
            t0,
            "the document's example is long past"
        );
    }

    fn broker(tls: bool) -> MqttBroker {
        MqttBroker {
            address: "127.0.0.1:1883".into(),
            client_id: "drc-sn".into(),
            username: "u".into(),
            password: "p".into(),
            expire_time: 600,
            enable_tls: tls,
        }
    }

    #[test]
    fn tls_needs_a_ca_file() {
        let cfg = DrcConfig::default();
        assert_eq!(
            options(&cfg, &broker(true)).err(),
            Some(ConnectError::NoCaFile)
        );
        let o = options(&cfg, &broker(false)).unwrap();
        assert_eq!(o.broker_address(), ("127.0.0.1".to_string(), 1883));
        assert_eq!(o.credentials().map(|l| l.username), Some("u".to_string()));
        let missing = DrcConfig {
            ca_file: Some("/nonexistent/ca.pem".into()),
            ..DrcConfig::default()
        };
        assert!(matches!(
            options(&missing, &broker(true)),
            Err(ConnectError::Tls(_))
        ));
        let dir = tempfile::tempdir().unwrap();
        let ca = dir.path().join("ca.pem");
        std::fs::write(&ca, crate::tls::TEST_CA_PEM).unwrap();
        let with_ca = DrcConfig {
            ca_file: Some(ca),
            ..DrcConfig::default()
        };
        with_ca.validate().unwrap();
        let o = options(&with_ca, &broker(true)).unwrap();
        assert!(matches!(o.transport(), rumqttc::Transport::Tls(_)));
        let plain = options(&with_ca, &broker(false)).unwrap();
        assert!(matches!(plain.transport(), rumqttc::Transport::Tcp));
    }

    #[tokio::test]
    async fn nobody_listening_is_a_connection_error() {
        let free = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = free.local_addr().unwrap();
        drop(free);
        let b = MqttBroker {
            address: addr.to_string(),
            ..broker(false)
        };
        let cfg = DrcConfig {
            connect_timeout_ms: 2000,
            ..DrcConfig::default()
        };
        let e = connect(&cfg, "SN1", &b).await.unwrap_err();
        assert!(
            matches!(e, ConnectError::Connection(_) | ConnectError::Timeout(_)),
            "{e}"
        );
    }

    #[tokio::test]
    async fn a_silent_server_times_out() {
        // Accepts TCP but never answers CONNECT.
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let hold = tokio::spawn(async move {
            let mut held = Vec::new();
            while let Ok((s, _)) = listener.accept().await {
                held.push(s);
            }
        });
        let b = MqttBroker {
            address: addr.to_string(),
            ..broker(false)
        };
        let cfg = DrcConfig {
            connect_timeout_ms: 300,
            ..DrcConfig::default()
        };
        let e = connect(&cfg, "SN1", &b).await.unwrap_err();
        assert_eq!(e, ConnectError::Timeout(Duration::from_millis(300)));
        hold.abort();
    }
}
