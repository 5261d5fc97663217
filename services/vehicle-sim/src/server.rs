//! The thin tokio layer: bind the endpoint, accept TCP clients or receive UDP
//! datagrams, decode frames into [`LinkEvent`]s for the engine, and write the
//! engine's frames back out. No simulation logic lives here.

use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;
use tracing::{debug, info, warn};

use crate::config::{Endpoint, Settings};
use crate::engine::{link_id, LinkEvent, LinkId, LINK_QUEUE_FRAMES};
use crate::stats::{self, SimStats};
use mavlink_frame::{BadFrame, FrameDecoder};

/// Read buffer per TCP client.
const READ_CHUNK: usize = 4096;

/// A TCP writer coalesces queued frames into writes of up to this size.
const MAX_WRITE_BATCH: usize = 16 * 1024;

/// Back-off after a failed `accept` (e.g. out of file descriptors).
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// An already-bound endpoint, so tests can bind port 0 and read the port back.
#[derive(Debug)]
pub enum BoundEndpoint {
    /// Serve TCP clients.
    Tcp(TcpListener),
    /// Serve UDP peers.
    Udp(UdpSocket),
}

impl BoundEndpoint {
    /// The bound address (with the real port when bound to port 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        match self {
            BoundEndpoint::Tcp(l) => l.local_addr(),
            BoundEndpoint::Udp(s) => s.local_addr(),
        }
    }
}

/// Bind the configured endpoint (vehicle 0's in swarm mode; see [`bind_all`]).
pub async fn bind(settings: &Settings) -> anyhow::Result<BoundEndpoint> {
    bind_endpoint(settings.endpoint).await
}

/// Bind every vehicle's endpoint ([`Settings::vehicles`]), in vehicle order.
pub async fn bind_all(settings: &Settings) -> anyhow::Result<Vec<BoundEndpoint>> {
    let mut out = Vec::with_capacity(settings.vehicle_count());
    for spec in settings.vehicles() {
        let bound = bind_endpoint(spec.endpoint)
            .await
            .with_context(|| format!("vehicle with system id {}", spec.system_id))?;
        out.push(bound);
    }
    Ok(out)
}

async fn bind_endpoint(endpoint: Endpoint) -> anyhow::Result<BoundEndpoint> {
    match endpoint {
        Endpoint::Tcp(addr) => Ok(BoundEndpoint::Tcp(
            TcpListener::bind(addr)
                .await
                .with_context(|| format!("binding tcp {addr}"))?,
        )),
        Endpoint::Udp(addr) => Ok(BoundEndpoint::Udp(
            UdpSocket::bind(addr)
                .await
                .with_context(|| format!("binding udp {addr}"))?,
        )),
    }
}

/// Serve vehicle `vehicle`'s endpoint until `shutdown`; client tasks are
/// spawned on `tracker`. `max_clients` applies to this endpoint alone.
pub(crate) async fn serve(
    listener: BoundEndpoint,
    vehicle: usize,
    events: mpsc::Sender<LinkEvent>,
    max_clients: usize,
    stats: Arc<SimStats>,
    shutdown: CancellationToken,
    tracker: TaskTracker,
) -> anyhow::Result<()> {
    match listener {
        BoundEndpoint::Tcp(l) => {
            serve_tcp(l, vehicle, events, max_clients, stats, shutdown, tracker).await;
            Ok(())
        }
        BoundEndpoint::Udp(s) => {
            serve_udp(s, link_id(vehicle, 0), events, max_clients, stats, shutdown).await
        }
    }
}

async fn serve_tcp(
    listener: TcpListener,
    vehicle: usize,
    events: mpsc::Sender<LinkEvent>,
    max_clients: usize,
    stats: Arc<SimStats>,
    shutdown: CancellationToken,
    tracker: TaskTracker,
) {
    // Clients of this endpoint (the stats gauge counts every vehicle's).
    let connected = Arc::new(AtomicU64::new(0));
    let mut next_id: u64 = 1;
    loop {
        let (stream, peer) = tokio::select! {
            () = shutdown.cancelled() => return,
            r = listener.accept() => match r {
                Ok(accepted) => accepted,
                Err(e) => {
                    warn!(error = %e, "accept failed");
                    tokio::select! {
                        () = shutdown.cancelled() => return,
                        () = tokio::time::sleep(ACCEPT_BACKOFF) => continue,
                    }
                }
            },
        };
        // Counted here, before the spawn, so a burst of connects cannot race past the limit.
        if connected.load(Ordering::Relaxed) >= max_clients as u64 {
            warn!(%peer, max_clients, "refusing client: too many connected");
            stats::add(&stats.clients_rejected, 1);
            continue;
        }
        connected.fetch_add(1, Ordering::Relaxed);
        stats::add(&stats.clients_connected, 1);
        stats::add(&stats.clients_total, 1);
        // Small frames (acks, 100 Hz attitude) should not wait for Nagle.
        if let Err(e) = stream.set_nodelay(true) {
            debug!(%peer, error = %e, "set_nodelay failed");
        }
        let id = link_id(vehicle, next_id);
        next_id += 1;
        tracker.spawn(tcp_client(
            id,
            stream,
            peer,
            events.clone(),
            stats.clone(),
            connected.clone(),
            shutdown.clone(),
        ));
    }
}

async fn tcp_client(
    id: LinkId,
    stream: TcpStream,
    peer: SocketAddr,
    events: mpsc::Sender<LinkEvent>,
    stats: Arc<SimStats>,
    connected: Arc<AtomicU64>,
    shutdown: CancellationToken,
) {
    let (tx, mut rx) = mpsc::channel(LINK_QUEUE_FRAMES);
    let opened = LinkEvent::Opened {
        id,
        peer: format!("tcp:{peer}"),
        tx,
    };
    if events.send(opened).await.is_ok() {
        info!(link = id, %peer, "client connected");
        let (mut rd, mut wr) = stream.into_split();
        let mut bad = BadFrameLog::default();
        let reason = tokio::select! {
            () = shutdown.cancelled() => "shutdown",
            r = read_loop(id, &mut rd, &events, &stats, &mut bad) => match r {
                Ok(()) => "closed by peer",
                Err(e) => {
                    debug!(link = id, error = %e, "read failed");
                    "read error"
                }
            },
            r = write_loop(&mut wr, &mut rx) => match r {
                Ok(()) => "simulation stopped",
                Err(e) => {
                    debug!(link = id, error = %e, "write failed");
                    "write error"
                }
            },
        };
        // The engine may already be gone at shutdown; nothing to tell it then.
        let _ = events.send(LinkEvent::Closed { id }).await;
        if let Err(e) = wr.shutdown().await {
            debug!(link = id, error = %e, "shutdown failed");
        }
        info!(link = id, %peer, reason, bad_frames = bad.count, "client disconnected");
    }
    stats::sub(&stats.clients_connected, 1);
    connected.fetch_sub(1, Ordering::Relaxed);
}

async fn read_loop(
    id: LinkId,
    rd: &mut OwnedReadHalf,
    events: &mpsc::Sender<LinkEvent>,
    stats: &SimStats,
    bad: &mut BadFrameLog,
) -> io::Result<()> {
    let mut decoder = FrameDecoder::new();
    let mut buf = vec![0u8; READ_CHUNK];
    loop {
        let n = rd.read(&mut buf).await?;
        if n == 0 {
            return Ok(());
        }
        decoder.push(&buf[..n]);
        if !forward_frames(id, &mut decoder, events, stats, bad).await {
            return Ok(());
        }
    }
}

async fn write_loop(wr: &mut OwnedWriteHalf, rx: &mut mpsc::Receiver<Vec<u8>>) -> io::Result<()> {
    let mut batch = Vec::with_capacity(MAX_WRITE_BATCH);
    while let Some(frame) = rx.recv().await {
        batch.clear();
        batch.extend_from_slice(&frame);
        // One write for everything already queued (e.g. a tick's telemetry).
        while batch.len() < MAX_WRITE_BATCH {
            match rx.try_recv() {
                Ok(more) => batch.extend_from_slice(&more),
                Err(_) => break,
            }
        }
        wr.write_all(&batch).await?;
    }
    Ok(())
}

/// Decode every complete frame and hand it to the engine. `false` when the
/// engine is gone.
async fn forward_frames(
    id: LinkId,
    decoder: &mut FrameDecoder,
    events: &mpsc::Sender<LinkEvent>,
    stats: &SimStats,
    bad: &mut BadFrameLog,
) -> bool {
    while let Some(r) = decoder.next_frame() {
        match r {
            Ok(frame) => {
                stats::add(&stats.frames_in, 1);
                if events.send(LinkEvent::Frame { id, frame }).await.is_err() {
                    return false;
                }
            }
            Err(BadFrame::Garbage { len }) => {
                stats::add(&stats.garbage_bytes, len as u64);
                bad.note(id, &BadFrame::Garbage { len });
            }
            Err(e) => {
                stats::add(&stats.bad_frames, 1);
                bad.note(id, &e);
            }
        }
    }
    true
}

/// Logs a link's first bad input as a warning and the rest at debug, so a
/// noisy link cannot flood the log; the total is logged at disconnect.
#[derive(Debug, Default)]
struct BadFrameLog {
    count: u64,
}

impl BadFrameLog {
    fn note(&mut self, id: LinkId, e: &BadFrame) {
        self.count += 1;
        if self.count == 1 {
            warn!(link = id, error = %e, "bad input on link (further ones logged at debug)");
        } else {
            debug!(link = id, error = %e, count = self.count, "bad input on link");
        }
    }
}

/// UDP: the socket is one link; telemetry goes to every peer that has sent a
/// datagram (at most `max_peers`, oldest forgotten first).
async fn serve_udp(
    socket: UdpSocket,
    id: LinkId,
    events: mpsc::Sender<LinkEvent>,
    max_peers: usize,
    stats: Arc<SimStats>,
    shutdown: CancellationToken,
) -> anyhow::Result<()> {
    let local = socket.local_addr().context("udp local address")?;
    let (tx, mut rx) = mpsc::channel::<Vec<u8>>(LINK_QUEUE_FRAMES);
    let opened = LinkEvent::Opened {
        id,
        peer: format!("udp:{local}"),
        tx,
    };
    if events.send(opened).await.is_err() {
        return Ok(());
    }
    let mut peers: Vec<SocketAddr> = Vec::new();
    let mut bad = BadFrameLog::default();
    let mut buf = vec![0u8; 65_536];
    loop {
        tokio::select! {
            biased;
            () = shutdown.cancelled() => break,
            frame = rx.recv() => {
                let Some(frame) = frame else { break };
                // One frame per datagram, as ArduPilot sends them.
                for peer in &peers {
                    if let Err(e) = socket.send_to(&frame, peer).await {
                        debug!(%peer, error = %e, "udp send failed");
                    }
                }
            }
            r = socket.recv_from(&mut buf) => {
                let (n, from) = match r {
                    Ok(x) => x,
                    Err(e) => {
                        // E.g. ICMP port unreachable from a vanished peer: not fatal.
                        debug!(error = %e, "udp receive failed");
                        continue;
                    }
                };
                if !peers.contains(&from) {
                    if peers.len() >= max_peers {
                        let old = peers.remove(0);
                        info!(peer = %old, "forgetting oldest udp peer");
                    }
                    info!(peer = %from, "udp peer joined");
                    stats::add(&stats.clients_total, 1);
                    peers.push(from);
                }
                // Datagrams are self-contained: a fresh decoder per datagram, and
                // whatever it could not complete is garbage.
                let mut decoder = FrameDecoder::new();
                decoder.push(&buf[..n]);
                if !forward_frames(id, &mut decoder, &events, &stats, &mut bad).await {
                    break;
                }
                let leftover = decoder.buffered();
                if leftover > 0 {
                    stats::add(&stats.garbage_bytes, leftover as u64);
                    bad.note(id, &BadFrame::Garbage { len: leftover });
                }
            }
        }
    }
    let _ = events.send(LinkEvent::Closed { id }).await;
    info!(
        peers = peers.len(),
        bad_frames = bad.count,
        "udp link closed"
    );
    Ok(())
}
