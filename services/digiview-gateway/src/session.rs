//! One DigiView connection: a reader that cuts 88-byte frames, runs each through
//! [`crate::handler`], sends SETs (translated) and CAM_OFFSET questions to the
//! pipeline and keeps the client's periodic GETs; and a writer that drains the
//! connection's bounded outgoing queue.
//!
//! A client affects only itself: its partial frame, its rate limit, its periodic
//! GETs and its outgoing queue are its own. While one of its SETs or CAM_OFFSET GETs
//! waits for the pipeline (at most `set_timeout`), its further frames wait in the
//! socket (replies stay in request order) but its periodic replies go on; a periodic
//! CAM_OFFSET asks again only once its last question is answered. Other clients
//! never wait.
//!
//! Frames have no sync word, so after garbage that is not a multiple of 88 bytes
//! every later frame is cut at the wrong place and fails its checksum: the client
//! gets CHECKSUM_ERROR for each until it reconnects (as with DigiView itself).

use std::collections::BTreeMap;
use std::fmt;
use std::future::Future;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use bytes::BytesMut;
use digiview_proto::{Frame, FrameCodec, MessageType, Param, ParamType, FRAME_LEN};
use skymesh_ipc_types::{ViewControl, ViewReply, VisionResult};
use skymesh_runtime::TokenBucket;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::time::Instant;
use tokio_util::codec::Decoder;
use tokio_util::sync::CancellationToken;

use crate::config::Settings;
use crate::drops::Drops;
use crate::handler::{self, Answered, Ask, Handled, Periodic, Rules, Step};
use crate::ipc::{BusHandle, CallError};
use crate::metrics::DisconnectReason;
use crate::refusal::Refusal;
use crate::reply::{set_reply_type, Reply};
use crate::translate;

/// Bytes asked of the socket per read.
const READ_CHUNK: usize = 4096;
/// Replies are written in batches of up to this many bytes.
const WRITE_BATCH: usize = 64 * FRAME_LEN;

/// How a session ended.
#[derive(Debug)]
pub enum End {
    /// The client closed the connection between frames.
    Closed,
    /// The client closed it with this many bytes of a frame buffered.
    Truncated(usize),
    /// The client sent QUIT.
    Quit,
    /// A frame begun was not completed in time.
    PartialFrameTimeout(Duration),
    /// The client stopped reading: its outgoing queue filled.
    Overflow,
    /// The gateway closed it (shutdown).
    Cancelled,
    Io(std::io::Error),
}

impl End {
    pub fn reason(&self) -> DisconnectReason {
        match self {
            End::Closed => DisconnectReason::Closed,
            End::Truncated(_) => DisconnectReason::Truncated,
            End::Quit => DisconnectReason::Quit,
            End::PartialFrameTimeout(_) => DisconnectReason::PartialFrameTimeout,
            End::Overflow => DisconnectReason::Overflow,
            End::Cancelled => DisconnectReason::Shutdown,
            End::Io(_) => DisconnectReason::Io,
        }
    }
}

impl fmt::Display for End {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            End::Closed => f.write_str("closed by the client"),
            End::Truncated(n) => write!(
                f,
                "closed by the client inside a frame ({n} of {FRAME_LEN} bytes dropped)"
            ),
            End::Quit => f.write_str("the client sent QUIT"),
            End::PartialFrameTimeout(t) => {
                write!(f, "a frame begun was not completed within {t:?}")
            }
            End::Overflow => f.write_str("outgoing queue full: the client stopped reading"),
            End::Cancelled => f.write_str("closed by the gateway"),
            End::Io(e) => write!(f, "connection error: {e}"),
        }
    }
}

/// What a session needs besides its socket.
#[derive(Debug, Clone)]
pub struct SessionCtx {
    /// Connection number, for logs.
    pub client: u64,
    pub peer: SocketAddr,
    pub rules: Rules,
    pub settings: Arc<Settings>,
    pub bus: BusHandle,
    pub drops: Drops,
}

/// Serves one connection until the client leaves, its input forces a close, or
/// `cancel`.
pub async fn run(stream: TcpStream, ctx: SessionCtx, cancel: CancellationToken) -> End {
    let (read, write) = stream.into_split();
    let (tx, rx) = mpsc::channel(ctx.settings.outgoing_queue);
    let mut reader = Reader::new(&ctx, tx);
    let end = tokio::select! {
        _ = cancel.cancelled() => End::Cancelled,
        end = reader.run(read) => end,
        end = write_loop(write, rx, &ctx) => end,
    };
    ctx.drops.periodic_changed(-(reader.periodic.len() as i64));
    end
}

/// One periodic GET: the request and when it is next answered.
#[derive(Debug)]
struct PeriodicGet {
    frame: Frame,
    next: Instant,
}

/// What woke the reader.
enum Event {
    Read(std::io::Result<usize>),
    Done(Box<Outcome>),
    PeriodicAsked(Box<Asked>),
    Tick,
    PartialTimeout,
}

/// The pipeline's answer to a question (or why none came).
type Asked = (Ask, Result<ViewReply, CallError>);

/// A request the reader waited for.
enum Outcome {
    Set(Box<(Frame, Result<ViewReply, CallError>, Duration)>),
    Ask(Box<Asked>),
}

type Pending = Pin<Box<dyn Future<Output = Outcome> + Send>>;

type PendingAsk = Pin<Box<dyn Future<Output = Asked> + Send>>;

struct Reader<'a> {
    ctx: &'a SessionCtx,
    tx: mpsc::Sender<Reply>,
    codec: FrameCodec,
    buf: BytesMut,
    /// `max_frames_per_s`, bursts of as many.
    rate: TokenBucket,
    /// By parameter type: a new periodic GET of a type replaces the old one.
    periodic: BTreeMap<ParamType, PeriodicGet>,
    /// The SET or GET waiting for the pipeline; no further frame is read meanwhile.
    pending: Option<Pending>,
    /// A periodic GET's question in flight (frames are read meanwhile).
    periodic_ask: Option<PendingAsk>,
    /// When the partial frame in `buf` was begun.
    partial_since: Option<Instant>,
}

impl<'a> Reader<'a> {
    fn new(ctx: &'a SessionCtx, tx: mpsc::Sender<Reply>) -> Self {
        Reader {
            ctx,
            tx,
            codec: FrameCodec::new(),
            buf: BytesMut::with_capacity(READ_CHUNK),
            rate: TokenBucket::new(
                ctx.settings.max_frames_per_s,
                ctx.settings.max_frames_per_s,
                Instant::now().into_std(),
            ),
            periodic: BTreeMap::new(),
            pending: None,
            periodic_ask: None,
            partial_since: None,
        }
    }

    async fn run(&mut self, mut read: OwnedReadHalf) -> End {
        let partial_timeout = self.ctx.settings.partial_frame_timeout;
        loop {
            if let Err(end) = self.drain() {
                return end;
            }
            let next_tick = self.periodic.values().map(|p| p.next).min();
            let partial_deadline = self
                .partial_since
                .filter(|_| self.pending.is_none())
                .map(|t| t + partial_timeout);
            let event = {
                let reading = self.pending.is_none();
                let buf = &mut self.buf;
                let pending = &mut self.pending;
                let asking = self.periodic_ask.is_some();
                let periodic_ask = &mut self.periodic_ask;
                tokio::select! {
                    r = read.read_buf(buf), if reading => Event::Read(r),
                    done = async { Box::new(pending.as_mut().expect("guarded").await) }, if !reading => {
                        Event::Done(done)
                    }
                    asked = async { Box::new(periodic_ask.as_mut().expect("guarded").await) }, if asking => {
                        Event::PeriodicAsked(asked)
                    }
                    _ = tokio::time::sleep_until(next_tick.unwrap_or_else(Instant::now)), if next_tick.is_some() => {
                        Event::Tick
                    }
                    _ = tokio::time::sleep_until(partial_deadline.unwrap_or_else(Instant::now)), if partial_deadline.is_some() => {
                        Event::PartialTimeout
                    }
                }
            };
            let step = match event {
                Event::Read(Ok(0)) if self.buf.is_empty() => Err(End::Closed),
                Event::Read(Ok(0)) => Err(End::Truncated(self.buf.len())),
                Event::Read(Ok(_)) => Ok(()),
                Event::Read(Err(e)) => Err(End::Io(e)),
                Event::Done(done) => {
                    self.pending = None;
                    match *done {
                        Outcome::Set(set) => {
                            let (frame, result, took) = *set;
                            self.set_done(&frame, result, took)
                        }
                        Outcome::Ask(asked) => {
                            let (ask, result) = *asked;
                            self.asked(&ask, result)
                        }
                    }
                }
                Event::PeriodicAsked(asked) => {
                    self.periodic_ask = None;
                    let (ask, result) = *asked;
                    self.asked(&ask, result)
                }
                Event::Tick => self.tick(),
                Event::PartialTimeout => {
                    self.ctx.drops.refused(
                        Refusal::PartialFrameTimeout,
                        self.ctx.client,
                        self.ctx.peer,
                        &format_args!(
                            "{} bytes of a frame for {partial_timeout:?}",
                            self.buf.len()
                        ),
                    );
                    Err(End::PartialFrameTimeout(partial_timeout))
                }
            };
            if let Err(end) = step {
                return end;
            }
        }
    }

    /// Handles every whole frame buffered, unless a SET is pending.
    fn drain(&mut self) -> Result<(), End> {
        let mut consumed = false;
        while self.pending.is_none() {
            let item = match self.codec.decode(&mut self.buf) {
                Ok(Some(item)) => item,
                // `decode` only ever asks for more bytes.
                Ok(None) | Err(_) => break,
            };
            consumed = true;
            let metrics = self.ctx.drops.metrics();
            metrics.frame_in(item.as_ref().ok().map(|f| f.message_type));
            if !self.rate.take(Instant::now().into_std()) {
                self.ctx.drops.refused(
                    Refusal::RateLimited,
                    self.ctx.client,
                    self.ctx.peer,
                    &format_args!(
                        "more than {} frames per second; dropped unanswered",
                        self.ctx.settings.max_frames_per_s
                    ),
                );
                continue;
            }
            let latest = self.ctx.bus.fresh_state(self.ctx.settings.state_timeout);
            let handled =
                handler::handle(item, &self.ctx.rules, latest.as_deref().map(|l| &*l.state));
            self.apply(handled)?;
        }
        if self.buf.is_empty() {
            self.partial_since = None;
        } else if consumed || self.partial_since.is_none() {
            self.partial_since = Some(Instant::now());
        }
        Ok(())
    }

    fn apply(&mut self, handled: Handled) -> Result<(), End> {
        let Handled { step, refusal } = handled;
        if let Some(r) = refusal {
            self.ctx
                .drops
                .refused(r.reason, self.ctx.client, self.ctx.peer, &r.detail);
        }
        match step {
            Step::Reply(replies) => self.send_all(replies),
            Step::Get {
                replies,
                periodic,
                ask,
            } => {
                self.send_all(replies)?;
                self.change_periodic(periodic);
                if let Some(ask) = ask {
                    let asking = self.ask(*ask);
                    self.pending = Some(Box::pin(
                        async move { Outcome::Ask(Box::new(asking.await)) },
                    ));
                }
                Ok(())
            }
            Step::Set(frame) => {
                // The handler forwards only SETs that decode and validate.
                let Some(control) = Param::decode(frame.param_type, &frame.data)
                    .ok()
                    .and_then(|p| translate::set_control(&p))
                else {
                    self.ctx.drops.refused(
                        Refusal::BadPayload,
                        self.ctx.client,
                        self.ctx.peer,
                        &format_args!(
                            "SET {}: no pipeline request for it",
                            frame.param_type.name()
                        ),
                    );
                    return self.send_all(vec![Reply::bare(
                        Refusal::BadPayload.reply_type(),
                        frame.timestamp,
                        frame.param_type as u8,
                    )]);
                };
                let asking = self.call(control);
                self.pending = Some(Box::pin(async move {
                    let started = Instant::now();
                    let r = asking.await;
                    Outcome::Set(Box::new((frame, r, started.elapsed())))
                }));
                Ok(())
            }
            Step::Quit => Err(End::Quit),
        }
    }

    /// Sends `control` to the pipeline; the answer within `set_timeout`.
    fn call(
        &self,
        control: ViewControl,
    ) -> impl Future<Output = Result<ViewReply, CallError>> + Send + 'static {
        let bus = self.ctx.bus.clone();
        let timeout = self.ctx.settings.set_timeout;
        async move { bus.call(control, timeout).await }
    }

    /// Asks the pipeline a GET's question.
    fn ask(&self, ask: Ask) -> impl Future<Output = Asked> + Send + 'static {
        let asking = self.call(ask.control());
        async move { (ask, asking.await) }
    }

    /// Replies to a GET the pipeline answered.
    fn asked(&self, ask: &Ask, result: Result<ViewReply, CallError>) -> Result<(), End> {
        let (replies, refusal) = ask.answer(result);
        if let Some(r) = refusal {
            self.ctx
                .drops
                .refused(r.reason, self.ctx.client, self.ctx.peer, &r.detail);
        }
        self.send_all(replies)
    }

    fn change_periodic(&mut self, change: Periodic) {
        let before = self.periodic.len() as i64;
        match change {
            Periodic::Unchanged => {}
            Periodic::Cancel(pt) => {
                self.periodic.remove(&pt);
            }
            Periodic::Start(frame) => {
                let next = Instant::now() + interval(&frame);
                self.periodic
                    .insert(frame.param_type, PeriodicGet { frame, next });
            }
        }
        self.ctx
            .drops
            .periodic_changed(self.periodic.len() as i64 - before);
    }

    /// Answers every periodic GET that is due.
    fn tick(&mut self) -> Result<(), End> {
        let now = Instant::now();
        let latest = self.ctx.bus.fresh_state(self.ctx.settings.state_timeout);
        let state = latest.as_deref().map(|l| &*l.state);
        let mut out = Vec::new();
        let mut question = None;
        for p in self.periodic.values_mut().filter(|p| p.next <= now) {
            let Answered {
                replies,
                refusal,
                ask,
            } = handler::answer(&p.frame, state, self.ctx.rules.roi_rel_frame);
            if let Some(r) = refusal {
                self.ctx
                    .drops
                    .refused(r.reason, self.ctx.client, self.ctx.peer, &r.detail);
            }
            out.extend(replies);
            question = question.or(ask);
            // Late ticks are not caught up in a burst.
            p.next = (p.next + interval(&p.frame)).max(now);
        }
        // One question at a time: a tick while the last is unanswered is skipped.
        if let Some(ask) = question.filter(|_| self.periodic_ask.is_none()) {
            self.periodic_ask = Some(Box::pin(self.ask(*ask)));
        }
        self.send_all(out)
    }

    fn set_done(
        &mut self,
        frame: &Frame,
        result: Result<ViewReply, CallError>,
        took: Duration,
    ) -> Result<(), End> {
        let metrics = self.ctx.drops.metrics();
        let (ctx, pt) = (self.ctx, frame.param_type);
        let outcome = match result {
            Ok(reply) => {
                metrics.pipeline_reply.observe(took.as_secs_f64());
                let r = reply.result();
                metrics.set_result(r.as_str());
                let message = reply.message.as_str();
                match r {
                    VisionResult::Applied => tracing::debug!(
                        peer = %ctx.peer, client = ctx.client, param = pt.name(), message,
                        "DigiView SET applied by the vision pipeline"
                    ),
                    VisionResult::Unsupported => ctx.drops.refused(
                        Refusal::PipelineUnsupported,
                        ctx.client,
                        ctx.peer,
                        &format_args!("SET {}: {message}", pt.name()),
                    ),
                    _ => ctx.drops.refused(
                        Refusal::PipelineRefused,
                        ctx.client,
                        ctx.peer,
                        &format_args!("SET {} {}: {message}", pt.name(), r.as_str()),
                    ),
                }
                Some(r)
            }
            Err(e) => {
                metrics.set_result("timeout");
                ctx.drops.refused(
                    Refusal::PipelineTimeout,
                    ctx.client,
                    ctx.peer,
                    &format_args!("SET {}: {e}", pt.name()),
                );
                None
            }
        };
        self.send_all(vec![Reply::bare(
            set_reply_type(outcome),
            frame.timestamp,
            pt as u8,
        )])
    }

    fn send_all(&self, replies: Vec<Reply>) -> Result<(), End> {
        for r in replies {
            match self.tx.try_send(r) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(_)) => return Err(End::Overflow),
                // The writer has ended; its own end is reported.
                Err(mpsc::error::TrySendError::Closed(_)) => return Err(End::Cancelled),
            }
        }
        Ok(())
    }
}

fn interval(frame: &Frame) -> Duration {
    Duration::from_millis(u64::from(frame.interval_ms))
}

async fn write_loop(
    mut write: OwnedWriteHalf,
    mut outgoing: mpsc::Receiver<Reply>,
    ctx: &SessionCtx,
) -> End {
    let metrics = ctx.drops.metrics();
    let mut batch: Vec<u8> = Vec::with_capacity(WRITE_BATCH);
    let mut kinds: Vec<MessageType> = Vec::new();
    while let Some(first) = outgoing.recv().await {
        batch.clear();
        kinds.clear();
        batch.extend_from_slice(&first.encode());
        kinds.push(first.message_type);
        while batch.len() < WRITE_BATCH {
            match outgoing.try_recv() {
                Ok(next) => {
                    batch.extend_from_slice(&next.encode());
                    kinds.push(next.message_type);
                }
                Err(_) => break,
            }
        }
        if let Err(e) = write.write_all(&batch).await {
            return End::Io(e);
        }
        for k in &kinds {
            metrics.reply(*k);
        }
    }
    End::Cancelled
}
