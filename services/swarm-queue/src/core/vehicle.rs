//! Samples from a drone's vehicle: state, status, command acks and arbiter events.

use super::*;

impl Swarm {
    /// The newest `VehicleState` of drone `idx`'s vehicle.
    pub fn handle_state(&mut self, idx: usize, s: &VehicleState, _now: u64) {
        let d = &mut self.drones[idx];
        if s.vehicle_id != d.vehicle_id {
            return;
        }
        let mut pose = Pose::from_state(&self.cfg.site, s);
        if !pose.position_valid {
            // No fix (yet): keep the last valid position rather than report the
            // drone at latitude 0, longitude 0; the attitude is still new.
            let last = d.pose.filter(|p| p.position_valid);
            pose.site = last.map_or([0.0; 3], |p| p.site);
            pose.alt_rel = last.map_or(0.0, |p| p.alt_rel);
            pose.home_alt_msl = last.map_or(self.cfg.site.origin().2, |p| p.home_alt_msl);
            pose.stamp_ns = last.map_or(0, |p| p.stamp_ns);
        }
        d.pose = Some(pose);
    }

    /// A `VehicleStatus` of drone `idx`'s vehicle.
    pub fn handle_status(&mut self, idx: usize, s: &VehicleStatus, now: u64) {
        let site = self.cfg.site;
        let d = &mut self.drones[idx];
        if s.vehicle_id != d.vehicle_id {
            return;
        }
        d.status = Some(*s);
        d.status_rx_ns = now;
        if d.autopilot_home.is_none()
            && s.home_valid == 1
            && s.home_lat_deg.is_finite()
            && s.home_lon_deg.is_finite()
            && s.home_alt_msl_m.is_finite()
        {
            let [x, y] = site.to_site_xy(s.home_lat_deg, s.home_lon_deg);
            d.autopilot_home = Some([
                x as f32,
                y as f32,
                site.z_of_msl(f64::from(s.home_alt_msl_m)) as f32,
            ]);
        }
    }

    /// A `CommandAck` from drone `idx`'s vehicle.
    pub fn handle_ack(&mut self, idx: usize, ack: &CommandAck, now: u64) {
        if ack.source != CommandSource::SwarmQueue.to_wire() {
            return;
        }
        let d = &mut self.drones[idx];
        if ack.vehicle_id != d.vehicle_id {
            return;
        }
        let Some(pos) = d
            .pending
            .iter()
            .position(|p| p.command_id == ack.command_id)
        else {
            return;
        };
        match ack.result() {
            Some(AckResult::InProgress) => {}
            Some(AckResult::Accepted) | Some(AckResult::Limited) => {
                let owner = d.pending.remove(pos).map_or(Owner::Nobody, |p| p.owner);
                self.accepted(idx, owner, ack.command_id, now);
            }
            _ => {
                let owner = d.pending.remove(pos).map_or(Owner::Nobody, |p| p.owner);
                self.vehicle_refused(idx, owner, &refusal_text(ack), now);
            }
        }
    }

    fn accepted(&mut self, idx: usize, owner: Owner, id: u32, now: u64) {
        match owner {
            Owner::Current(token) => {
                let d = &mut self.drones[idx];
                let Some(mut r) = d.current.take_if(|r| r.token == token) else {
                    return;
                };
                if r.awaiting == Some(id) {
                    r.awaiting = None;
                    if let Err(e) = self.next_takeoff_step(idx, &mut r, now) {
                        self.finish(idx, r, SwarmResult::Refused, &e);
                        return;
                    }
                    self.drones[idx].current = Some(r);
                    // Send what waited for this (a position after GUIDED) at once.
                    self.step_current(idx, now);
                } else {
                    self.drones[idx].current = Some(r);
                }
            }
            Owner::Side(token) => {
                let d = &mut self.drones[idx];
                if let Some(pos) = d.side.iter().position(|s| s.token == token) {
                    let op = d.side.remove(pos);
                    if op.cmd.kind == K::EmergencyMode.to_wire() {
                        // The arbiter took (or withdrew) this queue's own stop.
                        d.emergency = op.cmd.int1 != 0;
                    }
                    let id = d.id;
                    self.success(&op.cmd, id);
                }
            }
            Owner::Nobody => {}
        }
    }

    /// An `ArbiterEvent` of drone `idx`'s vehicle: the decision on a geofence this
    /// queue sent (matched by `request_id`), and the state of its own emergency stop
    /// (engaged: also when the stop's ack says it failed to confirm the brake;
    /// released by this queue; ended by its last engager or an operator's clear).
    pub fn handle_event(&mut self, idx: usize, e: &ArbiterEvent, _now: u64) {
        let d = &mut self.drones[idx];
        if e.vehicle_id != d.vehicle_id {
            return;
        }
        let ours = e.source == CommandSource::SwarmQueue.to_wire();
        match e.event_kind() {
            Some(ArbiterEventKind::EmergencyStop) if ours => d.emergency = true,
            Some(ArbiterEventKind::EmergencyReleased) if ours => d.emergency = false,
            Some(ArbiterEventKind::EmergencyCleared) => {
                if d.emergency {
                    tracing::warn!(drone = d.id, detail = %e.detail.as_str(), "emergency stop ended by the arbiter");
                }
                d.emergency = false;
            }
            Some(
                kind @ (ArbiterEventKind::GeofenceUpdated | ArbiterEventKind::GeofenceInvalid),
            ) if ours && e.request_id != 0 => {
                let Some(pos) = d
                    .fence_requests
                    .iter()
                    .position(|r| r.request_id == e.request_id)
                else {
                    return;
                };
                let r = d.fence_requests.remove(pos);
                let id = d.id;
                if kind == ArbiterEventKind::GeofenceUpdated {
                    tracing::info!(drone = id, min = ?r.fence.min, max = ?r.fence.max, "geofence set");
                    d.fence = Some(r.fence);
                    self.success(&r.cmd, id);
                } else {
                    let why = format!("geofence refused: {}", e.detail.as_str());
                    self.refuse(&r.cmd, id, &why);
                }
            }
            _ => {}
        }
    }

    fn vehicle_refused(&mut self, idx: usize, owner: Owner, why: &str, _now: u64) {
        let id = self.drones[idx].id;
        match owner {
            Owner::Current(token) => {
                if let Some(r) = self.drones[idx].current.take_if(|r| r.token == token) {
                    self.finish(idx, r, SwarmResult::Refused, why);
                }
            }
            Owner::Side(token) => {
                let d = &mut self.drones[idx];
                if let Some(pos) = d.side.iter().position(|s| s.token == token) {
                    let op = d.side.remove(pos);
                    self.refuse(&op.cmd, id, why);
                }
            }
            Owner::Nobody => tracing::warn!(drone = id, reason = why, "vehicle refused"),
        }
    }

    /// `GO_EXTERNAL`: the command after the one just accepted.
    fn next_takeoff_step(&mut self, idx: usize, r: &mut Running, now: u64) -> Result<(), String> {
        let Exec::Takeoff { step, .. } = &mut r.exec else {
            return Ok(());
        };
        let owner = Owner::Current(r.token);
        let src = CommandSource::SwarmQueue;
        match *step {
            TakeoffStep::Mode => {
                r.awaiting =
                    Some(self.send(idx, src, &Command::Arm { force: false }, owner, now)?);
                *step = TakeoffStep::Arm;
            }
            TakeoffStep::Arm => {
                let alt_rel_m = self.cfg.takeoff_alt_m;
                r.awaiting =
                    Some(self.send(idx, src, &Command::Takeoff { alt_rel_m }, owner, now)?);
                *step = TakeoffStep::Takeoff;
            }
            TakeoffStep::Takeoff => *step = TakeoffStep::Climb,
            TakeoffStep::Climb => {}
        }
        Ok(())
    }
}
