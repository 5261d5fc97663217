//! The emergency mode: the queue's own emergency stop, engaged and withdrawn.

use super::*;

impl Swarm {
    /// `EMERGENCY_MODE`: 1 engages an emergency stop under this queue's own source;
    /// 0 withdraws it (`ReleaseEmergency`: another source's stop stays, and the
    /// arbiter, not this queue, knows whether ours is still engaged: it may be from
    /// before a restart). The drone's flag follows the arbiter's answers.
    pub(super) fn emergency(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        if cmd.int1 != 0 {
            tracing::warn!(drone = id, "emergency mode: emergency stop");
            let current = self.drones[idx].current.take();
            let queued: Vec<Queued> = self.drones[idx].queue.drain(..).collect();
            for q in current.map(|r| r.q).into_iter().chain(queued) {
                self.refuse(&q.cmd, id, "emergency mode");
            }
            self.side_command(
                idx,
                cmd,
                CommandSource::SwarmQueue,
                &Command::EmergencyStop,
                now,
            );
        } else {
            tracing::warn!(
                drone = id,
                "emergency mode ended: the queue withdraws its emergency stop"
            );
            self.side_command(
                idx,
                cmd,
                CommandSource::SwarmQueue,
                &Command::ReleaseEmergency,
                now,
            );
        }
    }

    /// The drone's emergency mode: its stop in force, or being engaged.
    pub(super) fn in_emergency(&self, idx: usize) -> bool {
        let d = &self.drones[idx];
        d.emergency
            || d.side
                .iter()
                .any(|s| s.cmd.kind == K::EmergencyMode.to_wire() && s.cmd.int1 != 0)
    }
}
