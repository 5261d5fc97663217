//! A service's handle on the mesh ([`Bus`]) and how a topic's iceoryx2 services are
//! opened through it.

use std::sync::Arc;
use std::time::Duration;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use skymesh_ipc_types::{Sample, SampleHeader, ServiceId, Topic};

use super::{ipc_err, Domain, IpcError, Svc};
use crate::stats::Stats;

/// `topic`'s event service of service kind `S` on `node`, created if needed.
fn open_event_of<S: iceoryx2::service::Service>(
    node: &Node<S>,
    topic: &Topic,
    op: &'static str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, IpcError> {
    let service_name =
        ServiceName::new(&topic.name).map_err(|e| ipc_err("service name", &topic.name, e))?;
    with_retry(node, &topic.name, op, || {
        node.service_builder(&service_name)
            .event()
            .max_listeners(topic.qos.event_listeners())
            .max_notifiers(topic.qos.event_notifiers())
            .max_nodes(topic.qos.max_nodes)
            // One event id (0): a listener's drain resets every id's counter in
            // shared memory, 256 atomic swaps over 2 KiB with iceoryx2's default
            // (255) — per wake-up, in every process.
            .event_id_max_value(0)
            .open_or_create()
    })
}

struct BusInner {
    node: Node<Svc>,
    name: String,
    service: ServiceId,
    instance: u16,
    stats: Stats,
}

/// A service's handle on the mesh: its iceoryx2 node plus the stats registry that
/// counts every sample in and out. Cheap to clone.
#[derive(Clone)]
pub struct Bus {
    inner: Arc<BusInner>,
}

impl core::fmt::Debug for Bus {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Bus")
            .field("name", &self.inner.name)
            .field("service", &self.inner.service)
            .finish()
    }
}

/// Retries `open` a few times, cleaning dead nodes in between: many processes
/// restarting at once can race stale-resource cleanup (iceoryx2 issue #1578).
pub(crate) fn with_retry<S: iceoryx2::service::Service, T, E: core::fmt::Debug>(
    node: &Node<S>,
    what: &str,
    op: &'static str,
    mut open: impl FnMut() -> Result<T, E>,
) -> Result<T, IpcError> {
    let mut delay = Duration::from_millis(20);
    let mut attempt = 0;
    loop {
        match open() {
            Ok(v) => return Ok(v),
            Err(e) if attempt < 5 => {
                tracing::debug!(what, op, error = ?e, attempt, "iceoryx2 open failed, cleaning dead nodes and retrying");
                let _ = node.try_cleanup_dead_nodes();
                std::thread::sleep(delay);
                delay *= 2;
                attempt += 1;
            }
            Err(e) => return Err(ipc_err(op, what, e)),
        }
    }
}

/// `topic`'s publish-subscribe service, opened (or created) through `node`.
fn open_pubsub_on<T: Sample>(
    node: &Node<Svc>,
    topic: &Topic,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>, IpcError> {
    let service_name =
        ServiceName::new(&topic.name).map_err(|e| ipc_err("service name", &topic.name, e))?;
    with_retry(node, &topic.name, "open publish-subscribe", || {
        with_qos(
            node.service_builder(&service_name).publish_subscribe::<T>(),
            topic,
        )
        .open_or_create()
    })
}

/// A publish-subscribe service's settings from `topic`'s QoS: every topic's, samples
/// and frames alike (a newest-first ring: a slow subscriber loses the oldest).
pub(crate) fn with_qos<P, H, S>(
    builder: iceoryx2::service::builder::publish_subscribe::Builder<P, H, S>,
    topic: &Topic,
) -> iceoryx2::service::builder::publish_subscribe::Builder<P, H, S>
where
    P: core::fmt::Debug + IceoryxSend + ?Sized,
    H: core::fmt::Debug + ZeroCopySend,
    S: iceoryx2::service::Service,
{
    let q = topic.qos;
    builder
        .max_publishers(q.max_publishers)
        .max_subscribers(q.max_subscribers)
        .max_nodes(q.max_nodes)
        .history_size(q.history)
        .subscriber_max_buffer_size(q.buffer)
        .enable_safe_overflow(true)
}

impl Bus {
    /// Creates the node `name` in `domain`. Signal handling stays with the caller.
    pub fn open(
        domain: &Domain,
        name: &str,
        service: ServiceId,
        instance: u16,
        stats: Stats,
    ) -> Result<Bus, IpcError> {
        let node_name = NodeName::new(name).map_err(|e| ipc_err("node name", name, e))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&domain.config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Svc>()
            .map_err(|e| ipc_err("create node", name, e))?;
        Ok(Bus {
            inner: Arc::new(BusInner {
                node,
                name: name.to_string(),
                service,
                instance,
                stats,
            }),
        })
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// The iceoryx2 node, for the other port kinds of this crate (frames).
    pub(crate) fn node(&self) -> &Node<Svc> {
        &self.inner.node
    }

    pub fn stats(&self) -> &Stats {
        &self.inner.stats
    }

    /// The header fields every publisher of this bus stamps (`service`, `instance`;
    /// sequence and time zero): what an answer addressed to this process carries
    /// (e.g. `HardwareReply::answers`).
    pub fn origin(&self) -> SampleHeader {
        SampleHeader {
            service: self.inner.service.to_wire(),
            instance: self.inner.instance,
            ..SampleHeader::default()
        }
    }

    pub(crate) fn open_event(
        &self,
        topic: &Topic,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, IpcError> {
        open_event_of(&self.inner.node, topic, "open event")
    }

    /// A publisher's notifier of `topic`'s event (with nobody waiting, a notify is
    /// a few atomic operations).
    pub(crate) fn notifier(&self, topic: &Topic) -> Result<Notifier<Svc>, IpcError> {
        self.open_event(topic)?
            .notifier_builder()
            .create()
            .map_err(|e| ipc_err("create notifier", &topic.name, e))
    }

    pub(super) fn open_pubsub<T: Sample>(
        &self,
        topic: &Topic,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>, IpcError>
    {
        open_pubsub_on(&self.inner.node, topic)
    }
}
