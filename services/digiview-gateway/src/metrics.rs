//! The metrics of digiview-gateway, exported through the runtime's stats sample.
//!
//! Label sets are bounded: message types are `digiview-proto` names or `invalid`,
//! refusal reasons are [`Refusal`], results the enums below.

use digiview_proto::MessageType;
use skymesh_runtime::stats::LATENCY_BOUNDS_S;
use skymesh_runtime::{CounterFamily, Gauge, Histogram, Stats};

use crate::refusal::Refusal;

/// How a connection attempt ended (label `result`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConnectionResult {
    Accepted,
    /// `max_clients` were connected already: closed at once.
    RefusedMaxClients,
}

impl ConnectionResult {
    fn as_str(self) -> &'static str {
        match self {
            ConnectionResult::Accepted => "accepted",
            ConnectionResult::RefusedMaxClients => "refused_max_clients",
        }
    }
}

/// Why a connection ended (label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DisconnectReason {
    /// The client closed between frames.
    Closed,
    /// The client closed inside a frame.
    Truncated,
    /// The client sent QUIT.
    Quit,
    /// A frame was begun and not completed within `partial_frame_timeout_s`.
    PartialFrameTimeout,
    /// The client stopped reading and its outgoing queue filled.
    Overflow,
    Io,
    /// The gateway is stopping.
    Shutdown,
}

impl DisconnectReason {
    pub fn as_str(self) -> &'static str {
        match self {
            DisconnectReason::Closed => "closed",
            DisconnectReason::Truncated => "truncated",
            DisconnectReason::Quit => "quit",
            DisconnectReason::PartialFrameTimeout => "partial_frame_timeout",
            DisconnectReason::Overflow => "overflow",
            DisconnectReason::Io => "io",
            DisconnectReason::Shutdown => "shutdown",
        }
    }
}

/// Every series digiview-gateway exports. Cheap to clone; shared by every task.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_digiview_clients`: clients connected now.
    pub clients: Gauge,
    /// `skymesh_digiview_periodic_gets`: periodic GETs active over all clients.
    pub periodic_gets: Gauge,
    /// `skymesh_digiview_pipeline_reply_seconds`: SET forwarded → `VisionReply`.
    pub pipeline_reply: Histogram,
    connections: CounterFamily,
    disconnects: CounterFamily,
    frames_in: CounterFamily,
    replies: CounterFamily,
    refused: CounterFamily,
    set_results: CounterFamily,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        let family = |name, key| CounterFamily::new(stats, name, (key, None));
        Metrics {
            clients: stats.gauge("skymesh_digiview_clients", &[]),
            periodic_gets: stats.gauge("skymesh_digiview_periodic_gets", &[]),
            pipeline_reply: stats.histogram(
                "skymesh_digiview_pipeline_reply_seconds",
                &[],
                &LATENCY_BOUNDS_S,
            ),
            connections: family("skymesh_digiview_connections_total", "result"),
            disconnects: family("skymesh_digiview_disconnects_total", "reason"),
            frames_in: family("skymesh_digiview_frames_in_total", "type"),
            replies: family("skymesh_digiview_replies_total", "type"),
            refused: family("skymesh_digiview_refused_total", "reason"),
            set_results: family("skymesh_digiview_set_results_total", "result"),
        }
    }

    pub fn connection(&self, result: ConnectionResult) {
        self.connections.inc(result.as_str());
    }

    pub fn disconnect(&self, reason: DisconnectReason) {
        self.disconnects.inc(reason.as_str());
    }

    /// One 88-byte frame from a client: its message type, or `invalid` if it failed
    /// its checks.
    pub fn frame_in(&self, message_type: Option<MessageType>) {
        self.frames_in
            .inc(message_type.map_or("invalid", MessageType::name));
    }

    /// One frame written to a client.
    pub fn reply(&self, message_type: MessageType) {
        self.replies.inc(message_type.name());
    }

    pub fn refused(&self, reason: Refusal) {
        self.refused.inc(reason.as_str());
    }

    /// The pipeline's answer to one SET (`result` label of `VisionResult`, or
    /// `timeout`).
    pub fn set_result(&self, result: &'static str) {
        self.set_results.inc(result);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn series_are_registered_on_use() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.frame_in(Some(MessageType::Get));
        m.frame_in(None);
        m.refused(Refusal::BadChecksum);
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        assert_eq!(
            find("skymesh_digiview_frames_in_total", "type=get"),
            Some(1.0)
        );
        assert_eq!(
            find("skymesh_digiview_frames_in_total", "type=invalid"),
            Some(1.0)
        );
        assert_eq!(
            find("skymesh_digiview_refused_total", "reason=bad_checksum"),
            Some(1.0)
        );
        assert_eq!(
            find("skymesh_digiview_refused_total", "reason=forbidden"),
            None
        );
    }
}
