//! The MAVLink connection: open, read, write, reconnect.
//!
//! Each open connection, over the raw byte transport of `transport`, gets a reader
//! that splits the bytes into frames ([`crate::frame`]), hands every frame to the
//! router [`Hub`] (byte for byte, to the endpoints) and decodes the ones the
//! dialect knows into the service's [`LinkEvent`] channel; and a writer thread
//! (tokio's blocking pool) that drains the [`Outbox`]: our own messages (queued
//! through [`LinkWriter`], serialised with our header and sequence) before frames
//! the router forwards from endpoints, each kind bounded on its own so
//! ground-station traffic can never crowd out our commands. A TCP or UDP socket
//! is read on the runtime (tokio's reactor says when it is readable: one wake-up
//! per telemetry batch, on the thread that also runs the service); a serial port
//! by a blocking thread that polls a stop flag at least every [`POLL`], so a
//! shutdown or a reconnect never waits on a blocked read. The writer sleeps until
//! there is something to write or the outbox is closed (which every stop does).
//!
//! COMMAND_ACKs that answer an endpoint's command (decided by the
//! [`AckLedger`], fed by the writer) are forwarded but not given to the service.
//!
//! [`spawn`] runs the supervising task: connect (with backoff after failures,
//! forever, so the autopilot may start after us; logged at a sane rate), report
//! [`LinkEvent::Connected`], wait for the reader or writer to fail, report
//! [`LinkEvent::Disconnected`], and start over. The service keeps its state across
//! reconnects; only this module knows about connections.

use std::collections::VecDeque;
use std::future::Future;
use std::io;
use std::net::TcpListener;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MavHeader, Message};
use skymesh_runtime::Backoff;
use tokio::io::unix::AsyncFd;
use tokio::io::Interest;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::config::Endpoint;
use crate::hub::Hub;
use crate::metrics::Metrics;
use crate::router::{AckLedger, AckOwner};
use crate::transport::{self, Received};
use mavlink_frame::{message_info, FrameParser, RawFrame};

pub use crate::transport::POLL;

/// Our own outgoing messages queued for the writer thread; beyond this a write is refused.
pub const WRITE_QUEUE: usize = 128;
/// Frames from router endpoints queued for the autopilot; beyond this they are dropped.
pub const FORWARD_QUEUE: usize = 256;
/// Incoming messages queued for the service; the reader waits when it is full.
pub const EVENT_QUEUE: usize = 512;
/// Repeated connection failures are logged at warn level at most this often.
const WARN_EVERY: Duration = Duration::from_secs(30);
/// Read buffer: one UDP datagram of any size.
const READ_BUFFER: usize = 65536;

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
/// Held by the service from `Connected` until `Disconnected`; the writer thread
/// drains the [`Outbox`] behind it and writes with our header (system id,
/// component 191).
#[derive(Debug, Clone)]
pub struct LinkWriter {
    outbox: Arc<Outbox>,
}

impl LinkWriter {
    /// Queues `msg` without waiting.
    pub fn send(&self, msg: MavMessage) -> Result<(), WriteError> {
        self.outbox.send(msg)
    }
}

/// What the writer thread writes next.
#[allow(clippy::large_enum_variant)] // moved once per write, never stored in bulk
#[derive(Debug)]
enum Outgoing {
    Own(MavMessage),
    Forwarded(RawFrame),
}

#[derive(Debug, Default)]
struct OutboxState {
    own: VecDeque<MavMessage>,
    forwarded: VecDeque<RawFrame>,
    closed: bool,
}

/// The writer thread's two bounded queues: our own messages ([`WRITE_QUEUE`],
/// written first) and frames forwarded from router endpoints ([`FORWARD_QUEUE`]).
/// Filled by the service (through [`LinkWriter`]) and the router [`Hub`]; drained
/// by the connection's writer thread; closed when that thread ends.
#[derive(Debug, Default)]
pub struct Outbox {
    state: Mutex<OutboxState>,
    ready: Condvar,
}

impl Outbox {
    fn lock(&self) -> MutexGuard<'_, OutboxState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn send(&self, msg: MavMessage) -> Result<(), WriteError> {
        let mut s = self.lock();
        if s.closed {
            return Err(WriteError::Closed);
        }
        if s.own.len() >= WRITE_QUEUE {
            return Err(WriteError::Congested);
        }
        s.own.push_back(msg);
        self.ready.notify_one();
        Ok(())
    }

    /// Queues a frame from a router endpoint without waiting.
    pub fn forward(&self, frame: &RawFrame) -> Result<(), WriteError> {
        let mut s = self.lock();
        if s.closed {
            return Err(WriteError::Closed);
        }
        if s.forwarded.len() >= FORWARD_QUEUE {
            return Err(WriteError::Congested);
        }
        s.forwarded.push_back(*frame);
        self.ready.notify_one();
        Ok(())
    }

    /// The next thing to write, waiting as long as it takes; `None` once closed.
    /// No timeout: every way a connection ends closes the outbox ([`StopGuard`],
    /// the writer's own end), which wakes this wait, so an idle link costs the
    /// writer thread no periodic wake-ups.
    fn next(&self) -> Option<Outgoing> {
        let mut s = self.lock();
        loop {
            if s.closed {
                return None;
            }
            if let Some(m) = s.own.pop_front() {
                return Some(Outgoing::Own(m));
            }
            if let Some(f) = s.forwarded.pop_front() {
                return Some(Outgoing::Forwarded(f));
            }
            s = self.ready.wait(s).unwrap_or_else(PoisonError::into_inner);
        }
    }

    fn close(&self) {
        let mut s = self.lock();
        s.closed = true;
        s.own.clear();
        s.forwarded.clear();
        self.ready.notify_all();
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
/// (then the task ends within about [`POLL`]) or the receiver is dropped. Every
/// frame read goes to `hub` as well; `hub` forwards endpoint frames into the open
/// connection.
pub fn spawn(
    config: LinkConfig,
    metrics: Metrics,
    hub: Arc<Hub>,
    shutdown: CancellationToken,
) -> (mpsc::Receiver<LinkEvent>, JoinHandle<()>) {
    let (tx, rx) = mpsc::channel(EVENT_QUEUE);
    let task = tokio::spawn(supervise(config, tx, metrics, hub, shutdown));
    (rx, task)
}

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
    hub: Arc<Hub>,
    shutdown: CancellationToken,
) {
    // No jitter: one link to its own flight controller, nobody to fall into lockstep
    // with; the delays are exactly reconnect_min, doubling to reconnect_max.
    let mut backoff = Backoff::new(config.reconnect_min, config.reconnect_max);
    let mut failures = FailureLog::default();
    let mut listener: Option<Arc<TcpListener>> = None;
    let mut connections: u64 = 0;
    while !shutdown.is_cancelled() {
        let stop = Arc::new(AtomicBool::new(false));
        let opening = {
            let (endpoint, stop, listener) =
                (config.endpoint.clone(), stop.clone(), listener.clone());
            tokio::task::spawn_blocking(move || transport::open(&endpoint, listener, &stop))
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
            Ok(halves) => {
                connections += 1;
                if connections > 1 {
                    metrics.reconnects.inc();
                }
                let attempts = failures.connected();
                tracing::info!(endpoint = %config.endpoint, failed_attempts = attempts, "MAVLink connection open");
                backoff.reset();
                let reason =
                    serve(&config, halves, &events, &metrics, &hub, &stop, &shutdown).await;
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
            Err(e) => {
                // Without jitter the unit (where in the jitter band) plays no part.
                let delay = backoff.next_delay(0.5);
                failures.failed(&config.endpoint, &e, delay);
                tokio::select! {
                    _ = tokio::time::sleep(delay) => {}
                    _ = shutdown.cancelled() => return,
                }
            }
        }
    }
}

/// Runs one open connection until it fails; returns why it ended.
async fn serve(
    config: &LinkConfig,
    (reader, writer): (transport::Reader, transport::Writer),
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    hub: &Arc<Hub>,
    stop: &Arc<AtomicBool>,
    shutdown: &CancellationToken,
) -> String {
    let outbox = Arc::new(Outbox::default());
    if events
        .send(LinkEvent::Connected(LinkWriter {
            outbox: outbox.clone(),
        }))
        .await
        .is_err()
    {
        return "service stopped".to_string();
    }
    hub.attach(outbox.clone());
    // Stops both threads however this future ends (also when it is dropped, e.g. by
    // a runtime shutting down, which would otherwise wait for them forever).
    let guard = StopGuard {
        stop: stop.clone(),
        outbox: outbox.clone(),
        hub: hub.clone(),
    };
    let me = (config.system_id, config.component_id);
    let ledger = Arc::new(Mutex::new(AckLedger::new(me)));
    let silence = config
        .silence_reconnect
        .filter(|_| config.endpoint.is_stream());
    // A socket is read here, on the runtime; a serial port by a blocking thread.
    let (mut reader, reader_thread): (Pin<Box<dyn Future<Output = String> + Send + '_>>, bool) =
        match reader.into_socket() {
            Ok(socket) => {
                let ledger = ledger.clone();
                (
                    Box::pin(async move {
                        read_socket(socket, silence, events, metrics, hub, &ledger).await
                    }),
                    false,
                )
            }
            Err(mut serial) => {
                let (events, metrics, hub, ledger, stop) = (
                    events.clone(),
                    metrics.clone(),
                    hub.clone(),
                    ledger.clone(),
                    stop.clone(),
                );
                let thread = tokio::task::spawn_blocking(move || {
                    read_loop(
                        &mut serial,
                        silence,
                        &events,
                        &metrics,
                        &hub,
                        &ledger,
                        &stop,
                    )
                });
                (
                    Box::pin(async move {
                        thread
                            .await
                            .unwrap_or_else(|e| format!("link thread failed: {e}"))
                    }),
                    true,
                )
            }
        };
    let mut writer = {
        let (metrics, hub, stop, outbox) =
            (metrics.clone(), hub.clone(), stop.clone(), outbox.clone());
        let header = MavHeader {
            system_id: u32::from(config.system_id),
            component_id: config.component_id,
            sequence: 0,
        };
        let mut writer_half = writer;
        tokio::task::spawn_blocking(move || {
            let ctx = WriteContext {
                header,
                outbox: &outbox,
                hub: &hub,
                ledger: &ledger,
                metrics: &metrics,
            };
            let reason = write_loop(&mut writer_half, &ctx, &stop);
            outbox.close();
            reason
        })
    };
    let joined = |r: Result<String, tokio::task::JoinError>| {
        r.unwrap_or_else(|e| format!("link thread failed: {e}"))
    };
    let (reason, reader_done, writer_done) = tokio::select! {
        r = &mut reader => (r, true, false),
        r = &mut writer => (joined(r), false, true),
        _ = shutdown.cancelled() => ("shutdown".to_string(), false, false),
    };
    drop(guard);
    // A reader thread sees the flag within POLL, the writer at once (closed outbox).
    // The reader thread may be waiting for room in the event channel; the service
    // keeps draining it until it drops the receiver. A socket reader just stops here.
    if !reader_done && reader_thread {
        let _ = reader.await;
    }
    if !writer_done {
        let _ = writer.await;
    }
    reason
}

/// Ends a connection's threads when dropped: stop flag, closed outbox, router detached.
struct StopGuard {
    stop: Arc<AtomicBool>,
    outbox: Arc<Outbox>,
    hub: Arc<Hub>,
}

impl Drop for StopGuard {
    fn drop(&mut self) {
        self.hub.detach();
        self.stop.store(true, Ordering::Relaxed);
        self.outbox.close();
    }
}

fn lock_ledger(ledger: &Mutex<AckLedger>) -> MutexGuard<'_, AckLedger> {
    ledger.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What the reader does with the bytes it read, however it waited for them: split
/// them into frames, route every frame to the endpoints, and decode the ones for
/// the service.
struct Intake<'a> {
    parser: FrameParser,
    last_message: Instant,
    metrics: &'a Metrics,
    hub: &'a Hub,
    ledger: &'a Mutex<AckLedger>,
    /// Decoded messages of the last read, handed to the service in one go after
    /// every frame of the read was routed (so a batch of telemetry wakes the
    /// service once, not once per message with routing in between).
    out: Vec<(MavHeader, MavMessage)>,
}

impl<'a> Intake<'a> {
    fn new(metrics: &'a Metrics, hub: &'a Hub, ledger: &'a Mutex<AckLedger>) -> Self {
        Intake {
            parser: FrameParser::new(),
            last_message: Instant::now(),
            metrics,
            hub,
            ledger,
            out: Vec::new(),
        }
    }

    /// Takes one read; the messages for the service are then in `self.out`.
    fn take(&mut self, bytes: &[u8], datagram: bool) {
        self.parser.push(bytes);
        while let Some(frame) = self.parser.next_frame() {
            self.last_message = Instant::now();
            self.hub.from_autopilot(&frame);
            if let Some(msg) = decode_for_service(&frame, self.metrics, self.ledger) {
                self.out.push((frame.header(), msg));
            }
        }
        if datagram {
            self.parser.end_datagram();
        }
        let bad = self.parser.take_malformed();
        if bad > 0 {
            self.hub.autopilot_malformed(bad);
        }
    }

    fn silent_for(&self, silence: Option<Duration>) -> Option<String> {
        let silence = silence?;
        (self.last_message.elapsed() >= silence)
            .then(|| format!("no MAVLink received for {silence:?}"))
    }
}

/// Reads a serial port until it fails, the stop flag is set or the service is gone
/// (a blocking thread; sockets are read by [`read_socket`]).
fn read_loop(
    reader: &mut transport::Reader,
    silence: Option<Duration>,
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    hub: &Hub,
    ledger: &Mutex<AckLedger>,
    stop: &AtomicBool,
) -> String {
    let mut buf = vec![0u8; READ_BUFFER];
    let mut intake = Intake::new(metrics, hub, ledger);
    while !stop.load(Ordering::Relaxed) {
        match reader.read(&mut buf) {
            Ok(Received::Stream(n)) => intake.take(&buf[..n], false),
            Ok(Received::Datagram(n)) => intake.take(&buf[..n], true),
            Ok(Received::Idle) => {
                if let Some(reason) = intake.silent_for(silence) {
                    return reason;
                }
                continue;
            }
            Ok(Received::Closed) => return "closed by the other end".to_string(),
            Err(e) => return format!("read failed: {e}"),
        }
        for (header, msg) in intake.out.drain(..) {
            if events
                .blocking_send(LinkEvent::Message(header, msg))
                .is_err()
            {
                return "service stopped".to_string();
            }
        }
    }
    "stopped".to_string()
}

/// Reads a TCP or UDP socket from tokio's reactor until it fails or the service is
/// gone (ends early when dropped). Compared with a reader thread, a datagram costs
/// one wake-up of the runtime's thread, which then also runs the service, instead
/// of the reader thread's wake-up plus the one it hands the messages to.
async fn read_socket(
    socket: transport::SocketReader,
    silence: Option<Duration>,
    events: &mpsc::Sender<LinkEvent>,
    metrics: &Metrics,
    hub: &Hub,
    ledger: &Mutex<AckLedger>,
) -> String {
    // `AsyncFd::new` is deprecated because it cannot prove the descriptor stays open
    // while registered; here the `AsyncFd` owns the socket, so it does.
    #[allow(deprecated)]
    let mut fd = match AsyncFd::with_interest(socket, Interest::READABLE) {
        Ok(fd) => fd,
        Err(e) => return format!("cannot wait on the socket: {e}"),
    };
    let mut buf = vec![0u8; READ_BUFFER];
    let mut intake = Intake::new(metrics, hub, ledger);
    // Looked at once per `silence` (not re-armed per message); no timer without one.
    let check = tokio::time::sleep(silence.unwrap_or_default());
    tokio::pin!(check);
    loop {
        let mut ready = tokio::select! {
            r = fd.readable_mut() => match r {
                Ok(guard) => guard,
                Err(e) => return format!("waiting on the socket failed: {e}"),
            },
            () = &mut check, if silence.is_some() => {
                if let Some(reason) = intake.silent_for(silence) {
                    return reason;
                }
                let next = intake.last_message + silence.unwrap_or_default();
                check.as_mut().reset(next.into());
                continue;
            }
        };
        match ready.get_inner_mut().read_now(&mut buf) {
            Ok(Received::Stream(n)) => {
                // A short read emptied the stream's receive queue: what arrives
                // later raises a new edge, so the `recv` that would only return
                // EAGAIN is skipped (tokio's own TcpStream does the same).
                if n < buf.len() {
                    ready.clear_ready();
                }
                intake.take(&buf[..n], false)
            }
            Ok(Received::Datagram(n)) => intake.take(&buf[..n], true),
            Ok(Received::Idle) => {
                ready.clear_ready();
                continue;
            }
            Ok(Received::Closed) => return "closed by the other end".to_string(),
            Err(e) => return format!("read failed: {e}"),
        }
        drop(ready);
        for (header, msg) in intake.out.drain(..) {
            if events.send(LinkEvent::Message(header, msg)).await.is_err() {
                return "service stopped".to_string();
            }
        }
    }
}

/// Decodes a frame from the autopilot for the service: `None` for frames that are
/// not for it (not in our dialect, unparsable, an endpoint's COMMAND_ACK).
fn decode_for_service(
    frame: &RawFrame,
    metrics: &Metrics,
    ledger: &Mutex<AckLedger>,
) -> Option<MavMessage> {
    let id = frame.message_id();
    // Not in our dialect: forwarded to the endpoints, nothing for us.
    message_info(id)?;
    let msg = match frame.decode() {
        Ok(msg) => msg,
        Err(e) => {
            metrics.parse_errors.inc();
            tracing::debug!(error = %e, message_id = id, "unparsable MAVLink frame");
            return None;
        }
    };
    metrics.received(msg.message_name());
    if let MavMessage::COMMAND_ACK(ack) = &msg {
        let command = ack.command as u16;
        let target = (ack.target_system, ack.target_component);
        let owner = lock_ledger(ledger).on_ack(command, ack.result as u8, target, Instant::now());
        if owner == AckOwner::Endpoint {
            tracing::debug!(
                command,
                ?target,
                "COMMAND_ACK for a router endpoint; not ours"
            );
            return None;
        }
    }
    Some(msg)
}

/// What the writer thread needs besides the transport.
struct WriteContext<'a> {
    header: MavHeader,
    outbox: &'a Outbox,
    hub: &'a Hub,
    ledger: &'a Mutex<AckLedger>,
    metrics: &'a Metrics,
}

fn write_loop(writer: &mut transport::Writer, ctx: &WriteContext<'_>, stop: &AtomicBool) -> String {
    let mut sequence: u8 = 0;
    while !stop.load(Ordering::Relaxed) {
        match ctx.outbox.next() {
            Some(Outgoing::Own(msg)) => {
                let header = MavHeader {
                    sequence,
                    ..ctx.header
                };
                sequence = sequence.wrapping_add(1);
                let frame = RawFrame::encode(header, &msg);
                // Recorded before writing: the answer may come back at once.
                if let Some(command) = frame.command() {
                    lock_ledger(ctx.ledger).sent(command, true, Instant::now());
                }
                if let Err(e) = writer.write_frame(frame.as_bytes()) {
                    return format!("write failed: {e}");
                }
                ctx.metrics.sent(msg.message_name());
                if let MavMessage::HEARTBEAT(_) = msg {
                    ctx.hub.from_local(&frame);
                }
            }
            Some(Outgoing::Forwarded(frame)) => {
                if let Some(command) = frame.command() {
                    lock_ledger(ctx.ledger).sent(command, false, Instant::now());
                }
                if let Err(e) = writer.write_frame(frame.as_bytes()) {
                    return format!("write failed: {e}");
                }
                ctx.hub.forwarded_to_autopilot();
            }
            // Closed: the connection is ending.
            None => break,
        }
    }
    "stopped".to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        MavAutopilot, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
    };
    use mavlink::{Connectable, MavConnection, TcpConfig};
    use skymesh_runtime::Stats;
    use std::net::TcpStream;

    fn hub() -> Arc<Hub> {
        Hub::detached((1, 191))
    }

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
        let (mut rx, task) = spawn(config(endpoint), metrics.clone(), hub(), shutdown.clone());

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
        // At least the second round's connection; the link may already have connected
        // a third time (the kernel accepts into the listener's backlog before `accept`).
        assert!(
            metrics.reconnects.get() >= 1,
            "{}",
            metrics.reconnects.get()
        );
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
            hub(),
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
            hub(),
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

    fn frame_from_autopilot(sequence: u8) -> RawFrame {
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence,
        };
        RawFrame::encode(header, &heartbeat())
    }

    /// A TCP autopilot that stops talking but keeps the socket open is dropped after
    /// `silence_reconnect`, and not while it talks (the check is re-armed by every
    /// message, not once from the connect).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_silent_tcp_autopilot_is_dropped_after_the_silence_and_not_before() {
        use std::io::Write;
        let server = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = server.local_addr().unwrap().port();
        let shutdown = CancellationToken::new();
        let mut cfg = config(Endpoint::TcpOut {
            host: "127.0.0.1".into(),
            port,
        });
        let silence = Duration::from_millis(800);
        cfg.silence_reconnect = Some(silence);
        let (mut rx, task) = spawn(cfg, Metrics::new(&Stats::new()), hub(), shutdown.clone());
        let talking = 20u8; // × 100 ms: well past the silence
        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        let peer = std::thread::spawn(move || {
            let (mut stream, _) = server.accept().unwrap();
            for seq in 0..talking {
                stream
                    .write_all(frame_from_autopilot(seq).as_bytes())
                    .unwrap();
                std::thread::sleep(Duration::from_millis(100));
            }
            // Silent from here, with the socket open until the test is done.
            let _ = done_rx.recv_timeout(Duration::from_secs(30));
            drop(stream);
        });
        assert!(matches!(next(&mut rx).await, LinkEvent::Connected(_)));
        for seq in 0..talking {
            match next(&mut rx).await {
                LinkEvent::Message(h, _) => assert_eq!(h.sequence, seq),
                other => panic!("message {seq} expected while the peer talks, got {other:?}"),
            }
        }
        let quiet_since = Instant::now();
        let LinkEvent::Disconnected { reason } = next(&mut rx).await else {
            panic!("expected Disconnected")
        };
        assert!(reason.contains("no MAVLink received"), "{reason}");
        // From the last message (sent ~100 ms before we noted the time).
        assert!(quiet_since.elapsed() + Duration::from_millis(150) >= silence);
        done_tx.send(()).unwrap();
        peer.join().unwrap();
        shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .unwrap()
            .unwrap();
    }

    /// `udpin`: we bind, the autopilot speaks first, and what we send goes to the
    /// last address the autopilot spoke from.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn udpin_replies_go_to_the_last_sender() {
        let addr = {
            let probe = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
            probe.local_addr().unwrap()
        };
        let shutdown = CancellationToken::new();
        let (mut rx, task) = spawn(
            config(Endpoint::UdpIn(addr)),
            Metrics::new(&Stats::new()),
            hub(),
            shutdown.clone(),
        );
        let LinkEvent::Connected(writer) = next(&mut rx).await else {
            panic!("expected Connected")
        };
        for (round, seq) in [(0, 7u8), (1, 9u8)] {
            let autopilot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
            autopilot
                .set_read_timeout(Some(Duration::from_secs(10)))
                .unwrap();
            autopilot
                .send_to(frame_from_autopilot(seq).as_bytes(), addr)
                .unwrap();
            let LinkEvent::Message(h, m) = next(&mut rx).await else {
                panic!("expected a message in round {round}")
            };
            assert_eq!((h.system_id, h.sequence), (1, seq));
            assert_eq!(m, heartbeat());
            writer.send(heartbeat()).unwrap();
            let mut buf = [0u8; 512];
            let n = autopilot.recv(&mut buf).expect("our reply at the sender");
            let mut parser = FrameParser::new();
            parser.push(&buf[..n]);
            let frame = parser.next_frame().expect("a whole frame");
            assert_eq!(
                (frame.header().system_id, frame.header().component_id),
                (1, 191)
            );
        }
        shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), task)
            .await
            .unwrap()
            .unwrap();
    }
}
