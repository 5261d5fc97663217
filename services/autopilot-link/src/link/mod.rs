//! The MAVLink connection: open, read, write, reconnect.
//!
//! Each open connection, over the raw byte transport of `transport`, gets a reader
//! that splits the bytes into frames ([`crate::frame`]), hands every frame to the
//! router [`Hub`] (byte for byte, to the endpoints) and decodes the ones the
//! dialect knows into the service's [`LinkEvent`] channel; and a writer thread
//! (tokio's blocking pool) that drains the [`Outbox`]: our own messages (queued
//! through [`LinkWriter`], serialised with our header and sequence) before frames
//! the router forwards from endpoints, each kind bounded on its own so
//! ground-station traffic can never crowd out our commands. On a socket, our own
//! message is written by the task that sends it when nothing is queued ahead of it
//! (a non-blocking send: a decided command leaves in the same wake-up, see
//! `outbox.rs`); the writer thread takes what the socket does not take at once. A
//! TCP or UDP socket is read on the runtime (tokio's reactor says when it is
//! readable: one wake-up per telemetry batch, on the thread that also runs the
//! service); a serial port by a blocking thread that polls a stop flag at least
//! every [`POLL`], so a shutdown or a reconnect never waits on a blocked read. The
//! writer sleeps until there is something to write or the outbox is closed (which
//! every stop does).
//!
//! COMMAND_ACKs that answer an endpoint's command (decided by the
//! [`AckLedger`], fed by the writer) are forwarded but not given to the service.
//!
//! [`spawn`] runs the supervising task: connect (with backoff after failures,
//! forever, so the autopilot may start after us; logged at a sane rate), report
//! [`LinkEvent::Connected`], wait for the reader or writer to fail, report
//! [`LinkEvent::Disconnected`], and start over. The service keeps its state across
//!
//! | file | holds |
//! |---|---|
//! | `mod.rs` | the events, connecting, supervising, reconnecting |
//! | `outbox.rs` | what is sent: [`LinkWriter`] (direct writes) and the [`Outbox`] |
//! | `io_loops.rs` | the reader (frames in, events out) and the writer loop |

mod io_loops;
mod outbox;
#[cfg(test)]
mod tests;

use std::future::Future;
use std::io;
use std::net::TcpListener;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::MavHeader;
use skymesh_runtime::Backoff;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::config::Endpoint;
use crate::hub::Hub;
use crate::metrics::Metrics;
use crate::router::AckLedger;
use crate::transport;

use io_loops::{read_loop, read_socket, write_loop};
use outbox::SendContext;
pub use outbox::{LinkWriter, Outbox};

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
    let me = (config.system_id, config.component_id);
    let ctx = Arc::new(SendContext {
        header: MavHeader {
            system_id: u32::from(config.system_id),
            component_id: config.component_id,
            sequence: 0,
        },
        ledger: Arc::new(Mutex::new(AckLedger::new(me))),
        metrics: metrics.clone(),
        hub: hub.clone(),
    });
    // Without a second handle our messages all go through the writer thread,
    // which is slower but complete.
    let direct = writer.direct().unwrap_or_else(|e| {
        tracing::warn!(error = %e, "no direct writes on the MAVLink socket; using the writer thread");
        None
    });
    let outbox = Arc::new(Outbox::with_direct(direct));
    if events
        .send(LinkEvent::Connected(LinkWriter {
            outbox: outbox.clone(),
            ctx: ctx.clone(),
        }))
        .await
        .is_err()
    {
        outbox.close();
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
    let ledger = ctx.ledger.clone();
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
        let (stop, outbox) = (stop.clone(), outbox.clone());
        let mut writer_half = writer;
        tokio::task::spawn_blocking(move || {
            let reason = write_loop(&mut writer_half, &outbox, &ctx, &stop);
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
