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
//!
//! | file | holds |
//! |---|---|
//! | `mod.rs` | binding, starting the endpoint tasks, what every endpoint shares |
//! | `udp.rs` | `udpin`/`udpout`: the peers, the [`UdpSink`] and the tasks |
//! | `tcp.rs` | `tcpin`/`tcpout`: the tasks and one connection's stream |

mod tcp;
#[cfg(test)]
mod tests;
mod udp;

use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use skymesh_runtime::Stats;
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::mpsc;
use tokio::task::{JoinHandle, JoinSet};
use tokio_util::sync::CancellationToken;

use crate::config::Endpoint;
use crate::hub::{label, DropReason, EndpointMetrics, Hub};
use crate::router::MAX_ENDPOINTS;
use crate::signing::{EndpointSigning, Signing, SigningSettings};
use crate::tlog::TlogSettings;
use mavlink_frame::{FrameParser, RawFrame};

use tcp::{tcp_in, tcp_out};
pub use udp::UdpSink;
use udp::{udp_in, udp_out};

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
/// endpoints, in configuration order) require MAVLink 2 signing, with which key;
/// with `tlog`, the autopilot link's traffic is recorded ([`crate::tlog`]). The
/// returned task ends once `shutdown` fires, every endpoint task has closed its
/// sockets and the flight log being written is closed.
pub fn start(
    bound: Bound,
    local: (u8, u8),
    signing: Option<&SigningSettings>,
    tlog: Option<&TlogSettings>,
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
    let recorder = tlog.and_then(|settings| match crate::tlog::start(settings, stats) {
        Ok((tap, recorder)) => {
            hub.set_tlog(tap);
            Some(recorder)
        }
        Err(e) => {
            // The link runs without flight logs rather than not at all.
            tracing::error!(error = %e, "tlog: cannot start the writer thread: no flight logs");
            None
        }
    });
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
        if let Some(recorder) = recorder {
            // Cancelled once the link has stopped: no frame comes after this.
            shutdown.cancelled().await;
            if let Err(e) = tokio::task::spawn_blocking(move || recorder.finish()).await {
                tracing::warn!(error = %e, "tlog: closing the flight log failed");
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

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}
async fn resolve(host: &str, port: u16) -> io::Result<SocketAddr> {
    tokio::net::lookup_host((host, port))
        .await?
        .next()
        .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, format!("{host} has no address")))
}
