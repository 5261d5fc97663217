//! Starting a drone's next queued command: what each kind sends first.

use super::*;

impl Swarm {
    /// Makes `q` drone `idx`'s current command (or answers it at once).
    ///
    /// A command that moves the vehicle asks for GUIDED first, also when the last
    /// status says GUIDED: that status repeats a heartbeat up to a second old, and
    /// someone (the pilot, a ground station) may have switched to LOITER since. A
    /// position target sent in LOITER is ignored, and the command would wait out its
    /// deadline. ArduCopter accepts a request for the mode it is in and changes
    /// nothing. The exception is `steering`, true for a manual target that replaces a
    /// running position command, as a dragged target does many times a second: it asks
    /// only when the status shows another mode (the command it replaces asked), so a
    /// fast stream is not held up by an acknowledgement per target.
    pub(super) fn start(&mut self, idx: usize, q: Queued, now: u64, steering: bool) {
        let token = self.token();
        let id = self.drones[idx].id;
        let cfg = &self.cfg;
        let d = &self.drones[idx];
        let pose = d.fresh_pose(now, cfg).copied();
        let tracking = d.tracking();
        let armed = d.armed();
        let flying = armed == Some(true) && pose.is_some_and(|p| !p.landed(cfg.landed_alt_m));
        let ask_guided = !steering
            || d.status
                .is_some_and(|s| s.flight_mode() != FlightMode::Guided);
        let refuse_motion = || -> Option<&'static str> {
            if pose.is_none() {
                Some("no position from the vehicle")
            } else if armed.is_none() {
                Some("no status from the vehicle")
            } else if !flying {
                Some("not flying: take off first")
            } else {
                None
            }
        };
        let c = q.cmd;
        let mut deadline_ns = None;
        let mut guided_first = false;
        let exec = match q.kind {
            K::ExtGoExternal => {
                if armed == Some(true) && pose.is_some_and(|p| p.alt_rel > cfg.landed_alt_m) {
                    return self.reply(&c, id, SwarmResult::Success, 0, "already flying");
                }
                let target = match (tracking, pose) {
                    (Some(t), Some(p)) => [t[0], t[1], t[2] - p.alt_rel + cfg.takeoff_alt_m],
                    _ => [0.0, 0.0, cfg.takeoff_alt_m],
                };
                deadline_ns = Some(now + secs(cfg.timeouts.takeoff));
                Exec::Takeoff {
                    step: TakeoffStep::Mode,
                    target,
                }
            }
            K::ExtWaypoint
            | K::SetManualTarget
            | K::ExtWaypointFollow
            | K::ExtWaypointFollowColor => {
                if let Some(why) = refuse_motion() {
                    return self.reply(&c, id, SwarmResult::Refused, 0, why);
                }
                let target = c.position();
                let speed = if c.f[3] > 0.0 {
                    c.f[3]
                } else {
                    cfg.default_speed_mps
                };
                let follow = is_follow(q.kind);
                if !follow {
                    let d = tracking.map_or(0.0, |t| dist(t, target));
                    deadline_ns = Some(
                        now + secs(cfg.timeouts.waypoint_base)
                            + ns_of_s(cfg.timeouts.waypoint_factor * d / speed),
                    );
                }
                guided_first = ask_guided;
                Exec::Waypoint {
                    target,
                    yaw: c.int1 as f32 / 100.0,
                    speed,
                    follow,
                    dirty: true,
                }
            }
            K::ExtGoHome => {
                if armed == Some(false) {
                    return self.reply(&c, id, SwarmResult::Success, 0, "on the ground");
                }
                if let Some(why) = refuse_motion() {
                    return self.reply(&c, id, SwarmResult::Refused, 0, why);
                }
                let Some(home) = d.home.or(d.setup_home).or(d.autopilot_home) else {
                    return self.reply(&c, id, SwarmResult::Refused, 0, "no home position");
                };
                let t = tracking.unwrap_or(home);
                let target = [home[0], home[1], t[2]];
                let dh = dist_xy(t, target);
                deadline_ns = Some(
                    now + secs(cfg.timeouts.waypoint_base)
                        + ns_of_s(cfg.timeouts.waypoint_factor * dh / cfg.default_speed_mps),
                );
                guided_first = ask_guided;
                Exec::GoHome {
                    target,
                    sent: false,
                    landing: false,
                }
            }
            K::ExtGoHomeAtPosition => {
                if armed == Some(false) {
                    return self.reply(&c, id, SwarmResult::Success, 0, "on the ground");
                }
                let target = match (tracking, pose) {
                    (Some(t), Some(p)) => [t[0], t[1], t[2] - p.alt_rel],
                    (Some(t), None) => t,
                    _ => [0.0; 3],
                };
                deadline_ns = Some(now + secs(cfg.timeouts.land));
                Exec::Land { target }
            }
            K::ExtPause => Exec::Pause {
                until_ns: now + ns_of_s(c.f[0]),
            },
            K::ExtColor => Exec::Color {
                from: d.color,
                to: c.rgb1(),
                start_ns: now,
                dur_ns: ns_of_s(c.f[0]),
            },
            K::ExtColorGradient => Exec::Color {
                from: c.rgb1(),
                to: c.rgb2(),
                start_ns: now,
                dur_ns: ns_of_s(c.f[0]),
            },
            K::ExtPlaybackAnim => {
                let Some(anim) = q.anim.clone() else {
                    return self.reply(&c, id, SwarmResult::Refused, 0, "no animation loaded");
                };
                let use_pos = c.f[2] >= 0.5;
                if use_pos {
                    if let Some(why) = refuse_motion() {
                        return self.reply(&c, id, SwarmResult::Refused, 0, why);
                    }
                }
                let n = anim.len();
                let first = (c.int1.max(0) as usize).min(n - 1);
                let last = if c.int2 < 0 {
                    n - 1
                } else {
                    (c.int2 as usize).clamp(first, n - 1)
                };
                let t0 = anim.frames()[first].time_s;
                let t1 = anim.frames()[last].time_s;
                guided_first = use_pos && ask_guided;
                Exec::Anim(AnimRun {
                    point: anim.frames()[first],
                    anim,
                    t0,
                    t1,
                    time: t0,
                    last_ns: now,
                    looping: c.f[0] >= 0.5,
                    cancel: false,
                    speed: c.f[1],
                    use_pos,
                    use_color: c.f[3] >= 0.5,
                    frame: first,
                })
            }
            other => {
                return self.reply(
                    &c,
                    id,
                    SwarmResult::Refused,
                    0,
                    &format!("{other} cannot be queued"),
                )
            }
        };
        if q.kind == K::ExtWaypointFollowColor {
            self.drones[idx].color = c.rgb1();
        }
        let kind = q.kind;
        let mut r = Running {
            q,
            token,
            started_ns: now,
            deadline_ns,
            exec,
            awaiting: None,
        };
        let first = match (&r.exec, guided_first) {
            (Exec::Takeoff { .. }, _) | (_, true) => Some(Command::SetMode(FlightMode::Guided)),
            (Exec::Land { .. }, _) => Some(Command::Land),
            _ => None,
        };
        if let Some(cmd) = first {
            match self.send(
                idx,
                CommandSource::SwarmQueue,
                &cmd,
                Owner::Current(token),
                now,
            ) {
                Ok(cid) => {
                    if !matches!(cmd, Command::Land) {
                        r.awaiting = Some(cid);
                    }
                }
                Err(e) => return self.finish(idx, r, SwarmResult::Refused, &e),
            }
        }
        tracing::debug!(
            drone = id,
            kind = kind.as_str(),
            request = r.q.cmd.request_id,
            "started"
        );
        self.drones[idx].current = Some(r);
        self.step_current(idx, now);
    }
}
