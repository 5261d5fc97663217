//! What a connection sends: our own messages, queued through [`LinkWriter`], before
//! the frames the router forwards, each kind bounded on its own.
//!
//! On a socket, our own message is written at once by the task that sends it
//! (`MSG_DONTWAIT`, [`DirectWriter`]) when nothing is queued or being written:
//! a command leaves in the same wake-up that decided it, without handing it to the
//! writer thread and waiting for that thread to be scheduled. What the socket does
//! not take at once (a full send buffer), everything behind a queue, and every
//! write on a serial port go through the writer thread, in order.

use std::collections::VecDeque;
use std::io;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MavHeader, Message};

use mavlink_frame::RawFrame;

use crate::hub::Hub;
use crate::metrics::Metrics;
use crate::router::AckLedger;
use crate::transport::DirectWriter;

use super::io_loops::lock_ledger;
use super::{WriteError, FORWARD_QUEUE, WRITE_QUEUE};

/// Queues messages for one connection, or writes them at once (see the module doc).
///
/// Held by the service from `Connected` until `Disconnected`; everything it sends
/// carries our header (system id, component 191) and the connection's sequence.
#[derive(Debug, Clone)]
pub struct LinkWriter {
    pub(super) outbox: Arc<Outbox>,
    pub(super) ctx: Arc<SendContext>,
}

impl LinkWriter {
    /// Writes `msg` now if the socket takes it, else queues it; never waits.
    pub fn send(&self, msg: MavMessage) -> Result<(), WriteError> {
        self.outbox.send(msg, &self.ctx)
    }
}

/// What sending one of our messages records besides the bytes: shared by the
/// direct path and the writer thread.
#[derive(Debug)]
pub(super) struct SendContext {
    /// Our system and component (the sequence comes from the [`Outbox`]).
    pub(super) header: MavHeader,
    pub(super) ledger: Arc<Mutex<AckLedger>>,
    pub(super) metrics: Metrics,
    pub(super) hub: Arc<Hub>,
}

impl SendContext {
    /// Serialises `msg` with sequence `sequence` and records a command in the ack
    /// ledger (before writing: the answer may come back at once).
    pub(super) fn encode(&self, msg: &MavMessage, sequence: u8) -> RawFrame {
        let header = MavHeader {
            sequence,
            ..self.header
        };
        let frame = RawFrame::encode(header, msg);
        if let Some(command) = frame.command() {
            lock_ledger(&self.ledger).sent(command, true, Instant::now());
        }
        frame
    }

    /// Counts a message written, shows our HEARTBEAT to the endpoints (and the
    /// flight log), and puts every other frame of ours in the flight log.
    pub(super) fn written(&self, name: &'static str, frame: &RawFrame) {
        self.metrics.sent(name);
        if frame.message_id() == HEARTBEAT_ID {
            self.hub.from_local(frame);
        } else {
            self.hub.own_written(frame);
        }
    }
}

/// HEARTBEAT's message id.
const HEARTBEAT_ID: u32 = 0;

/// What the writer thread writes next.
#[allow(clippy::large_enum_variant)] // moved once per write, never stored in bulk
#[derive(Debug)]
pub(super) enum Outgoing {
    /// Our message, with the sequence it goes out with.
    Own(MavMessage, u8),
    /// Our message already serialised, `written` bytes of it on the wire (the
    /// direct write's remainder).
    Rest(Pending),
    Forwarded(RawFrame),
}

/// One of our frames the direct write could not finish.
#[derive(Debug, Clone, Copy)]
pub(super) struct Pending {
    pub(super) frame: RawFrame,
    pub(super) written: usize,
    pub(super) name: &'static str,
}

#[derive(Debug, Default)]
struct OutboxState {
    /// Written before anything else: it follows bytes already on the wire.
    rest: Option<Pending>,
    own: VecDeque<MavMessage>,
    forwarded: VecDeque<RawFrame>,
    /// The sequence of our next message.
    sequence: u8,
    /// The writer thread holds something it took and has not finished writing.
    writing: bool,
    /// The socket for direct writes (`None` on a serial port and once closed).
    direct: Option<DirectWriter>,
    closed: bool,
}

impl OutboxState {
    fn next_sequence(&mut self) -> u8 {
        let s = self.sequence;
        self.sequence = s.wrapping_add(1);
        s
    }

    /// Nothing is queued or being written: a frame written now is next on the wire.
    fn idle(&self) -> bool {
        !self.writing && self.rest.is_none() && self.own.is_empty() && self.forwarded.is_empty()
    }
}

/// The writer thread's two bounded queues: our own messages ([`WRITE_QUEUE`],
/// written first) and frames forwarded from router endpoints ([`FORWARD_QUEUE`]),
/// plus the socket for direct writes. Filled by the service (through
/// [`LinkWriter`]) and the router [`Hub`]; drained by the connection's writer
/// thread; closed when the connection ends.
#[derive(Debug, Default)]
pub struct Outbox {
    state: Mutex<OutboxState>,
    ready: Condvar,
}

impl Outbox {
    /// An outbox whose own messages are written directly to `direct` when idle.
    pub(super) fn with_direct(direct: Option<DirectWriter>) -> Outbox {
        Outbox {
            state: Mutex::new(OutboxState {
                direct,
                ..OutboxState::default()
            }),
            ready: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, OutboxState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub(super) fn send(&self, msg: MavMessage, ctx: &SendContext) -> Result<(), WriteError> {
        let mut s = self.lock();
        if s.closed {
            return Err(WriteError::Closed);
        }
        if !s.idle() || s.direct.is_none() {
            if s.own.len() >= WRITE_QUEUE {
                return Err(WriteError::Congested);
            }
            s.own.push_back(msg);
            self.ready.notify_one();
            return Ok(());
        }
        // Idle: this frame is next on the wire. Written under the lock, so neither
        // the writer thread nor a forwarded frame can come between its bytes.
        let sequence = s.next_sequence();
        let frame = ctx.encode(&msg, sequence);
        let name = msg.message_name();
        let bytes = frame.as_bytes();
        let written = match s.direct.as_ref().map(|d| d.try_write(bytes)) {
            Some(Ok(n)) => n,
            Some(Err(e)) if e.kind() == io::ErrorKind::WouldBlock => 0,
            // A failed socket: the writer thread tries the same frame, fails the
            // same way and ends the connection, as for any write of its own.
            Some(Err(_)) | None => 0,
        };
        if written >= bytes.len() {
            drop(s);
            ctx.written(name, &frame);
            return Ok(());
        }
        s.rest = Some(Pending {
            frame,
            written,
            name,
        });
        self.ready.notify_one();
        Ok(())
    }

    /// Queues a frame from a router endpoint without waiting.
    pub fn forward(&self, frame: &RawFrame) -> Result<(), WriteError> {
        let mut s = self.lock();
        if s.closed {
            return Err(WriteError::Closed);
        }
        if s.forwarded.len() >= FORWARD_QUEUE {
            return Err(WriteError::Congested);
        }
        s.forwarded.push_back(*frame);
        self.ready.notify_one();
        Ok(())
    }

    /// The next thing to write, waiting as long as it takes; `None` once closed.
    /// Calling it again says the last one was written. No timeout: every way a
    /// connection ends closes the outbox ([`StopGuard`](super::StopGuard), the
    /// writer's own end), which wakes this wait, so an idle link costs the writer
    /// thread no periodic wake-ups.
    pub(super) fn next(&self) -> Option<Outgoing> {
        let mut s = self.lock();
        s.writing = false;
        loop {
            if s.closed {
                return None;
            }
            let next = if let Some(p) = s.rest.take() {
                Some(Outgoing::Rest(p))
            } else if let Some(m) = s.own.pop_front() {
                let sequence = s.next_sequence();
                Some(Outgoing::Own(m, sequence))
            } else {
                s.forwarded.pop_front().map(Outgoing::Forwarded)
            };
            if let Some(next) = next {
                s.writing = true;
                return Some(next);
            }
            s = self.ready.wait(s).unwrap_or_else(PoisonError::into_inner);
        }
    }

    pub(super) fn close(&self) {
        let mut s = self.lock();
        s.closed = true;
        s.rest = None;
        s.own.clear();
        s.forwarded.clear();
        // The service may hold its writer a while longer: the socket must not
        // stay open through it.
        s.direct = None;
        self.ready.notify_all();
    }
}
