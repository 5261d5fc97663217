//! A subscriber for one thread that blocks on one topic: a control loop reading its
//! input at hundreds of Hz to kHz ([`BlockingSubscriber`]).
//!
//! Every other port of the bus is built on iceoryx2's thread-safe service flavour
//! (`ipc_threadsafe`), so tokio tasks can own and move it. That flavour puts each port
//! behind a recursive mutex: a receive locks it three times (connections, receive,
//! the sample's release) and clones and drops a reference count. After 10 ms asleep
//! those lines and their code are cold, and `samples-bench` measured the single-thread
//! flavour (`ipc`, the same shared-memory layout without the mutex) at 0.81 of the
//! thread-safe one's receiver CPU per message at 100 Hz (median of twelve interleaved
//! runs, docs/benchmarks.md). A `BlockingSubscriber` is a port of that flavour, on a
//! node of its own, woken through the topic's event count ([`crate::futex`]).
//!
//! The price is iceoryx2's: the port is neither `Send` nor `Sync`. Create it on the
//! thread that receives (clone the [`Bus`] into the thread, then call
//! [`Bus::blocking_subscriber`] there). It has no async receive: a tokio task uses
//! [`crate::Subscriber`].

use std::time::Duration;

use iceoryx2::prelude::*;
use skymesh_ipc_types::{Sample, Topic};

use crate::futex::{Deadline, TopicWord};
use crate::ipc::{ipc_err, open_pubsub_on, spin_for, take, Bus, IpcError, ReceiveCounts};

/// Receives samples of one type on one topic, on the thread that created it, by
/// blocking in the kernel until one is published (see the module documentation).
/// Counts what it receives in the same series as [`crate::Subscriber`]
/// (`skymesh_topic_samples_received_total`, `…_lost_total`, `…_sample_age_seconds`).
pub struct BlockingSubscriber<T: Sample> {
    // Fields drop in declaration order: the port before the node it was made on.
    port: iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>,
    word: TopicWord,
    counts: ReceiveCounts,
    spin: Duration,
    topic: String,
    _node: Node<ipc::Service>,
    _bus: Bus,
}

impl<T: Sample> core::fmt::Debug for BlockingSubscriber<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("BlockingSubscriber")
            .field("topic", &self.topic)
            .finish()
    }
}

impl Bus {
    /// A [`BlockingSubscriber`] on `topic`, for the calling thread only.
    pub fn blocking_subscriber<T: Sample>(
        &self,
        topic: &Topic,
    ) -> Result<BlockingSubscriber<T>, IpcError> {
        let node_name =
            NodeName::new(self.name()).map_err(|e| ipc_err("node name", self.name(), e))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(self.config())
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| ipc_err("create node", self.name(), e))?;
        let port = open_pubsub_on::<_, T>(&node, topic)?
            .subscriber_builder()
            .create()
            .map_err(|e| ipc_err("create subscriber", &topic.name, e))?;
        Ok(BlockingSubscriber {
            port,
            word: self.topic_word(&topic.name)?,
            counts: ReceiveCounts::new(self.stats(), &topic.name),
            spin: Duration::ZERO,
            topic: topic.name.clone(),
            _node: node,
            _bus: self.clone(),
        })
    }
}

impl<T: Sample> BlockingSubscriber<T> {
    /// Takes one pending sample without waiting.
    pub fn try_recv(&self) -> Result<Option<T>, IpcError> {
        let value = take(&self.port, &self.topic)?;
        if let Some(v) = &value {
            self.counts.count(v.header());
        }
        Ok(value)
    }

    /// Polls shared memory for up to `spin` before every blocking wait, as
    /// [`crate::Subscriber::set_spin`] does. Zero (the default) blocks at once.
    pub fn set_spin(&mut self, spin: Duration) {
        self.spin = spin;
    }

    /// Waits for the next sample: after the optional spin, sleeps on the topic's
    /// event count (one `futex` call per wake-up) until a sample is published.
    /// `None` after `timeout` without a sample; `timeout = None` waits indefinitely.
    pub fn recv_blocking(&self, timeout: Option<Duration>) -> Result<Option<T>, IpcError> {
        let deadline = timeout.map(Deadline::after);
        if let Some(v) = spin_for(self.spin, || self.try_recv())? {
            return Ok(Some(v));
        }
        self.word.recv(deadline, || self.try_recv())
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}
