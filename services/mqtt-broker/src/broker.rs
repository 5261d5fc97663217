//! The embedded rumqttd broker.
//!
//! rumqttd runs on its own threads: `Broker::new` starts its router thread and
//! `Broker::start` (blocking) starts one thread per listener with its own
//! current-thread tokio runtime, then joins them. We call `start` on a dedicated
//! std thread; the service's tokio side only reads the meters and waits for the
//! shutdown token.
//!
//! rumqttd 0.20 has no stop API: its threads run until the process ends. So on
//! SIGTERM [`serve`] returns at once, `service_main` returns, and the process exits
//! (ending the broker threads and closing every client connection) well within the
//! runtime's grace period. Embedded in a test process, the broker keeps listening
//! after `serve` returns.
//!
//! A listener that rumqttd cannot bind is only logged by rumqttd, and `start` then
//! returns `Ok`. So the address is bound once here first (a port in use is a clear
//! [`BrokerError::Listen`]), and the broker thread ending for any reason is an
//! error ([`BrokerError::Stopped`]).

use std::collections::HashMap;
use std::net::SocketAddr;

use rumqttd::{
    Broker, Config, ConnectionSettings, MetricSettings, MetricType, RouterConfig, ServerSettings,
};
use skymesh_runtime::{CancellationToken, Stats};
use tokio::sync::oneshot;

use crate::config::Settings;
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

/// The rumqttd configuration for `settings`: one plain TCP MQTT 3.1.1 listener.
pub fn rumqttd_config(settings: &Settings) -> Result<Config, BrokerError> {
    let connections = ConnectionSettings {
        connection_timeout_ms: u16::try_from(settings.connection_timeout.as_millis())
            .map_err(|_| BrokerError::Config("connection timeout over 65535 ms".into()))?,
        max_payload_size: settings.max_payload_size,
        max_inflight_count: settings.max_inflight,
        auth: (!settings.users.is_empty()).then(|| {
            settings
                .users
                .iter()
                .map(|(u, p)| (u.clone(), p.clone()))
                .collect()
        }),
        external_auth: None,
        // Clients may subscribe to any filter (not only pre-declared ones).
        dynamic_filters: true,
    };
    let server = ServerSettings {
        name: "mqtt-v4".into(),
        listen: settings.listen,
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

/// Runs the broker until `shutdown` (then `Ok`) or until it stops by itself (an
/// error). `ready` is called once the broker's threads are started.
pub async fn serve(
    settings: Settings,
    stats: Stats,
    shutdown: CancellationToken,
    ready: impl FnOnce(),
) -> Result<(), BrokerError> {
    let metrics = Metrics::new(&stats);
    // Fail clearly on a port in use: rumqttd would only log it on its thread.
    drop(std_listener(settings.listen)?);
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
    let config = rumqttd_config(&settings)?;
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
    tracing::info!(
        listen = %settings.listen,
        max_connections = settings.max_connections,
        max_payload_size = settings.max_payload_size,
        users = settings.users.len(),
        "MQTT broker started (plain TCP, MQTT 3.1.1)"
    );
    if let Some((listener, config)) = tls {
        let t = settings
            .tls
            .as_ref()
            .map(|t| (t.listen, t.client_ca_file.is_some()));
        let upstream = crate::tls::upstream_of(settings.listen);
        tracing::info!(
            listen = ?t.map(|t| t.0),
            forwards_to = %upstream,
            client_certificates = t.is_some_and(|t| t.1),
            "MQTT over TLS listener started"
        );
        tokio::spawn(crate::tls::serve(
            listener,
            crate::tls::Terminator {
                acceptor: tokio_rustls::TlsAcceptor::from(config),
                upstream,
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
