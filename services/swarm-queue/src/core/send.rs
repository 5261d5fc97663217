//! Vehicle commands sent for a drone: flight commands with their bookkeeping,
//! streamed targets, side commands and the brake.

use super::*;

impl Swarm {
    /// Sends `command` to drone `idx`'s vehicle; `owner` waits for its ack. Keeps
    /// the arbiter's view of the queue's position target and the time of the last
    /// flight command (see [`Swarm::keepalive`]).
    pub(super) fn send(
        &mut self,
        idx: usize,
        source: CommandSource,
        command: &Command,
        owner: Owner,
        now: u64,
    ) -> Result<u32, String> {
        let id = self.next_command_id;
        self.next_command_id = self.next_command_id.wrapping_add(1).max(1);
        let d = &mut self.drones[idx];
        let c = VehicleCommand::new(d.vehicle_id, source, id, command)
            .map_err(|e| format!("{}: {e}", command.kind()))?;
        self.out.commands.push(c);
        let kind = command.kind();
        if kind.authority() == Some(AuthorityDomain::Flight) {
            d.flight_sent_ns = Some(now);
        }
        match (kind, owner) {
            (CommandKind::GoTo | CommandKind::Takeoff, Owner::Current(token)) => {
                d.target_token = Some(token)
            }
            (k, _) if ends_target(k) => d.target_token = None,
            _ => {}
        }
        if d.pending.len() >= MAX_PENDING {
            d.pending.pop_front();
        }
        d.pending.push_back(Pending {
            command_id: id,
            owner,
        });
        Ok(id)
    }

    /// A position target for drone `idx` at site point `target` (GroundControl's
    /// frame: the calibration offset is taken off), facing `yaw` (CCW from east).
    pub(super) fn goto(
        &mut self,
        idx: usize,
        target: [f32; 3],
        yaw: Option<f32>,
        speed: Option<f32>,
        owner: Owner,
        now: u64,
    ) -> Result<u32, String> {
        let d = &self.drones[idx];
        let pose = d
            .fresh_pose(now, &self.cfg)
            .ok_or("no position from the vehicle")?;
        let v = [0, 1, 2].map(|i| f64::from(target[i] - d.calibration[i]));
        let (lat_deg, lon_deg) = self.cfg.site.to_geodetic(v[0], v[1]);
        let alt_rel_m = self.cfg.site.alt_rel_of_z(v[2], pose.home_alt_msl) as f32;
        let cmd = Command::GoTo {
            lat_deg,
            lon_deg,
            alt_rel_m,
            yaw_deg: yaw.map(heading_of_yaw),
            speed_mps: speed,
        };
        let id = self.send(idx, CommandSource::SwarmQueue, &cmd, owner, now)?;
        let s = &mut self.drones[idx].stream;
        s.last_ns = Some(now);
        if speed.is_some() {
            s.last_speed = speed;
        }
        Ok(id)
    }

    /// `speed` if it differs from the last speed sent to drone `idx`.
    pub(super) fn changed_speed(&self, idx: usize, speed: f32) -> Option<f32> {
        match self.drones[idx].stream.last_speed {
            Some(l) if (l - speed).abs() < SPEED_RESEND_MPS => None,
            _ => Some(speed),
        }
    }

    /// A streamed target may go out (a tenth of the period early: ticks jitter).
    pub(super) fn stream_due(&self, idx: usize, now: u64) -> bool {
        let period = secs(self.cfg.setpoint_period);
        self.drones[idx]
            .stream
            .last_ns
            .is_none_or(|t| now.saturating_sub(t) >= period - period / 10)
    }

    /// An immediate command answered by the vehicle: the reply waits for its ack.
    pub(super) fn side_command(
        &mut self,
        idx: usize,
        cmd: &SwarmCommand,
        source: CommandSource,
        command: &Command,
        now: u64,
    ) {
        let token = self.token();
        match self.send(idx, source, command, Owner::Side(token), now) {
            Ok(_) => {
                let deadline_ns = now + secs(self.cfg.timeouts.ack);
                self.drones[idx].side.push(SideOp {
                    token,
                    cmd: *cmd,
                    deadline_ns,
                });
            }
            Err(e) => {
                let id = self.drones[idx].id;
                self.refuse(cmd, id, &e);
            }
        }
    }

    /// Brakes drone `idx` unless it is known to be disarmed.
    pub(super) fn brake(&mut self, idx: usize, now: u64) {
        if self.drones[idx].armed() != Some(false) {
            if let Err(e) = self.send(
                idx,
                CommandSource::SwarmQueue,
                &Command::Brake,
                Owner::Nobody,
                now,
            ) {
                tracing::warn!(drone = self.drones[idx].id, error = %e, "brake not sent");
            }
        }
    }
}
