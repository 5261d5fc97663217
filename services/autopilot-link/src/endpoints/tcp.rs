//! The TCP endpoints (`tcpin`, `tcpout`): the listening and connecting tasks and
//! one connection's stream.

use std::io;
use std::sync::Arc;
use std::time::Duration;

use skymesh_runtime::Backoff;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::task::JoinSet;
use tokio_util::sync::CancellationToken;

use super::{
    deliver, outgoing, resolve, Sig, CONNECT_TIMEOUT, ENDPOINT_QUEUE, MAX_CLIENTS, RECONNECT_MAX,
    RECONNECT_MIN, WRITE_TIMEOUT,
};
use crate::hub::{DropReason, Hub};
use crate::signing::EndpointSigning;
use mavlink_frame::{FrameParser, RawFrame};

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
pub(super) async fn tcp_in(
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

pub(super) async fn tcp_out(
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

/// Who is at the other end of a TCP endpoint's stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Accepted {
    /// A `tcpin` client: anyone who reached the port.
    Client,
    /// The configured `tcpout` destination (we chose it).
    Destination,
}

/// Runs one TCP connection of endpoint `index` until it ends; returns why.
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
