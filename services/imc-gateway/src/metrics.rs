//! The metrics of imc-gateway, exported through the runtime's stats sample.
//!
//! Label sets are bounded: `message` is one of the IMC abbreviations this gateway
//! implements, `reason` one of the drop reasons listed in `deploy/imc-gateway.toml`
//! (decode error kinds, refusal and hardware result names from closed enums).
//! Labelled series are registered on first use: a service has 128 series in its
//! stats sample.

use skymesh_runtime::{Counter, Gauge, Stats};

/// Which way a message went (label `direction`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// From a peer, accepted.
    In,
    /// Sent to a peer.
    Out,
}

impl Direction {
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::In => "in",
            Direction::Out => "out",
        }
    }
}

/// Every series imc-gateway exports. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Metrics {
    stats: Stats,
    /// `skymesh_imc_peers`: peers that get heartbeats now (static ones included).
    pub peers: Gauge,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        Metrics {
            stats: stats.clone(),
            peers: stats.gauge("skymesh_imc_peers", &[]),
        }
    }

    /// `skymesh_imc_messages_total{direction,message}`.
    pub fn message(&self, direction: Direction, message: &'static str) {
        self.counter(
            "skymesh_imc_messages_total",
            &[("direction", direction.as_str()), ("message", message)],
        )
        .inc();
    }

    /// `skymesh_imc_dropped_total{reason}`.
    pub fn dropped(&self, reason: &'static str) {
        self.counter("skymesh_imc_dropped_total", &[("reason", reason)])
            .inc();
    }

    /// `skymesh_imc_send_errors_total{message}`: a datagram the socket would not send.
    pub fn send_error(&self, message: &'static str) {
        self.counter("skymesh_imc_send_errors_total", &[("message", message)])
            .inc();
    }

    /// `skymesh_imc_bus_samples_total{kind}`: commands, hardware requests and button
    /// events published (`command`, `hardware_request`, `button`).
    pub fn published(&self, kind: &'static str) {
        self.counter("skymesh_imc_bus_samples_total", &[("kind", kind)])
            .inc();
    }

    fn counter(&self, name: &str, labels: &[(&str, &str)]) -> Counter {
        self.stats.counter(name, labels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn series_are_registered_on_first_use() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.message(Direction::In, "SetPWM");
        m.message(Direction::In, "SetPWM");
        m.dropped("bad_crc");
        m.peers.set(2.0);
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        assert_eq!(
            find("skymesh_imc_messages_total", "direction=in,message=SetPWM"),
            Some(2.0)
        );
        assert_eq!(
            find("skymesh_imc_dropped_total", "reason=bad_crc"),
            Some(1.0)
        );
        assert_eq!(find("skymesh_imc_dropped_total", "reason=not_for_us"), None);
        assert_eq!(find("skymesh_imc_peers", ""), Some(2.0));
    }
}
