//! Counters for metrics, shared by `Arc` between [`crate::run`] (which updates
//! them) and whoever exports them (the service's stats sample, tests).

use std::sync::atomic::{AtomicU64, Ordering};

use mavlink::dialects::ardupilotmega::MavResult;

/// Live counters. All are monotonic except `clients_connected`.
#[derive(Debug, Default)]
pub struct SimStats {
    /// Frames decoded from clients.
    pub frames_in: AtomicU64,
    /// Frames queued to links (a UDP link's frame goes to each of its peers).
    pub frames_out: AtomicU64,
    /// Outbound frames dropped because a client was not reading.
    pub frames_dropped: AtomicU64,
    /// Inbound frame candidates rejected (bad checksum, unknown id, bad payload).
    pub bad_frames: AtomicU64,
    /// Inbound bytes skipped while looking for a frame marker.
    pub garbage_bytes: AtomicU64,
    /// TCP clients connected now (UDP peers are not counted).
    pub clients_connected: AtomicU64,
    /// TCP clients / UDP peers seen since start.
    pub clients_total: AtomicU64,
    /// TCP connections refused at `max_clients`.
    pub clients_rejected: AtomicU64,
    /// COMMAND_ACKs sent with MAV_RESULT_ACCEPTED.
    pub commands_accepted: AtomicU64,
    /// … MAV_RESULT_TEMPORARILY_REJECTED.
    pub commands_temporarily_rejected: AtomicU64,
    /// … MAV_RESULT_DENIED.
    pub commands_denied: AtomicU64,
    /// … MAV_RESULT_UNSUPPORTED.
    pub commands_unsupported: AtomicU64,
    /// … MAV_RESULT_FAILED (and any other result).
    pub commands_failed: AtomicU64,
}

/// A plain copy of [`SimStats`] at one instant.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[allow(missing_docs)]
pub struct SimStatsSnapshot {
    pub frames_in: u64,
    pub frames_out: u64,
    pub frames_dropped: u64,
    pub bad_frames: u64,
    pub garbage_bytes: u64,
    pub clients_connected: u64,
    pub clients_total: u64,
    pub clients_rejected: u64,
    pub commands_accepted: u64,
    pub commands_temporarily_rejected: u64,
    pub commands_denied: u64,
    pub commands_unsupported: u64,
    pub commands_failed: u64,
}

impl SimStats {
    /// Read every counter (each individually atomic; the set is not a transaction).
    pub fn snapshot(&self) -> SimStatsSnapshot {
        let r = |c: &AtomicU64| c.load(Ordering::Relaxed);
        SimStatsSnapshot {
            frames_in: r(&self.frames_in),
            frames_out: r(&self.frames_out),
            frames_dropped: r(&self.frames_dropped),
            bad_frames: r(&self.bad_frames),
            garbage_bytes: r(&self.garbage_bytes),
            clients_connected: r(&self.clients_connected),
            clients_total: r(&self.clients_total),
            clients_rejected: r(&self.clients_rejected),
            commands_accepted: r(&self.commands_accepted),
            commands_temporarily_rejected: r(&self.commands_temporarily_rejected),
            commands_denied: r(&self.commands_denied),
            commands_unsupported: r(&self.commands_unsupported),
            commands_failed: r(&self.commands_failed),
        }
    }

    /// Count one COMMAND_ACK by result.
    pub(crate) fn count_command(&self, result: MavResult) {
        let c = match result {
            MavResult::MAV_RESULT_ACCEPTED => &self.commands_accepted,
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED => &self.commands_temporarily_rejected,
            MavResult::MAV_RESULT_DENIED => &self.commands_denied,
            MavResult::MAV_RESULT_UNSUPPORTED => &self.commands_unsupported,
            _ => &self.commands_failed,
        };
        add(c, 1);
    }
}

/// Relaxed increment: counters are independent, no ordering needed.
pub(crate) fn add(c: &AtomicU64, n: u64) {
    c.fetch_add(n, Ordering::Relaxed);
}

/// Relaxed decrement of a gauge.
pub(crate) fn sub(c: &AtomicU64, n: u64) {
    c.fetch_sub(n, Ordering::Relaxed);
}
