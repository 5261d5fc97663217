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

use std::sync::Mutex;
use std::time::Instant;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use skymesh_ipc_types::{FrameHeader, FrameHeaderError, Topic};

use crate::clock::monotonic_ns;
use crate::ipc::{ipc_err, with_qos, with_retry, Bus, IpcError, ReceiveCounts, SocketWait, Svc};
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
        let notifier = self.notifier(topic)?;
        let origin = self.origin();
        Ok(FramePublisher {
            port,
            pubsub,
            notifier,
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
    /// drained with [`FrameSubscriber::try_recv_with`].
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
    notifier: Notifier<Svc>,
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
        sample
            .send()
            .map_err(|e| ipc_err("send frame", &self.topic, e))?;
        self.seq = seq;
        self.notifier
            .notify()
            .map_err(|e| ipc_err("notify", &self.topic, e))?;
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

/// Receives frames of one stream, read in place in shared memory.
pub struct FrameSubscriber {
    /// The stream's event, which the receives wait on.
    socket: SocketWait,
    port: iceoryx2::port::subscriber::Subscriber<Svc, [u8], FrameHeader>,
    counts: ReceiveCounts,
    invalid: Counter,
    warn: Mutex<WarnLimiter<&'static str>>,
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
    /// (see `Notifications` in `ipc`).
    fn settle(&self) -> Result<(), IpcError> {
        self.socket.settle_async(&self.topic)
    }

    /// Waits until frames may be pending (see `wait_listener` in `ipc`).
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
        self.counts.count(&h.header);
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}
