//! The arbiter's envelope step: speed limits from the config, then the geofence
//! ([`super::geofence`]) for position targets, take-offs and velocity setpoints.

use skymesh_ipc_types::{ArbiterEventKind, Command, CommandSource};

use super::{Arbiter, Effect, VehicleView};

impl Arbiter {
    /// Speed limits and the geofence. `Err` is a geofence refusal.
    pub(super) fn envelope(
        &mut self,
        command: Command,
        vehicle: &VehicleView,
        source: CommandSource,
        effects: &mut Vec<Effect>,
    ) -> Result<(Command, Option<String>), String> {
        let s = &self.settings;
        let mut note = None;
        match command {
            Command::VelocityNed {
                vel_ned_mps,
                yaw_rate_dps,
            } => {
                let mut v = vel_ned_mps;
                let h = v[0].hypot(v[1]);
                if h > s.max_horizontal_speed_mps {
                    let k = s.max_horizontal_speed_mps / h;
                    v[0] *= k;
                    v[1] *= k;
                    note = Some(format!(
                        "speed {h:.1}->{:.1} m/s",
                        s.max_horizontal_speed_mps
                    ));
                }
                let vd = v[2].clamp(-s.max_climb_mps, s.max_descent_mps);
                if vd != v[2] {
                    note = Some(format!("vertical {:.1}->{vd:.1} m/s", v[2]));
                    v[2] = vd;
                }
                let yaw = yaw_rate_dps.map(|r| r.clamp(-s.max_yaw_rate_dps, s.max_yaw_rate_dps));
                if yaw != yaw_rate_dps {
                    note = Some(format!("yaw rate max {:.0} deg/s", s.max_yaw_rate_dps));
                }
                let mut fence_limit = None;
                if !self.fence.is_empty() {
                    match vehicle.position {
                        Some(k) => {
                            for fence in self.fence.fences() {
                                let pos = fence.frame.to_local(k.lat_deg, k.lon_deg);
                                let (out, why) = fence.limit_velocity(
                                    &self.envelope,
                                    pos,
                                    k.alt_rel_m,
                                    k.vel_ned_mps,
                                    v,
                                    &mut self.scratch,
                                );
                                v = out;
                                fence_limit = fence_limit.or(why.map(|w| w.to_string()));
                            }
                        }
                        None if v.iter().any(|x| *x != 0.0) => {
                            v = [0.0; 3];
                            fence_limit = Some("position unknown: fence holds".to_string());
                        }
                        None => {}
                    }
                }
                if fence_limit.is_some() != self.fence_limiting {
                    self.fence_limiting = fence_limit.is_some();
                    if let Some(why) = &fence_limit {
                        effects.push(Effect::Event {
                            kind: ArbiterEventKind::GeofenceLimited,
                            source: Some(source),
                            detail: why.clone(),
                        });
                    }
                }
                Ok((
                    Command::VelocityNed {
                        vel_ned_mps: v,
                        yaw_rate_dps: yaw,
                    },
                    fence_limit.or(note),
                ))
            }
            Command::GoTo {
                lat_deg,
                lon_deg,
                alt_rel_m,
                yaw_deg,
                speed_mps,
            } => {
                let speed = speed_mps.map(|v| v.min(s.max_horizontal_speed_mps));
                if speed != speed_mps {
                    note = Some(format!("speed max {:.1} m/s", s.max_horizontal_speed_mps));
                }
                for fence in self.fence.fences() {
                    if !fence.altitude_ok(alt_rel_m) {
                        return Err(format!(
                            "target alt {alt_rel_m:.1} m outside {:.1}..{:.1} m",
                            fence.floor_m, fence.ceiling_m
                        ));
                    }
                    let target = fence.frame.to_local(lat_deg, lon_deg);
                    if !fence.contains(target) {
                        return Err("target outside the fence".to_string());
                    }
                    if let Some(k) = vehicle.position {
                        let pos = fence.frame.to_local(k.lat_deg, k.lon_deg);
                        let way = target - pos;
                        let dist = way.norm();
                        if fence.contains(pos) && dist > 1e-3 {
                            if let Some(exit) =
                                fence.exit_distance(pos, way / dist, &mut self.scratch)
                            {
                                if exit < dist {
                                    return Err(format!("path leaves the fence after {exit:.0} m"));
                                }
                            }
                        }
                    }
                }
                Ok((
                    Command::GoTo {
                        lat_deg,
                        lon_deg,
                        alt_rel_m,
                        yaw_deg,
                        speed_mps: speed,
                    },
                    note,
                ))
            }
            Command::Takeoff { alt_rel_m } => {
                for fence in self.fence.fences() {
                    if alt_rel_m > fence.ceiling_m {
                        return Err(format!(
                            "takeoff to {alt_rel_m:.1} m above ceiling {:.1} m",
                            fence.ceiling_m
                        ));
                    }
                    if let Some(k) = vehicle.position {
                        if !fence.contains(fence.frame.to_local(k.lat_deg, k.lon_deg)) {
                            return Err("vehicle outside the fence".to_string());
                        }
                    }
                }
                Ok((command, None))
            }
            Command::SetYaw {
                yaw_deg,
                rate_dps,
                relative,
            } if rate_dps > s.max_yaw_rate_dps => Ok((
                Command::SetYaw {
                    yaw_deg,
                    rate_dps: s.max_yaw_rate_dps,
                    relative,
                },
                Some(format!("yaw rate max {:.0} deg/s", s.max_yaw_rate_dps)),
            )),
            other => Ok((other, None)),
        }
    }
}
