//! The router hub: moves frames between the autopilot link and the endpoints by
//! the decisions of [`crate::router`], without ever waiting (bounded queues or
//! non-blocking UDP sends, drop and count), and the router's metrics.
//!
//! Frames for a UDP endpoint are sent by whoever routes them (the link's reader
//! for the autopilot's telemetry) with a non-blocking `send_to` on the endpoint's
//! socket ([`UdpSink`]): no queue and no tokio wake-up per frame.
//! TCP endpoints keep a bounded queue drained by their task.
//!
//! | metric | labels |
//! |---|---|
//! | `skymesh_router_frames_total` | `endpoint`, `direction` (`in`: valid frames received; `out`: frames written, once per peer) |
//! | `skymesh_router_frames_dropped_total` | `endpoint`, `reason` ([`DropReason`]) |
//! | `skymesh_router_endpoint_peers` | `endpoint` |
//!
//! `endpoint` is the configured endpoint (with the bound port for `udpin`/`tcpin`),
//! `autopilot` for frames forwarded to the autopilot and its malformed input, or
//! `gimbal_v2` for frames delivered to the virtual gimbals ([`Hub::attach_local`]).
//! Every series is registered on first use: an endpoint costs between 0 and 8 of
//! the stats sample's 384 entries (at most 8 endpoints).

use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

use skymesh_runtime::{Counter, Gauge, Stats};
use tokio::sync::mpsc;

use crate::config::Endpoint;
use crate::endpoints::UdpSink;
use crate::link::{Outbox, WriteError};
use crate::router::{Learned, Link, Router};
use mavlink_frame::RawFrame;

/// Label values longer than this (with the key and the other label) would not fit
/// the stats sample's 72-byte label field: such endpoints are labelled `#<index>`.
const MAX_LABEL: usize = 40;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Why a frame was not delivered (label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropReason {
    /// The destination's queue (or UDP socket send buffer) was full: it is slower
    /// than the traffic.
    QueueFull,
    /// Input that was not a MAVLink frame (junk, bad checksum): counted per resync.
    Malformed,
    /// The socket refused the frame.
    SendError,
    /// A frame from an endpoint with the autopilot's or our own source id.
    Loop,
    /// For the autopilot while its link is down.
    LinkDown,
    /// A `udpout` destination nothing listens at (it answered with ICMP port
    /// unreachable): it gets one frame a second until it listens again.
    NotListening,
}

impl DropReason {
    const ALL: [DropReason; 6] = [
        DropReason::QueueFull,
        DropReason::Malformed,
        DropReason::SendError,
        DropReason::Loop,
        DropReason::LinkDown,
        DropReason::NotListening,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            DropReason::QueueFull => "queue_full",
            DropReason::Malformed => "malformed",
            DropReason::SendError => "send_error",
            DropReason::Loop => "loop",
            DropReason::LinkDown => "link_down",
            DropReason::NotListening => "not_listening",
        }
    }
}

/// The series of one endpoint (or of the autopilot side, label `autopilot`), each
/// registered on first use so that idle endpoints cost none of the stats sample's
/// 384 entries.
#[derive(Debug)]
pub struct EndpointMetrics {
    stats: Stats,
    label: String,
    frames_in: OnceLock<Counter>,
    frames_out: OnceLock<Counter>,
    peers: OnceLock<Gauge>,
    dropped: [OnceLock<Counter>; DropReason::ALL.len()],
}

impl EndpointMetrics {
    pub(crate) fn new(stats: &Stats, label: String) -> Self {
        EndpointMetrics {
            stats: stats.clone(),
            label,
            frames_in: OnceLock::new(),
            frames_out: OnceLock::new(),
            peers: OnceLock::new(),
            dropped: Default::default(),
        }
    }

    fn frames(&self, direction: &'static str) -> &Counter {
        let cell = if direction == "in" {
            &self.frames_in
        } else {
            &self.frames_out
        };
        cell.get_or_init(|| {
            self.stats.counter(
                "skymesh_router_frames_total",
                &[("endpoint", &self.label), ("direction", direction)],
            )
        })
    }

    /// `skymesh_router_frames_total{direction="in"}`: valid frames received.
    pub fn frame_in(&self) {
        self.frames("in").inc();
    }

    /// `skymesh_router_frames_total{direction="out"}`: frames written (once per peer).
    pub fn frame_out(&self) {
        self.frames("out").inc();
    }

    /// `skymesh_router_frames_dropped_total{reason}`.
    pub fn dropped(&self, reason: DropReason, n: u64) {
        let i = DropReason::ALL
            .iter()
            .position(|r| *r == reason)
            .unwrap_or(0);
        self.dropped[i]
            .get_or_init(|| {
                self.stats.counter(
                    "skymesh_router_frames_dropped_total",
                    &[("endpoint", &self.label), ("reason", reason.as_str())],
                )
            })
            .add(n);
    }

    /// `skymesh_router_endpoint_peers`: peers being sent to now.
    pub fn peers(&self, n: usize) {
        self.peers
            .get_or_init(|| {
                self.stats.gauge(
                    "skymesh_router_endpoint_peers",
                    &[("endpoint", &self.label)],
                )
            })
            .set(n as f64);
    }

    pub fn label(&self) -> &str {
        &self.label
    }
}

/// The label of endpoint `index`: its configured string, or `#<index>` if too long.
pub fn label(index: usize, endpoint: &Endpoint) -> String {
    let s = endpoint.to_string();
    if s.len() <= MAX_LABEL {
        s
    } else {
        format!("#{index}")
    }
}

#[derive(Debug)]
struct Port {
    /// A TCP endpoint's queue (drained by its task); `None` for a UDP endpoint.
    queue: Option<mpsc::Sender<RawFrame>>,
    /// A UDP endpoint's socket while it is open (set and cleared by its task);
    /// frames routed to the endpoint while there is none are dropped uncounted,
    /// as there is nobody to send them to.
    udp: Mutex<Option<Arc<UdpSink>>>,
    metrics: EndpointMetrics,
}

/// Moves frames between the autopilot link and the endpoints. Shared (in an `Arc`)
/// by the link's reader and writer threads and every endpoint task; every method
/// returns without waiting.
#[derive(Debug)]
pub struct Hub {
    router: Mutex<Router>,
    ports: Vec<Port>,
    /// The open autopilot connection's forward queue; `None` while the link is down.
    autopilot: Mutex<Option<Arc<Outbox>>>,
    autopilot_metrics: EndpointMetrics,
    /// The virtual gimbals' inbox (the service's event loop drains it), once attached.
    local: Mutex<Option<mpsc::Sender<RawFrame>>>,
    local_metrics: EndpointMetrics,
    /// The flight log's tap on the autopilot link ([`crate::tlog`]), if `[tlog]` is on.
    tlog: OnceLock<crate::tlog::Tap>,
}

/// Messages addressed to a whole system (or broadcast) that the virtual gimbals
/// take: GIMBAL_MANAGER_SET_ATTITUDE and GIMBAL_MANAGER_SET_PITCHYAW (their
/// `gimbal_device_id` says which gimbal). Commands are only taken when addressed to
/// a virtual component: a broadcast command is the autopilot's to answer.
const LOCAL_BROADCAST_IDS: [u32; 2] = [282, 287];

impl Hub {
    /// `ports`: each endpoint's queue (drained by its task; `None` for a UDP
    /// endpoint, which sends directly once it calls [`Hub::set_udp_sink`]) and series.
    pub(crate) fn new(
        local: (u8, u8),
        ports: Vec<(Option<mpsc::Sender<RawFrame>>, EndpointMetrics)>,
        stats: &Stats,
    ) -> Hub {
        let ports: Vec<Port> = ports
            .into_iter()
            .map(|(queue, metrics)| Port {
                queue,
                udp: Mutex::new(None),
                metrics,
            })
            .collect();
        Hub {
            router: Mutex::new(Router::new(ports.len(), local)),
            ports,
            autopilot: Mutex::new(None),
            autopilot_metrics: EndpointMetrics::new(stats, "autopilot".to_string()),
            local: Mutex::new(None),
            local_metrics: EndpointMetrics::new(stats, "gimbal_v2".to_string()),
            tlog: OnceLock::new(),
        }
    }

    /// Records the autopilot link's traffic into a flight log from now on.
    pub(crate) fn set_tlog(&self, tap: crate::tlog::Tap) {
        let _ = self.tlog.set(tap);
    }

    /// Serves `components` of our system locally: frames from endpoints addressed to
    /// them (and broadcast gimbal-manager messages) go into `inbox` instead of to
    /// the autopilot.
    pub fn attach_local(&self, components: &[u8], inbox: mpsc::Sender<RawFrame>) {
        let mut router = lock(&self.router);
        for c in components {
            router.add_local_component(*c);
        }
        *lock(&self.local) = Some(inbox);
    }

    fn to_local(&self, frame: &RawFrame) {
        let targeted = matches!(frame.target(), mavlink_frame::Target::Component(..));
        if !targeted && !LOCAL_BROADCAST_IDS.contains(&frame.message_id()) {
            return;
        }
        let Some(tx) = lock(&self.local).clone() else {
            return;
        };
        match tx.try_send(*frame) {
            Ok(()) => self.local_metrics.frame_out(),
            Err(mpsc::error::TrySendError::Full(_)) => {
                self.local_metrics.dropped(DropReason::QueueFull, 1);
            }
            Err(mpsc::error::TrySendError::Closed(_)) => {}
        }
    }

    /// A hub without endpoints (frames from the autopilot go nowhere).
    pub fn detached(local: (u8, u8)) -> Arc<Hub> {
        Arc::new(Hub::new(local, Vec::new(), &Stats::new()))
    }

    /// The link opened a connection: forward endpoint traffic into `outbox`.
    pub fn attach(&self, outbox: Arc<Outbox>) {
        *lock(&self.autopilot) = Some(outbox);
        if let Some(tlog) = self.tlog.get() {
            tlog.connected();
        }
    }

    /// The connection closed.
    pub fn detach(&self) {
        *lock(&self.autopilot) = None;
        if let Some(tlog) = self.tlog.get() {
            tlog.disconnected();
        }
    }

    /// A frame read from the autopilot: to every endpoint.
    pub fn from_autopilot(&self, frame: &RawFrame) {
        if let Some(tlog) = self.tlog.get() {
            tlog.from_autopilot(frame);
        }
        if self.ports.is_empty() {
            return;
        }
        let to = {
            let mut router = lock(&self.router);
            router.learn(Link::Autopilot, (frame.system_id(), frame.component_id()));
            router.route(Link::Autopilot, frame.target())
        };
        for i in to.endpoints() {
            self.to_endpoint(i, frame);
        }
    }

    /// Our own frame (the heartbeat of component 191 after it went to the autopilot,
    /// or a virtual gimbal's traffic): to every endpoint.
    pub fn from_local(&self, frame: &RawFrame) {
        if frame.component_id() == crate::requests::OWN_COMPONENT {
            if let Some(tlog) = self.tlog.get() {
                tlog.to_autopilot(frame);
            }
        }
        if self.ports.is_empty() {
            return;
        }
        let to = lock(&self.router).route(Link::Local, frame.target());
        for i in to.endpoints() {
            self.to_endpoint(i, frame);
        }
    }

    /// A frame received on endpoint `index`.
    pub fn from_endpoint(&self, index: u8, frame: &RawFrame) {
        let Some(port) = self.ports.get(usize::from(index)) else {
            return;
        };
        port.metrics.frame_in();
        let link = Link::Endpoint(index);
        let to = {
            let mut router = lock(&self.router);
            if router.learn(link, (frame.system_id(), frame.component_id())) == Learned::Loop {
                drop(router);
                port.metrics.dropped(DropReason::Loop, 1);
                tracing::debug!(
                    endpoint = port.metrics.label(),
                    ?frame,
                    "dropping a frame with the autopilot's or our own source id (loop)"
                );
                return;
            }
            router.route(link, frame.target())
        };
        if to.local {
            self.to_local(frame);
        }
        if to.autopilot {
            self.to_autopilot(frame);
        }
        for i in to.endpoints() {
            self.to_endpoint(i, frame);
        }
    }

    fn to_endpoint(&self, index: u8, frame: &RawFrame) {
        let Some(port) = self.ports.get(usize::from(index)) else {
            return;
        };
        match &port.queue {
            Some(tx) => {
                if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send(*frame) {
                    port.metrics.dropped(DropReason::QueueFull, 1);
                }
            }
            None => {
                let sink = lock(&port.udp).clone();
                if let Some(sink) = sink {
                    sink.send(frame, &port.metrics);
                }
            }
        }
    }

    /// UDP endpoint `index` opened its socket (`Some`: frames routed to it are sent
    /// on `sink` from now on) or closed it (`None`).
    pub(crate) fn set_udp_sink(&self, index: u8, sink: Option<Arc<UdpSink>>) {
        if let Some(port) = self.ports.get(usize::from(index)) {
            *lock(&port.udp) = sink;
        }
    }

    /// One of our own frames (a command, a setpoint, a stream request) written to
    /// the autopilot: into the flight log only; the endpoints see the vehicle's answers.
    pub fn own_written(&self, frame: &RawFrame) {
        if let Some(tlog) = self.tlog.get() {
            tlog.to_autopilot(frame);
        }
    }

    fn to_autopilot(&self, frame: &RawFrame) {
        let outbox = lock(&self.autopilot).clone();
        let result = match outbox {
            Some(outbox) => outbox.forward(frame),
            None => Err(WriteError::Closed),
        };
        match result {
            Ok(()) => {
                if let Some(tlog) = self.tlog.get() {
                    tlog.to_autopilot(frame);
                }
            }
            Err(WriteError::Congested) => self.autopilot_metrics.dropped(DropReason::QueueFull, 1),
            Err(WriteError::Closed) => self.autopilot_metrics.dropped(DropReason::LinkDown, 1),
        }
    }

    /// The link's writer wrote a forwarded frame to the autopilot.
    pub fn forwarded_to_autopilot(&self) {
        if !self.ports.is_empty() {
            self.autopilot_metrics.frame_out();
        }
    }

    /// The autopilot link skipped `n` runs of input that were not MAVLink.
    pub fn autopilot_malformed(&self, n: u64) {
        self.autopilot_metrics.dropped(DropReason::Malformed, n);
    }

    /// The series of endpoint `index` (< the number of endpoints).
    pub(crate) fn metrics(&self, index: u8) -> &EndpointMetrics {
        &self.ports[usize::from(index)].metrics
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_endpoint_strings_get_an_index_label() {
        let short = Endpoint::parse("e", "udpout:127.0.0.1:14550").unwrap();
        assert_eq!(label(0, &short), "udpout:127.0.0.1:14550");
        let long = Endpoint::parse(
            "e",
            "tcpout:a-rather-long-ground-station-name.example.org:5760",
        )
        .unwrap();
        assert_eq!(label(3, &long), "#3");
    }

    #[test]
    fn drops_and_frames_register_series_on_first_use() {
        let stats = Stats::new();
        let m = EndpointMetrics::new(&stats, "udpin:127.0.0.1:14560".into());
        let mut out = Box::<skymesh_ipc_types::ServiceStats>::default();
        stats.snapshot_into(&mut out);
        assert_eq!(out.entries().len(), 0);
        m.frame_in();
        m.frame_in();
        m.dropped(DropReason::QueueFull, 3);
        m.peers(2);
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        assert_eq!(
            find(
                "skymesh_router_frames_total",
                "endpoint=udpin:127.0.0.1:14560,direction=in"
            ),
            Some(2.0)
        );
        assert_eq!(
            find(
                "skymesh_router_frames_dropped_total",
                "endpoint=udpin:127.0.0.1:14560,reason=queue_full"
            ),
            Some(3.0)
        );
        assert_eq!(
            find(
                "skymesh_router_endpoint_peers",
                "endpoint=udpin:127.0.0.1:14560"
            ),
            Some(2.0)
        );
        assert_eq!(out.entries().len(), 3);
    }
}
