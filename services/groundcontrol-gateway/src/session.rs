//! One state-server connection: a reader that cuts 32-byte records, decides about
//! each ([`crate::inbound`]) and publishes the commands, and a writer that drains
//! the connection's bounded outgoing queue.
//!
//! Each connection has its own buffer and its own parameter records, so a client
//! that disconnects inside a record, floods garbage or stops reading affects only
//! itself: its partial record is dropped and counted, and a full outgoing queue
//! closes it without ever blocking the hub or another client.
//!
//! Input limits, per connection: records beyond a token bucket of `record_burst`
//! refilled at `max_records_per_s` are dropped and counted (`rate_limited`), the
//! connection stays; a record left incomplete for `partial_record_timeout_s`
//! (slow-loris) closes the connection.

use std::fmt;
use std::net::SocketAddr;
use std::time::Duration;

use bytes::BytesMut;
use gc_proto::{Record, RecordCodec, RECORD_LEN};
use skymesh_runtime::backend::BackendWait;
use skymesh_runtime::{IpcError, TokenBucket};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_util::codec::Decoder;
use tokio_util::sync::CancellationToken;

use crate::drops::Drops;
use crate::inbound::{self, Inbound, RefuseReason, Verdict};
use crate::ipc::Commands;
use crate::metrics::DisconnectReason;

/// Bytes asked of the socket per read.
const READ_CHUNK: usize = 4096;
/// Records are written in batches of up to this many bytes.
const WRITE_BATCH: usize = 64 * 1024;

/// How a session ended.
#[derive(Debug)]
pub enum End {
    /// The client closed the connection between records.
    Closed,
    /// The client closed it with this many bytes of a record buffered.
    Truncated(usize),
    /// The client stopped reading: its outgoing queue filled.
    Overflow,
    /// A record stayed incomplete for `partial_record_timeout` (this many bytes of
    /// it had arrived): a slow-loris client.
    Stalled(usize),
    /// The hub closed it (shutdown, or the hub found the queue full).
    Cancelled,
    Io(std::io::Error),
    /// The bus failed: fatal for the service.
    Bus(IpcError),
}

impl End {
    /// The `reason` label of the disconnect (`None` for a bus failure).
    pub fn reason(&self) -> DisconnectReason {
        match self {
            End::Closed => DisconnectReason::Closed,
            End::Truncated(_) => DisconnectReason::Truncated,
            End::Overflow => DisconnectReason::Overflow,
            End::Stalled(_) => DisconnectReason::PartialRecordTimeout,
            End::Cancelled => DisconnectReason::Shutdown,
            End::Io(_) | End::Bus(_) => DisconnectReason::Io,
        }
    }
}

impl fmt::Display for End {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            End::Closed => f.write_str("closed by the client"),
            End::Truncated(n) => write!(
                f,
                "closed by the client inside a record ({n} of {RECORD_LEN} bytes dropped)"
            ),
            End::Overflow => f.write_str("outgoing queue full: the client stopped reading"),
            End::Stalled(n) => write!(
                f,
                "a record stayed incomplete for partial_record_timeout_s ({n} of {RECORD_LEN} bytes)"
            ),
            End::Cancelled => f.write_str("closed by the gateway"),
            End::Io(e) => write!(f, "connection error: {e}"),
            End::Bus(e) => write!(f, "bus error: {e}"),
        }
    }
}

/// What a session needs besides its socket.
#[derive(Debug, Clone)]
pub struct SessionCtx {
    /// The connection id carried in every `SwarmCommand` (`client`).
    pub client: u16,
    pub peer: SocketAddr,
    pub privileged: bool,
    pub commands: Commands,
    pub drops: Drops,
    /// The session's own outgoing queue (PING_RESPONSE goes straight back).
    pub replies: mpsc::Sender<Record>,
    pub limits: Limits,
}

/// The per-connection input limits (from [`crate::Settings`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub max_records_per_s: u32,
    pub record_burst: u32,
    pub partial_record_timeout: Duration,
    /// How long a command waits for the swarm queue to read the bus.
    pub backend_wait: Duration,
}

impl Limits {
    pub fn of(settings: &crate::Settings) -> Limits {
        Limits {
            max_records_per_s: settings.max_records_per_s,
            record_burst: settings.record_burst,
            partial_record_timeout: settings.partial_record_timeout,
            backend_wait: settings.backend_wait,
        }
    }
}

/// Serves one connection until the client leaves, its input or reading forces a
/// close, or `cancel`.
pub async fn run(
    stream: TcpStream,
    ctx: SessionCtx,
    outgoing: mpsc::Receiver<Record>,
    cancel: CancellationToken,
) -> End {
    let (read, write) = stream.into_split();
    tokio::select! {
        _ = cancel.cancelled() => End::Cancelled,
        end = read_loop(read, &ctx) => end,
        end = write_loop(write, outgoing, &ctx) => end,
    }
}

async fn read_loop(mut read: OwnedReadHalf, ctx: &SessionCtx) -> End {
    let mut inbound = Inbound::new(ctx.client, ctx.privileged);
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::with_capacity(READ_CHUNK);
    let limits = ctx.limits;
    let mut rate = TokenBucket::new(
        limits.max_records_per_s,
        limits.record_burst,
        Instant::now().into_std(),
    );
    // When the first byte of the incomplete record in `buf` arrived.
    let mut partial_since: Option<Instant> = None;
    let mut backend = BackendWait::default();
    loop {
        let mut consumed = false;
        loop {
            let record = match codec.decode(&mut buf) {
                Ok(Some(r)) => r,
                Ok(None) => break,
                Err(e) => return End::Io(std::io::Error::other(e)),
            };
            consumed = true;
            if !rate.take(Instant::now().into_std()) {
                ctx.drops.metrics().record_in(record.kind);
                ctx.drops.refused(
                    RefuseReason::RateLimited,
                    ctx.client,
                    ctx.peer,
                    &format_args!(
                        "more than {} records per second (burst {}); dropped",
                        limits.max_records_per_s, limits.record_burst
                    ),
                );
                if let Some(end) = inbound::refusal_reply(&record).and_then(|r| reply(ctx, r)) {
                    return end;
                }
                continue;
            }
            if let Some(end) = handle(&mut inbound, &mut backend, &record, ctx).await {
                return end;
            }
        }
        // The bytes left over started arriving in the last read, at the latest.
        if buf.is_empty() {
            partial_since = None;
        } else if consumed || partial_since.is_none() {
            partial_since = Some(Instant::now());
        }
        buf.reserve(READ_CHUNK);
        let read = match partial_since {
            None => read.read_buf(&mut buf).await,
            Some(since) => {
                let deadline = since + limits.partial_record_timeout;
                match tokio::time::timeout_at(deadline, read.read_buf(&mut buf)).await {
                    Ok(r) => r,
                    Err(_) => {
                        ctx.drops.stalled(ctx.client, ctx.peer, buf.len());
                        return End::Stalled(buf.len());
                    }
                }
            }
        };
        match read {
            Ok(0) if buf.is_empty() => return End::Closed,
            Ok(0) => return End::Truncated(buf.len()),
            Ok(_) => {}
            Err(e) => return End::Io(e),
        }
    }
}

/// Acts on one record; `Some` ends the session.
///
/// A command sent while no swarm queue reads the bus (after `backend_wait`) is
/// answered ACK_CMD_TIMEOUT for its drone and type, as the queue answers one it
/// could not deliver: the client is never left without an answer.
async fn handle(
    inbound: &mut Inbound,
    backend: &mut BackendWait,
    record: &Record,
    ctx: &SessionCtx,
) -> Option<End> {
    let metrics = ctx.drops.metrics();
    metrics.record_in(record.kind);
    match inbound.on_record(record) {
        Verdict::Reply(record) => reply(ctx, record),
        Verdict::Publish(_)
            if !backend
                .present(ctx.limits.backend_wait, || ctx.commands.queue_reads())
                .await =>
        {
            ctx.drops.refused(
                RefuseReason::BackendMissing,
                ctx.client,
                ctx.peer,
                &format_args!(
                    "no swarm queue reads the bus after waiting {} ms; answered ACK_CMD_TIMEOUT",
                    ctx.limits.backend_wait.as_millis()
                ),
            );
            reply(ctx, Record::ack(false, record.context, record.kind))
        }
        Verdict::Publish(cmd) => match ctx.commands.publish(*cmd) {
            Ok(request_id) => {
                metrics.commands_published.inc();
                tracing::debug!(
                    client = ctx.client,
                    request_id,
                    drone = cmd.drone,
                    kind = cmd.kind().map_or("?", |k| k.as_str()),
                    "swarm command published"
                );
                None
            }
            Err(e) => Some(End::Bus(e)),
        },
        Verdict::Stored | Verdict::Ignored => None,
        Verdict::Refused(r) => {
            ctx.drops.refused(r.reason, ctx.client, ctx.peer, &r.detail);
            r.reply.and_then(|record| reply(ctx, record))
        }
    }
}

/// Queues `record` for the client; `Some` ends the session.
fn reply(ctx: &SessionCtx, record: Record) -> Option<End> {
    match ctx.replies.try_send(record) {
        Ok(()) => None,
        Err(mpsc::error::TrySendError::Full(_)) => Some(End::Overflow),
        Err(mpsc::error::TrySendError::Closed(_)) => Some(End::Cancelled),
    }
}

async fn write_loop(
    mut write: OwnedWriteHalf,
    mut outgoing: mpsc::Receiver<Record>,
    ctx: &SessionCtx,
) -> End {
    let metrics = ctx.drops.metrics();
    let mut batch: Vec<u8> = Vec::with_capacity(WRITE_BATCH);
    let mut kinds: Vec<i32> = Vec::new();
    while let Some(first) = outgoing.recv().await {
        batch.clear();
        kinds.clear();
        batch.extend_from_slice(&first.encode());
        kinds.push(first.kind);
        while batch.len() < WRITE_BATCH {
            match outgoing.try_recv() {
                Ok(next) => {
                    batch.extend_from_slice(&next.encode());
                    kinds.push(next.kind);
                }
                Err(_) => break,
            }
        }
        if let Err(e) = write.write_all(&batch).await {
            return End::Io(e);
        }
        for k in &kinds {
            metrics.record_out(*k);
        }
    }
    End::Cancelled
}
