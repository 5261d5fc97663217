//! Swarm commands: validated, then applied per kind to one drone or to every drone
//! (queued, followed, played back, halted, homed, rotated).

use super::*;

impl Swarm {
    /// One `SwarmCommand` from the gateway: validated again, then applied to its
    /// drone or to every drone.
    pub fn handle_command(&mut self, cmd: &SwarmCommand, now: u64) {
        self.metrics.received.inc();
        let kind = match cmd.kind() {
            Ok(k) => k,
            Err(e) => return self.refuse(cmd, cmd.drone, &e.to_string()),
        };
        if let Err(e) = cmd.validate() {
            return self.refuse(cmd, cmd.drone, &e.to_string());
        }
        if !kind.is_ext() && !cmd.has(swarm_flags::PRIVILEGED) {
            return self.refuse(
                cmd,
                cmd.drone,
                "privileged command from an unprivileged client",
            );
        }
        if cmd.drone == ALL_DRONES && answered_once(kind) {
            self.quiet = true;
            for idx in 0..self.drones.len() {
                self.apply(idx, cmd, kind, now);
            }
            self.quiet = false;
            self.success(cmd, ALL_DRONES);
        } else if cmd.drone == ALL_DRONES {
            for idx in 0..self.drones.len() {
                self.apply(idx, cmd, kind, now);
            }
        } else if let Some(&idx) = self.by_id.get(&cmd.drone) {
            self.apply(idx, cmd, kind, now);
        } else {
            self.refuse(cmd, cmd.drone, "unknown drone");
        }
    }

    fn apply(&mut self, idx: usize, cmd: &SwarmCommand, kind: SwarmCommandKind, now: u64) {
        let id = self.drones[idx].id;
        if needs_active(kind, cmd) && !self.drones[idx].active {
            return self.refuse(cmd, id, "inactive");
        }
        if moves(kind, cmd) && self.in_emergency(idx) {
            return self.refuse(cmd, id, "emergency mode");
        }
        match kind {
            K::ExtGoExternal
            | K::ExtGoHome
            | K::ExtGoHomeAtPosition
            | K::ExtPause
            | K::ExtColor
            | K::ExtColorGradient => self.enqueue(idx, *cmd, kind, None, now),
            K::ExtWaypoint => {
                let mut c = *cmd;
                if let Err(e) = self.fit_box(idx, &mut c) {
                    return self.refuse(cmd, id, &e);
                }
                self.enqueue(idx, c, kind, None, now);
            }
            K::ExtWaypointFollow | K::ExtWaypointFollowColor => self.follow(idx, cmd, kind, now),
            K::SetManualTarget => self.manual_target(idx, cmd, now),
            K::ExtPlaybackAnim => self.playback(idx, cmd, now),
            K::ExtHalt => {
                self.halt(idx, false, "halted", now);
                self.success(cmd, id);
            }
            K::ExtHaltAndSaveCurCmd => {
                self.halt(idx, true, "halted", now);
                self.success(cmd, id);
            }
            K::ExtPushSavedCmd => self.push_saved(idx, cmd, now),
            K::ExtCheckAllIdle => {
                let idle = i32::from(self.drones[idx].idle());
                self.reply(cmd, id, SwarmResult::IdleState, idle, "");
            }
            K::ExtAnimCancelLoop => self.cancel_loop(idx, cmd),
            K::ExtAnimAdjPlaybackSpeed | K::SetAnimPlaybackSpeed => match self.running_anim(idx) {
                Some(a) => {
                    a.speed = cmd.f[0];
                    self.success(cmd, id);
                }
                None => self.refuse(cmd, id, "no animation playing"),
            },
            K::SetAnimPlaybackTime => match self.running_anim(idx) {
                Some(a) => {
                    let start = a.anim.frames()[0].time_s;
                    a.time = (start + f64::from(cmd.f[0])).clamp(a.t0, a.t1);
                    self.success(cmd, id);
                }
                None => self.refuse(cmd, id, "no animation playing"),
            },
            K::SetAnimColorIntensity => {
                self.drones[idx].anim_intensity = cmd.f[0];
                self.success(cmd, id);
            }
            K::ExtSetActive | K::SetActive => {
                self.drones[idx].active = cmd.int1 == 1;
                tracing::info!(drone = id, active = cmd.int1 == 1, "active set");
                self.success(cmd, id);
            }
            K::ExtSetBoundingBox => {
                let b = Aabb {
                    min: [cmd.f[4], cmd.f[5], cmd.f[6]],
                    max: [cmd.f[0], cmd.f[1], cmd.f[2]],
                };
                tracing::info!(drone = id, min = ?b.min, max = ?b.max, "bounding box set");
                self.drones[idx].bbox = Some(b);
                self.success(cmd, id);
            }
            K::ExtSetHomePositionCoordinate => {
                let home = cmd.position();
                self.drones[idx].home_yaw = cmd.f[3];
                self.set_home(idx, cmd, home, now);
            }
            K::ResetHomePosition => match self.drones[idx].tracking() {
                Some(p) if self.drones[idx].fresh_pose(now, &self.cfg).is_some() => {
                    self.set_home(idx, cmd, p, now)
                }
                _ => self.refuse(cmd, id, "no position from the vehicle"),
            },
            K::ResetHomeToSetup => {
                let d = &self.drones[idx];
                match d.setup_home.or(d.autopilot_home) {
                    Some(h) => self.set_home(idx, cmd, h, now),
                    None => self.refuse(cmd, id, "no setup home"),
                }
            }
            K::ResetHomePositionToAnim => match self.anims.get(id) {
                Ok(a) => {
                    let off = self.drones[idx].anim_offset;
                    let p = a.frames()[0].pos;
                    self.set_home(idx, cmd, [0, 1, 2].map(|i| p[i] + off[i]), now);
                }
                Err(e) => self.refuse(cmd, id, &e),
            },
            K::ResetAnimPosition => {
                self.drones[idx].anim_offset = [0.0; 3];
                self.success(cmd, id);
            }
            K::ResetAnimPositionToDrone => {
                let anim = self.anims.get(id);
                let d = &mut self.drones[idx];
                match (anim, d.tracking()) {
                    (Err(e), _) => self.refuse(cmd, id, &e),
                    (Ok(_), None) => self.refuse(cmd, id, "no position from the vehicle"),
                    (Ok(a), Some(t)) => {
                        let p = a.frames()[0].pos;
                        d.anim_offset = [0, 1, 2].map(|i| t[i] - p[i]);
                        tracing::info!(drone = id, offset = ?d.anim_offset, "animation offset set");
                        self.success(cmd, id);
                    }
                }
            }
            K::ExtText => {
                let text = cmd.text.as_str().to_string();
                if self.hw_index == Some(idx) {
                    self.lcd(&text);
                }
                tracing::info!(drone = id, text = %text, "text");
                self.drones[idx].text = text;
                self.success(cmd, id);
            }
            K::ExtVehicleCmd => self.rotate(idx, cmd, now),
            K::EmergencyMode => self.emergency(idx, cmd, now),
            K::MotorsCmd => {
                let c = if cmd.int1 == 1 {
                    Command::Arm { force: false }
                } else {
                    Command::Disarm { force: false }
                };
                self.side_command(idx, cmd, CommandSource::SwarmQueue, &c, now);
            }
            K::SetCalibrationOffset => {
                self.drones[idx].calibration = cmd.position();
                tracing::info!(drone = id, offset = ?cmd.position(), "calibration offset set");
                self.success(cmd, id);
            }
            K::SetGeofence | K::ReconfigureGeofence => {
                let b = Aabb {
                    min: [cmd.f[4], cmd.f[5], cmd.f[6]],
                    max: [cmd.f[0], cmd.f[1], cmd.f[2]],
                };
                self.set_fence(idx, cmd, b, now);
            }
            K::SetGeofencePosition => match self.drones[idx].fence {
                Some(f) => {
                    let c = cmd.position();
                    let half = [0, 1, 2].map(|i| (f.max[i] - f.min[i]) / 2.0);
                    let b = Aabb {
                        min: [0, 1, 2].map(|i| c[i] - half[i]),
                        max: [0, 1, 2].map(|i| c[i] + half[i]),
                    };
                    self.set_fence(idx, cmd, b, now);
                }
                None => self.refuse(cmd, id, "no geofence set"),
            },
            K::ColorMode | K::ManualColorMode => {
                self.drones[idx].manual_color = cmd.int1 != 0;
                tracing::info!(drone = id, manual = cmd.int1 != 0, "colour source set");
                self.success(cmd, id);
            }
            K::CtrlMode => {
                self.drones[idx].ctrl_mode = cmd.int1;
                tracing::info!(drone = id, mode = cmd.int1, "control mode recorded");
                self.success(cmd, id);
            }
            K::SetGroup => {
                self.drones[idx].group = cmd.int1;
                tracing::info!(drone = id, group = cmd.int1, "group recorded");
                self.success(cmd, id);
            }
            K::SetClockTimeout => {
                self.drones[idx].clock_timeout_ms = cmd.int1;
                tracing::info!(drone = id, ms = cmd.int1, "clock timeout recorded");
                self.success(cmd, id);
            }
            K::ExtResetTrackingToFrame => {
                self.drones[idx].tracking_frame = Some(cmd.int1);
                tracing::info!(
                    drone = id,
                    frame = cmd.int1,
                    "reset tracking to frame recorded (GPS/EKF tracking needs no reset)"
                );
                self.success(cmd, id);
            }
            K::ExtVideo | K::ExtVideoCmd | K::ExtTimecode | K::ExtTimecodeActive => {
                tracing::info!(drone = id, kind = kind.as_str(), int1 = cmd.int1, int2 = cmd.int2, f = ?&cmd.f[..4], d = ?cmd.d, "recorded");
                self.success(cmd, id);
            }
            K::WakeUp | K::EnableSafetyPilot | K::ResetTrackingToSetup => {
                self.refuse(cmd, id, "not meaningful for a MAVLink drone")
            }
        }
    }

    /// Applies the drone's box (bounding box ∩ geofence) to a position command.
    fn fit_box(&self, idx: usize, cmd: &mut SwarmCommand) -> Result<(), String> {
        let d = &self.drones[idx];
        let b = match d.limits() {
            Ok(None) => return Ok(()),
            Ok(Some(b)) => b,
            Err(e) => return Err(e.to_string()),
        };
        let p = cmd.position();
        if b.contains(p) {
            return Ok(());
        }
        match self.cfg.bounding_box {
            BoxPolicy::Refuse => Err("outside the bounding box".into()),
            BoxPolicy::Clamp => {
                let c = b.clamp(p);
                tracing::info!(drone = d.id, from = ?p, to = ?c, "waypoint clamped into the bounding box");
                cmd.f[..3].copy_from_slice(&c);
                Ok(())
            }
        }
    }

    fn enqueue(
        &mut self,
        idx: usize,
        cmd: SwarmCommand,
        kind: SwarmCommandKind,
        anim: Option<std::sync::Arc<crate::anim::Animation>>,
        now: u64,
    ) {
        let d = &mut self.drones[idx];
        if d.queue.len() >= self.cfg.queue_capacity {
            let id = d.id;
            return self.refuse(&cmd, id, "queue full");
        }
        d.queue.push_back(Queued { cmd, kind, anim });
        self.advance(idx, now);
    }

    fn follow(&mut self, idx: usize, cmd: &SwarmCommand, kind: SwarmCommandKind, now: u64) {
        let id = self.drones[idx].id;
        let mut c = *cmd;
        if let Err(e) = self.fit_box(idx, &mut c) {
            return self.refuse(cmd, id, &e);
        }
        let default_speed = self.cfg.default_speed_mps;
        let d = &mut self.drones[idx];
        let new = Queued {
            cmd: c,
            kind,
            anim: None,
        };
        if let Some(r) = d.current.as_mut().filter(|r| is_follow(r.q.kind)) {
            let old = std::mem::replace(&mut r.q, new);
            if let Exec::Waypoint {
                target,
                yaw,
                speed,
                dirty,
                ..
            } = &mut r.exec
            {
                *target = c.position();
                *yaw = c.int1 as f32 / 100.0;
                *speed = if c.f[3] > 0.0 { c.f[3] } else { default_speed };
                *dirty = true;
            }
            if kind == K::ExtWaypointFollowColor {
                d.color = c.rgb1();
            }
            self.reply(
                &old.cmd,
                id,
                SwarmResult::Success,
                0,
                "replaced by a newer follow",
            );
            self.step_current(idx, now);
            return;
        }
        if let Some(q) = d.queue.iter_mut().find(|q| is_follow(q.kind)) {
            let old = std::mem::replace(q, new);
            self.reply(
                &old.cmd,
                id,
                SwarmResult::Success,
                0,
                "replaced by a newer follow",
            );
            return;
        }
        self.enqueue(idx, c, kind, None, now);
    }

    fn manual_target(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        let mut c = *cmd;
        if let Err(e) = self.fit_box(idx, &mut c) {
            return self.refuse(cmd, id, &e);
        }
        let mut steering = false;
        if let Some(r) = self.drones[idx].current.take() {
            steering = matches!(r.exec, Exec::Waypoint { .. });
            self.reply(
                &r.q.cmd,
                id,
                SwarmResult::Refused,
                0,
                "replaced by a manual target",
            );
        }
        self.start(
            idx,
            Queued {
                cmd: c,
                kind: K::SetManualTarget,
                anim: None,
            },
            now,
            steering,
        );
    }

    fn playback(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        let anim = match self.anims.get(id) {
            Ok(a) => a,
            Err(e) => return self.refuse(cmd, id, &e),
        };
        let n = anim.len();
        let first = cmd.int1 as usize;
        if first >= n {
            return self.refuse(
                cmd,
                id,
                &format!("first frame {first} beyond the {n} frames"),
            );
        }
        if cmd.int2 >= 0 && (cmd.int2 as usize) < first {
            return self.refuse(cmd, id, "last frame before the first");
        }
        self.enqueue(idx, *cmd, K::ExtPlaybackAnim, Some(anim), now);
    }

    fn running_anim(&mut self, idx: usize) -> Option<&mut AnimRun> {
        match self.drones[idx].current.as_mut().map(|r| &mut r.exec) {
            Some(Exec::Anim(a)) => Some(a),
            _ => None,
        }
    }

    fn cancel_loop(&mut self, idx: usize, cmd: &SwarmCommand) {
        let id = self.drones[idx].id;
        let mut any = false;
        if let Some(a) = self.running_anim(idx) {
            a.cancel = true;
            any = true;
        }
        for q in self.drones[idx].queue.iter_mut() {
            if q.kind == K::ExtPlaybackAnim {
                q.cmd.f[0] = 0.0;
                any = true;
            }
        }
        if any {
            self.success(cmd, id);
        } else {
            self.refuse(cmd, id, "no animation playing");
        }
    }

    /// Clears the current command (saved when `save`) and the queue, and brakes.
    fn halt(&mut self, idx: usize, save: bool, why: &str, now: u64) {
        let id = self.drones[idx].id;
        let current = self.drones[idx].current.take();
        let queued: Vec<Queued> = self.drones[idx].queue.drain(..).collect();
        if let Some(r) = current {
            if save {
                tracing::info!(
                    drone = id,
                    kind = r.q.kind.as_str(),
                    "current command saved"
                );
                if let Some(old) = self.drones[idx].saved.replace(r.q) {
                    self.refuse(&old.cmd, id, "saved command replaced by a newer one");
                }
            } else {
                self.refuse(&r.q.cmd, id, why);
            }
        }
        for q in queued {
            self.refuse(&q.cmd, id, why);
        }
        self.brake(idx, now);
    }

    fn push_saved(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        let d = &mut self.drones[idx];
        let Some(saved) = d.saved.take() else {
            return self.refuse(cmd, id, "no saved command");
        };
        if d.queue.len() >= self.cfg.queue_capacity {
            d.saved = Some(saved);
            return self.refuse(cmd, id, "queue full");
        }
        d.queue.push_back(saved);
        self.success(cmd, id);
        self.advance(idx, now);
    }

    fn set_home(&mut self, idx: usize, cmd: &SwarmCommand, home: [f32; 3], now: u64) {
        let d = &mut self.drones[idx];
        d.home = Some(home);
        tracing::info!(drone = d.id, home = ?home, "home set");
        // Home keeps its altitude: the vehicle measures heights from it, and a home
        // moved up to a hovering drone would put the ground below zero.
        let alt_msl_m =
            d.pose
                .map(|p| p.home_alt_msl)
                .or_else(|| {
                    d.status
                        .filter(|s| s.home_valid == 1)
                        .map(|s| f64::from(s.home_alt_msl_m))
                })
                .unwrap_or_else(|| self.cfg.site.msl_of_z(f64::from(home[2]))) as f32;
        let v = [0, 1].map(|i| f64::from(home[i] - d.calibration[i]));
        let (lat_deg, lon_deg) = self.cfg.site.to_geodetic(v[0], v[1]);
        let c = Command::SetHome {
            lat_deg,
            lon_deg,
            alt_msl_m,
        };
        self.side_command(idx, cmd, CommandSource::SwarmQueue, &c, now);
    }

    /// `EXT_VEHICLECMD`: `int1` 1 relative, 2 absolute rotation, 4 void.
    fn rotate(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let rot = cmd.f[0];
        let c = match cmd.int1 {
            1 => {
                // Relative, CCW positive; CONDITION_YAW turns clockwise positive.
                let r = wrap_deg(rot);
                let d = &mut self.drones[idx];
                d.relative_rotation = wrap_deg(d.relative_rotation + r);
                Command::SetYaw {
                    yaw_deg: -r,
                    rate_dps: 0.0,
                    relative: true,
                }
            }
            2 => {
                self.drones[idx].relative_rotation = wrap_deg(rot);
                Command::SetYaw {
                    yaw_deg: heading_of_yaw(rot),
                    rate_dps: 0.0,
                    relative: false,
                }
            }
            _ => {
                let id = self.drones[idx].id;
                tracing::debug!(drone = id, "void vehicle command");
                return self.success(cmd, id);
            }
        };
        self.side_command(idx, cmd, CommandSource::SwarmQueue, &c, now);
    }
}
