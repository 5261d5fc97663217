//! One app connection: a reader that checks every frame and publishes the good ones,
//! and a writer that drains the connection's bounded outgoing queue.
//!
//! The session never decides whether the app may stay connected; the [`crate::hub`]
//! does, and closes a session by cancelling its token. A session ends by itself only
//! when the app closes, the connection fails, or the app's input forces it
//! (too long, stalled, its own replies overflowing the queue).

use std::fmt;
use std::net::SocketAddr;
use std::time::Duration;

use bytes::{Bytes, BytesMut};
use skymesh_runtime::backend::BackendWait;
use skymesh_runtime::TokenBucket;
use solo_proto::{FrameError, TlvCodec};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::drops::Drops;
use crate::framing::{FrameReader, ReadError};
use crate::inbound::{self, Verdict};
use crate::ipc::{FromApp, PublishError};
use crate::metrics::{Direction, Malformed};
use crate::translate;

/// One whole TLV frame for the app.
#[derive(Debug, Clone)]
pub struct Outgoing {
    pub msg_type: u32,
    pub frame: Bytes,
}

/// Frames are written in batches of up to this many bytes.
const WRITE_BATCH: usize = 64 * 1024;

/// How a session ended.
#[derive(Debug)]
pub enum End {
    /// The app closed the connection.
    Closed,
    /// The hub closed it (replaced, overflow, shutdown).
    Cancelled,
    /// The app's input forced it closed (counted under this kind).
    Dropped(Malformed),
    /// The connection closed in the middle of a frame.
    Truncated(usize),
    Io(std::io::Error),
    /// The bus failed: fatal for the service.
    Bus(PublishError),
}

impl fmt::Display for End {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            End::Closed => f.write_str("closed by the app"),
            End::Cancelled => f.write_str("closed by the gateway"),
            End::Dropped(kind) => write!(f, "dropped: {}", kind.as_str()),
            End::Truncated(n) => write!(f, "closed by the app inside a frame ({n} bytes)"),
            End::Io(e) => write!(f, "connection error: {e}"),
            End::Bus(e) => write!(f, "bus error: {e}"),
        }
    }
}

/// What a session needs besides its socket.
#[derive(Debug, Clone)]
pub struct SessionCtx {
    pub session: u32,
    pub peer: SocketAddr,
    pub frame_timeout: Duration,
    pub from_app: FromApp,
    pub drops: Drops,
    /// The session's own outgoing queue, for the gateway's direct answers.
    pub replies: mpsc::Sender<Outgoing>,
    /// `max_messages_per_s` and `message_burst`.
    pub rate: (u32, u32),
    /// How long a request the shot engine answers waits for one to read the bus.
    pub backend_wait: Duration,
}

/// Whether the shot engine is there to answer the app's requests.
#[derive(Debug, Default)]
struct Backend {
    wait: BackendWait,
}

impl Backend {
    /// `verdict` unchanged, or, for a request the engine answers while no engine
    /// reads its topic within `backend_wait`, the gateway's own answer.
    async fn check(&mut self, verdict: Verdict, msg_type: u32, ctx: &SessionCtx) -> Verdict {
        let geofence = match &verdict {
            Verdict::Forward(_) => false,
            Verdict::Geofence(_) => true,
            _ => return verdict,
        };
        if !inbound::expects_reply(msg_type) || self.present(geofence, ctx).await {
            return verdict;
        }
        let message = match &verdict {
            Verdict::Forward(m) => Some(m),
            _ => None,
        };
        inbound::backend_missing(msg_type, message, ctx.backend_wait).unwrap_or(verdict)
    }

    async fn present(&mut self, geofence: bool, ctx: &SessionCtx) -> bool {
        self.wait
            .present(ctx.backend_wait, || ctx.from_app.engine_reads(geofence))
            .await
    }
}

/// Serves one connection until the app leaves, its input forces a close, or `cancel`.
pub async fn run(
    stream: TcpStream,
    ctx: SessionCtx,
    outgoing: mpsc::Receiver<Outgoing>,
    cancel: CancellationToken,
) -> End {
    let (read, write) = stream.into_split();
    let mut reader = FrameReader::new(read, TlvCodec::new(), Some(ctx.frame_timeout));
    tokio::select! {
        _ = cancel.cancelled() => End::Cancelled,
        end = read_loop(&mut reader, &ctx) => end,
        end = write_loop(write, outgoing, &ctx) => end,
    }
}

async fn read_loop(reader: &mut FrameReader<OwnedReadHalf>, ctx: &SessionCtx) -> End {
    let metrics = ctx.drops.metrics();
    let (per_s, burst) = ctx.rate;
    let mut rate = TokenBucket::new(per_s, burst, Instant::now().into_std());
    let mut backend = Backend::default();
    loop {
        let frame = match reader.next_frame().await {
            Ok(Some(frame)) => frame,
            Ok(None) => return End::Closed,
            Err(e @ ReadError::Frame(FrameError::TooLong { .. })) => {
                ctx.drops.record(Malformed::TooLong, ctx.peer, &e);
                return End::Dropped(Malformed::TooLong);
            }
            Err(e @ ReadError::Stalled { .. }) => {
                ctx.drops.record(Malformed::Stalled, ctx.peer, &e);
                return End::Dropped(Malformed::Stalled);
            }
            Err(ReadError::TruncatedFrame { buffered }) => return End::Truncated(buffered),
            Err(ReadError::Frame(FrameError::Io(e))) => return End::Io(e),
        };
        let verdict = if rate.take(Instant::now().into_std()) {
            inbound::check(&frame)
        } else {
            inbound::rate_limited(
                &frame,
                format!(
                    "type {}: more than {per_s} frames per second (burst {burst}); dropped",
                    frame.msg_type
                ),
            )
        };
        let verdict = backend.check(verdict, frame.msg_type, ctx).await;
        match verdict {
            Verdict::Forward(message) => match translate::request(&message) {
                Some(request) => {
                    metrics.message(Direction::In, frame.msg_type);
                    if let Err(e) = ctx.from_app.publish(ctx.session, &request, false) {
                        return End::Bus(e);
                    }
                }
                // `inbound::check` forwards only what the app may send, each of
                // which has a request; kept as a drop should the two ever disagree.
                None => ctx.drops.record(
                    Malformed::WrongDirection,
                    ctx.peer,
                    &format_args!("{} is no request for the shot engine", message.name()),
                ),
            },
            Verdict::Geofence(fence) => {
                metrics.message(Direction::In, frame.msg_type);
                if let Err(e) = ctx.from_app.publish_geofence(ctx.session, &fence) {
                    return End::Bus(e.into());
                }
            }
            Verdict::Drop { kind, reason } => ctx.drops.record(kind, ctx.peer, &reason),
            Verdict::Answer {
                msg_type,
                kind,
                reason,
                replies,
            } => {
                if matches!(kind, Malformed::TooLargeForBus | Malformed::BackendMissing) {
                    metrics.message(Direction::In, msg_type);
                }
                ctx.drops.record(kind, ctx.peer, &reason);
                for reply in replies {
                    let out = Outgoing {
                        msg_type: reply.msg_type(),
                        frame: reply.to_bytes(),
                    };
                    match ctx.replies.try_send(out) {
                        Ok(()) => {}
                        Err(mpsc::error::TrySendError::Full(_)) => {
                            let why = "outgoing queue full: the app stopped reading";
                            ctx.drops.record(Malformed::Overflow, ctx.peer, &why);
                            return End::Dropped(Malformed::Overflow);
                        }
                        Err(mpsc::error::TrySendError::Closed(_)) => return End::Cancelled,
                    }
                }
            }
        }
    }
}

async fn write_loop(
    mut write: OwnedWriteHalf,
    mut outgoing: mpsc::Receiver<Outgoing>,
    ctx: &SessionCtx,
) -> End {
    let metrics = ctx.drops.metrics();
    let mut batch = BytesMut::with_capacity(WRITE_BATCH);
    let mut types = Vec::new();
    while let Some(first) = outgoing.recv().await {
        batch.clear();
        types.clear();
        batch.extend_from_slice(&first.frame);
        types.push(first.msg_type);
        while batch.len() < WRITE_BATCH {
            match outgoing.try_recv() {
                Ok(next) => {
                    batch.extend_from_slice(&next.frame);
                    types.push(next.msg_type);
                }
                Err(_) => break,
            }
        }
        if let Err(e) = write.write_all(&batch).await {
            return End::Io(e);
        }
        for t in &types {
            metrics.message(Direction::Out, *t);
        }
    }
    End::Cancelled
}

/// Tells a second phone that an app is connected already, then closes it.
///
/// Waits (at most `linger`) for the client to close first: closing a socket with
/// unread input resets it, and a reset can destroy the notification before the
/// client has read it.
pub async fn reject_second_phone(mut stream: TcpStream, linger: Duration) {
    let notification = solo_proto::SoloMessage::SecondPhoneNotification.to_bytes();
    let result = tokio::time::timeout(linger, async {
        stream.write_all(&notification).await?;
        stream.shutdown().await?;
        let mut sink = [0u8; 512];
        while stream.read(&mut sink).await? > 0 {}
        Ok::<_, std::io::Error>(())
    })
    .await;
    if let Ok(Err(e)) = result {
        tracing::debug!(error = %e, "closing a rejected second phone");
    }
}
