//! Typed publishers: stamp, send, wake the subscribers.

use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::PortFactory as _;
use skymesh_ipc_types::{Sample, Topic};

use super::{ipc_err, Bus, IpcError, Svc};
use crate::clock::monotonic_ns;
use crate::stats::Counter;

impl Bus {
    /// A publisher on `topic` that stamps headers, sends and wakes subscribers.
    pub fn publisher<T: Sample>(&self, topic: &Topic) -> Result<Publisher<T>, IpcError> {
        self.publisher_counted_as(topic, &topic.name)
    }

    /// A publisher whose metrics carry `topic="<family>"` instead of its own name:
    /// for a process with one port per vehicle of a large swarm, so e.g. 250
    /// `skymesh/vehicle/{id}/command` ports are one series
    /// (`skymesh/vehicle/*/command`) and fit the stats sample.
    pub fn publisher_counted_as<T: Sample>(
        &self,
        topic: &Topic,
        family: &str,
    ) -> Result<Publisher<T>, IpcError> {
        let pubsub = self.open_pubsub::<T>(topic)?;
        let port = pubsub
            .publisher_builder()
            .create()
            .map_err(|e| ipc_err("create publisher", &topic.name, e))?;
        let notifier = self.notifier(topic)?;
        let published = self.stats().counter(
            "skymesh_topic_samples_published_total",
            &[("topic", family)],
        );
        let origin = self.origin();
        Ok(Publisher {
            port,
            pubsub,
            notifier,
            seq: 0,
            service: origin.service,
            instance: origin.instance,
            published,
            topic: topic.name.clone(),
            _bus: self.clone(),
        })
    }
}

/// Sends samples of one type on one topic.
pub struct Publisher<T: Sample> {
    port: iceoryx2::port::publisher::Publisher<Svc, T, ()>,
    /// The topic's service, for its port table ([`Publisher::subscribers`]).
    pubsub: iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>,
    notifier: Notifier<Svc>,
    seq: u64,
    service: u16,
    instance: u16,
    published: Counter,
    topic: String,
    _bus: Bus,
}

impl<T: Sample> core::fmt::Debug for Publisher<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Publisher")
            .field("topic", &self.topic)
            .field("seq", &self.seq)
            .finish()
    }
}

impl<T: Sample> Publisher<T> {
    /// Stamps the header (sequence, monotonic time, publisher id), sends, and wakes
    /// the subscribers. Returns the sequence number used.
    pub fn publish(&mut self, sample: T) -> Result<u64, IpcError> {
        self.send(sample, true)
    }

    /// Like [`Publisher::publish`] but without waking anyone: for samples the
    /// subscribers look at on their own schedule (a periodic heartbeat the
    /// supervisor drains once a second), which would otherwise cost each of them a
    /// wake-up per sample.
    pub fn publish_quiet(&mut self, sample: T) -> Result<u64, IpcError> {
        self.send(sample, false)
    }

    fn send(&mut self, mut sample: T, wake: bool) -> Result<u64, IpcError> {
        self.seq += 1;
        let h = sample.header_mut();
        h.seq = self.seq;
        h.stamp_ns = monotonic_ns();
        h.service = self.service;
        h.instance = self.instance;
        self.port
            .send_copy(sample)
            .map_err(|e| ipc_err("send", &self.topic, e))?;
        self.sent(wake)
    }

    fn sent(&mut self, wake: bool) -> Result<u64, IpcError> {
        if wake {
            self.notifier
                .notify()
                .map_err(|e| ipc_err("notify", &self.topic, e))?;
        }
        self.published.inc();
        Ok(self.seq)
    }

    /// Like [`Publisher::publish`], but `fill` writes the sample in place in shared
    /// memory (starting from `T::default()`): for large samples (the stats sample is
    /// ~130 KiB) that must not be copied through the stack.
    pub fn publish_with(&mut self, fill: impl FnOnce(&mut T)) -> Result<u64, IpcError> {
        self.send_with(fill, true)
    }

    /// [`Publisher::publish_with`] without waking anyone (see
    /// [`Publisher::publish_quiet`]).
    pub fn publish_with_quiet(&mut self, fill: impl FnOnce(&mut T)) -> Result<u64, IpcError> {
        self.send_with(fill, false)
    }

    fn send_with(&mut self, fill: impl FnOnce(&mut T), wake: bool) -> Result<u64, IpcError> {
        let mut sample = self
            .port
            .loan()
            .map_err(|e| ipc_err("loan", &self.topic, e))?;
        let value = sample.payload_mut();
        fill(value);
        self.seq += 1;
        let h = value.header_mut();
        h.seq = self.seq;
        h.stamp_ns = monotonic_ns();
        h.service = self.service;
        h.instance = self.instance;
        sample.send().map_err(|e| ipc_err("send", &self.topic, e))?;
        self.sent(wake)
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// How many subscribers the topic has now (every process's, this one's
    /// included): a gateway's way to tell whether the service that answers its
    /// requests is there.
    pub fn subscribers(&self) -> usize {
        self.pubsub.dynamic_config().number_of_subscribers()
    }
}
