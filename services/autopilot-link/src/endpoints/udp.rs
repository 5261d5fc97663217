//! The UDP endpoints (`udpin`, `udpout`): the live peers, the sink the routing
//! thread sends through, and each endpoint's receiving task.

use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use skymesh_runtime::refusals::{self, Admit, Refusals};
use skymesh_runtime::Backoff;
use tokio::io::unix::AsyncFd;
use tokio::io::Interest;
use tokio::net::UdpSocket;
use tokio_util::sync::CancellationToken;

use super::{
    deliver, lock, outgoing, resolve, Sig, MAX_PEERS, PEER_TIMEOUT, RECONNECT_MAX, RECONNECT_MIN,
};
use crate::hub::{DropReason, EndpointMetrics, Hub};
use mavlink_frame::{FrameParser, RawFrame};

/// The live peers of a `udpin` endpoint. Pure.
#[derive(Debug, Default)]
pub(super) struct Peers {
    /// Peer and when it was last heard, oldest first.
    pub(super) heard: Vec<(SocketAddr, Instant)>,
}

impl Peers {
    /// Notes a datagram from `peer`; true if it is new.
    pub(super) fn heard(&mut self, peer: SocketAddr, now: Instant) -> bool {
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
    pub(super) fn expire(&mut self, now: Instant) -> usize {
        let before = self.heard.len();
        self.heard
            .retain(|(_, t)| now.duration_since(*t) < PEER_TIMEOUT);
        before - self.heard.len()
    }
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

pub(super) async fn udp_in(
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
/// Waits `delay`; false on shutdown.
async fn pause(delay: Duration, shutdown: &CancellationToken) -> bool {
    tokio::select! {
        _ = shutdown.cancelled() => false,
        _ = tokio::time::sleep(delay) => true,
    }
}

pub(super) async fn udp_out(
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
