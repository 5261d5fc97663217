//! The router's endpoints: ground stations and other MAVLink programs beside the
//! autopilot (`endpoints = [...]` in the config), and the [`Hub`] that moves frames
//! between them and the autopilot link by the decisions of [`crate::router`]
//! (the hub and the router metrics are in [`crate::hub`]).
//!
//! Each endpoint is one tokio task (TCP servers add one per client). A TCP
//! endpoint has a bounded queue of frames to send, into which the hub only ever
//! `try_send`s. A UDP endpoint has none: once its socket is open, its task hands
//! the hub a [`UdpSink`] (a non-blocking copy of the socket, the destination or
//! live peer list, the endpoint's signing) and the thread that routes a frame
//! sends it there itself, so the autopilot's telemetry costs no tokio wake-up per
//! frame; the task only wakes to receive. Either way a slow or dead endpoint loses
//! frames (counted, `reason="queue_full"`: queue or socket buffer full) and never
//! holds up the autopilot's reader or another endpoint. Frames towards the
//! autopilot go into the link's own bounded forward queue the same way.
//!
//! A `udpout` destination that nothing listens at (its host answers with ICMP port
//! unreachable) is sent one frame a second instead of the stream until a frame
//! draws no refusal or a datagram comes from it ([`skymesh_runtime::refusals`]);
//! the frames left out are counted (`reason="not_listening"`): a loopback
//! datagram to a closed port costs the sender tens of µs of CPU, which at 50 Hz
//! telemetry would be most of this process's idle cost.
//!
//! | scheme | socket | peers |
//! |---|---|---|
//! | `udpout:HOST:PORT` | sends to HOST:PORT from an ephemeral port, reads the replies | 1 |
//! | `udpin:IP:PORT` | listens; sends to every address that sent something in the last [`PEER_TIMEOUT`] (at most [`MAX_PEERS`]) | as heard |
//! | `tcpin:IP:PORT` | listens; any number of clients up to [`MAX_CLIENTS`] | clients |
//! | `tcpout:HOST:PORT` | connects, reconnects with backoff | 0 or 1 |
//!
//! All peers of one endpoint are one link for routing (as in mavlink-router): a
//! frame from one of them is not sent to the others.
//!
//! Endpoints listed in `[signing] endpoints` check every frame they receive before
//! it reaches the hub and sign every frame they send ([`crate::signing`]). A
//! `udpin` signing endpoint only learns (and sends to) peers that have sent a
//! correctly signed frame, so unauthenticated senders can neither read the
//! vehicle's traffic there nor push the ground station out of its peer list.

use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use skymesh_runtime::refusals::{self, Admit, Refusals};
use skymesh_runtime::{Backoff, Stats};
use tokio::io::unix::AsyncFd;
use tokio::io::{AsyncReadExt, AsyncWriteExt, Interest};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio::task::{JoinHandle, JoinSet};
use tokio_util::sync::CancellationToken;

use crate::config::Endpoint;
use crate::hub::{label, DropReason, EndpointMetrics, Hub};
use crate::router::MAX_ENDPOINTS;
use crate::signing::{EndpointSigning, Signing, SigningSettings};
use mavlink_frame::{FrameParser, RawFrame};

/// The signing of one endpoint, if it requires signing.
type Sig = Option<Arc<EndpointSigning>>;

/// Frames waiting for one TCP endpoint (or one TCP client); beyond this they are dropped.
pub const ENDPOINT_QUEUE: usize = 256;
/// A `udpin` peer silent this long is no longer sent to (ground stations send a
/// HEARTBEAT every second).
pub const PEER_TIMEOUT: Duration = Duration::from_secs(15);
/// Remembered `udpin` peers; the oldest is forgotten first.
pub const MAX_PEERS: usize = 16;
/// Simultaneous clients of one `tcpin` endpoint; more are refused.
pub const MAX_CLIENTS: usize = 8;
/// A TCP client that takes longer than this to accept one frame is disconnected.
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);
const RECONNECT_MIN: Duration = Duration::from_millis(500);
const RECONNECT_MAX: Duration = Duration::from_secs(5);

/// Why binding an endpoint failed (the OS cause is the `source`, shown by `{:#}`).
#[derive(Debug, thiserror::Error)]
#[error("cannot listen on router endpoint {endpoint}")]
pub struct BindError {
    pub endpoint: String,
    #[source]
    pub source: io::Error,
}

#[derive(Debug)]
enum Socket {
    UdpIn(UdpSocket),
    TcpIn(TcpListener),
    /// Resolved and opened by the endpoint's task (and again after failures).
    Out,
}

impl Socket {
    fn local_addr(&self) -> Option<SocketAddr> {
        match self {
            Socket::UdpIn(u) => u.local_addr().ok(),
            Socket::TcpIn(t) => t.local_addr().ok(),
            Socket::Out => None,
        }
    }

    /// `endpoint` with the port actually bound (configured port 0 → the real one).
    fn shown(&self, endpoint: &Endpoint) -> Endpoint {
        match (endpoint, self.local_addr()) {
            (Endpoint::UdpIn(_), Some(a)) => Endpoint::UdpIn(a),
            (Endpoint::TcpIn(_), Some(a)) => Endpoint::TcpIn(a),
            _ => endpoint.clone(),
        }
    }
}

/// The endpoints with their listening sockets bound (so a port in use fails the
/// start, and tests can bind port 0 and read the port).
#[derive(Debug)]
pub struct Bound {
    endpoints: Vec<(Endpoint, Socket)>,
}

impl Bound {
    /// Binds the `udpin`/`tcpin` endpoints; `udpout`/`tcpout` connect later.
    pub async fn bind(endpoints: &[Endpoint]) -> Result<Bound, BindError> {
        let mut out = Vec::new();
        for e in endpoints.iter().take(MAX_ENDPOINTS) {
            let err = |source| BindError {
                endpoint: e.to_string(),
                source,
            };
            let socket = match e {
                Endpoint::UdpIn(addr) => Socket::UdpIn(UdpSocket::bind(addr).await.map_err(err)?),
                Endpoint::TcpIn(addr) => Socket::TcpIn(TcpListener::bind(addr).await.map_err(err)?),
                _ => Socket::Out,
            };
            out.push((e.clone(), socket));
        }
        Ok(Bound { endpoints: out })
    }

    /// No endpoints.
    pub fn none() -> Bound {
        Bound {
            endpoints: Vec::new(),
        }
    }

    /// The bound address of each listening endpoint (`None` for `udpout`/`tcpout`).
    pub fn local_addrs(&self) -> Vec<Option<SocketAddr>> {
        self.endpoints.iter().map(|(_, s)| s.local_addr()).collect()
    }
}

/// Starts every endpoint; `signing` says which of them (indices into the bound
/// endpoints, in configuration order) require MAVLink 2 signing, with which key.
/// The returned task ends once `shutdown` fires and every endpoint task has closed
/// its sockets.
pub fn start(
    bound: Bound,
    local: (u8, u8),
    signing: Option<&SigningSettings>,
    stats: &Stats,
    shutdown: CancellationToken,
) -> (Arc<Hub>, JoinHandle<()>) {
    let mut ports = Vec::new();
    let mut receivers = Vec::new();
    let mut signers = Vec::new();
    let shared = signing.map(|s| Signing::new(s.key.clone()));
    for (i, (endpoint, socket)) in bound.endpoints.iter().enumerate() {
        // UDP endpoints are sent to directly ([`UdpSink`]); TCP ones through a queue.
        let (tx, rx) = if matches!(endpoint, Endpoint::TcpIn(_) | Endpoint::TcpOut { .. }) {
            let (tx, rx) = mpsc::channel(ENDPOINT_QUEUE);
            (Some(tx), Some(rx))
        } else {
            (None, None)
        };
        let label = label(i, &socket.shown(endpoint));
        let signs = signing.is_some_and(|s| s.endpoints.contains(&i));
        signers.push(match (&shared, signs) {
            // The link id is the endpoint's index (< MAX_ENDPOINTS).
            (Some(shared), true) => Some(Arc::new(EndpointSigning::new(
                shared.clone(),
                i as u8,
                stats,
                label.clone(),
            ))),
            _ => None,
        });
        ports.push((tx, EndpointMetrics::new(stats, label)));
        receivers.push(rx);
    }
    let hub = Arc::new(Hub::new(local, ports, stats));
    let mut tasks = JoinSet::new();
    let all = bound.endpoints.into_iter().zip(receivers).zip(signers);
    for (i, (((endpoint, socket), rx), sig)) in all.enumerate() {
        let index = i as u8;
        let (hub, stop) = (hub.clone(), shutdown.clone());
        tracing::info!(
            %endpoint,
            bound = %socket.shown(&endpoint),
            label = hub.metrics(index).label(),
            signing = sig.is_some(),
            link_id = sig.as_ref().map(|s| s.link_id()),
            "MAVLink router endpoint"
        );
        match (endpoint, socket, rx) {
            (_, Socket::UdpIn(s), _) => tasks.spawn(udp_in(index, s, hub, sig, stop)),
            (_, Socket::TcpIn(l), Some(rx)) => tasks.spawn(tcp_in(index, l, hub, rx, sig, stop)),
            (Endpoint::UdpOut { host, port }, Socket::Out, _) => {
                tasks.spawn(udp_out(index, host, port, hub, sig, stop))
            }
            (Endpoint::TcpOut { host, port }, Socket::Out, Some(rx)) => {
                tasks.spawn(tcp_out(index, host, port, hub, rx, sig, stop))
            }
            (other, _, _) => {
                // Config validation refuses these; nothing to run.
                tracing::warn!(endpoint = %other, "unsupported router endpoint ignored");
                continue;
            }
        };
    }
    let task = tokio::spawn(async move {
        while let Some(r) = tasks.join_next().await {
            if let Err(e) = r {
                tracing::warn!(error = %e, "router endpoint task failed");
            }
        }
    });
    (hub, task)
}

/// Feeds bytes from endpoint `index` through `parser` into the hub; on a signing
/// endpoint only the frames that pass the check. Returns how many frames went in.
fn deliver(
    hub: &Hub,
    index: u8,
    parser: &mut FrameParser,
    bytes: &[u8],
    datagram: bool,
    signing: Option<&EndpointSigning>,
) -> usize {
    parser.push(bytes);
    let mut delivered = 0;
    while let Some(frame) = parser.next_frame() {
        if signing.is_some_and(|s| !s.accept(&frame)) {
            continue;
        }
        hub.from_endpoint(index, &frame);
        delivered += 1;
    }
    if datagram {
        parser.end_datagram();
    }
    let bad = parser.take_malformed();
    if bad > 0 {
        hub.metrics(index).dropped(DropReason::Malformed, bad);
    }
    delivered
}

/// `frame` as endpoint `signing` sends it (signed there).
fn outgoing(frame: RawFrame, signing: Option<&EndpointSigning>) -> RawFrame {
    match signing {
        Some(s) => s.outgoing(&frame),
        None => frame,
    }
}

/// The live peers of a `udpin` endpoint. Pure.
#[derive(Debug, Default)]
struct Peers {
    /// Peer and when it was last heard, oldest first.
    heard: Vec<(SocketAddr, Instant)>,
}

impl Peers {
    /// Notes a datagram from `peer`; true if it is new.
    fn heard(&mut self, peer: SocketAddr, now: Instant) -> bool {
        if let Some(p) = self.heard.iter_mut().find(|(a, _)| *a == peer) {
            p.1 = now;
            return false;
        }
        if self.heard.len() >= MAX_PEERS {
            let old = self.heard.remove(0);
            tracing::info!(peer = %old.0, "forgetting the oldest udp peer");
        }
        self.heard.push((peer, now));
        true
    }

    /// Forgets peers silent for [`PEER_TIMEOUT`]; returns how many were forgotten.
    fn expire(&mut self, now: Instant) -> usize {
        let before = self.heard.len();
        self.heard
            .retain(|(_, t)| now.duration_since(*t) < PEER_TIMEOUT);
        before - self.heard.len()
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Where a UDP endpoint's frames go.
#[derive(Debug)]
enum Destination {
    /// `udpout`: the resolved address, and whether it listens.
    Fixed {
        to: SocketAddr,
        refusals: Mutex<Refusals>,
    },
    /// `udpin`: every live peer (learnt by the endpoint's task as it receives).
    Peers(Mutex<Peers>),
}

/// A UDP endpoint's sending side, shared by its task (which receives on another
/// handle of the same socket) and the hub: whichever thread routes a frame to the
/// endpoint sends it with [`UdpSink::send`], never waiting.
#[derive(Debug)]
pub struct UdpSink {
    /// Non-blocking.
    socket: std::net::UdpSocket,
    to: Destination,
    signing: Sig,
}

impl UdpSink {
    /// Sends `frame` (signed if the endpoint signs) to the endpoint's destination
    /// or to each of its live peers, counting each datagram sent or dropped on
    /// `metrics`; a full socket buffer drops it (`queue_full`) rather than wait.
    pub(crate) fn send(&self, frame: &RawFrame, metrics: &EndpointMetrics) {
        match &self.to {
            Destination::Fixed { to, refusals } => {
                let mut refusals = lock(refusals);
                if refusals.admit(&self.socket, *to) == Admit::Skip {
                    metrics.dropped(DropReason::NotListening, 1);
                    return;
                }
                let frame = outgoing(*frame, self.signing.as_deref());
                let bytes = frame.as_bytes();
                if let Err(e) = send_datagram(&self.socket, bytes, *to, metrics) {
                    // With refusal reports on, a send fails with the error an
                    // earlier datagram drew (this one was not sent): read it, and
                    // send this one unless it is for the refusing destination.
                    if refusals.send_failed(&self.socket, *to, &e) {
                        let _ = send_datagram(&self.socket, bytes, *to, metrics);
                    } else if refusals.is_refusing(*to) {
                        metrics.dropped(DropReason::NotListening, 1);
                    } else {
                        count_send_error(&e, *to, metrics);
                    }
                }
            }
            Destination::Peers(peers) => {
                let mut peers = lock(peers);
                if peers.expire(Instant::now()) > 0 {
                    metrics.peers(peers.heard.len());
                }
                if peers.heard.is_empty() {
                    return;
                }
                let frame = outgoing(*frame, self.signing.as_deref());
                for (peer, _) in &peers.heard {
                    if let Err(e) = send_datagram(&self.socket, frame.as_bytes(), *peer, metrics) {
                        count_send_error(&e, *peer, metrics);
                    }
                }
            }
        }
    }
}

/// Sends one frame as a datagram without waiting, counting it sent; the error for
/// the caller to count ([`count_send_error`]) or act on.
fn send_datagram(
    socket: &std::net::UdpSocket,
    bytes: &[u8],
    to: SocketAddr,
    metrics: &EndpointMetrics,
) -> io::Result<()> {
    socket.send_to(bytes, to)?;
    metrics.frame_out();
    Ok(())
}

/// Counts a frame a send dropped with `e`.
fn count_send_error(e: &io::Error, to: SocketAddr, metrics: &EndpointMetrics) {
    if e.kind() == io::ErrorKind::WouldBlock {
        metrics.dropped(DropReason::QueueFull, 1);
    } else {
        metrics.dropped(DropReason::SendError, 1);
        tracing::debug!(%to, error = %e, "udp send failed");
    }
}

/// The receiving half of a UDP endpoint's socket, registered with tokio for reads
/// only: sends on the [`UdpSink`]'s handle of the same socket then never wake the
/// runtime (with write interest, as `tokio::net::UdpSocket` registers, every
/// datagram leaving the send buffer signals writability and wakes the reactor).
#[derive(Debug)]
struct UdpReceiver(AsyncFd<std::net::UdpSocket>);

impl UdpReceiver {
    /// `socket` (non-blocking) registered for reads.
    fn new(socket: std::net::UdpSocket) -> io::Result<UdpReceiver> {
        // Deprecated in tokio 1.54 because an `AsRawFd` type that does not own its
        // descriptor could close it while registered; `std::net::UdpSocket` owns it
        // and the `AsyncFd` owns the socket, so the descriptor stays valid until
        // it is deregistered. Its replacement is `unsafe` for that reason only.
        #[allow(deprecated)]
        let fd = AsyncFd::with_interest(socket, Interest::READABLE)?;
        Ok(UdpReceiver(fd))
    }

    async fn recv_from(&self, buf: &mut [u8]) -> io::Result<(usize, SocketAddr)> {
        loop {
            let mut ready = self.0.readable().await?;
            if let Ok(r) = ready.try_io(|s| s.get_ref().recv_from(buf)) {
                return r;
            }
        }
    }
}

/// Splits an open UDP socket into the task's receiving half and the hub's sink
/// (sending to `to`, signing with `signing`).
fn split_udp(
    socket: std::net::UdpSocket,
    to: Destination,
    signing: Sig,
) -> io::Result<(UdpReceiver, Arc<UdpSink>)> {
    socket.set_nonblocking(true)?;
    if matches!(to, Destination::Fixed { .. }) {
        refusals::enable_reports(&socket, socket.local_addr()?)?;
    }
    let sink = UdpSink {
        socket: socket.try_clone()?,
        to,
        signing,
    };
    let receiver = UdpReceiver::new(socket)?;
    Ok((receiver, Arc::new(sink)))
}

/// Removes a UDP endpoint's sink from the hub when its task ends (so the socket
/// closes with the task, however it ends).
struct SinkInstalled<'a> {
    hub: &'a Hub,
    index: u8,
}

impl<'a> SinkInstalled<'a> {
    fn new(hub: &'a Hub, index: u8, sink: Arc<UdpSink>) -> Self {
        hub.set_udp_sink(index, Some(sink));
        SinkInstalled { hub, index }
    }
}

impl Drop for SinkInstalled<'_> {
    fn drop(&mut self) {
        self.hub.set_udp_sink(self.index, None);
    }
}

async fn udp_in(
    index: u8,
    socket: UdpSocket,
    hub: Arc<Hub>,
    signing: Sig,
    shutdown: CancellationToken,
) {
    let metrics = &hub.metrics(index);
    let opened = socket.into_std().and_then(|s| {
        split_udp(
            s,
            Destination::Peers(Mutex::new(Peers::default())),
            signing.clone(),
        )
    });
    let (socket, sink) = match opened {
        Ok(v) => v,
        Err(e) => {
            // Only fails if the OS refuses a file descriptor or epoll registration.
            tracing::error!(endpoint = metrics.label(), error = %e, "cannot set up udp endpoint; it is disabled");
            return;
        }
    };
    let Destination::Peers(peers) = &sink.to else {
        return;
    };
    let _installed = SinkInstalled::new(&hub, index, sink.clone());
    let signing = signing.as_deref();
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 65536];
    metrics.peers(0);
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return,
            r = socket.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    let delivered = deliver(&hub, index, &mut parser, &buf[..n], true, signing);
                    // On a signing endpoint only an authenticated sender is a peer.
                    if signing.is_none() || delivered > 0 {
                        let mut peers = lock(peers);
                        if peers.heard(from, Instant::now()) {
                            tracing::info!(endpoint = metrics.label(), peer = %from, "udp peer joined");
                            metrics.peers(peers.heard.len());
                        }
                    }
                }
                // E.g. ICMP port unreachable from a vanished peer: not fatal.
                Err(e) => tracing::debug!(endpoint = metrics.label(), error = %e, "udp receive failed"),
            },
        }
    }
}

async fn resolve(host: &str, port: u16) -> io::Result<SocketAddr> {
    tokio::net::lookup_host((host, port))
        .await?
        .next()
        .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, format!("{host} has no address")))
}

/// Waits `delay` while discarding queued frames (nobody to send them to); false on shutdown.
async fn idle(
    delay: Duration,
    rx: &mut mpsc::Receiver<RawFrame>,
    shutdown: &CancellationToken,
) -> bool {
    let sleep = tokio::time::sleep(delay);
    tokio::pin!(sleep);
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return false,
            _ = &mut sleep => return true,
            f = rx.recv() => if f.is_none() { return false },
        }
    }
}

/// Waits `delay`; false on shutdown.
async fn pause(delay: Duration, shutdown: &CancellationToken) -> bool {
    tokio::select! {
        _ = shutdown.cancelled() => false,
        _ = tokio::time::sleep(delay) => true,
    }
}

async fn udp_out(
    index: u8,
    host: String,
    port: u16,
    hub: Arc<Hub>,
    signing: Sig,
    shutdown: CancellationToken,
) {
    let metrics = &hub.metrics(index);
    let mut backoff = Backoff::new(RECONNECT_MIN, RECONNECT_MAX);
    let (socket, sink) = loop {
        let opened = async {
            let to = resolve(&host, port).await?;
            let any: SocketAddr = if to.is_ipv4() {
                ([0, 0, 0, 0], 0).into()
            } else {
                (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
            };
            let refusals = Mutex::new(Refusals::new(metrics.label()));
            split_udp(
                std::net::UdpSocket::bind(any)?,
                Destination::Fixed { to, refusals },
                signing.clone(),
            )
        };
        let opened = tokio::select! {
            _ = shutdown.cancelled() => return,
            o = opened => o,
        };
        match opened {
            Ok(v) => break v,
            Err(e) => {
                // No jitter (one endpoint, one destination): the unit plays no part.
                let delay = backoff.next_delay(0.5);
                tracing::warn!(endpoint = metrics.label(), error = %e, retry_in_s = delay.as_secs_f32(), "cannot open udp endpoint; retrying");
                if !pause(delay, &shutdown).await {
                    return;
                }
            }
        }
    };
    let _installed = SinkInstalled::new(&hub, index, sink.clone());
    let Destination::Fixed { to, refusals } = &sink.to else {
        return;
    };
    let signing = signing.as_deref();
    metrics.peers(1);
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 65536];
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return,
            r = socket.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    if from == *to {
                        lock(refusals).heard(from);
                    }
                    deliver(&hub, index, &mut parser, &buf[..n], true, signing);
                }
                // A refusal report (ICMP port unreachable while no ground station
                // listens) ends a receive: read it where the sends look.
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => {
                    lock(refusals).collect(&sink.socket);
                }
                Err(e) => tracing::trace!(error = %e, "udp receive failed"),
            },
        }
    }
}

async fn tcp_in(
    index: u8,
    listener: TcpListener,
    hub: Arc<Hub>,
    mut rx: mpsc::Receiver<RawFrame>,
    signing: Sig,
    shutdown: CancellationToken,
) {
    let metrics = &hub.metrics(index);
    let mut clients: Vec<(u64, mpsc::Sender<RawFrame>)> = Vec::new();
    let mut tasks = JoinSet::new();
    let mut next_id = 0u64;
    metrics.peers(0);
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => break,
            frame = rx.recv() => {
                let Some(frame) = frame else { break };
                if clients.is_empty() {
                    continue;
                }
                let frame = outgoing(frame, signing.as_deref());
                for (_, tx) in &clients {
                    if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send(frame) {
                        metrics.dropped(DropReason::QueueFull, 1);
                    }
                }
            }
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) if clients.len() >= MAX_CLIENTS => {
                    tracing::warn!(endpoint = metrics.label(), %peer, MAX_CLIENTS, "refusing client: too many connected");
                    drop(stream);
                }
                Ok((stream, peer)) => {
                    tracing::info!(endpoint = metrics.label(), %peer, "tcp client connected");
                    let (tx, crx) = mpsc::channel(ENDPOINT_QUEUE);
                    let id = next_id;
                    next_id += 1;
                    clients.push((id, tx));
                    metrics.peers(clients.len());
                    let (hub, stop, sig) = (hub.clone(), shutdown.clone(), signing.clone());
                    tasks.spawn(async move {
                        let reason = serve_stream(index, stream, &hub, crx, sig.as_deref(), Accepted::Client, &stop).await;
                        tracing::info!(endpoint = hub.metrics(index).label(), %peer, reason, "tcp client disconnected");
                        id
                    });
                }
                Err(e) => {
                    // E.g. out of file descriptors: back off instead of spinning.
                    tracing::warn!(endpoint = metrics.label(), error = %e, "accept failed");
                    tokio::time::sleep(RECONNECT_MIN).await;
                }
            },
            Some(done) = tasks.join_next() => {
                if let Ok(id) = done {
                    clients.retain(|(c, _)| *c != id);
                } else {
                    clients.retain(|(_, tx)| !tx.is_closed());
                }
                metrics.peers(clients.len());
            }
        }
    }
    // The client tasks see the same shutdown token.
    drop(clients);
    while tasks.join_next().await.is_some() {}
}

async fn tcp_out(
    index: u8,
    host: String,
    port: u16,
    hub: Arc<Hub>,
    mut rx: mpsc::Receiver<RawFrame>,
    signing: Sig,
    shutdown: CancellationToken,
) {
    let signing = signing.as_deref();
    let metrics = &hub.metrics(index);
    let mut backoff = Backoff::new(RECONNECT_MIN, RECONNECT_MAX);
    metrics.peers(0);
    loop {
        let connect = async {
            let to = resolve(&host, port).await?;
            tokio::time::timeout(CONNECT_TIMEOUT, TcpStream::connect(to))
                .await
                .map_err(|_| io::Error::new(io::ErrorKind::TimedOut, "connect timed out"))?
        };
        let connected = tokio::select! {
            _ = shutdown.cancelled() => return,
            c = connect => c,
        };
        let delay = match connected {
            Ok(stream) => {
                tracing::info!(endpoint = metrics.label(), "tcp endpoint connected");
                backoff.reset();
                metrics.peers(1);
                let (tx, crx) = mpsc::channel(ENDPOINT_QUEUE);
                let serve = serve_stream(
                    index,
                    stream,
                    &hub,
                    crx,
                    signing,
                    Accepted::Destination,
                    &shutdown,
                );
                tokio::pin!(serve);
                let reason = loop {
                    tokio::select! {
                        reason = &mut serve => break reason,
                        frame = rx.recv() => match frame {
                            Some(frame) => {
                                let frame = outgoing(frame, signing);
                                if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send(frame) {
                                    metrics.dropped(DropReason::QueueFull, 1);
                                }
                            }
                            None => return,
                        },
                    }
                };
                metrics.peers(0);
                if shutdown.is_cancelled() {
                    return;
                }
                tracing::warn!(
                    endpoint = metrics.label(),
                    reason,
                    "tcp endpoint disconnected; reconnecting"
                );
                RECONNECT_MIN
            }
            Err(e) => {
                // No jitter (one endpoint, one destination): the unit plays no part.
                let delay = backoff.next_delay(0.5);
                tracing::debug!(endpoint = metrics.label(), error = %e, retry_in_s = delay.as_secs_f32(), "cannot connect tcp endpoint; retrying");
                delay
            }
        };
        if !idle(delay, &mut rx, &shutdown).await {
            return;
        }
    }
}

/// Runs one TCP connection of endpoint `index` until it ends; returns why.
/// Who is at the other end of a TCP endpoint's stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Accepted {
    /// A `tcpin` client: anyone who reached the port.
    Client,
    /// The configured `tcpout` destination (we chose it).
    Destination,
}

async fn serve_stream(
    index: u8,
    stream: TcpStream,
    hub: &Hub,
    mut rx: mpsc::Receiver<RawFrame>,
    signing: Option<&EndpointSigning>,
    peer: Accepted,
    shutdown: &CancellationToken,
) -> &'static str {
    let metrics = &hub.metrics(index);
    if let Err(e) = stream.set_nodelay(true) {
        tracing::debug!(error = %e, "set_nodelay failed");
    }
    let (mut reader, mut writer) = stream.into_split();
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 4096];
    // On a signing `tcpin` endpoint a client is sent nothing (telemetry, parameters,
    // mission) until it has delivered one validly signed frame, as a `udpin` peer
    // only becomes a peer then: whoever merely reaches the port learns nothing.
    let mut authenticated = signing.is_none() || peer == Accepted::Destination;
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return "shutdown",
            frame = rx.recv() => {
                let Some(frame) = frame else { return "endpoint stopped" };
                if !authenticated {
                    continue;
                }
                match tokio::time::timeout(WRITE_TIMEOUT, writer.write_all(frame.as_bytes())).await {
                    Ok(Ok(())) => metrics.frame_out(),
                    Ok(Err(_)) => {
                        metrics.dropped(DropReason::SendError, 1);
                        return "write failed";
                    }
                    Err(_) => {
                        metrics.dropped(DropReason::SendError, 1);
                        return "write timed out (client stopped reading)";
                    }
                }
            }
            r = reader.read(&mut buf) => match r {
                Ok(0) => return "closed by the other end",
                Ok(n) => {
                    if deliver(hub, index, &mut parser, &buf[..n], false, signing) > 0 && !authenticated {
                        authenticated = true;
                        tracing::info!(endpoint = metrics.label(), "tcp client authenticated (first validly signed frame)");
                    }
                }
                Err(_) => return "read failed",
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
    use mavlink::MavHeader;
    use mavlink_frame::signing::{signature_is_valid, signed_parts, SigningKey};

    const PATIENCE: Duration = Duration::from_secs(10);

    /// An ATTITUDE from the autopilot (system 1) or, with `from`, someone else.
    fn attitude(i: u32) -> RawFrame {
        attitude_from((1, 1), i)
    }

    fn attitude_from(from: (u8, u8), i: u32) -> RawFrame {
        let header = MavHeader {
            system_id: u32::from(from.0),
            component_id: from.1,
            sequence: i as u8,
        };
        let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: i,
            ..ATTITUDE_DATA::DEFAULT
        });
        RawFrame::encode(header, &msg)
    }

    fn ground_station() -> std::net::UdpSocket {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        s.set_read_timeout(Some(PATIENCE)).unwrap();
        s
    }

    /// The next datagram on `socket` (within [`PATIENCE`]) as a frame.
    fn next_frame(socket: &std::net::UdpSocket, who: &str) -> RawFrame {
        let mut buf = [0u8; 512];
        let n = socket
            .recv(&mut buf)
            .unwrap_or_else(|e| panic!("{who}: no frame within {PATIENCE:?}: {e}"));
        let mut parser = FrameParser::new();
        parser.push(&buf[..n]);
        parser
            .next_frame()
            .unwrap_or_else(|| panic!("{who}: not a frame: {:?}", &buf[..n]))
    }

    /// Frames for `udpout` and `udpin` endpoints are sent by the thread that routes
    /// them: they arrive (signed on a signing endpoint) while the endpoints' only
    /// runtime thread is blocked, so no tokio wake-up is needed per frame.
    #[test]
    fn udp_endpoints_are_sent_to_by_the_routing_thread() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let (plain, signed) = (ground_station(), ground_station());
        let out = |s: &std::net::UdpSocket| Endpoint::UdpOut {
            host: "127.0.0.1".into(),
            port: s.local_addr().unwrap().port(),
        };
        let endpoints = vec![
            out(&plain),
            out(&signed),
            Endpoint::UdpIn("127.0.0.1:0".parse().unwrap()),
        ];
        let key = SigningKey::new([7; 32]);
        let signing = SigningSettings {
            key: key.clone(),
            endpoints: vec![1],
        };
        let stats = Stats::new();
        let shutdown = CancellationToken::new();
        let peer = ground_station();
        let (hub, task) = rt.block_on(async {
            let bound = Bound::bind(&endpoints).await.unwrap();
            let udpin = bound.local_addrs()[2].unwrap();
            let (hub, task) = start(bound, (1, 191), Some(&signing), &stats, shutdown.clone());
            // The udpin endpoint learns its peer from what it sends; the udpout
            // ones open their sockets: wait (driving the runtime) until all three
            // receive what the hub routes.
            let mut ready = [false; 3];
            let deadline = Instant::now() + PATIENCE;
            while ready.contains(&false) {
                assert!(Instant::now() < deadline, "endpoints not up: {ready:?}");
                peer.send_to(attitude_from((255, 190), 0).as_bytes(), udpin)
                    .unwrap();
                hub.from_autopilot(&attitude(0));
                tokio::time::sleep(Duration::from_millis(20)).await;
                for (i, s) in [&plain, &signed, &peer].into_iter().enumerate() {
                    s.set_nonblocking(true).unwrap();
                    while s.recv(&mut [0u8; 512]).is_ok() {
                        ready[i] = true;
                    }
                    s.set_nonblocking(false).unwrap();
                }
            }
            (hub, task)
        });

        // The runtime is not running now: nothing but the routing thread can send.
        let n = 20u32;
        let router = {
            let hub = hub.clone();
            std::thread::spawn(move || {
                for i in 1..=n {
                    hub.from_autopilot(&attitude(i));
                }
            })
        };
        for i in 1..=n {
            let sent = attitude(i);
            let got = next_frame(&plain, "udpout");
            assert_eq!(got.as_bytes(), sent.as_bytes(), "udpout frame {i}");
            let got = next_frame(&peer, "udpin peer");
            assert_eq!(got.as_bytes(), sent.as_bytes(), "udpin frame {i}");
            let got = next_frame(&signed, "signing udpout");
            assert!(
                got.is_signed(),
                "frame {i} to the signing endpoint is unsigned"
            );
            assert!(
                signature_is_valid(&key, got.as_bytes()),
                "frame {i}: bad signature"
            );
            assert_eq!(signed_parts(got.as_bytes()).unwrap().link_id, 1);
            // Header (but the incompatibility flags) and payload unchanged.
            let payload_end = 10 + usize::from(sent.as_bytes()[1]);
            let (g, w) = (got.as_bytes(), sent.as_bytes());
            assert_eq!(g[..2], w[..2], "frame {i}");
            assert_eq!(g[3..payload_end], w[3..payload_end], "frame {i}");
        }
        router.join().unwrap();

        let mut snapshot = Box::<skymesh_ipc_types::ServiceStats>::default();
        stats.snapshot_into(&mut snapshot);
        let sent_to = |label: String| {
            snapshot
                .entries()
                .iter()
                .find(|e| {
                    e.name.as_str() == "skymesh_router_frames_total"
                        && e.labels.as_str() == format!("endpoint={label},direction=out")
                })
                .map_or(0.0, |e| e.value)
        };
        assert!(sent_to(endpoints[0].to_string()) >= f64::from(n + 1));
        assert!(sent_to(endpoints[1].to_string()) >= f64::from(n + 1));

        shutdown.cancel();
        rt.block_on(task).unwrap();
    }

    #[test]
    fn udp_peers_are_remembered_bounded_and_expire() {
        let t = Instant::now();
        let mut p = Peers::default();
        let a: SocketAddr = "127.0.0.1:1000".parse().unwrap();
        assert!(p.heard(a, t));
        assert!(!p.heard(a, t + Duration::from_secs(10)));
        for port in 0..MAX_PEERS as u16 {
            p.heard(SocketAddr::from(([127, 0, 0, 2], port)), t);
        }
        assert_eq!(p.heard.len(), MAX_PEERS);
        assert!(
            p.heard.iter().all(|(x, _)| *x != a),
            "the oldest was forgotten"
        );
        assert_eq!(p.expire(t + PEER_TIMEOUT), MAX_PEERS);
    }

    /// A `udpout` ground station that is not listening (ICMP port unreachable) gets
    /// one frame a second, the rest counted `not_listening`; once something listens
    /// there it gets the whole stream again within two seconds.
    #[test]
    fn a_udpout_destination_nobody_listens_at_gets_a_frame_a_second_until_it_listens() {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let port = ground_station().local_addr().unwrap().port(); // closed again
        let endpoint = Endpoint::UdpOut {
            host: "127.0.0.1".into(),
            port,
        };
        let name = label(0, &endpoint);
        let stats = Stats::new();
        let shutdown = CancellationToken::new();
        let (hub, _task) = rt.block_on(async {
            let bound = Bound::bind(&[endpoint]).await.unwrap();
            let started = start(bound, (1, 191), None, &stats, shutdown.clone());
            // Let the endpoint task open its socket and install its sink.
            tokio::time::sleep(Duration::from_millis(200)).await;
            started
        });
        let count = |what: &str| {
            stats
                .value(
                    "skymesh_router_frames_total",
                    &format!("endpoint={name},direction={what}"),
                )
                .unwrap_or(0.0)
        };
        let not_listening = || {
            stats
                .value(
                    "skymesh_router_frames_dropped_total",
                    &format!("endpoint={name},reason=not_listening"),
                )
                .unwrap_or(0.0)
        };
        // 1.5 s of 200 Hz telemetry to nobody.
        let t0 = Instant::now();
        let mut i = 0;
        while t0.elapsed() < Duration::from_millis(1500) {
            hub.from_autopilot(&attitude(i));
            i += 1;
            std::thread::sleep(Duration::from_millis(5));
        }
        let (out, skipped) = (count("out"), not_listening());
        assert!(
            // (A loaded machine may process an ICMP error a few frames late.)
            skipped >= f64::from(i) - 20.0 && out <= 15.0,
            "{i} frames to a closed port: {out} sent, {skipped} counted not_listening"
        );
        // Now a ground station listens there: the stream comes back.
        let gs = std::net::UdpSocket::bind(("127.0.0.1", port)).unwrap();
        gs.set_nonblocking(true).unwrap();
        let t1 = Instant::now();
        let mut got = 0;
        while got < 50 {
            assert!(
                t1.elapsed() < PATIENCE,
                "{got} frames within {PATIENCE:?} of listening"
            );
            hub.from_autopilot(&attitude(i));
            i += 1;
            std::thread::sleep(Duration::from_millis(5));
            while gs.recv(&mut [0u8; 512]).is_ok() {
                got += 1;
            }
        }
        // Within two probe periods (plus slack for a loaded machine), not 50 probes.
        assert!(
            t1.elapsed() < Duration::from_secs(5),
            "stream back after {:?}",
            t1.elapsed()
        );
        shutdown.cancel();
    }
}
