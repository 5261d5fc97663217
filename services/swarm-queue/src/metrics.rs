//! The metrics of the swarm queue (`skymesh_swarm_*`), exported through the
//! runtime's stats sample.
//!
//! Registered before the bus ports are opened, so they come first in the stats
//! sample. The per-vehicle ports are counted as topic families
//! (`skymesh/vehicle/*/state`, …: about twenty series whatever the swarm size), so
//! at 250 drones the queue depths (250), the tick histogram and the
//! `commands_total` series (registered on first use; label values are bounded:
//! command kinds from the ipc-types enum, results from `SwarmResult`) all fit the
//! sample's 384 series.

use skymesh_ipc_types::{SwarmCommandKind, SwarmResult};
use skymesh_runtime::stats::LATENCY_BOUNDS_S;
use skymesh_runtime::{Counter, CounterFamily, Gauge, Histogram, Stats};

/// Every series the queue exports.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_swarm_queue_depth{drone}`: commands waiting behind the current one,
    /// by drone (index = the drone's position in the configuration).
    pub queue_depth: Vec<Gauge>,
    /// `skymesh_swarm_commands_total{kind,outcome}`: replies by command kind and
    /// result (`success`, `timeout`, `refused`, `idle_state`).
    commands: CounterFamily,
    /// `skymesh_swarm_tick_seconds`: duration of one queue tick (drain, step every
    /// drone, publish).
    pub tick_seconds: Histogram,
    /// `skymesh_swarm_tick_overruns_total`: ticks longer than the tick period, or
    /// started more than a period late.
    pub overruns: Counter,
    /// `skymesh_swarm_replies_dropped_total`: replies dropped because too many
    /// were waiting to be published.
    pub replies_dropped: Counter,
    /// `skymesh_swarm_commands_received_total`: `SwarmCommand` samples received.
    pub received: Counter,
    /// `skymesh_swarm_drones_flying`: drones armed and off the ground.
    pub flying: Gauge,
    /// `skymesh_swarm_resting`: 1 while the queue ticks once a second (nothing to
    /// fly, no reader watching its state), 0 while it ticks at `tick_hz`.
    pub resting: Gauge,
}

impl Metrics {
    /// The series for drones `ids` (in configuration order).
    pub fn new(stats: &Stats, ids: &[u16]) -> Self {
        Metrics {
            tick_seconds: stats.histogram("skymesh_swarm_tick_seconds", &[], &LATENCY_BOUNDS_S),
            overruns: stats.counter("skymesh_swarm_tick_overruns_total", &[]),
            replies_dropped: stats.counter("skymesh_swarm_replies_dropped_total", &[]),
            received: stats.counter("skymesh_swarm_commands_received_total", &[]),
            flying: stats.gauge("skymesh_swarm_drones_flying", &[]),
            resting: stats.gauge("skymesh_swarm_resting", &[]),
            queue_depth: ids
                .iter()
                .map(|id| stats.gauge("skymesh_swarm_queue_depth", &[("drone", &id.to_string())]))
                .collect(),
            commands: CounterFamily::new(
                stats,
                "skymesh_swarm_commands_total",
                ("kind", Some("outcome")),
            ),
        }
    }

    /// Counts one reply.
    pub fn reply(&self, kind: Option<SwarmCommandKind>, result: SwarmResult) {
        self.commands
            .get(
                kind.map_or("unknown", SwarmCommandKind::as_str),
                result.as_str(),
            )
            .inc();
    }
}
