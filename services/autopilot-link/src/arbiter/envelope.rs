//! The arbiter's envelope step: speed limits from the config, then the fences
//! ([`super::fence_stack`], all sources' at once) for position targets, take-offs and
//! velocity setpoints.
//!
//! - `VelocityNed`: [`super::fence_stack::FenceStack::limit_velocity`] (the stop
//!   predicted from the current velocity, the command and the fix's age stays the
//!   margin inside every fence).
//! - `GoTo`: always sent with a speed (the command's, capped, else the cap), so a
//!   `DO_CHANGE_SPEED` always precedes it. Under a fence: the target altitude within
//!   the vertical margin, the target the margin inside, the straight path checked
//!   ([`super::fence_stack::FenceStack::check_path`]); refused when the position is
//!   unknown; from outside, only a path that enters once and stays in, clear of
//!   every keep-out by the margin; from inside a keep-out, refused.
//! - `Takeoff`: under a fence, refused when the position is unknown, outside the
//!   fence, or above the lowest ceiling less the vertical margin.

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
                    match &vehicle.position {
                        Some(k) => {
                            let (out, why) = self.fence.limit_velocity(
                                &self.envelope,
                                k,
                                v,
                                s.max_horizontal_speed_mps,
                            );
                            v = out;
                            fence_limit = why.map(|w| w.to_string());
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
                // Always a speed: without one the autopilot flies its own default
                // (WPNAV_SPEED), which nothing here bounds.
                let cap = s.max_horizontal_speed_mps;
                let speed = speed_mps.map_or(cap, |v| v.min(cap));
                if speed_mps.is_some_and(|v| v > cap) {
                    note = Some(format!("speed max {cap:.1} m/s"));
                }
                if !self.fence.is_empty() {
                    self.altitude_target(alt_rel_m, "target alt")?;
                    let from = vehicle.position.map(|k| (k.lat_deg, k.lon_deg));
                    self.fence.check_path(
                        from,
                        (lat_deg, lon_deg),
                        self.envelope.margin_m,
                        &mut self.scratch,
                    )?;
                }
                Ok((
                    Command::GoTo {
                        lat_deg,
                        lon_deg,
                        alt_rel_m,
                        yaw_deg,
                        speed_mps: Some(speed),
                    },
                    note,
                ))
            }
            Command::Takeoff { alt_rel_m } => {
                if !self.fence.is_empty() {
                    self.altitude_target(alt_rel_m, "takeoff to")?;
                    let Some(k) = vehicle.position else {
                        return Err("position unknown: takeoff not checked".to_string());
                    };
                    if !self.fence.contains(k.lat_deg, k.lon_deg) {
                        return Err("vehicle outside the fence".to_string());
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

    /// A target altitude within the fences' lowest ceiling and highest floor, the
    /// vertical margin inside.
    fn altitude_target(&self, alt_rel_m: f32, what: &str) -> Result<(), String> {
        let vm = self.envelope.vertical_margin_m as f32;
        let ceiling = self.fence.ceiling_m().unwrap_or(f32::MAX) - vm;
        let floor = self.fence.floor_m().unwrap_or(f32::MIN) + vm;
        if (floor..=ceiling).contains(&alt_rel_m) {
            Ok(())
        } else {
            Err(format!(
                "{what} {alt_rel_m:.1} m outside {floor:.1}..{ceiling:.1} m"
            ))
        }
    }
}
