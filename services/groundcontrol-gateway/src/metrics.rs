//! The metrics of groundcontrol-gateway, exported through the runtime's stats sample.
//!
//! Label sets are bounded: record types are `gc-proto` labels of the known types or
//! `unknown` (registered on first use), reasons and results are the enums below.

use gc_proto::NetCmdType;
use skymesh_runtime::{Counter, CounterFamily, Gauge, Stats};

use crate::inbound::RefuseReason;

/// How a connection attempt ended (label `result` of `skymesh_gc_connections_total`).
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

/// Why a connection ended (label `reason` of `skymesh_gc_disconnects_total`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DisconnectReason {
    /// The client closed between records.
    Closed,
    /// The client closed inside a record (the partial record is dropped).
    Truncated,
    /// The client stopped reading and its outgoing queue filled.
    Overflow,
    /// A record stayed incomplete for `partial_record_timeout_s` (slow-loris).
    PartialRecordTimeout,
    /// The connection failed.
    Io,
    /// The gateway is stopping.
    Shutdown,
}

impl DisconnectReason {
    pub fn as_str(self) -> &'static str {
        match self {
            DisconnectReason::Closed => "closed",
            DisconnectReason::Truncated => "truncated",
            DisconnectReason::Overflow => "overflow",
            DisconnectReason::PartialRecordTimeout => "partial_record_timeout",
            DisconnectReason::Io => "io",
            DisconnectReason::Shutdown => "shutdown",
        }
    }
}

/// Why a `SwarmReply` for a client was not written (label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplyDrop {
    /// The client has disconnected (or never was ours).
    ClientGone,
    /// The client's outgoing queue was full: the client is closed.
    Overflow,
    /// A result value the gateway does not know.
    Invalid,
}

impl ReplyDrop {
    fn as_str(self) -> &'static str {
        match self {
            ReplyDrop::ClientGone => "client_gone",
            ReplyDrop::Overflow => "overflow",
            ReplyDrop::Invalid => "invalid",
        }
    }
}

/// Why a broadcast tick sent nothing (label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BroadcastSkip {
    /// No `SwarmState` received yet.
    NoState,
    /// The latest `SwarmState` is older than `state_timeout_s`.
    Stale,
    /// One destination's datagram not sent: nothing listens there (it answered an
    /// earlier one with ICMP port unreachable) and its once-a-second probe is not
    /// due. Counted per destination, not per tick.
    NotListening,
}

impl BroadcastSkip {
    fn as_str(self) -> &'static str {
        match self {
            BroadcastSkip::NoState => "no_state",
            BroadcastSkip::Stale => "stale",
            BroadcastSkip::NotListening => "not_listening",
        }
    }
}

/// The metric label of a record type.
pub fn type_label(kind: i32) -> &'static str {
    NetCmdType::from_i32(kind).map_or("unknown", NetCmdType::label)
}

/// Every series groundcontrol-gateway exports. Cheap to clone; shared by every task.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_gc_clients`: state-server clients connected now.
    pub clients: Gauge,
    connections: CounterFamily,
    disconnects: CounterFamily,
    records_in: CounterFamily,
    records_out: CounterFamily,
    refused: CounterFamily,
    /// `skymesh_gc_commands_published_total`: `SwarmCommand`s sent to the queue.
    pub commands_published: Counter,
    queue_replies: CounterFamily,
    replies_dropped: CounterFamily,
    /// `skymesh_gc_broadcast_datagrams_total`: pose datagrams sent (per destination).
    pub broadcast_datagrams: Counter,
    /// `skymesh_gc_broadcast_bytes_total`.
    pub broadcast_bytes: Counter,
    /// `skymesh_gc_broadcast_errors_total`: sends that failed.
    pub broadcast_errors: Counter,
    /// `skymesh_gc_broadcast_drones`: records in the last datagram.
    pub broadcast_drones: Gauge,
    broadcast_skipped: CounterFamily,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        let family = |name, key| CounterFamily::new(stats, name, (key, None));
        Metrics {
            clients: stats.gauge("skymesh_gc_clients", &[]),
            connections: family("skymesh_gc_connections_total", "result"),
            disconnects: family("skymesh_gc_disconnects_total", "reason"),
            records_in: family("skymesh_gc_records_in_total", "type"),
            records_out: family("skymesh_gc_records_out_total", "type"),
            refused: family("skymesh_gc_refused_total", "reason"),
            commands_published: stats.counter("skymesh_gc_commands_published_total", &[]),
            queue_replies: family("skymesh_gc_queue_replies_total", "result"),
            replies_dropped: family("skymesh_gc_replies_dropped_total", "reason"),
            broadcast_datagrams: stats.counter("skymesh_gc_broadcast_datagrams_total", &[]),
            broadcast_bytes: stats.counter("skymesh_gc_broadcast_bytes_total", &[]),
            broadcast_errors: stats.counter("skymesh_gc_broadcast_errors_total", &[]),
            broadcast_drones: stats.gauge("skymesh_gc_broadcast_drones", &[]),
            broadcast_skipped: family("skymesh_gc_broadcast_skipped_total", "reason"),
        }
    }

    pub fn connection(&self, result: ConnectionResult) {
        self.connections.inc(result.as_str());
    }

    pub fn disconnect(&self, reason: DisconnectReason) {
        self.disconnects.inc(reason.as_str());
    }

    /// One record from a client, whatever became of it.
    pub fn record_in(&self, kind: i32) {
        self.records_in.inc(type_label(kind));
    }

    /// One record written to a client.
    pub fn record_out(&self, kind: i32) {
        self.records_out.inc(type_label(kind));
    }

    pub fn refused(&self, reason: RefuseReason) {
        self.refused.inc(reason.as_str());
    }

    /// One `SwarmReply` for one of our clients, by its result label.
    pub fn queue_reply(&self, result: &'static str) {
        self.queue_replies.inc(result);
    }

    pub fn reply_dropped(&self, reason: ReplyDrop) {
        self.replies_dropped.inc(reason.as_str());
    }

    pub fn broadcast_skipped(&self, reason: BroadcastSkip) {
        self.broadcast_skipped.inc(reason.as_str());
    }

    /// Counts what a tick every `period` would have counted over a `span` the
    /// broadcast did not tick: `per_tick` skips (`reason`) per tick.
    pub fn broadcast_ticks_skipped(
        &self,
        reason: BroadcastSkip,
        span: std::time::Duration,
        period: std::time::Duration,
        per_tick: usize,
    ) {
        let ticks = span.as_nanos() / period.as_nanos().max(1);
        let n = u64::try_from(ticks.saturating_mul(per_tick as u128)).unwrap_or(u64::MAX);
        if n > 0 {
            self.broadcast_skipped.add(reason.as_str(), n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn labels_are_bounded_and_registered_on_use() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.record_in(0xA6);
        m.record_in(0x7777);
        m.record_in(-3);
        m.refused(RefuseReason::NotPrivileged);
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        assert_eq!(
            find("skymesh_gc_records_in_total", "type=cmd_ext_waypoint"),
            Some(1.0)
        );
        assert_eq!(
            find("skymesh_gc_records_in_total", "type=unknown"),
            Some(2.0)
        );
        assert_eq!(
            find("skymesh_gc_refused_total", "reason=not_privileged"),
            Some(1.0)
        );
        assert_eq!(find("skymesh_gc_refused_total", "reason=bad_context"), None);
        assert_eq!(find("skymesh_gc_clients", ""), Some(0.0));
    }

    #[test]
    fn reason_names_are_distinct() {
        let mut names: Vec<_> = RefuseReason::ALL.iter().map(|r| r.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), RefuseReason::ALL.len());
    }
}
