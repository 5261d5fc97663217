//! What the console remembers of each vehicle between reads (pure): the newest
//! arbiter events and command decisions, and the altitude/speed history its plot
//! draws. Filled by `crate::vehicles` whenever it reads the vehicle's topics (a
//! console poll or a `/metrics` scrape), so the history has points only while
//! someone looks; the page draws a gap where there are none.

use std::collections::VecDeque;
use std::time::Duration;

use skymesh_ipc_types::{ArbiterEvent, CommandAck, VehicleState};

/// Arbiter events and command decisions kept per vehicle.
pub const LOG_KEPT: usize = 12;
/// How far back the plot's history reaches.
pub const HISTORY: Duration = Duration::from_secs(300);
/// Closest spacing of two history points (a faster poll adds no points).
pub const HISTORY_STEP: Duration = Duration::from_millis(500);

/// One point of the plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// `CLOCK_MONOTONIC` ns of the `VehicleState` it was read from.
    pub stamp_ns: u64,
    /// Altitude above home, m.
    pub alt_rel_m: f32,
    /// Horizontal speed over ground, m/s.
    pub ground_speed_mps: f32,
}

/// One vehicle's recent events, decisions and history.
#[derive(Debug, Clone, Default)]
pub struct VehicleLog {
    /// Newest last.
    pub events: VecDeque<ArbiterEvent>,
    /// Newest last.
    pub acks: VecDeque<CommandAck>,
    /// Oldest first, at most [`HISTORY`] old, [`HISTORY_STEP`] apart.
    pub history: VecDeque<Point>,
}

/// Horizontal speed of `s`, m/s.
pub fn ground_speed(s: &VehicleState) -> f32 {
    s.vel_ned_mps[0].hypot(s.vel_ned_mps[1])
}

fn push_bounded<T>(q: &mut VecDeque<T>, v: T) {
    if q.len() == LOG_KEPT {
        q.pop_front();
    }
    q.push_back(v);
}

impl VehicleLog {
    pub fn event(&mut self, e: ArbiterEvent) {
        push_bounded(&mut self.events, e);
    }

    pub fn ack(&mut self, a: CommandAck) {
        push_bounded(&mut self.acks, a);
    }

    /// Adds a history point from `s` (with a position, and far enough from the
    /// previous point) and forgets points older than [`HISTORY`].
    pub fn record(&mut self, s: &VehicleState) {
        if s.position_valid == 0 {
            return;
        }
        let t = s.header.stamp_ns;
        let spaced = self
            .history
            .back()
            .is_none_or(|p| t.saturating_sub(p.stamp_ns) >= HISTORY_STEP.as_nanos() as u64);
        if spaced {
            self.history.push_back(Point {
                stamp_ns: t,
                alt_rel_m: s.alt_rel_m,
                ground_speed_mps: ground_speed(s),
            });
        }
        let horizon = t.saturating_sub(HISTORY.as_nanos() as u64);
        while self.history.front().is_some_and(|p| p.stamp_ns < horizon) {
            self.history.pop_front();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::SampleHeader;

    fn state(t_ms: u64, alt: f32) -> VehicleState {
        VehicleState {
            header: SampleHeader {
                stamp_ns: t_ms * 1_000_000,
                ..SampleHeader::default()
            },
            position_valid: 1,
            alt_rel_m: alt,
            vel_ned_mps: [3.0, 4.0, 0.0],
            ..VehicleState::default()
        }
    }

    #[test]
    fn history_is_spaced_and_bounded_in_time() {
        let mut log = VehicleLog::default();
        log.record(&state(1_000, 0.0));
        log.record(&state(1_100, 1.0)); // too close: skipped
        log.record(&state(1_500, 2.0));
        assert_eq!(log.history.len(), 2);
        assert_eq!(log.history[1].alt_rel_m, 2.0);
        assert_eq!(log.history[1].ground_speed_mps, 5.0);
        log.record(&state(1_500 + 300_000, 3.0));
        assert_eq!(log.history.len(), 2, "the first point aged out");
        assert_eq!(log.history[0].alt_rel_m, 2.0);
        let mut no_fix = state(400_000, 9.0);
        no_fix.position_valid = 0;
        log.record(&no_fix);
        assert_eq!(log.history.len(), 2);
    }

    #[test]
    fn logs_keep_the_newest() {
        let mut log = VehicleLog::default();
        for i in 0..(LOG_KEPT as u32 + 5) {
            log.ack(CommandAck {
                command_id: i,
                ..CommandAck::default()
            });
            log.event(ArbiterEvent::default());
        }
        assert_eq!(log.acks.len(), LOG_KEPT);
        assert_eq!(log.events.len(), LOG_KEPT);
        assert_eq!(log.acks.back().unwrap().command_id, LOG_KEPT as u32 + 4);
        assert_eq!(log.acks.front().unwrap().command_id, 5);
    }
}
