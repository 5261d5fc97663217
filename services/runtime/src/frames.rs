//! Camera frames on the bus: iceoryx2 slice samples (`[u8]`) with a
//! [`FrameHeader`] as iceoryx2 user header, written and read in place in shared memory.
//!
//! A frame never crosses a process boundary by copy: the publisher loans a slice of
//! the frame's length from shared memory and hands it to the caller's closure, which
//! writes the pixels there (e.g. the camera's converter); subscribers get a `&[u8]`
//! pointing into the same memory. The API allocates nothing per frame.
//!
//! Wake-up, sequence stamping and stats are those of the typed channels in
//! [`crate::ipc`]: one event per topic, `skymesh_topic_samples_*_total` counters.

use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use skymesh_ipc_types::{FrameHeader, FrameHeaderError, Topic};

use crate::anticipate::{poll_until, Anticipating, AnticipationStats};
use crate::clock::monotonic_ns;
use crate::futex::{making_word, wait_either, Deadline, Either, TopicWord};
use crate::ipc::{
    ipc_err, recv_anticipating, time_left, with_qos, with_retry, Bus, IpcError, ReceiveCounts,
    SocketWait, Svc, WaitSource, Wakers,
};
use crate::stats::Counter;
use crate::warn_limit::WarnLimiter;

type FramePortFactory =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [u8], FrameHeader>;

/// A failure to publish or receive a frame.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error("frame of {len} bytes on `{topic}` exceeds the publisher's maximum of {max} bytes")]
    TooLarge {
        topic: String,
        len: usize,
        max: usize,
    },
    #[error("frame length {len} on `{topic}` does not fit the header's u32 payload length")]
    LengthOverflow { topic: String, len: usize },
    #[error("frame on `{topic}` not sent: its header does not describe its pixels: {source}")]
    InvalidHeader {
        topic: String,
        source: FrameHeaderError,
    },
}

impl Bus {
    fn open_frames(&self, topic: &Topic) -> Result<FramePortFactory, IpcError> {
        let service_name =
            ServiceName::new(&topic.name).map_err(|e| ipc_err("service name", &topic.name, e))?;
        with_retry(self.node(), &topic.name, "open frame topic", || {
            with_qos(
                self.node()
                    .service_builder(&service_name)
                    .publish_subscribe::<[u8]>()
                    .user_header::<FrameHeader>(),
                topic,
            )
            .open_or_create()
        })
    }

    /// A frame publisher on `topic` whose frames are at most `max_len` bytes (shared
    /// memory for a few frames of that size is reserved now, so size it to the
    /// stream's largest frame, e.g. [`skymesh_ipc_types::MAX_FRAME_LEN`]).
    pub fn frame_publisher(
        &self,
        topic: &Topic,
        max_len: usize,
    ) -> Result<FramePublisher, FrameError> {
        if u32::try_from(max_len).is_err() {
            return Err(FrameError::LengthOverflow {
                topic: topic.name.clone(),
                len: max_len,
            });
        }
        let pubsub = self.open_frames(topic)?;
        let port = pubsub
            .publisher_builder()
            .initial_max_slice_len(max_len.max(1))
            .allocation_strategy(AllocationStrategy::Static)
            .create()
            .map_err(|e| ipc_err("create frame publisher", &topic.name, e))?;
        let wakers = self.wakers(topic)?;
        let making = self.topic_word(&making_word(&topic.name))?;
        let origin = self.origin();
        Ok(FramePublisher {
            port,
            pubsub,
            wakers,
            making,
            seq: 0,
            service: origin.service,
            instance: origin.instance,
            max_len,
            published: self.stats().counter(
                "skymesh_topic_samples_published_total",
                &[("topic", &topic.name)],
            ),
            topic: topic.name.clone(),
            _bus: self.clone(),
        })
    }

    /// A frame subscriber on `topic`: awaited with [`FrameSubscriber::recv_with`] or
    /// drained with [`FrameSubscriber::try_recv_with`] (e.g. from [`crate::wait_loop`]).
    pub fn frame_subscriber(&self, topic: &Topic) -> Result<FrameSubscriber, FrameError> {
        let pubsub = self.open_frames(topic)?;
        let event = self.open_event(topic)?;
        let port = pubsub
            .subscriber_builder()
            .create()
            .map_err(|e| ipc_err("create frame subscriber", &topic.name, e))?;
        let socket = SocketWait::new(event, &topic.name)?;
        let stats = self.stats();
        Ok(FrameSubscriber {
            socket,
            port,
            counts: ReceiveCounts::new(stats, &topic.name),
            invalid: stats.counter(
                "skymesh_topic_samples_invalid_total",
                &[("topic", topic.name.as_str())],
            ),
            warn: Mutex::new(WarnLimiter::default()),
            anticipation: Anticipating::default(),
            futex: None,
            early: None,
            topic: topic.name.clone(),
            _bus: self.clone(),
        })
    }
}

/// Publishes frames of one stream, written in place in shared memory.
pub struct FramePublisher {
    port: iceoryx2::port::publisher::Publisher<Svc, [u8], FrameHeader>,
    /// The topic's service, for its subscriber count.
    pubsub: FramePortFactory,
    wakers: Wakers,
    /// The stream's making word: odd from just before a frame's loan until its send, for
    /// the receivers that wake then ([`FrameSubscriber::set_early_wake`]).
    making: TopicWord,
    seq: u64,
    service: u16,
    instance: u16,
    max_len: usize,
    published: Counter,
    topic: String,
    _bus: Bus,
}

impl core::fmt::Debug for FramePublisher {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FramePublisher")
            .field("topic", &self.topic)
            .field("seq", &self.seq)
            .field("max_len", &self.max_len)
            .finish()
    }
}

impl FramePublisher {
    /// Loans `len` bytes of shared memory, lets `fill` write the frame's header and
    /// pixels in place, checks the header against the pixels, stamps it (sequence,
    /// publish time, publisher id, `payload_len`), sends and wakes the subscribers.
    /// Returns the sequence number used.
    ///
    /// The pixels start zeroed (the safe way to hand out loaned memory; one `memset`).
    /// A frame longer than the publisher's maximum, or whose header does not describe
    /// `len` bytes of pixels, is refused and not sent.
    pub fn publish_with(
        &mut self,
        len: usize,
        fill: impl FnOnce(&mut FrameHeader, &mut [u8]),
    ) -> Result<u64, FrameError> {
        if len > self.max_len {
            return Err(FrameError::TooLarge {
                topic: self.topic.clone(),
                len,
                max: self.max_len,
            });
        }
        let payload_len = u32::try_from(len).map_err(|_| FrameError::LengthOverflow {
            topic: self.topic.clone(),
            len,
        })?;
        // Before the loan: an early receiver's wake-up then runs while the frame is
        // loaned (iceoryx2 zero-fills it) and written, and it is polling when the
        // frame is sent. Announced after the loan, the wake-up had only the pixel
        // write to run in (0.1–0.2 ms at 1080p here) and missed it for 2–30 frames
        // of 400 on its own core; before it, for 0–3, at the cost of polling
        // through the fill too (docs/benchmarks.md, "Early wake"). The guard comes
        // first: the word is odd from `begin_making`'s first step, so a failed
        // wake-up in it, a failed loan and every other early return end the making.
        let _making = EndMaking(&self.making);
        self.making.begin_making()?;
        let mut sample = self
            .port
            .loan_slice(len)
            .map_err(|e| ipc_err("loan frame", &self.topic, e))?;
        // iceoryx2 lends header and payload through two `&mut self` accessors, so the
        // header (152 bytes) is filled on the side and stored; the pixels are written
        // where they lie.
        let mut filled = FrameHeader::default();
        fill(&mut filled, sample.payload_mut());
        let header = sample.user_header_mut();
        *header = filled;
        header.payload_len = payload_len;
        header
            .validate(len)
            .map_err(|source| FrameError::InvalidHeader {
                topic: self.topic.clone(),
                source,
            })?;
        let seq = self.seq + 1;
        header.header.seq = seq;
        header.header.stamp_ns = monotonic_ns();
        header.header.service = self.service;
        header.header.instance = self.instance;
        // Ended before the send: a receiver that takes this frame the moment it is
        // sent and comes back for the next must not find it still in the making
        // (it would poll for a frame a period away).
        self.making.end_making();
        sample
            .send()
            .map_err(|e| ipc_err("send frame", &self.topic, e))?;
        self.seq = seq;
        self.wakers.notify(&self.topic)?;
        self.published.inc();
        Ok(seq)
    }

    /// How many subscribers the topic has now, in every process: a producer whose
    /// frames nobody reads need not make them (the camera renders only while this is
    /// above zero). Reads the service's shared-memory port table; no system call.
    pub fn subscribers(&self) -> usize {
        self.pubsub.dynamic_config().number_of_subscribers()
    }

    /// The largest frame this publisher accepts, in bytes.
    pub fn max_len(&self) -> usize {
        self.max_len
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}

/// Ends a frame's making however `publish_with` returns early (refused, failed);
/// after the send's own `end_making` it changes nothing.
struct EndMaking<'a>(&'a TopicWord);

impl Drop for EndMaking<'_> {
    fn drop(&mut self) {
        self.0.end_making();
    }
}

/// [`FrameSubscriber::set_early_wake`]'s state.
#[derive(Debug)]
struct EarlyWake {
    making: TopicWord,
    max_spin: Duration,
    polls: AtomicU64,
    hits: AtomicU64,
}

/// How an early-waking frame receiver has done ([`FrameSubscriber::set_early_wake`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EarlyWakeStats {
    /// Receives that polled for a frame in the making.
    pub polls: u64,
    /// Of those, the receives that took their frame while polling: no wake-up
    /// after the send.
    pub hits: u64,
}

/// Receives frames of one stream, read in place in shared memory.
pub struct FrameSubscriber {
    /// The stream's socket event: async receives, and blocking ones without the
    /// futex wake-up.
    socket: SocketWait,
    port: iceoryx2::port::subscriber::Subscriber<Svc, [u8], FrameHeader>,
    counts: ReceiveCounts,
    invalid: Counter,
    warn: Mutex<WarnLimiter<&'static str>>,
    /// Set by [`FrameSubscriber::set_anticipate`].
    anticipation: Anticipating,
    /// Set by [`FrameSubscriber::set_futex_wake`].
    futex: Option<TopicWord>,
    /// Set by [`FrameSubscriber::set_early_wake`].
    early: Option<EarlyWake>,
    topic: String,
    _bus: Bus,
}

impl core::fmt::Debug for FrameSubscriber {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FrameSubscriber")
            .field("topic", &self.topic)
            .finish()
    }
}

impl FrameSubscriber {
    /// Takes one pending frame without waiting and hands its header and pixels to
    /// `read` where they lie in shared memory. Frames whose header does not describe
    /// their pixels are dropped, counted (`skymesh_topic_samples_invalid_total`) and
    /// logged (rate-limited); the next pending frame is taken instead.
    pub fn try_recv_with<R>(
        &self,
        read: impl FnOnce(&FrameHeader, &[u8]) -> R,
    ) -> Result<Option<R>, FrameError> {
        loop {
            let Some(sample) = self
                .port
                .receive()
                .map_err(|e| ipc_err("receive frame", &self.topic, e))?
            else {
                return Ok(None);
            };
            let header = sample.user_header();
            let pixels = sample.payload();
            if let Err(e) = header.validate(pixels.len()) {
                self.invalid.inc();
                self.warn_invalid(&e);
                continue;
            }
            self.account(header);
            return Ok(Some(read(header, pixels)));
        }
    }

    /// Takes every pending frame without waiting, keeps only the newest valid one and
    /// hands it to `read` in place; the older ones are released unread. Returns
    /// `read`'s result and how many older frames were skipped (a consumer slower than
    /// the camera processes the newest frame, never a backlog, and copies nothing).
    pub fn try_latest_with<R>(
        &self,
        read: impl FnOnce(&FrameHeader, &[u8]) -> R,
    ) -> Result<Option<(R, u64)>, FrameError> {
        let mut newest = None;
        let mut skipped = 0u64;
        while let Some(sample) = self
            .port
            .receive()
            .map_err(|e| ipc_err("receive frame", &self.topic, e))?
        {
            if let Err(e) = sample.user_header().validate(sample.payload().len()) {
                self.invalid.inc();
                self.warn_invalid(&e);
                continue;
            }
            self.account(sample.user_header());
            if newest.replace(sample).is_some() {
                skipped += 1;
            }
        }
        Ok(newest.map(|sample| (read(sample.user_header(), sample.payload()), skipped)))
    }

    /// Consumes the last wake-up's notification before a receive looks for frames
    /// (see `Notifications` in `ipc.rs`).
    fn settle(&self) -> Result<(), IpcError> {
        self.socket.settle_async(&self.topic)
    }

    /// Waits until frames may be pending (see `wait_listener` in `ipc.rs`).
    async fn wait(&mut self) -> Result<(), IpcError> {
        self.socket.wait_async(&self.topic).await
    }

    /// Waits until at least one frame is pending, then behaves like
    /// [`FrameSubscriber::try_latest_with`]. Cancel-safe.
    pub async fn latest_with<R>(
        &mut self,
        mut read: impl FnMut(&FrameHeader, &[u8]) -> R,
    ) -> Result<(R, u64), FrameError> {
        self.settle()?;
        loop {
            if let Some(r) = self.try_latest_with(&mut read)? {
                return Ok(r);
            }
            self.wait().await?;
        }
    }

    /// Returns once a frame is pending (at once if one already is), without taking
    /// it: follow with [`FrameSubscriber::try_latest_with`]. Cancel-safe. It may
    /// return without a frame after a spurious wake-up; the `try_` call then says
    /// `None`.
    pub async fn ready(&mut self) -> Result<(), FrameError> {
        self.settle()?;
        if self
            .port
            .has_samples()
            .map_err(|e| ipc_err("check frames", &self.topic, e))?
        {
            return Ok(());
        }
        self.wait().await?;
        Ok(())
    }

    /// Waits for the next frame and hands it to `read` in place (see
    /// [`FrameSubscriber::try_recv_with`]). Cancel-safe.
    pub async fn recv_with<R>(
        &mut self,
        mut read: impl FnMut(&FrameHeader, &[u8]) -> R,
    ) -> Result<R, FrameError> {
        self.settle()?;
        loop {
            if let Some(r) = self.try_recv_with(&mut read)? {
                return Ok(r);
            }
            self.wait().await?;
        }
    }

    /// Low-latency receive of a camera stream with
    /// [`FrameSubscriber::recv_blocking_with`]: wakes on a timer shortly before the
    /// next frame is due (learnt from the frames' send stamps) and polls shared
    /// memory until it comes, at most `max_spin` per frame, so the frame is in hand
    /// within microseconds of its publication instead of one process wake-up later.
    /// See [`crate::ipc::Subscriber::set_anticipate`]; zero turns it off.
    pub fn set_anticipate(&mut self, max_spin: Duration) {
        self.anticipation.set(max_spin);
    }

    /// What [`FrameSubscriber::set_anticipate`] has done; `None` when it is off.
    pub fn anticipation(&self) -> Option<AnticipationStats> {
        self.anticipation.stats()
    }

    /// [`FrameSubscriber::recv_blocking_with`] sleeps on the stream's event count:
    /// see [`crate::Subscriber::set_futex_wake`]. `set_anticipate` takes precedence.
    pub fn set_futex_wake(&mut self) -> Result<(), FrameError> {
        self._bus.futex_wait_into(&mut self.futex, &self.topic)?;
        self.socket.release();
        Ok(())
    }

    /// Low-latency receive with [`FrameSubscriber::recv_blocking_with`] that needs no
    /// regular stream: the receiver sleeps until the publisher *starts* a frame
    /// (just before its loan, which zero-fills it, and the pixel write: at 1080p RGB
    /// 0.4–1.0 ms on this project's VM) and then polls shared memory until the frame
    /// is sent, at most `max_spin`, so the frame is in hand within microseconds of its
    /// send and the wake-up ran while the frame was loaned and written. Unlike
    /// [`FrameSubscriber::set_anticipate`] it does not predict: a camera whose frames
    /// come late or irregularly is still met. Costs the receiver the time from a
    /// frame's start to its send in polling CPU (yielding to whatever else is
    /// runnable every 25 µs), per frame. A frame not sent within `max_spin` is waited
    /// for as with [`FrameSubscriber::set_futex_wake`], which this turns on. Takes
    /// precedence over `set_anticipate`; zero turns it off.
    pub fn set_early_wake(&mut self, max_spin: Duration) -> Result<(), FrameError> {
        if max_spin.is_zero() {
            self.early = None;
            return Ok(());
        }
        self.set_futex_wake()?;
        let making = self._bus.topic_word(&making_word(&self.topic))?;
        self.early = Some(EarlyWake {
            making,
            max_spin,
            polls: AtomicU64::new(0),
            hits: AtomicU64::new(0),
        });
        Ok(())
    }

    /// What [`FrameSubscriber::set_early_wake`] has done; `None` when it is off.
    pub fn early_wake(&self) -> Option<EarlyWakeStats> {
        self.early.as_ref().map(|e| EarlyWakeStats {
            polls: e.polls.load(Relaxed),
            hits: e.hits.load(Relaxed),
        })
    }

    /// Waits on the calling thread, without an async runtime, for the next frame and
    /// hands it to `read` in place (see [`FrameSubscriber::try_recv_with`]): blocks in
    /// the kernel on the stream's event, as a blocking socket read does. `None` after
    /// `timeout` without a frame; `timeout = None` waits indefinitely.
    pub fn recv_blocking_with<R>(
        &self,
        timeout: Option<Duration>,
        mut read: impl FnMut(&FrameHeader, &[u8]) -> R,
    ) -> Result<Option<R>, FrameError> {
        if let (Some(early), Some(word)) = (&self.early, &self.futex) {
            let deadline = timeout.map(Deadline::after);
            return recv_early(early, word, deadline, || self.try_recv_with(&mut read));
        }
        if let (Some(word), None) = (&self.futex, self.anticipation.get()) {
            let deadline = timeout.map(Deadline::after);
            return word.recv(deadline, || self.try_recv_with(&mut read));
        }
        let deadline = timeout.map(|t| Instant::now() + t);
        self.socket.settle(&self.topic)?;
        if let Some(a) = self.anticipation.get() {
            return recv_anticipating(&self.socket, a, deadline, &self.topic, || {
                self.try_recv_with(&mut read)
            });
        }
        loop {
            if let Some(r) = self.try_recv_with(&mut read)? {
                return Ok(Some(r));
            }
            let Some(left) = time_left(deadline) else {
                return Ok(None);
            };
            self.socket.wait_blocking(left, &self.topic)?;
        }
    }

    fn warn_invalid(&self, e: &FrameHeaderError) {
        let allow = self
            .warn
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .allow("invalid frame header", Instant::now());
        match allow {
            Some(hidden) => {
                tracing::warn!(topic = %self.topic, error = %e, hidden, "dropped a frame with an invalid header")
            }
            None => {
                tracing::debug!(topic = %self.topic, error = %e, "dropped a frame with an invalid header")
            }
        }
    }

    fn account(&self, h: &FrameHeader) {
        let h = &h.header;
        self.anticipation.observe(h.stamp_ns);
        self.counts.count(h);
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}

/// [`FrameSubscriber::set_early_wake`]'s receive: `look` takes a pending frame.
fn recv_early<R>(
    early: &EarlyWake,
    word: &TopicWord,
    deadline: Option<Deadline>,
    mut look: impl FnMut() -> Result<Option<R>, FrameError>,
) -> Result<Option<R>, FrameError> {
    loop {
        if let Some(r) = look()? {
            return Ok(Some(r));
        }
        let making = early.making.arm();
        if !making.in_making() {
            // Nothing in the making: sleep until the publisher starts a frame or
            // sends one (a publisher that does not announce its frames, e.g. of an
            // older build, still wakes the receiver), announced on both words
            // before the last look so neither is missed.
            let sent = word.arm();
            if let Some(r) = look()? {
                return Ok(Some(r));
            }
            match wait_either(&making, &sent, deadline)? {
                Either::TimedOut => return look(),
                Either::Unsupported => {
                    drop((making, sent));
                    warn_no_waitv();
                    return word.recv(deadline, look);
                }
                Either::Woken => {}
            }
            drop((making, sent));
            if !early.making.in_making() {
                // A send (or its whole making since the wake-up), a signal: look.
                continue;
            }
        } else {
            drop(making);
        }
        // A frame is in the making: poll until it is sent.
        early.polls.fetch_add(1, Relaxed);
        let spin = u64::try_from(early.max_spin.as_nanos()).unwrap_or(u64::MAX);
        let until = monotonic_ns().saturating_add(spin);
        let expired = |now| deadline.is_some_and(|d| d.passed(now));
        if let Some(r) = poll_until(until, expired, &mut look)? {
            early.hits.fetch_add(1, Relaxed);
            return Ok(Some(r));
        }
        // Not sent within `max_spin` (a slow frame, a publisher that died
        // mid-frame): wait for the send itself.
        return word.recv(deadline, look);
    }
}

/// Once per process: the kernel cannot wait on two words, so early receives wait
/// for the send as `set_futex_wake` does.
fn warn_no_waitv() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        tracing::warn!(
            "early frame wake-up needs futex_waitv (Linux 5.16 or later); receiving without it"
        );
    });
}

impl WaitSource for FrameSubscriber {
    fn listener(&self) -> Result<&Listener<Svc>, IpcError> {
        self.socket.listener(&self.topic)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc;

    use skymesh_ipc_types::{topics, PixelFormat, ServiceId};

    use crate::ipc::DomainGuard;
    use crate::{Bus, Domain, Stats};

    use super::*;

    /// A frame sent the way a publisher that does not announce its frames sends
    /// it (an older build's): loan, write, send, notify, no making word.
    fn publish_unannounced(publ: &mut FramePublisher, seq: u64) {
        let (f, w, h) = (PixelFormat::Nv12, 2, 2);
        let len = f.frame_len(w, h, w).unwrap() as usize;
        let mut sample = publ.port.loan_slice(len).unwrap();
        let mut header = FrameHeader {
            frame_seq: seq,
            ..Default::default()
        };
        header.set_geometry(f, w, h, w);
        header.payload_len = len as u32;
        header.header.seq = seq;
        header.header.stamp_ns = monotonic_ns();
        *sample.user_header_mut() = header;
        sample.send().unwrap();
        publ.wakers.notify(&publ.topic).unwrap();
    }

    /// The making starts before the loan, so a loan that fails must end it: a word
    /// left odd would make every early receiver poll `max_spin` for nothing on
    /// each receive.
    #[test]
    fn a_frame_whose_loan_fails_is_not_left_in_the_making() {
        let d = DomainGuard(Domain::load(&format!("ut{}loan", std::process::id()), None).unwrap());
        let bus = Bus::open(&d, "loan-fail", ServiceId::Tool, 0, Stats::new()).unwrap();
        let topic = topics::camera_frames("loan");
        let (f, w, h) = (PixelFormat::Nv12, 2, 2);
        let len = f.frame_len(w, h, w).unwrap() as usize;
        let mut publ = bus.frame_publisher(&topic, len).unwrap();
        // Hold loans until the port refuses one: the next publish's loan fails too.
        let mut held = Vec::new();
        while let Ok(sample) = publ.port.loan_slice(len) {
            held.push(sample);
            assert!(held.len() < 1024, "the port never refused a loan");
        }
        let fill = |hd: &mut FrameHeader, _: &mut [u8]| hd.set_geometry(f, w, h, w);
        let refused = publ.publish_with(len, fill);
        assert!(
            refused.is_err(),
            "a publish without a loan to take: {refused:?}"
        );
        assert!(
            !publ.making.in_making(),
            "a failed loan left the frame in the making"
        );
        drop(held);
        assert_eq!(publ.publish_with(len, fill).unwrap(), 1);
        assert!(!publ.making.in_making());
    }

    /// An early receiver asleep between frames wakes for a frame whose publisher
    /// never announced it: it waits on the send too, not only on the making word
    /// (waiting on the making word alone it would sleep until its timeout, here
    /// none: the receive would never return).
    #[test]
    fn an_early_receiver_takes_frames_a_publisher_did_not_announce() {
        let d = DomainGuard(Domain::load(&format!("ut{}early", std::process::id()), None).unwrap());
        let bus = Bus::open(&d, "early-old", ServiceId::Tool, 0, Stats::new()).unwrap();
        let topic = topics::camera_frames("old");
        let mut sub = bus.frame_subscriber(&topic).unwrap();
        sub.set_early_wake(Duration::from_millis(2)).unwrap();
        let mut publ = bus.frame_publisher(&topic, 64).unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for _ in 0..3 {
                let got = sub.recv_blocking_with(None, |h, _| h.frame_seq).unwrap();
                tx.send((got, sub.early_wake())).unwrap();
            }
        });
        for seq in 1..=3 {
            // Let the receiver fall asleep first (it may not have; then the frame
            // is pending when it looks, which proves nothing but breaks nothing).
            std::thread::sleep(Duration::from_millis(50));
            publish_unannounced(&mut publ, seq);
            let (got, stats) = rx
                .recv_timeout(Duration::from_secs(30))
                .expect("the receiver woke for the unannounced frame");
            assert_eq!(got, Some(seq));
            // No frame was announced, so none was polled for.
            assert_eq!(stats, Some(EarlyWakeStats { polls: 0, hits: 0 }));
        }
    }
}
