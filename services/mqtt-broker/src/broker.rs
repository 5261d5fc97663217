//! The embedded rumqttd broker behind the gate.
//!
//! rumqttd runs on its own threads: `Broker::new` starts its router thread and
//! `Broker::start` (blocking) starts one thread per listener with its own
//! current-thread tokio runtime, then joins them. We call `start` on a dedicated
//! std thread. rumqttd listens only on an internal 127.0.0.1 port and accepts only
//! the gate's secret password; clients connect to the gate ([`crate::gate`]) on
//! `listen` (and through the TLS terminator), which checks logins, topic ACLs and
//! the topic limit, and forwards to rumqttd.
//!
//! rumqttd 0.20 has no stop API: its threads run until the process ends. So on
//! SIGTERM [`serve`] returns at once, `service_main` returns, and the process exits
//! (ending the broker threads and closing every client connection) well within the
//! runtime's grace period. Embedded in a test process, the broker keeps listening
//! after `serve` returns.
//!
//! The public addresses are bound here first (a port in use is a clear
//! [`BrokerError::Listen`]). The internal port is picked free just before rumqttd
//! binds it; rumqttd only logs a bind failure and its thread then ends, which is
//! [`BrokerError::Stopped`] (the supervisor restarts the service). Before `ready`,
//! the gate logs in to rumqttd once (CONNECT/CONNACK), so ready means serving.

use std::collections::HashMap;
use std::net::SocketAddr;

use std::sync::Arc;
use std::time::Duration;

use bytes::BytesMut;
use rumqttd::protocol::v4::V4;
use rumqttd::protocol::{Connect, ConnectReturnCode, Login, Packet, Protocol};
use rumqttd::{
    Broker, Config, ConnectionSettings, MetricSettings, MetricType, RouterConfig, ServerSettings,
};
use skymesh_runtime::{CancellationToken, Stats};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{oneshot, Semaphore};

use crate::config::Settings;
use crate::gate::{Gate, GateMetrics};
use crate::metrics::Metrics;

/// Why the broker could not run.
#[derive(Debug, thiserror::Error)]
pub enum BrokerError {
    /// The OS cause is the `source` (shown by `{:#}`), not repeated here.
    #[error("cannot listen on {addr}")]
    Listen {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("TLS: {0}")]
    Tls(#[from] crate::tls::TlsError),
    #[error("cannot build the rumqttd configuration: {0}")]
    Config(String),
    #[error("cannot start the broker thread: {0}")]
    Thread(std::io::Error),
    #[error("cannot read rumqttd's meters or alerts: {0}")]
    Meters(String),
    #[error("cannot make the internal password: {0}")]
    Secret(std::io::Error),
    #[error("the broker does not answer on its internal port {addr}: {why}")]
    Probe { addr: SocketAddr, why: String },
    #[error("the broker stopped ({0}); rumqttd's log above says why")]
    Stopped(String),
}

/// Binds `addr` (non-blocking, for tokio), or the clear [`BrokerError::Listen`].
fn std_listener(addr: SocketAddr) -> Result<std::net::TcpListener, BrokerError> {
    let listen_err = |source| BrokerError::Listen { addr, source };
    let l = std::net::TcpListener::bind(addr).map_err(listen_err)?;
    l.set_nonblocking(true).map_err(listen_err)?;
    Ok(l)
}

/// Segments of one topic's log kept in memory (rumqttd keeps every topic's recent
/// publishes for slow subscribers): 2 × max(4 MiB, max_payload_size) per topic.
const SEGMENT_COUNT: usize = 2;
const MIN_SEGMENT_SIZE: usize = 4 * 1024 * 1024;
/// Packets queued towards one client before the router waits for it.
const MAX_OUTGOING_PACKETS: u64 = 200;

/// The rumqttd configuration for `settings`: one plain TCP MQTT 3.1.1 listener on
/// `internal` (the loopback) that accepts only the password `secret`.
pub fn rumqttd_config(
    settings: &Settings,
    internal: SocketAddr,
    secret: &str,
) -> Result<Config, BrokerError> {
    let mut connections = ConnectionSettings {
        connection_timeout_ms: u16::try_from(settings.connection_timeout.as_millis())
            .map_err(|_| BrokerError::Config("connection timeout over 65535 ms".into()))?,
        max_payload_size: settings.max_payload_size,
        max_inflight_count: settings.max_inflight,
        auth: None,
        external_auth: None,
        // Clients may subscribe to any filter the gate lets through.
        dynamic_filters: true,
    };
    // Any username (the gate checked it), only the gate's secret.
    let secret = Arc::new(secret.to_owned());
    connections.set_auth_handler(move |_client, _user, password| {
        let ok = crate::gate::constant_time_eq(password.as_bytes(), secret.as_bytes());
        async move { ok }
    });
    let server = ServerSettings {
        name: "mqtt-v4".into(),
        listen: internal,
        tls: None,
        next_connection_delay_ms: 1,
        connections,
    };
    // `MetricSettings` has private fields: build it through serde. Both kinds must
    // be configured: rumqttd 0.20's timer thread panics when only one is.
    let interval: MetricSettings = serde_json::from_value(serde_json::json!({
        "push_interval": settings.meters_interval.as_secs().max(1),
    }))
    .map_err(|e| BrokerError::Config(e.to_string()))?;
    Ok(Config {
        id: 0,
        router: RouterConfig {
            max_connections: settings.max_connections,
            max_outgoing_packet_count: MAX_OUTGOING_PACKETS,
            max_segment_size: settings.max_payload_size.max(MIN_SEGMENT_SIZE),
            max_segment_count: SEGMENT_COUNT,
            ..RouterConfig::default()
        },
        v4: Some(HashMap::from([("1".to_string(), server)])),
        metrics: Some(HashMap::from([
            (MetricType::Meters, interval.clone()),
            (MetricType::Alerts, interval),
        ])),
        ..Config::default()
    })
}

/// How long the broker has to answer the gate's first login at start.
const PROBE_TIMEOUT: Duration = Duration::from_secs(10);

/// Logs in to rumqttd on `addr` with `secret` and waits for CONNACK accepted, then
/// closes the connection cleanly (a FIN, and rumqttd's own close read).
async fn probe(addr: SocketAddr, secret: &str) -> Result<(), String> {
    let mut s = tokio::net::TcpStream::connect(addr)
        .await
        .map_err(|e| e.to_string())?;
    let connect = Connect {
        keep_alive: 10,
        client_id: "skymesh-mqtt-broker-probe".into(),
        clean_session: true,
    };
    let login = Login {
        username: String::new(),
        password: secret.to_owned(),
    };
    let mut out = BytesMut::new();
    V4.write(
        Packet::Connect(connect, None, None, None, Some(login)),
        &mut out,
    )
    .map_err(|e| e.to_string())?;
    s.write_all(&out).await.map_err(|e| e.to_string())?;
    let mut buf = BytesMut::new();
    loop {
        if s.read_buf(&mut buf).await.map_err(|e| e.to_string())? == 0 {
            return Err("closed before CONNACK".into());
        }
        match V4.read_mut(&mut buf, 16) {
            Ok(Packet::ConnAck(a, _)) if a.code == ConnectReturnCode::Success => break,
            Ok(other) => return Err(format!("answered {other:?}")),
            Err(rumqttd::protocol::Error::InsufficientBytes(_)) => {}
            Err(e) => return Err(e.to_string()),
        }
    }
    s.shutdown().await.map_err(|e| e.to_string())?;
    let mut rest = [0u8; 64];
    while matches!(s.read(&mut rest).await, Ok(n) if n > 0) {}
    Ok(())
}

/// A 127.0.0.1 port that is free now, for rumqttd's internal listener.
fn free_loopback() -> Result<SocketAddr, BrokerError> {
    let addr: SocketAddr = ([127, 0, 0, 1], 0).into();
    let l =
        std::net::TcpListener::bind(addr).map_err(|source| BrokerError::Listen { addr, source })?;
    l.local_addr()
        .map_err(|source| BrokerError::Listen { addr, source })
}

/// Accepts plain clients on `listener` until `shutdown`; each goes through `gate`.
/// Open connections outlive the shutdown (they end with the process).
async fn serve_plain(
    listener: tokio::net::TcpListener,
    gate: Arc<Gate>,
    max_connections: usize,
    shutdown: CancellationToken,
) {
    let slots = Arc::new(Semaphore::new(max_connections));
    loop {
        let (stream, peer) = tokio::select! {
            _ = shutdown.cancelled() => return,
            r = listener.accept() => match r {
                Ok(x) => x,
                Err(e) => {
                    tracing::warn!(error = %e, "MQTT listener: accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            tracing::debug!(%peer, max_connections, "MQTT client refused: too many connections");
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let gate = gate.clone();
        tokio::spawn(async move {
            gate.client(stream, peer).await;
            drop(slot);
        });
    }
}

/// Runs the broker until `shutdown` (then `Ok`) or until it stops by itself (an
/// error). `ready` is called once rumqttd answered the gate's first login and the
/// listeners accept clients.
pub async fn serve(
    settings: Settings,
    stats: Stats,
    shutdown: CancellationToken,
    ready: impl FnOnce(),
) -> Result<(), BrokerError> {
    let metrics = Metrics::new(&stats);
    let gate_metrics = GateMetrics::new(&stats);
    // Fail clearly on a port in use.
    let listen_err = |source| BrokerError::Listen {
        addr: settings.listen,
        source,
    };
    let plain =
        tokio::net::TcpListener::from_std(std_listener(settings.listen)?).map_err(listen_err)?;
    // The TLS listener is bound before the broker starts, so a port in use fails
    // the same clear way; its files were checked by the config and are read again.
    let tls = match &settings.tls {
        None => None,
        Some(t) => {
            let config = crate::tls::server_config(t)?;
            let listener = std_listener(t.listen)?;
            let listener = tokio::net::TcpListener::from_std(listener).map_err(|source| {
                BrokerError::Listen {
                    addr: t.listen,
                    source,
                }
            })?;
            Some((listener, config))
        }
    };
    let secret = crate::gate::make_secret().map_err(BrokerError::Secret)?;
    let internal = free_loopback()?;
    let config = rumqttd_config(&settings, internal, &secret)?;
    let mut broker = Broker::new(config);
    let meters = broker
        .meters()
        .map_err(|e| BrokerError::Meters(e.to_string()))?;
    let alerts = broker
        .alerts()
        .map_err(|e| BrokerError::Meters(e.to_string()))?;
    let (done_tx, mut done_rx) = oneshot::channel();
    std::thread::Builder::new()
        .name("mqtt-broker".into())
        .spawn(move || {
            let outcome = match broker.start() {
                Ok(()) => "its listener ended".to_string(),
                Err(e) => e.to_string(),
            };
            let _ = done_tx.send(outcome);
        })
        .map_err(BrokerError::Thread)?;
    // rumqttd binds its listener on its own thread: log in once it does.
    let probed = async {
        let deadline = tokio::time::Instant::now() + PROBE_TIMEOUT;
        loop {
            match probe(internal, &secret).await {
                Ok(()) => return Ok(()),
                Err(why) if tokio::time::Instant::now() >= deadline => {
                    return Err(BrokerError::Probe {
                        addr: internal,
                        why,
                    })
                }
                Err(_) => tokio::time::sleep(Duration::from_millis(20)).await,
            }
        }
    };
    tokio::select! {
        r = probed => r?,
        outcome = &mut done_rx => {
            let why = outcome.unwrap_or_else(|_| "its thread panicked".to_string());
            return Err(BrokerError::Stopped(why));
        }
    }
    let gate = Arc::new(Gate::new(&settings, secret, internal, gate_metrics));
    tokio::spawn(serve_plain(
        plain,
        gate.clone(),
        settings.max_connections,
        shutdown.clone(),
    ));
    tracing::info!(
        listen = %settings.listen,
        max_connections = settings.max_connections,
        max_payload_size = settings.max_payload_size,
        max_topics = settings.max_topics,
        users = settings.users.len(),
        "MQTT broker started (plain TCP, MQTT 3.1.1)"
    );
    if let Some((listener, config)) = tls {
        let t = settings
            .tls
            .as_ref()
            .map(|t| (t.listen, t.client_ca_file.is_some()));
        tracing::info!(
            listen = ?t.map(|t| t.0),
            client_certificates = t.is_some_and(|t| t.1),
            "MQTT over TLS listener started"
        );
        tokio::spawn(crate::tls::serve(
            listener,
            crate::tls::Terminator {
                acceptor: tokio_rustls::TlsAcceptor::from(config),
                gate: gate.clone(),
                handshake_timeout: settings.connection_timeout,
                max_connections: settings.max_connections,
            },
            crate::tls::TlsMetrics::new(&stats),
            shutdown.clone(),
        ));
    }
    ready();
    loop {
        tokio::select! {
            biased;
            _ = shutdown.cancelled() => {
                tracing::info!("stopping: the broker's threads end with the process");
                return Ok(());
            }
            outcome = &mut done_rx => {
                let why = outcome.unwrap_or_else(|_| "its thread panicked".to_string());
                return Err(BrokerError::Stopped(why));
            }
            m = meters.next() => match m {
                Ok(m) => metrics.record(&m),
                Err(e) => return Err(BrokerError::Meters(e.to_string())),
            },
            a = alerts.next() => match a {
                Ok(a) => metrics.record_alerts(&a),
                Err(e) => return Err(BrokerError::Meters(e.to_string())),
            },
        }
    }
}
