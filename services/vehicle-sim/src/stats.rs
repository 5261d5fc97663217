//! Counters for metrics, shared by `Arc` between [`crate::run`] (which updates
//! them) and whoever exports them (the service's stats sample, tests).

use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

use mavlink::dialects::ardupilotmega::{GoproRequestStatus, MavResult};

use crate::handler::GoProRequest;
use crate::model::Vehicle;

/// Live counters, for all vehicles of the process together. All are monotonic
/// except `clients_connected`, `vehicles*` and the payload state
/// (`gopro_recording`, `gimbal_*`: the first vehicle's).
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
    /// 1 while the GoPro records (video or time lapse), else 0.
    pub gopro_recording: AtomicU64,
    /// Photos the GoPro has taken (single, burst and time-lapse frames).
    pub gopro_photos: AtomicU64,
    /// GOPRO_SET_REQUESTs answered SUCCESS.
    pub gopro_set_success: AtomicU64,
    /// GOPRO_SET_REQUESTs answered FAILED.
    pub gopro_set_failed: AtomicU64,
    /// GOPRO_GET_REQUESTs answered SUCCESS.
    pub gopro_get_success: AtomicU64,
    /// GOPRO_GET_REQUESTs answered FAILED.
    pub gopro_get_failed: AtomicU64,
    /// Gimbal pitch, centidegrees (negative down).
    pub gimbal_pitch_cdeg: AtomicI64,
    /// Gimbal yaw relative to the nose, centidegrees.
    pub gimbal_yaw_cdeg: AtomicI64,
    /// Vehicles this process simulates (1, or the swarm's count).
    pub vehicles: AtomicU64,
    /// Vehicles armed now.
    pub vehicles_armed: AtomicU64,
    /// Vehicles with at least one client (TCP) or the UDP socket open.
    pub vehicles_linked: AtomicU64,
    /// Physics steps skipped because the simulation fell behind the clock.
    pub steps_skipped: AtomicU64,
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
    pub gopro_recording: u64,
    pub gopro_photos: u64,
    pub gopro_set_success: u64,
    pub gopro_set_failed: u64,
    pub gopro_get_success: u64,
    pub gopro_get_failed: u64,
    pub gimbal_pitch_cdeg: i64,
    pub gimbal_yaw_cdeg: i64,
    pub vehicles: u64,
    pub vehicles_armed: u64,
    pub vehicles_linked: u64,
    pub steps_skipped: u64,
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
            gopro_recording: r(&self.gopro_recording),
            gopro_photos: r(&self.gopro_photos),
            gopro_set_success: r(&self.gopro_set_success),
            gopro_set_failed: r(&self.gopro_set_failed),
            gopro_get_success: r(&self.gopro_get_success),
            gopro_get_failed: r(&self.gopro_get_failed),
            gimbal_pitch_cdeg: self.gimbal_pitch_cdeg.load(Ordering::Relaxed),
            gimbal_yaw_cdeg: self.gimbal_yaw_cdeg.load(Ordering::Relaxed),
            vehicles: r(&self.vehicles),
            vehicles_armed: r(&self.vehicles_armed),
            vehicles_linked: r(&self.vehicles_linked),
            steps_skipped: r(&self.steps_skipped),
        }
    }

    /// Count one GoPro request answer.
    pub(crate) fn count_gopro(&self, request: GoProRequest, status: GoproRequestStatus) {
        let ok = status == GoproRequestStatus::GOPRO_REQUEST_SUCCESS;
        let c = match (request, ok) {
            (GoProRequest::Set, true) => &self.gopro_set_success,
            (GoProRequest::Set, false) => &self.gopro_set_failed,
            (GoProRequest::Get, true) => &self.gopro_get_success,
            (GoProRequest::Get, false) => &self.gopro_get_failed,
        };
        add(c, 1);
    }

    /// Copy the payload state (gimbal attitude, GoPro) after a physics tick.
    pub(crate) fn observe(&self, v: &Vehicle) {
        let g = v.gimbal().attitude();
        let cdeg = |rad: f64| (rad.to_degrees() * 100.0).round() as i64;
        self.gimbal_pitch_cdeg
            .store(cdeg(g.pitch), Ordering::Relaxed);
        self.gimbal_yaw_cdeg.store(cdeg(g.yaw), Ordering::Relaxed);
        if let Some(gopro) = v.gopro() {
            self.gopro_recording
                .store(u64::from(gopro.heartbeat().recording), Ordering::Relaxed);
            self.gopro_photos
                .store(gopro.photos_taken(), Ordering::Relaxed);
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

/// Relaxed store of a gauge.
pub(crate) fn set(c: &AtomicU64, n: u64) {
    c.store(n, Ordering::Relaxed);
}

/// Relaxed decrement of a gauge.
pub(crate) fn sub(c: &AtomicU64, n: u64) {
    c.fetch_sub(n, Ordering::Relaxed);
}
