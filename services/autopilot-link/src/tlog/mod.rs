//! Flight logs: a MAVLink telemetry log (`.tlog`, [`format`]) of the autopilot
//! link, per arming or per connection (`[tlog]`, off unless configured).
//!
//! Recorded: every frame read from the autopilot (whether or not it is routed or
//! used) and every frame written to it (our own messages and what the router
//! forwards from endpoints), in the order the link saw them, as MAVProxy records
//! its master link. Frames between endpoints and the virtual gimbals' traffic
//! never touch the autopilot link and are not recorded.
//!
//! The link's threads only ever call the [`Tap`]: a timestamp and a `try_send`
//! into a bounded queue (and, in `arming` mode, two byte reads of each autopilot
//! HEARTBEAT). A [`writer`] thread drains it, writes, rotates and deletes old logs.
//! A full queue drops the frame (counted in
//! `skymesh_autopilot_tlog_dropped_frames_total`, one warning per recording); an
//! I/O error (disk full, directory gone) is logged and counted and ends that
//! recording, never the link; the next arming or connection tries again.
//!
//! | file | holds |
//! |---|---|
//! | `mod.rs` | [`TlogSettings`], the [`Tap`] on the link, [`start`] |
//! | `format.rs` | records, file names, cutting a torn last record (pure) |
//! | `retention.rs` | which old logs to delete (pure plan + the deleting) |
//! | `writer.rs` | the writer thread: sessions → files, flush, rotation, close |

pub mod format;
pub mod retention;
mod writer;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::{sync_channel, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, SystemTime};

use mavlink_frame::RawFrame;
use skymesh_runtime::Stats;

use crate::metrics::TlogMetrics;

pub use retention::Limits;

/// When a recording starts and ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TlogMode {
    /// From the autopilot's first armed HEARTBEAT to its first disarmed one (or
    /// the end of the connection): one log per flight.
    Arming,
    /// For as long as the autopilot link is connected: one log per connection.
    Connection,
}

impl TlogMode {
    pub fn as_str(self) -> &'static str {
        match self {
            TlogMode::Arming => "arming",
            TlogMode::Connection => "connection",
        }
    }
}

/// The validated `[tlog]` table.
#[derive(Debug, Clone, PartialEq)]
pub struct TlogSettings {
    pub dir: PathBuf,
    pub mode: TlogMode,
    /// The autopilot's system id (its HEARTBEAT says armed or not; in file names).
    pub vehicle_id: u8,
    pub limits: Limits,
    /// A log reaching this many bytes is closed and the next one opened.
    pub max_file_bytes: u64,
    /// Frames waiting for the writer thread; beyond this they are dropped.
    pub queue_frames: usize,
    /// The file being written is flushed to the kernel this often, so a crash of
    /// the process loses at most this much.
    pub flush_interval: Duration,
}

/// Which way a frame went on the autopilot link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    FromAutopilot,
    ToAutopilot,
}

/// One frame for the writer: when, which recording, the bytes.
// Frames are most entries, and boxing them would allocate on the link's threads.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub(crate) enum Entry {
    Frame {
        at: SystemTime,
        session: u32,
        frame: RawFrame,
    },
    /// The service is stopping: close the log and end.
    Shutdown,
}

/// What the tap and the writer share.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    /// A recording is on: frames are queued.
    active: AtomicBool,
    /// The current (or last) recording's number; a new one starts with +1.
    session: AtomicU32,
    /// The queue overflowed during this recording (warned once).
    warned: AtomicBool,
    /// Connected and armed, as last heard (changes under this lock only).
    state: Mutex<LinkState>,
}

#[derive(Debug, Default)]
struct LinkState {
    connected: bool,
    armed: bool,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Shared {
    pub(crate) fn is_active(&self) -> bool {
        self.active.load(Ordering::Acquire)
    }

    pub(crate) fn session(&self) -> u32 {
        self.session.load(Ordering::Acquire)
    }
}

/// MAVLink HEARTBEAT: message id, payload offsets of `autopilot` and `base_mode`.
const HEARTBEAT: u32 = 0;
const HB_AUTOPILOT: usize = 5;
const HB_BASE_MODE: usize = 6;
/// `MAV_AUTOPILOT_INVALID`: a ground station's or a peripheral's heartbeat.
const AUTOPILOT_INVALID: u8 = 8;
/// `MAV_MODE_FLAG_SAFETY_ARMED`.
const ARMED: u8 = 0x80;
/// The autopilot's component id (as [`crate::telemetry`] identifies it).
const AUTOPILOT_COMPONENT: u8 = 1;

/// The recorder's end on the autopilot link: every method returns at once.
#[derive(Debug)]
pub struct Tap {
    tx: SyncSender<Entry>,
    shared: Arc<Shared>,
    mode: TlogMode,
    vehicle_id: u8,
    metrics: TlogMetrics,
}

impl Tap {
    /// The link connected to the autopilot.
    pub fn connected(&self) {
        let mut s = lock(&self.shared.state);
        s.connected = true;
        if self.mode == TlogMode::Connection {
            self.begin();
        }
    }

    /// The link's connection ended: any recording ends with it.
    pub fn disconnected(&self) {
        let mut s = lock(&self.shared.state);
        s.connected = false;
        s.armed = false;
        self.shared.active.store(false, Ordering::Release);
    }

    /// Starts a recording unless one is on (call with the state locked).
    fn begin(&self) {
        if !self.shared.is_active() {
            self.shared.session.fetch_add(1, Ordering::AcqRel);
            self.shared.warned.store(false, Ordering::Relaxed);
            self.shared.active.store(true, Ordering::Release);
        }
    }

    /// A frame read from the autopilot.
    pub fn from_autopilot(&self, frame: &RawFrame) {
        if self.mode == TlogMode::Arming
            && frame.message_id() == HEARTBEAT
            && frame.system_id() == self.vehicle_id
            && frame.component_id() == AUTOPILOT_COMPONENT
            && frame.payload_byte(HB_AUTOPILOT) != AUTOPILOT_INVALID
        {
            let armed = frame.payload_byte(HB_BASE_MODE) & ARMED != 0;
            self.armed(armed, frame);
            return;
        }
        self.record(frame);
    }

    /// The autopilot's HEARTBEAT: the first armed one starts a recording (and is its
    /// first frame), the first disarmed one is the last frame of it.
    fn armed(&self, armed: bool, frame: &RawFrame) {
        let mut s = lock(&self.shared.state);
        if armed && !s.armed && s.connected {
            self.begin();
        }
        s.armed = armed;
        self.record(frame);
        if !armed {
            self.shared.active.store(false, Ordering::Release);
        }
    }

    /// A frame written to the autopilot.
    pub fn to_autopilot(&self, frame: &RawFrame) {
        self.record(frame);
    }

    fn record(&self, frame: &RawFrame) {
        if !self.shared.is_active() {
            return;
        }
        let entry = Entry::Frame {
            at: SystemTime::now(),
            session: self.shared.session(),
            frame: *frame,
        };
        match self.tx.try_send(entry) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.metrics.dropped.inc();
                if !self.shared.warned.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        "tlog: the writer is behind (queue full), dropping frames from \
                         this flight log (counted in skymesh_autopilot_tlog_dropped_frames_total)"
                    );
                }
            }
            // The writer ended after an error it logged.
            Err(TrySendError::Disconnected(_)) => {}
        }
    }
}

/// The writer thread: [`Recorder::finish`] closes the log and joins it.
#[derive(Debug)]
pub struct Recorder {
    tx: SyncSender<Entry>,
    thread: std::thread::JoinHandle<()>,
}

impl Recorder {
    /// Closes the log being written (flushed, synced, renamed) and ends the thread.
    /// Blocks: call from a blocking context.
    pub fn finish(self) {
        // Blocks while the queue is full; the writer is draining it.
        let _ = self.tx.send(Entry::Shutdown);
        if self.thread.join().is_err() {
            tracing::warn!("tlog writer thread panicked");
        }
    }
}

/// Starts the writer thread; the [`Tap`] goes on the link ([`crate::hub::Hub`]).
pub fn start(settings: &TlogSettings, stats: &Stats) -> std::io::Result<(Tap, Recorder)> {
    let (tx, rx) = sync_channel(settings.queue_frames);
    let shared = Arc::new(Shared::default());
    let metrics = TlogMetrics::new(stats);
    let thread = writer::spawn(settings.clone(), rx, shared.clone(), metrics.clone())?;
    tracing::info!(
        dir = %settings.dir.display(),
        mode = settings.mode.as_str(),
        max_files = settings.limits.max_files,
        max_total_bytes = settings.limits.max_total,
        min_free_bytes = settings.limits.min_free,
        "tlog: flight logs on"
    );
    Ok((
        Tap {
            tx: tx.clone(),
            shared,
            mode: settings.mode,
            vehicle_id: settings.vehicle_id,
            metrics,
        },
        Recorder { tx, thread },
    ))
}

#[cfg(test)]
mod tests;
