//! What the writer thread of a connection sends: our own messages, queued
//! through [`LinkWriter`], before the frames the router forwards, each kind
//! bounded on its own.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

use mavlink::dialects::ardupilotmega::MavMessage;

use mavlink_frame::RawFrame;

use super::{WriteError, FORWARD_QUEUE, WRITE_QUEUE};

/// Queues messages for the writer thread of one connection.
///
/// Held by the service from `Connected` until `Disconnected`; the writer thread
/// drains the [`Outbox`] behind it and writes with our header (system id,
/// component 191).
#[derive(Debug, Clone)]
pub struct LinkWriter {
    pub(super) outbox: Arc<Outbox>,
}

impl LinkWriter {
    /// Queues `msg` without waiting.
    pub fn send(&self, msg: MavMessage) -> Result<(), WriteError> {
        self.outbox.send(msg)
    }
}

/// What the writer thread writes next.
#[allow(clippy::large_enum_variant)] // moved once per write, never stored in bulk
#[derive(Debug)]
pub(super) enum Outgoing {
    Own(MavMessage),
    Forwarded(RawFrame),
}

#[derive(Debug, Default)]
struct OutboxState {
    own: VecDeque<MavMessage>,
    forwarded: VecDeque<RawFrame>,
    closed: bool,
}

/// The writer thread's two bounded queues: our own messages ([`WRITE_QUEUE`],
/// written first) and frames forwarded from router endpoints ([`FORWARD_QUEUE`]).
/// Filled by the service (through [`LinkWriter`]) and the router [`Hub`]; drained
/// by the connection's writer thread; closed when that thread ends.
#[derive(Debug, Default)]
pub struct Outbox {
    state: Mutex<OutboxState>,
    ready: Condvar,
}

impl Outbox {
    fn lock(&self) -> MutexGuard<'_, OutboxState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub(super) fn send(&self, msg: MavMessage) -> Result<(), WriteError> {
        let mut s = self.lock();
        if s.closed {
            return Err(WriteError::Closed);
        }
        if s.own.len() >= WRITE_QUEUE {
            return Err(WriteError::Congested);
        }
        s.own.push_back(msg);
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
    /// No timeout: every way a connection ends closes the outbox ([`StopGuard`],
    /// the writer's own end), which wakes this wait, so an idle link costs the
    /// writer thread no periodic wake-ups.
    pub(super) fn next(&self) -> Option<Outgoing> {
        let mut s = self.lock();
        loop {
            if s.closed {
                return None;
            }
            if let Some(m) = s.own.pop_front() {
                return Some(Outgoing::Own(m));
            }
            if let Some(f) = s.forwarded.pop_front() {
                return Some(Outgoing::Forwarded(f));
            }
            s = self.ready.wait(s).unwrap_or_else(PoisonError::into_inner);
        }
    }

    pub(super) fn close(&self) {
        let mut s = self.lock();
        s.closed = true;
        s.own.clear();
        s.forwarded.clear();
        self.ready.notify_all();
    }
}
