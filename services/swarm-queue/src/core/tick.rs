//! Execution: the tick, keep-alives, side-command timeouts and stepping each
//! running command to its end.

use super::*;

impl Swarm {
    /// Whether a tick would only refresh the state: no drone has a command running,
    /// queued or waiting for its vehicle's answer (a side command), no reply or
    /// output waits to be published, and the LEDs show the hardware drone's colour.
    /// Then nothing the queue does depends on when it next ticks: a swarm command
    /// ends the rest as it arrives.
    pub fn at_rest(&self) -> bool {
        self.drones
            .iter()
            .all(|d| d.idle() && d.side.is_empty() && d.fence_requests.is_empty())
            && self.replies.is_empty()
            && self.out.is_empty()
            && self.led_bytes().is_none_or(|b| self.hw_last == Some(b))
    }

    /// Steps every drone: side-command timeouts, the current command, the next
    /// command when the current one finished; LEDs; gauges.
    pub fn tick(&mut self, now: u64) {
        let mut flying = 0;
        for idx in 0..self.drones.len() {
            self.expire_side(idx, now);
            self.step_current(idx, now);
            self.advance(idx, now);
            self.keepalive(idx, now);
            let d = &self.drones[idx];
            if d.armed() == Some(true)
                && d.pose
                    .as_ref()
                    .is_some_and(|p| !p.landed(self.cfg.landed_alt_m))
            {
                flying += 1;
            }
            if let Some(g) = self.metrics.queue_depth.get(idx) {
                g.set(d.queue.len() as f64);
            }
        }
        self.metrics.flying.set(f64::from(flying));
        self.leds(now);
    }

    /// Keeps the queue's flight authority while drone `idx`'s current command flies
    /// a position target: the arbiter takes authority from a source silent for its
    /// authority timeout (5 s by default) and then brakes that source's `GoTo` /
    /// `Takeoff`, so a climb or a waypoint leg longer than that would stop halfway.
    /// A `GrabFlightAuthority` goes out when no flight command was sent for
    /// `authority_keepalive` (a tenth early: ticks jitter); streamed targets (a
    /// follow being dragged, an animation) are their own keep-alive. Owned by the
    /// command: refused (`NoAuthority` when a higher source holds authority, or an
    /// emergency stop), it ends the command with the arbiter's reason, as any
    /// refused command of it does. Nothing is sent for a drone without such a
    /// command (at rest, pausing, landing).
    pub(super) fn keepalive(&mut self, idx: usize, now: u64) {
        let period = secs(self.cfg.authority_keepalive);
        let d = &self.drones[idx];
        let Some(token) = d.current.as_ref().map(|r| r.token) else {
            return;
        };
        if d.target_token != Some(token)
            || d.flight_sent_ns
                .is_some_and(|t| now.saturating_sub(t) < period - period / 10)
        {
            return;
        }
        let grab = Command::GrabFlightAuthority;
        if let Err(e) = self.send(
            idx,
            CommandSource::SwarmQueue,
            &grab,
            Owner::Current(token),
            now,
        ) {
            tracing::warn!(drone = self.drones[idx].id, error = %e, "authority keep-alive not sent");
        }
    }

    fn expire_side(&mut self, idx: usize, now: u64) {
        self.expire_fences(idx, now);
        if self.drones[idx].side.iter().all(|s| s.deadline_ns > now) {
            return;
        }
        let id = self.drones[idx].id;
        let (late, keep): (Vec<SideOp>, Vec<SideOp>) = self.drones[idx]
            .side
            .drain(..)
            .partition(|s| s.deadline_ns <= now);
        self.drones[idx].side = keep;
        for op in late {
            self.reply(
                &op.cmd,
                id,
                SwarmResult::Timeout,
                0,
                "no answer from the vehicle",
            );
        }
    }

    /// Starts queued commands until one keeps running (or the queue is empty).
    pub(super) fn advance(&mut self, idx: usize, now: u64) {
        let mut budget = self.drones[idx].queue.len();
        while self.drones[idx].current.is_none() && budget > 0 {
            budget -= 1;
            let Some(q) = self.drones[idx].queue.pop_front() else {
                break;
            };
            self.start(idx, q, now, false);
        }
    }

    pub(super) fn finish(&mut self, idx: usize, r: Running, result: SwarmResult, why: &str) {
        let id = self.drones[idx].id;
        self.reply(&r.q.cmd, id, result, 0, why);
    }

    pub(super) fn step_current(&mut self, idx: usize, now: u64) {
        let Some(mut r) = self.drones[idx].current.take() else {
            return;
        };
        match self.step(idx, &mut r, now) {
            None => self.drones[idx].current = Some(r),
            Some((result, why)) => self.finish(idx, r, result, &why),
        }
    }

    /// One step of the running command `r` of drone `idx`; `Some` when it ends.
    pub(super) fn step(
        &mut self,
        idx: usize,
        r: &mut Running,
        now: u64,
    ) -> Option<(SwarmResult, String)> {
        if let Some(dl) = r.deadline_ns {
            if now >= dl {
                let s = (dl - r.started_ns) as f64 / 1e9;
                return Some((
                    SwarmResult::Timeout,
                    format!("{} not finished in {s:.0} s", r.q.kind),
                ));
            }
        }
        let tol = self.cfg.waypoint_tolerance_m;
        let landed_alt = self.cfg.landed_alt_m;
        let token = r.token;
        let awaiting = r.awaiting;
        let d = &self.drones[idx];
        let pose = d.fresh_pose(now, &self.cfg).copied();
        let tracking = d.tracking();
        let landed = d.armed() == Some(false) || pose.is_some_and(|p| p.landed(landed_alt));
        match &mut r.exec {
            Exec::Takeoff { step, .. } => {
                if *step == TakeoffStep::Climb
                    && pose.is_some_and(|p| p.alt_rel >= self.cfg.takeoff_alt_m - tol)
                {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Waypoint {
                target,
                yaw,
                speed,
                follow,
                dirty,
            } => {
                if awaiting.is_none() && *dirty && (!*follow || self.stream_due(idx, now)) {
                    let spd = if *follow {
                        self.changed_speed(idx, *speed)
                    } else {
                        Some(*speed)
                    };
                    let (t, y) = (*target, *yaw);
                    if let Err(e) = self.goto(idx, t, Some(y), spd, Owner::Current(token), now) {
                        return Some((SwarmResult::Refused, e));
                    }
                    *dirty = false;
                }
                if !*follow && tracking.is_some_and(|p| dist(p, *target) <= tol) && pose.is_some() {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::GoHome {
                target,
                sent,
                landing,
            } => {
                if *landing {
                    if landed {
                        return Some((SwarmResult::Success, String::new()));
                    }
                } else if awaiting.is_none() {
                    if !*sent {
                        let t = *target;
                        let speed = Some(self.cfg.default_speed_mps);
                        if let Err(e) = self.goto(idx, t, None, speed, Owner::Current(token), now) {
                            return Some((SwarmResult::Refused, e));
                        }
                        *sent = true;
                    }
                    if pose.is_some() && tracking.is_some_and(|p| dist_xy(p, *target) <= tol) {
                        if let Err(e) = self.send(
                            idx,
                            CommandSource::SwarmQueue,
                            &Command::Land,
                            Owner::Current(token),
                            now,
                        ) {
                            return Some((SwarmResult::Refused, e));
                        }
                        *landing = true;
                        if let (Some(t), Some(p)) = (tracking, pose) {
                            *target = [t[0], t[1], t[2] - p.alt_rel];
                        }
                        r.deadline_ns = Some(now + secs(self.cfg.timeouts.land));
                    }
                }
            }
            Exec::Land { .. } => {
                if landed {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Pause { until_ns } => {
                if now >= *until_ns {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Color {
                from,
                to,
                start_ns,
                dur_ns,
            } => {
                let u = if *dur_ns == 0 {
                    1.0
                } else {
                    (now.saturating_sub(*start_ns) as f64 / *dur_ns as f64).min(1.0) as f32
                };
                self.drones[idx].color = lerp3(*from, *to, u);
                if u >= 1.0 {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Anim(a) => return self.step_anim(idx, a, token, awaiting, now),
        }
        None
    }

    fn step_anim(
        &mut self,
        idx: usize,
        a: &mut AnimRun,
        token: u64,
        awaiting: Option<u32>,
        now: u64,
    ) -> Option<(SwarmResult, String)> {
        let dt = now.saturating_sub(a.last_ns) as f64 / 1e9;
        a.last_ns = now;
        a.time += dt * f64::from(a.speed);
        let mut done = false;
        if a.time >= a.t1 {
            let len = a.t1 - a.t0;
            if a.looping && !a.cancel && len > 0.0 {
                a.time = a.t0 + (a.time - a.t0) % len;
            } else if a.looping && !a.cancel {
                a.time = a.t1;
            } else {
                a.time = a.t1;
                done = true;
            }
        }
        let (k, frame) = a.anim.sample(a.time);
        let d = &self.drones[idx];
        let off = d.anim_offset;
        let mut pos = [0, 1, 2].map(|i| k.pos[i] + off[i]);
        if let Ok(Some(b)) = d.limits() {
            pos = b.clamp(pos);
        }
        a.frame = frame;
        a.point = Keyframe { pos, ..k };
        if a.use_color && !d.manual_color {
            let i = d.anim_intensity;
            self.drones[idx].color = k.rgb.map(|c| c * i);
        }
        if a.use_pos && awaiting.is_none() && (done || self.stream_due(idx, now)) {
            let path = a.anim.speed_at(a.time) * a.speed;
            let speed = (path * 1.5 + STREAM_SPEED_MARGIN_MPS)
                .max(self.cfg.default_speed_mps)
                .min(skymesh_ipc_types::swarm::SWARM_MAX_SPEED_MPS);
            let spd = self.changed_speed(idx, speed);
            if let Err(e) = self.goto(idx, pos, Some(k.yaw_deg), spd, Owner::Current(token), now) {
                return Some((SwarmResult::Refused, e));
            }
        }
        done.then(|| (SwarmResult::Success, String::new()))
    }
}
