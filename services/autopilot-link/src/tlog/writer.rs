//! The writer thread: turns the tap's queue into files.
//!
//! Each recording (a session number from the [`super::Tap`]) is one log, split
//! into more when a file reaches `max_file_mb`. A log is written as
//! `<name>.tlog.part`, flushed every `flush_s` (a crash of the process leaves every
//! record but the last fraction of a second), and on close flushed, synced,
//! renamed to `<name>.tlog` and its directory synced. `.part` files of our vehicle
//! found at start were left by a crash: their torn last record is cut and they are
//! renamed. Old logs are deleted before a file opens and every [`CHECK_EVERY`]
//! while one is written ([`super::retention`]).
//!
//! While nothing is recorded the thread sleeps in the queue's `recv` (the tap
//! queues nothing then, so it is never woken); while recording it drains the
//! queue every [`POLL`], so the link's threads never wake it.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use mavlink_frame::RawFrame;

use super::format::{self, file_name, parse_name, utc_stamp, PART};
use super::retention;
use super::{lock, Entry, Shared, TlogSettings};
use crate::metrics::TlogMetrics;

/// While recording, the queue is drained this often.
pub const POLL: Duration = Duration::from_millis(50);
/// While recording, old logs and free space are checked this often.
pub const CHECK_EVERY: Duration = Duration::from_secs(10);
const BUFFER: usize = 64 * 1024;

pub(super) fn spawn(
    settings: TlogSettings,
    rx: Receiver<Entry>,
    shared: Arc<Shared>,
    metrics: TlogMetrics,
) -> io::Result<std::thread::JoinHandle<()>> {
    std::thread::Builder::new()
        .name("tlog".into())
        .spawn(move || {
            let mut w = Writer {
                settings,
                shared,
                metrics,
                open: None,
                done: 0,
                last: None,
            };
            w.recover();
            w.run(&rx);
        })
}

/// The log being written.
struct Open {
    session: u32,
    file: BufWriter<File>,
    /// `<name>.tlog.part`, renamed to `path` on close.
    part: PathBuf,
    path: PathBuf,
    bytes: u64,
    frames: u64,
    flushed: Instant,
    checked: Instant,
}

struct Writer {
    settings: TlogSettings,
    shared: Arc<Shared>,
    metrics: TlogMetrics,
    open: Option<Open>,
    /// Sessions up to this one are over (closed, failed or out of room): their
    /// late frames are dropped.
    done: u32,
    /// The stamp and number of the last log opened: one opened in the same
    /// millisecond gets a higher number, so names keep the order logs were written
    /// in even after the older ones are deleted.
    last: Option<(String, u32)>,
}

impl Writer {
    fn run(&mut self, rx: &Receiver<Entry>) {
        loop {
            // Idle: wait for the first frame of a recording (or the end).
            let first = if self.open.is_none() {
                match rx.recv() {
                    Ok(e) => Some(e),
                    Err(_) => return,
                }
            } else {
                std::thread::sleep(POLL);
                None
            };
            let capacity = self.settings.queue_frames;
            for entry in first.into_iter().chain(rx.try_iter().take(capacity)) {
                match entry {
                    Entry::Frame { at, session, frame } => self.frame(at, session, &frame),
                    Entry::Shutdown => {
                        self.close();
                        return;
                    }
                }
            }
            self.tick();
        }
    }

    /// After a drain: the recording ended, or periodic work is due.
    fn tick(&mut self) {
        let Some(o) = &self.open else {
            return;
        };
        if !self.shared.is_active() || self.shared.session() != o.session {
            let session = o.session;
            self.close();
            self.done = self.done.max(session);
            return;
        }
        let now = Instant::now();
        if now.duration_since(o.flushed) >= self.settings.flush_interval {
            let session = o.session;
            let flushed = self.open.as_mut().map(|o| {
                o.flushed = now;
                o.file.flush()
            });
            if let Some(Err(e)) = flushed {
                self.fail(session, "flushing", &e);
                return;
            }
        }
        if let Some(o) = &self.open {
            if now.duration_since(o.checked) >= CHECK_EVERY {
                let (session, bytes) = (o.session, o.bytes);
                if let Some(o) = self.open.as_mut() {
                    o.checked = now;
                }
                if !self.make_room(bytes) {
                    self.close();
                    self.stop(session);
                }
            }
        }
    }

    fn frame(&mut self, at: SystemTime, session: u32, frame: &RawFrame) {
        if session <= self.done {
            return;
        }
        if self.open.as_ref().is_some_and(|o| o.session != session) {
            let old = self.open.as_ref().map_or(0, |o| o.session);
            self.close();
            self.done = self.done.max(old);
        }
        if self.open.is_none() && !self.open_file(session, at) {
            return;
        }
        let Some(o) = self.open.as_mut() else {
            return;
        };
        let bytes = frame.as_bytes();
        let written = o
            .file
            .write_all(&format::stamp(at))
            .and_then(|()| o.file.write_all(bytes));
        if let Err(e) = written {
            self.fail(session, "writing", &e);
            return;
        }
        let n = (format::STAMP_LEN + bytes.len()) as u64;
        o.bytes += n;
        o.frames += 1;
        self.metrics.frames.inc();
        self.metrics.bytes.add(n);
        if o.bytes >= self.settings.max_file_bytes {
            // Rotation: the next frame of this recording opens the next file.
            self.close();
        }
    }

    /// Deletes old logs so a file of `current` bytes fits; `false` if it cannot.
    fn make_room(&mut self, current: u64) -> bool {
        let s = &self.settings;
        match retention::enforce(&s.dir, s.vehicle_id, current, s.limits) {
            Ok(done) => {
                for path in &done.deleted {
                    self.metrics.deleted.inc();
                    tracing::info!(file = %path.display(), "tlog: deleted an old flight log (retention)");
                }
                if !done.fits {
                    self.metrics.no_room.inc();
                    tracing::warn!(
                        dir = %s.dir.display(),
                        "tlog: no room for a flight log within max_total_mb / min_free_mb \
                         (every older log of ours is deleted): not recording"
                    );
                }
                done.fits
            }
            Err(e) => {
                self.metrics.errors.inc();
                tracing::error!(dir = %s.dir.display(), error = %e, "tlog: cannot apply retention");
                false
            }
        }
    }

    /// Opens the next log of `session`; `false` (logged, counted, recording
    /// stopped) if it cannot.
    fn open_file(&mut self, session: u32, at: SystemTime) -> bool {
        if let Err(e) = std::fs::create_dir_all(&self.settings.dir) {
            self.fail(session, "creating the directory", &e);
            return false;
        }
        if !self.make_room(0) {
            self.stop(session);
            return false;
        }
        let stamp = utc_stamp(at);
        let dir = &self.settings.dir;
        let mut n = match &self.last {
            Some((last, n)) if *last == stamp => n + 1,
            _ => 0,
        };
        let (path, part) = loop {
            let path = dir.join(file_name(self.settings.vehicle_id, &stamp, n));
            let part = part_of(&path);
            if !path.exists() && !part.exists() {
                break (path, part);
            }
            n += 1;
        };
        self.last = Some((stamp, n));
        let file = match OpenOptions::new().write(true).create_new(true).open(&part) {
            Ok(f) => f,
            Err(e) => {
                self.fail(session, "creating a log", &e);
                return false;
            }
        };
        tracing::info!(file = %part.display(), "tlog: recording");
        self.metrics.recording.set(1.0);
        let now = Instant::now();
        self.open = Some(Open {
            session,
            file: BufWriter::with_capacity(BUFFER, file),
            part,
            path,
            bytes: 0,
            frames: 0,
            flushed: now,
            checked: now,
        });
        true
    }

    /// Flushes, syncs and renames the log being written, if any.
    fn close(&mut self) {
        let Some(mut o) = self.open.take() else {
            return;
        };
        self.metrics.recording.set(0.0);
        let synced = o.file.flush().and_then(|()| o.file.get_ref().sync_all());
        drop(o.file);
        let renamed = std::fs::rename(&o.part, &o.path).and_then(|()| sync_dir(&self.settings.dir));
        match synced.and(renamed) {
            Ok(()) => tracing::info!(
                file = %o.path.display(),
                frames = o.frames,
                bytes = o.bytes,
                "tlog: flight log closed"
            ),
            Err(e) => {
                self.metrics.errors.inc();
                tracing::error!(file = %o.part.display(), error = %e, "tlog: closing a flight log failed");
            }
        }
    }

    /// An I/O error ends the recording `session` (the link carries on).
    fn fail(&mut self, session: u32, what: &str, e: &io::Error) {
        self.metrics.errors.inc();
        tracing::error!(
            dir = %self.settings.dir.display(),
            error = %e,
            "tlog: {what} failed: this flight log ends here (the link is not affected; \
             the next arming or connection tries again)"
        );
        // Keep what was written: the flush may fail too (disk full), the rename not.
        self.close();
        self.stop(session);
    }

    /// No more frames for `session`: the tap stops queuing them.
    fn stop(&mut self, session: u32) {
        self.done = self.done.max(session);
        let _state = lock(&self.shared.state);
        if self.shared.session() == session {
            self.shared.active.store(false, Ordering::Release);
        }
    }

    /// Finishes the `.part` logs of our vehicle a crash left behind.
    fn recover(&mut self) {
        let dir = self.settings.dir.clone();
        let Ok(entries) = std::fs::read_dir(&dir) else {
            // Created when the first log opens (errors are reported then).
            return;
        };
        for entry in entries.flatten() {
            let name = entry.file_name();
            let is_part = name
                .to_str()
                .and_then(|n| parse_name(self.settings.vehicle_id, n))
                .is_some_and(|n| n.part);
            let regular = entry.file_type().is_ok_and(|t| t.is_file());
            if !is_part || !regular {
                continue;
            }
            let part = entry.path();
            match finish_part(&part) {
                Ok((path, kept)) => tracing::warn!(
                    file = %path.display(),
                    bytes = kept,
                    "tlog: recovered a flight log left unfinished (the service stopped without closing it)"
                ),
                Err(e) => {
                    self.metrics.errors.inc();
                    tracing::error!(file = %part.display(), error = %e, "tlog: cannot recover a flight log");
                }
            }
        }
    }
}

/// `<name>.tlog` → `<name>.tlog.part`.
fn part_of(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(PART);
    PathBuf::from(s)
}

/// Cuts a `.part` log after its last whole record and renames it; returns the new
/// path and its length.
fn finish_part(part: &Path) -> io::Result<(PathBuf, u64)> {
    let mut file = OpenOptions::new().read(true).write(true).open(part)?;
    let len = file.metadata()?.len();
    let whole = format::whole_records(&mut file, len)?;
    if whole < len {
        file.set_len(whole)?;
    }
    file.sync_all()?;
    let name = part.to_string_lossy();
    let path = PathBuf::from(name.strip_suffix(PART).unwrap_or(&name).to_string());
    std::fs::rename(part, &path)?;
    if let Some(dir) = path.parent() {
        sync_dir(dir)?;
    }
    Ok((path, whole))
}

fn sync_dir(dir: &Path) -> io::Result<()> {
    File::open(dir)?.sync_all()
}
