//! The futex wake-up for blocking receivers ([`crate::Subscriber::set_futex_wake`]).
//!
//! Every topic has two ways to wake a receiver, and every publisher uses both:
//!
//! - the **socket** event (iceoryx2's default: a Unix datagram per wake-up). It has a
//!   file descriptor, so tokio and epoll can wait on it: every async receiver uses it.
//!   A blocking wait on it is two system calls (the wait and the read that re-arms
//!   the notifier), against one `recv` for a UDP socket: on this project's VM the
//!   mechanism alone costs the receiver 1.3× UDP's CPU per message
//!   (`scripts/wake-floor.c`).
//! - the topic's **event count**: a 32-bit word in shared memory ([`WakeWord`], one
//!   per topic and domain) that every publish increments after its sample is in
//!   place. A futex receiver reads the word, looks for a sample, and sleeps in one
//!   `futex` call only while the word still holds what it read — so a sample
//!   published between the look and the sleep ends the sleep at once. A publish
//!   makes the `FUTEX_WAKE` call only while a receiver is announced as waiting
//!   (the word's second half), so the second mechanism costs publishers two atomic
//!   operations until a blocking receiver waits. It has no file descriptor: only a
//!   thread that blocks can use it.
//!
//! **Why not iceoryx2's semaphore event**, which this replaced (2026-11-28): its
//! listener wraps the semaphore in a mutex, a notification state and a drain of the
//! semaphore and the event ids after every wake. After 10 ms asleep that cost a
//! 100 Hz receiver 3–4 µs of cold user-space work per message over the event count
//! (`samples-bench` receivers `iox-raw` and `iox-word`, docs/benchmarks.md), and its
//! timed wait polls, so timeouts took a watchdog thread per subscriber. `FUTEX_WAIT`
//! takes a timeout itself.
//!
//! **The word's life.** It is created by the first publisher or futex receiver of
//! the topic that opens it and is owned by nobody, so a service restarted alone
//! finds the same word as the processes still running (a fresh word per opener
//! would leave a publisher and a receiver on different words: a receive that only
//! a timeout ends). Its file (`/dev/shm/<domain>.fx_…_w<hash>.dyn`, 4 KiB) lives
//! under the domain's wake-up prefix and goes with the domain's other files when the
//! supervisor stops the mesh ([`crate::Domain::leftover_files`]). Two topics whose
//! names hash alike would share a word: their receivers would wake for each other's
//! samples, look, and sleep again — a cost, never a lost wake-up. A receiver killed
//! while announced leaves the announcement behind: publishers of that topic then
//! make the wake-up call on every publish (~1 µs each) until the domain is removed.
//!
//! **A frame stream's making word.** Frame streams have a second word of the same
//! kind, `<topic>#making` ([`making_word`]), which a frame publisher makes odd just
//! before its loan and even just before its send: an early receiver
//! ([`crate::FrameSubscriber::set_early_wake`]) sleeps on it and on the topic's
//! word together (`futex_waitv`) and polls for the frame while it is loaned and
//! written. Its file lives and goes with the topic's.

use std::num::NonZeroU32;
use std::sync::atomic::Ordering::SeqCst;
use std::time::Duration;

use iceoryx2::prelude::*;
use iceoryx2_bb_concurrency::atomic::AtomicU32;
use iceoryx2_cal::dynamic_storage::{DynamicStorage, DynamicStorageBuilder};
use iceoryx2_cal::named_concept::{
    NamedConceptBuilder, NamedConceptConfiguration, NamedConceptMgmt,
};
use rustix::thread::futex;

use crate::clock::monotonic_ns;
use crate::ipc::{ipc_err, IpcError};

/// When a futex receive gives up: a point on `CLOCK_MONOTONIC`, which the wait
/// hands to the kernel as it is (`FUTEX_WAIT_BITSET`'s absolute timeout). Taking it
/// is the receive's one clock read, where a deadline kept as an `Instant` took two
/// (one to set it, one to turn it into the relative timeout `FUTEX_WAIT` takes).
/// Without either read a 100 Hz receiver spent ~1 µs less of its ~20 per message
/// (`samples-bench`, docs/benchmarks.md); this keeps one of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Deadline(u64);

impl Deadline {
    /// `timeout` from now.
    pub fn after(timeout: Duration) -> Deadline {
        let ns = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
        Deadline(monotonic_ns().saturating_add(ns))
    }

    /// True once `now_ns` (`CLOCK_MONOTONIC`) is at or past it.
    pub(crate) fn passed(self, now_ns: u64) -> bool {
        now_ns >= self.0
    }

    fn timespec(self) -> futex::Timespec {
        futex::Timespec {
            tv_sec: i64::try_from(self.0 / 1_000_000_000).unwrap_or(i64::MAX),
            tv_nsec: (self.0 % 1_000_000_000) as i64,
        }
    }
}

/// A topic's event count, in shared memory.
#[derive(Debug, ZeroCopySend)]
#[repr(C)]
pub(crate) struct WakeWord {
    /// Incremented by every publish, after the sample is in place: the futex word.
    seq: AtomicU32,
    /// Receives announced as waiting (between [`TopicWord::arm`] and the end of the
    /// wait): a publish makes the wake-up call only while this is not zero.
    waiters: AtomicU32,
}

type WordStorage = iceoryx2_cal::dynamic_storage::posix_shared_memory::Storage<WakeWord>;

/// How long an open waits for a word that another process is creating.
const OPEN_TIMEOUT: Duration = Duration::from_millis(500);

/// `FUTEX_WAKE`'s count for "every waiter". The kernel reads the count as a C
/// `int` and stops once it has woken that many or more, so `u32::MAX` (-1 there)
/// wakes exactly one: with two receivers asleep on a topic, the other slept
/// through the publish until the next one or its timeout. `INT_MAX`, as glibc's
/// `pthread_cond_broadcast` passes.
const WAKE_ALL: u32 = i32::MAX as u32;

/// FNV-1a, 64 bits: the word's file name from the topic's name. Stable across
/// builds and toolchains (every service of a mesh must derive the same name).
fn name_hash(topic: &str) -> u64 {
    topic.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The name of a frame stream's *making* word: a second event count, odd from
/// the moment its publisher starts a frame until just before it sends it
/// ([`TopicWord::begin_making`], [`crate::FrameSubscriber::set_early_wake`]).
pub(crate) fn making_word(topic: &str) -> String {
    format!("{topic}#making")
}

/// One process's handle on a topic's event count. The bus opens it for every
/// publisher and futex receiver; public for tools that measure the mechanism alone
/// (`samples-bench` receiver `iox-word`).
#[derive(Debug)]
pub struct TopicWord {
    storage: WordStorage,
    topic: String,
}

impl TopicWord {
    /// Opens `topic`'s word under the domain's wake-up prefix (`wake_prefix`, see
    /// [`crate::Domain::wake_prefix`]), creating it if no process has.
    pub fn open(wake_prefix: &str, topic: &str) -> Result<TopicWord, IpcError> {
        let prefix = FileName::new(wake_prefix.as_bytes())
            .map_err(|e| ipc_err("futex word prefix", topic, e))?;
        let name = FileName::new(format!("w{:016x}", name_hash(topic)).as_bytes())
            .map_err(|e| ipc_err("futex word name", topic, e))?;
        let config = <WordStorage as NamedConceptMgmt>::Configuration::default().prefix(&prefix);
        let storage = <WordStorage as DynamicStorage<WakeWord>>::Builder::new(&name)
            .config(&config)
            .has_ownership(false)
            .timeout(OPEN_TIMEOUT)
            .initializer(|word, _| {
                word.write(WakeWord {
                    seq: AtomicU32::new(0),
                    waiters: AtomicU32::new(0),
                });
                true
            })
            .open_or_create()
            .map_err(|e| ipc_err("open futex word", topic, e))?;
        Ok(TopicWord {
            storage,
            topic: topic.to_string(),
        })
    }

    fn word(&self) -> &WakeWord {
        self.storage.get()
    }

    /// A publish's part, after its sample is in place: counts it, and wakes every
    /// receiver of the topic that waits (in every process).
    pub fn wake(&self) -> Result<(), IpcError> {
        self.word().seq.fetch_add(1, SeqCst);
        self.wake_waiters()
    }

    /// After a change of the count: the `FUTEX_WAKE` call, only while a receive is
    /// announced as waiting. It wakes every waiter, in every process.
    fn wake_waiters(&self) -> Result<(), IpcError> {
        let w = self.word();
        if w.waiters.load(SeqCst) != 0 {
            futex::wake(&w.seq, futex::Flags::empty(), WAKE_ALL)
                .map_err(|e| ipc_err("futex wake", &self.topic, e))?;
        }
        Ok(())
    }

    /// A frame publisher's announcement, before its loan, that a frame is in the
    /// making (the stream's *making* word, [`making_word`]): makes the word odd and
    /// wakes the receivers waiting for it
    /// ([`crate::FrameSubscriber::set_early_wake`]). Follow with
    /// [`TopicWord::end_making`] whatever becomes of the frame, this call's error
    /// included (the word is odd before the wake-up is tried). Two atomic
    /// operations while nobody waits.
    pub(crate) fn begin_making(&self) -> Result<(), IpcError> {
        // Already odd only after a publisher died between begin and end: the word
        // then stays as it is, and this frame's end makes it even again.
        self.word().seq.fetch_or(1, SeqCst);
        self.wake_waiters()
    }

    /// The frame announced by [`TopicWord::begin_making`] is about to be sent, or
    /// is given up: the word even again (a new value). Nobody waits on an odd
    /// word, so no wake-up. A second call changes nothing.
    pub(crate) fn end_making(&self) {
        let w = self.word();
        let _ = w
            .seq
            .fetch_update(SeqCst, SeqCst, |v| (v & 1 == 1).then(|| v.wrapping_add(1)));
    }

    /// True while a frame is in the making (the word is odd): on a stream's making
    /// word.
    pub(crate) fn in_making(&self) -> bool {
        self.word().seq.load(SeqCst) & 1 == 1
    }

    /// A receive's first step: announces a wait and reads the count. Look for a
    /// sample after this, then [`Armed::wait`] if there was none; a sample
    /// published after this call ends that wait at once.
    pub fn arm(&self) -> Armed<'_> {
        let w = self.word();
        w.waiters.fetch_add(1, SeqCst);
        Armed {
            seen: w.seq.load(SeqCst),
            word: w,
            topic: &self.topic,
        }
    }

    /// A blocking receive on the count, for [`crate::Subscriber`] and
    /// [`crate::FrameSubscriber`]: announce the wait and read the count, `look`,
    /// sleep while the count is unchanged (a sample published after the announcement
    /// ends the sleep at once), until `look` finds something or `deadline` passes
    /// (`None`: no limit).
    pub(crate) fn recv<R, E: From<IpcError>>(
        &self,
        deadline: Option<Deadline>,
        mut look: impl FnMut() -> Result<Option<R>, E>,
    ) -> Result<Option<R>, E> {
        loop {
            let armed = self.arm();
            if let Some(r) = look()? {
                return Ok(Some(r));
            }
            let timed_out = armed.wait_until(deadline)?;
            // Woken (or timed out): look before announcing again. After a publish's
            // wake-up this finds the sample, and the receive ends without two more
            // atomic operations on the word, which the publisher has just written.
            // Finding nothing, the loop announces and looks again before it sleeps,
            // so a sample published in between is not missed.
            if let Some(r) = look()? {
                return Ok(Some(r));
            }
            if timed_out {
                return Ok(None);
            }
        }
    }

    /// How many receives are announced as waiting on the topic, in every process
    /// (diagnostics and tests: zero whenever no futex receive is in progress).
    pub fn waiters(&self) -> u32 {
        self.word().waiters.load(SeqCst)
    }
}

/// An announced wait ([`TopicWord::arm`]); dropping it withdraws the announcement.
#[derive(Debug)]
pub struct Armed<'a> {
    word: &'a WakeWord,
    seen: u32,
    topic: &'a str,
}

impl Armed<'_> {
    /// On a stream's making word: a frame was in the making when the wait was
    /// announced (the word was odd), so there is nothing to sleep for.
    pub(crate) fn in_making(&self) -> bool {
        self.seen & 1 == 1
    }

    /// Sleeps as [`Armed::wait`] does, until `deadline` at the latest (`None`: no
    /// limit); `true` if it passed (then or before the call).
    pub fn wait_until(self, deadline: Option<Deadline>) -> Result<bool, IpcError> {
        let limit = deadline.map(Deadline::timespec);
        match futex::wait_bitset(
            &self.word.seq,
            futex::Flags::empty(),
            self.seen,
            limit.as_ref(),
            NonZeroU32::MAX,
        ) {
            Ok(()) | Err(rustix::io::Errno::AGAIN) | Err(rustix::io::Errno::INTR) => Ok(false),
            Err(rustix::io::Errno::TIMEDOUT) => Ok(true),
            Err(e) => Err(ipc_err("futex wait", self.topic, e)),
        }
    }

    /// Sleeps until a publish after the arming (returns at once if one came
    /// already), `timeout` (`None`: no limit), or a signal. Callers look for samples
    /// and at the clock whichever it was.
    pub fn wait(self, timeout: Option<Duration>) -> Result<(), IpcError> {
        self.wait_until(timeout.map(Deadline::after)).map(drop)
    }
}

/// How [`wait_either`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Either {
    /// One of the words changed (or a signal or spurious wake-up): look.
    Woken,
    TimedOut,
    /// The kernel has no `futex_waitv` (Linux < 5.16).
    Unsupported,
}

/// Sleeps until either armed word changes from what its arming read (a publish on
/// either, in any process), `deadline` (`None`: no limit) or a signal: one
/// `futex_waitv` call on both. Both stay announced while asleep, so either's
/// publisher makes the wake-up call.
pub(crate) fn wait_either(
    a: &Armed<'_>,
    b: &Armed<'_>,
    deadline: Option<Deadline>,
) -> Result<Either, IpcError> {
    let entry = |armed: &Armed<'_>| {
        let mut w = futex::Wait::new();
        w.val = u64::from(armed.seen);
        w.uaddr = futex::WaitPtr::new(armed.word.seq.as_ptr().cast());
        w.flags = futex::WaitFlags::SIZE_U32;
        w
    };
    let limit = deadline.map(Deadline::timespec);
    match futex::waitv(
        &[entry(a), entry(b)],
        futex::WaitvFlags::empty(),
        limit.as_ref(),
        rustix::thread::ClockId::Monotonic,
    ) {
        Ok(_) | Err(rustix::io::Errno::AGAIN) | Err(rustix::io::Errno::INTR) => Ok(Either::Woken),
        Err(rustix::io::Errno::TIMEDOUT) => Ok(Either::TimedOut),
        Err(rustix::io::Errno::NOSYS) => Ok(Either::Unsupported),
        Err(e) => Err(ipc_err("futex waitv", a.topic, e)),
    }
}

impl Drop for Armed<'_> {
    fn drop(&mut self) {
        self.word.waiters.fetch_sub(1, SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prefix(tag: &str) -> String {
        format!("fxw{}{tag}.fx_", std::process::id())
    }

    fn remove(prefix: &str) {
        for e in std::fs::read_dir("/dev/shm").unwrap().flatten() {
            if e.file_name().to_string_lossy().starts_with(prefix) {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }

    #[test]
    fn the_name_hash_is_fnv1a() {
        // Published FNV-1a 64 test vectors: every build must derive the same file.
        assert_eq!(name_hash(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(name_hash("a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(name_hash("foobar"), 0x8594_4171_f739_67e8);
    }

    /// Two openers share one word: what one publishes wakes the other's wait, and
    /// the word outlives both (a service restarted alone must find it).
    #[test]
    fn openers_share_the_word_and_it_outlives_them() {
        let p = prefix("a");
        let publ = TopicWord::open(&p, "skymesh/test/a").unwrap();
        let recv = TopicWord::open(&p, "skymesh/test/a").unwrap();
        let armed = recv.arm();
        assert_eq!(publ.word().waiters.load(SeqCst), 1);
        publ.wake().unwrap();
        // The publish came after the arming: the wait returns at once, not in 10 s.
        let t0 = std::time::Instant::now();
        armed.wait(Some(Duration::from_secs(10))).unwrap();
        assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
        assert_eq!(recv.waiters(), 0, "the announcement outlived the wait");
        drop((publ, recv));
        let again = TopicWord::open(&p, "skymesh/test/a").unwrap();
        assert_eq!(
            again.word().seq.load(SeqCst),
            1,
            "a fresh word, not the same"
        );
        drop(again);
        remove(&p);
    }

    /// One publish wakes every receiver asleep on the topic, not one of them: each
    /// waiter here opens its own handle, as a process of its own would, and must be
    /// woken long before its 20 s guard.
    #[test]
    fn a_publish_wakes_every_waiter() {
        const WAITERS: u32 = 3;
        let p = prefix("c");
        let topic = "skymesh/test/c";
        let publ = TopicWord::open(&p, topic).unwrap();
        let waiters: Vec<_> = (0..WAITERS)
            .map(|_| {
                let p = p.clone();
                std::thread::spawn(move || {
                    let recv = TopicWord::open(&p, topic).unwrap();
                    let timed_out = recv
                        .arm()
                        .wait_until(Some(Deadline::after(Duration::from_secs(20))))
                        .unwrap();
                    !timed_out
                })
            })
            .collect();
        // Every wait announced before the publish (a wait announced but not yet
        // asleep returns at once when the count has moved; one asleep needs the call).
        let t0 = std::time::Instant::now();
        while publ.waiters() < WAITERS {
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "waiters did not arm"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(20));
        publ.wake().unwrap();
        let woken = waiters
            .into_iter()
            .map(|w| w.join().unwrap())
            .filter(|woke| *woke)
            .count();
        assert_eq!(woken, WAITERS as usize, "waiters woken by one publish");
        assert_eq!(publ.waiters(), 0);
        drop(publ);
        remove(&p);
    }

    /// Without a publish the wait ends at its timeout (no watchdog thread).
    #[test]
    fn a_wait_ends_at_its_timeout() {
        let p = prefix("b");
        let recv = TopicWord::open(&p, "skymesh/test/b").unwrap();
        let t0 = std::time::Instant::now();
        recv.arm().wait(Some(Duration::from_millis(30))).unwrap();
        let waited = t0.elapsed();
        assert!(waited >= Duration::from_millis(30), "{waited:?}");
        assert_eq!(recv.waiters(), 0);
        drop(recv);
        remove(&p);
    }
}
