//! The MAVLink connection: open, read, write, reconnect.
//!
//! The `mavlink` crate's connections are blocking, so each open connection gets two
//! blocking threads (tokio's blocking pool): a reader that forwards every message
//! into the service's [`LinkEvent`] channel, and a writer that drains the bounded
//! queue behind [`LinkWriter`]. Both poll a stop flag at least every
//! [`POLL`] (every transport is opened with a read timeout), so a shutdown or a
//! reconnect never waits on a blocked read.
//!
//! [`spawn`] runs the supervising task: connect (with backoff after failures,
//! forever, so the autopilot may start after us; logged at a sane rate), report
//! [`LinkEvent::Connected`], wait for the reader or writer to fail, report
//! [`LinkEvent::Disconnected`], and start over. The service keeps its state across
//! reconnects; only this module knows about sockets and serial ports.

use std::io;
use std::net::{TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self as std_mpsc, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::error::MessageReadError;
use mavlink::{
    Connectable, Connection, MavConnection, MavHeader, Message, SerialConfig, TcpConfig, UdpConfig,
    UdpMode,
};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::config::Endpoint;
use crate::metrics::Metrics;

/// How often blocking reads, writes and accepts look at the stop flag.
pub const POLL: Duration = Duration::from_millis(100);
/// Outgoing messages queued for the writer thread; beyond this a write is refused.
pub const WRITE_QUEUE: usize = 128;
/// Incoming messages queued for the service; the reader waits when it is full.
pub const EVENT_QUEUE: usize = 512;
/// How long a TCP connect may take (a host that drops SYNs would block for minutes).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);
/// A write blocked this long (peer stopped reading) fails the connection.
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);
/// Repeated connection failures are logged at warn level at most this often.
const WARN_EVERY: Duration = Duration::from_secs(30);

/// What the link tells the service.
// Nearly every event is a `Message`: boxing it would allocate per message for
// channel slots that are sized by the largest variant anyway.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum LinkEvent {
    /// A connection is open; write through this handle until `Disconnected`.
    Connected(LinkWriter),
    /// A message from the other end (any system, any component).
    Message(MavHeader, MavMessage),
    /// The connection closed or failed; a new one is being attempted.
    Disconnected { reason: String },
}

/// Why a message could not be queued for writing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WriteError {
    #[error("link write queue full ({WRITE_QUEUE} messages)")]
    Congested,
    #[error("link closed")]
    Closed,
}

/// Queues messages for the writer thread of one connection.
///
/// Held by the service from `Connected` until `Disconnected`; the writer thread holds
/// the receiving end and writes with our header (system id, component 191).
#[derive(Debug, Clone)]
pub struct LinkWriter {
    tx: SyncSender<MavMessage>,
}

impl LinkWriter {
    /// Queues `msg` without waiting.
    pub fn send(&self, msg: MavMessage) -> Result<(), WriteError> {
        self.tx.try_send(msg).map_err(|e| match e {
            TrySendError::Full(_) => WriteError::Congested,
            TrySendError::Disconnected(_) => WriteError::Closed,
        })
    }
}

/// What the link needs from the settings.
#[derive(Debug, Clone)]
pub struct LinkConfig {
    pub endpoint: Endpoint,
    /// Header of everything we send.
    pub system_id: u8,
    pub component_id: u8,
    pub reconnect_min: Duration,
    pub reconnect_max: Duration,
    /// Reopen a stream transport that delivered nothing for this long.
    pub silence_reconnect: Option<Duration>,
}

/// Starts the link. Events arrive on the returned receiver until `shutdown` fires
/// (then the task ends within about [`POLL`]) or the receiver is dropped.
pub fn spawn(
    config: LinkConfig,
    metrics: Metrics,
    shutdown: CancellationToken,
) -> (mpsc::Receiver<LinkEvent>, JoinHandle<()>) {
    let (tx, rx) = mpsc::channel(EVENT_QUEUE);
    let task = tokio::spawn(supervise(config, tx, metrics, shutdown));
    (rx, task)
}

type Conn = Connection<MavMessage>;

/// Connection failures, logged at warn level once and then every [`WARN_EVERY`].
#[derive(Debug, Default)]
struct FailureLog {
    attempts: u64,
    last_warn: Option<Instant>,
}

impl FailureLog {
    fn failed(&mut self, endpoint: &Endpoint, error: &io::Error, retry_in: Duration) {
        self.attempts += 1;
        let now = Instant::now();
        if self.last_warn.is_none_or(|t| now - t >= WARN_EVERY) {
            self.last_warn = Some(now);
            tracing::warn!(%endpoint, %error, attempts = self.attempts, retry_in_s = retry_in.as_secs_f32(), "cannot connect to the autopilot; retrying");
        } else {
            tracing::debug!(%endpoint, %error, attempts = self.attempts, retry_in_s = retry_in.as_secs_f32(), "cannot connect to the autopilot; retrying");
        }
    }

    fn connected(&mut self) -> u64 {
        self.last_warn = None;
        std::mem::take(&mut self.attempts)
    }
}

async fn supervise(
    config: LinkConfig,
    events: mpsc::Sender<LinkEvent>,
    metrics: Metrics,
    shutdown: CancellationToken,
) {
    let mut delay = config.reconnect_min;
    let mut failures = FailureLog::default();
    let mut listener: Option<Arc<TcpListener>> = None;
    let mut connections: u64 = 0;
    while !shutdown.is_cancelled() {
        let stop = Arc::new(AtomicBool::new(false));
        let opening = {
            let (endpoint, stop, listener) =
                (config.endpoint.clone(), stop.clone(), listener.clone());
            tokio::task::spawn_blocking(move || open(&endpoint, listener, &stop))
        };
        let (kept_listener, opened) = tokio::select! {
            r = opening => match r {
                Ok(v) => v,
                Err(e) => (None, Err(io::Error::other(format!("connect task failed: {e}")))),
            },
            _ = shutdown.cancelled() => {
                stop.store(true, Ordering::Relaxed);
                return;
            }
        };
        listener = kept_listener;
        match opened {
            Ok(conn) => {
                connections += 1;
                if connections > 1 {
                    metrics.reconnects.inc();
                }
                let attempts = failures.connected();
                tracing::info!(endpoint = %config.endpoint, failed_attempts = attempts, "MAVLink connection open");
                delay = config.reconnect_min;
                let reason = serve(&config, conn, &events, &metrics, &stop, &shutdown).await;
                if shutdown.is_cancelled() {
                    return;
                }
                tracing::warn!(endpoint = %config.endpoint, %reason, "MAVLink connection lost; reconnecting");
                if events
                    .send(LinkEvent::Disconnected { reason })
                    .await
                    .is_err()
                {
                    return;
                }
                // Reconnect at once: a peer that restarted is usually back already.
                continue;
            }
            Err(e) => failures.failed(&config.endpoint, &e, delay),
        }
        tokio::select! {
            _ = tokio::time::sleep(delay) => {}
            _ = shutdown.cancelled() => return,
        }
        delay = (delay * 2).min(config.reconnect_max);
    }
}

/// Runs one open connection until it fails; returns why it ended.
async fn serve(
    config: &LinkConfig,
    conn: Conn,
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    stop: &Arc<AtomicBool>,
    shutdown: &CancellationToken,
) -> String {
    let conn = Arc::new(conn);
    let (wtx, wrx) = std_mpsc::sync_channel(WRITE_QUEUE);
    if events
        .send(LinkEvent::Connected(LinkWriter { tx: wtx }))
        .await
        .is_err()
    {
        return "service stopped".to_string();
    }
    let header = MavHeader {
        system_id: u32::from(config.system_id),
        component_id: config.component_id,
        sequence: 0,
    };
    let mut reader = {
        let (conn, events, metrics, stop) =
            (conn.clone(), events.clone(), metrics.clone(), stop.clone());
        let read_mode = ReadMode::of(&config.endpoint, config.silence_reconnect);
        tokio::task::spawn_blocking(move || read_loop(&conn, read_mode, &events, &metrics, &stop))
    };
    let mut writer = {
        let (metrics, stop) = (metrics.clone(), stop.clone());
        tokio::task::spawn_blocking(move || write_loop(&conn, header, &wrx, &metrics, &stop))
    };
    let joined = |r: Result<String, tokio::task::JoinError>| {
        r.unwrap_or_else(|e| format!("link thread failed: {e}"))
    };
    let (reason, reader_done, writer_done) = tokio::select! {
        r = &mut reader => (joined(r), true, false),
        r = &mut writer => (joined(r), false, true),
        _ = shutdown.cancelled() => ("shutdown".to_string(), false, false),
    };
    stop.store(true, Ordering::Relaxed);
    // Both threads see the flag within POLL. The reader may be waiting for room in
    // the event channel; the service keeps draining it until it drops the receiver.
    if !reader_done {
        let _ = reader.await;
    }
    if !writer_done {
        let _ = writer.await;
    }
    reason
}

/// How the reader thread waits for data.
#[derive(Debug, Clone, Copy)]
struct ReadMode {
    /// Serial `recv` retries timeouts internally and would never see the stop flag;
    /// `try_recv` returns after the port's read timeout instead.
    use_try_recv: bool,
    silence: Option<Duration>,
}

impl ReadMode {
    fn of(endpoint: &Endpoint, silence: Option<Duration>) -> Self {
        ReadMode {
            use_try_recv: matches!(endpoint, Endpoint::Serial { .. }),
            silence: silence.filter(|_| endpoint.is_stream()),
        }
    }
}

fn is_idle(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

fn read_loop(
    conn: &Conn,
    mode: ReadMode,
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    stop: &AtomicBool,
) -> String {
    let mut last_message = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        let received = if mode.use_try_recv {
            conn.try_recv()
        } else {
            conn.recv()
        };
        match received {
            Ok((header, msg)) => {
                last_message = Instant::now();
                metrics.received(msg.message_name());
                if events
                    .blocking_send(LinkEvent::Message(header, msg))
                    .is_err()
                {
                    return "service stopped".to_string();
                }
            }
            Err(MessageReadError::Io(e)) if is_idle(&e) => {
                if let Some(silence) = mode.silence {
                    if last_message.elapsed() >= silence {
                        return format!("no MAVLink received for {silence:?}");
                    }
                }
            }
            Err(MessageReadError::Io(e)) if e.kind() == io::ErrorKind::UnexpectedEof => {
                return "closed by the other end".to_string();
            }
            Err(MessageReadError::Io(e)) => return format!("read failed: {e}"),
            Err(MessageReadError::Parse(e)) => {
                metrics.parse_errors.inc();
                tracing::debug!(error = %e, "unparsable MAVLink frame");
            }
        }
    }
    "stopped".to_string()
}

fn write_loop(
    conn: &Conn,
    header: MavHeader,
    queue: &std_mpsc::Receiver<MavMessage>,
    metrics: &Metrics,
    stop: &AtomicBool,
) -> String {
    loop {
        match queue.recv_timeout(POLL) {
            Ok(msg) => match conn.send(&header, &msg) {
                Ok(_) => metrics.sent(msg.message_name()),
                Err(e) => return format!("write failed: {e}"),
            },
            Err(RecvTimeoutError::Timeout) => {
                if stop.load(Ordering::Relaxed) {
                    return "stopped".to_string();
                }
            }
            Err(RecvTimeoutError::Disconnected) => return "writer closed".to_string(),
        }
    }
}

/// Opens the transport (blocking). For `tcpin` the listener is kept across
/// connections and handed back.
fn open(
    endpoint: &Endpoint,
    listener: Option<Arc<TcpListener>>,
    stop: &AtomicBool,
) -> (Option<Arc<TcpListener>>, io::Result<Conn>) {
    match endpoint {
        Endpoint::TcpIn(addr) => {
            let listener = match listener {
                Some(l) => l,
                None => match TcpListener::bind(addr).and_then(|l| {
                    l.set_nonblocking(true)?;
                    Ok(l)
                }) {
                    Ok(l) => {
                        tracing::info!(%addr, "waiting for the autopilot to connect over TCP");
                        Arc::new(l)
                    }
                    Err(e) => return (None, Err(e)),
                },
            };
            let conn = accept(&listener, stop).and_then(stream_connection);
            (Some(listener), conn)
        }
        Endpoint::TcpOut { host, port } => {
            let conn = (host.as_str(), *port)
                .to_socket_addrs()
                .and_then(|mut addrs| {
                    addrs.next().ok_or_else(|| {
                        io::Error::new(io::ErrorKind::NotFound, format!("{host} has no address"))
                    })
                })
                .and_then(|addr| TcpStream::connect_timeout(&addr, CONNECT_TIMEOUT))
                .and_then(stream_connection);
            (None, conn)
        }
        Endpoint::UdpIn(addr) => (None, udp(&addr.to_string(), UdpMode::Udpin)),
        Endpoint::UdpOut { host, port } => (None, udp(&format!("{host}:{port}"), UdpMode::Udpout)),
        Endpoint::Serial { device, baud } => {
            let conn = SerialConfig::new(device.clone(), *baud)
                .timeout(POLL)
                .connect::<MavMessage>();
            (None, conn.map(prepare))
        }
    }
}

fn accept(listener: &TcpListener, stop: &AtomicBool) -> io::Result<TcpStream> {
    loop {
        match listener.accept() {
            Ok((stream, peer)) => {
                tracing::info!(%peer, "autopilot connected over TCP");
                stream.set_nonblocking(false)?;
                return Ok(stream);
            }
            Err(e) if is_idle(&e) => {
                if stop.load(Ordering::Relaxed) {
                    return Err(io::Error::new(io::ErrorKind::Interrupted, "stopped"));
                }
                std::thread::sleep(POLL);
            }
            Err(e) => return Err(e),
        }
    }
}

fn stream_connection(stream: TcpStream) -> io::Result<Conn> {
    stream.set_read_timeout(Some(POLL))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    stream.set_nodelay(true)?;
    Ok(prepare(
        TcpConfig::from_stream(stream)?.connect::<MavMessage>()?,
    ))
}

fn udp(address: &str, mode: UdpMode) -> io::Result<Conn> {
    Ok(prepare(
        UdpConfig::new(address.to_string(), mode)
            .read_timeout(POLL)
            .connect::<MavMessage>()?,
    ))
}

/// MAVLink 2 out; MAVLink 1 or 2 in (old radios and firmware speak 1 until they hear 2).
fn prepare(mut conn: Conn) -> Conn {
    conn.set_protocol_version(mavlink::MavlinkVersion::V2);
    conn.set_allow_recv_any_version(true);
    conn
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        MavAutopilot, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
    };
    use skymesh_runtime::Stats;

    fn heartbeat() -> MavMessage {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 4,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    fn config(endpoint: Endpoint) -> LinkConfig {
        LinkConfig {
            endpoint,
            system_id: 1,
            component_id: 191,
            reconnect_min: Duration::from_millis(50),
            reconnect_max: Duration::from_millis(200),
            silence_reconnect: None,
        }
    }

    async fn next(rx: &mut mpsc::Receiver<LinkEvent>) -> LinkEvent {
        tokio::time::timeout(Duration::from_secs(20), rx.recv())
            .await
            .expect("a link event within 20 s")
            .expect("link task alive")
    }

    /// A fake autopilot on a TCP port: the link connects, messages flow both ways,
    /// the peer closes, the link reports it and connects again to a new peer.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn tcp_messages_flow_both_ways_and_the_link_reconnects() {
        let server = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = server.local_addr().unwrap().port();
        let stats = Stats::new();
        let metrics = Metrics::new(&stats);
        let shutdown = CancellationToken::new();
        let endpoint = Endpoint::TcpOut {
            host: "127.0.0.1".into(),
            port,
        };
        let (mut rx, task) = spawn(config(endpoint), metrics.clone(), shutdown.clone());

        for round in 0..2 {
            let peer = tokio::task::spawn_blocking({
                let server = server.try_clone().unwrap();
                move || {
                    let (stream, _) = server.accept().unwrap();
                    stream
                        .set_read_timeout(Some(Duration::from_secs(20)))
                        .unwrap();
                    let conn = TcpConfig::from_stream(stream)
                        .unwrap()
                        .connect::<MavMessage>()
                        .unwrap();
                    let hdr = MavHeader {
                        system_id: 1,
                        component_id: 1,
                        sequence: 0,
                    };
                    conn.send(&hdr, &heartbeat()).unwrap();
                    let (h, m) = conn.recv().unwrap();
                    (h, m)
                }
            });
            let LinkEvent::Connected(writer) = next(&mut rx).await else {
                panic!("expected Connected in round {round}")
            };
            let LinkEvent::Message(h, m) = next(&mut rx).await else {
                panic!("expected a message")
            };
            assert_eq!((h.system_id, h.component_id), (1, 1));
            assert_eq!(m, heartbeat());
            writer.send(heartbeat()).unwrap();
            let (h, m) = peer.await.unwrap();
            assert_eq!((h.system_id, h.component_id), (1, 191));
            assert_eq!(m, heartbeat());
            // The peer is gone now.
            let LinkEvent::Disconnected { reason } = next(&mut rx).await else {
                panic!("expected Disconnected")
            };
            assert!(!reason.is_empty());
        }
        assert_eq!(metrics.reconnects.get(), 1);
        shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .unwrap()
            .unwrap();
    }

    /// Nobody listening: attempts repeat with backoff and shutdown ends the task quickly.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn an_unreachable_autopilot_is_retried_until_shutdown() {
        let port = {
            let l = TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().port()
        };
        let shutdown = CancellationToken::new();
        let (mut rx, task) = spawn(
            config(Endpoint::TcpOut {
                host: "127.0.0.1".into(),
                port,
            }),
            Metrics::new(&Stats::new()),
            shutdown.clone(),
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
        assert!(rx.try_recv().is_err(), "no event without a connection");
        shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .unwrap()
            .unwrap();
    }

    /// `tcpin`: we listen, a peer connects, and the listener survives the peer.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn tcpin_accepts_one_client_after_another() {
        let port = {
            let l = TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().port()
        };
        let addr = format!("127.0.0.1:{port}").parse().unwrap();
        let shutdown = CancellationToken::new();
        let (mut rx, task) = spawn(
            config(Endpoint::TcpIn(addr)),
            Metrics::new(&Stats::new()),
            shutdown.clone(),
        );
        for _ in 0..2 {
            let client = tokio::task::spawn_blocking(move || {
                let deadline = Instant::now() + Duration::from_secs(20);
                loop {
                    match TcpStream::connect(addr) {
                        Ok(s) => break s,
                        Err(_) if Instant::now() < deadline => {
                            std::thread::sleep(Duration::from_millis(50))
                        }
                        Err(e) => panic!("{e}"),
                    }
                }
            })
            .await
            .unwrap();
            assert!(matches!(next(&mut rx).await, LinkEvent::Connected(_)));
            drop(client);
            assert!(matches!(
                next(&mut rx).await,
                LinkEvent::Disconnected { .. }
            ));
        }
        shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .unwrap()
            .unwrap();
    }
}
