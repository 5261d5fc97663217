//! The router's endpoints: ground stations and other MAVLink programs beside the
//! autopilot (`endpoints = [...]` in the config), and the [`Hub`] that moves frames
//! between them and the autopilot link by the decisions of [`crate::router`]
//! (the hub and the router metrics are in [`crate::hub`]).
//!
//! Each endpoint is one tokio task (TCP servers add one per client) with a bounded
//! queue of frames to send. The hub only ever `try_send`s into those queues: a
//! slow or dead endpoint loses frames (counted, `reason="queue_full"`) and never
//! holds up the autopilot's reader thread or another endpoint. Frames towards the
//! autopilot go into the link's own bounded forward queue the same way.
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
use std::sync::Arc;
use std::time::{Duration, Instant};

use skymesh_runtime::Stats;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio::task::{JoinHandle, JoinSet};
use tokio_util::sync::CancellationToken;

use crate::config::Endpoint;
use crate::frame::{FrameParser, RawFrame};
use crate::hub::{label, DropReason, EndpointMetrics, Hub};
use crate::router::MAX_ENDPOINTS;
use crate::signing::{EndpointSigning, Signing, SigningSettings};

/// The signing of one endpoint, if it requires signing.
type Sig = Option<Arc<EndpointSigning>>;

/// Frames waiting for one endpoint (or one TCP client); beyond this they are dropped.
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
        let (tx, rx) = mpsc::channel(ENDPOINT_QUEUE);
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
        match (endpoint, socket) {
            (_, Socket::UdpIn(s)) => tasks.spawn(udp_in(index, s, hub, rx, sig, stop)),
            (_, Socket::TcpIn(l)) => tasks.spawn(tcp_in(index, l, hub, rx, sig, stop)),
            (Endpoint::UdpOut { host, port }, Socket::Out) => {
                tasks.spawn(udp_out(index, host, port, hub, rx, sig, stop))
            }
            (Endpoint::TcpOut { host, port }, Socket::Out) => {
                tasks.spawn(tcp_out(index, host, port, hub, rx, sig, stop))
            }
            (other, Socket::Out) => {
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

async fn udp_in(
    index: u8,
    socket: UdpSocket,
    hub: Arc<Hub>,
    mut rx: mpsc::Receiver<RawFrame>,
    signing: Sig,
    shutdown: CancellationToken,
) {
    let signing = signing.as_deref();
    let metrics = &hub.metrics(index);
    let mut peers = Peers::default();
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 65536];
    metrics.peers(0);
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return,
            frame = rx.recv() => {
                let Some(frame) = frame else { return };
                if peers.expire(Instant::now()) > 0 {
                    metrics.peers(peers.heard.len());
                }
                if peers.heard.is_empty() {
                    continue;
                }
                let frame = outgoing(frame, signing);
                for (peer, _) in &peers.heard {
                    send_datagram(&socket, frame.as_bytes(), *peer, metrics).await;
                }
            }
            r = socket.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    let delivered = deliver(&hub, index, &mut parser, &buf[..n], true, signing);
                    // On a signing endpoint only an authenticated sender is a peer.
                    if (signing.is_none() || delivered > 0) && peers.heard(from, Instant::now()) {
                        tracing::info!(endpoint = metrics.label(), peer = %from, "udp peer joined");
                        metrics.peers(peers.heard.len());
                    }
                }
                // E.g. ICMP port unreachable from a vanished peer: not fatal.
                Err(e) => tracing::debug!(endpoint = metrics.label(), error = %e, "udp receive failed"),
            },
        }
    }
}

/// Sends one frame as a datagram, counting it sent or dropped.
async fn send_datagram(
    socket: &UdpSocket,
    bytes: &[u8],
    to: SocketAddr,
    metrics: &EndpointMetrics,
) {
    match socket.send_to(bytes, to).await {
        Ok(_) => metrics.frame_out(),
        Err(e) => {
            metrics.dropped(DropReason::SendError, 1);
            tracing::debug!(%to, error = %e, "udp send failed");
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

async fn udp_out(
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
    let mut delay = RECONNECT_MIN;
    let (socket, to) = loop {
        let opened = async {
            let to = resolve(&host, port).await?;
            let any: SocketAddr = if to.is_ipv4() {
                ([0, 0, 0, 0], 0).into()
            } else {
                (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
            };
            Ok::<_, io::Error>((UdpSocket::bind(any).await?, to))
        };
        match opened.await {
            Ok(v) => break v,
            Err(e) => {
                tracing::warn!(endpoint = metrics.label(), error = %e, retry_in_s = delay.as_secs_f32(), "cannot open udp endpoint; retrying");
                if !idle(delay, &mut rx, &shutdown).await {
                    return;
                }
                delay = (delay * 2).min(RECONNECT_MAX);
            }
        }
    };
    metrics.peers(1);
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 65536];
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return,
            frame = rx.recv() => {
                let Some(frame) = frame else { return };
                let frame = outgoing(frame, signing);
                send_datagram(&socket, frame.as_bytes(), to, metrics).await;
            }
            r = socket.recv_from(&mut buf) => match r {
                Ok((n, _)) => {
                    deliver(&hub, index, &mut parser, &buf[..n], true, signing);
                }
                // ICMP port unreachable while no ground station listens: expected.
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
                        let reason = serve_stream(index, stream, &hub, crx, sig.as_deref(), &stop).await;
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
    let mut delay = RECONNECT_MIN;
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
        match connected {
            Ok(stream) => {
                tracing::info!(endpoint = metrics.label(), "tcp endpoint connected");
                delay = RECONNECT_MIN;
                metrics.peers(1);
                let (tx, crx) = mpsc::channel(ENDPOINT_QUEUE);
                let serve = serve_stream(index, stream, &hub, crx, signing, &shutdown);
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
            }
            Err(e) => {
                tracing::debug!(endpoint = metrics.label(), error = %e, retry_in_s = delay.as_secs_f32(), "cannot connect tcp endpoint; retrying");
                delay = (delay * 2).min(RECONNECT_MAX);
            }
        }
        if !idle(delay, &mut rx, &shutdown).await {
            return;
        }
    }
}

/// Runs one TCP connection of endpoint `index` until it ends; returns why.
async fn serve_stream(
    index: u8,
    stream: TcpStream,
    hub: &Hub,
    mut rx: mpsc::Receiver<RawFrame>,
    signing: Option<&EndpointSigning>,
    shutdown: &CancellationToken,
) -> &'static str {
    let metrics = &hub.metrics(index);
    if let Err(e) = stream.set_nodelay(true) {
        tracing::debug!(error = %e, "set_nodelay failed");
    }
    let (mut reader, mut writer) = stream.into_split();
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 4096];
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => return "shutdown",
            frame = rx.recv() => {
                let Some(frame) = frame else { return "endpoint stopped" };
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
                    deliver(hub, index, &mut parser, &buf[..n], false, signing);
                }
                Err(_) => return "read failed",
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
