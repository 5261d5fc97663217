//! What each flight mode asks of the position controller: per step, a velocity
//! demand, and whether that demand may lift the vehicle off the ground.

use nalgebra::{Vector2, Vector3};

use super::control::{position_demand, Limits};
use super::yaw::YawMode;
use super::Vehicle;

/// Above this height LAND descends at the full descent speed (LAND_ALT_LOW).
const LAND_ALT_LOW_M: f64 = 10.0;

/// RTL loiters this long above home before landing (RTL_LOIT_TIME).
const RTL_LOITER_S: f64 = 5.0;

/// A position target counts as reached within this distance, metres.
const ARRIVED_M: f64 = 0.2;

/// CIRCLE radius and rate (CIRCLE_RADIUS 10 m, CIRCLE_RATE 20°/s clockwise).
pub(super) const CIRCLE_RADIUS_M: f64 = 10.0;
const CIRCLE_RATE_RAD_S: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// The active guidance of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Guidance {
    /// Hold a point (LOITER, POSHOLD, BRAKE, AUTO without mission, GUIDED idle).
    Hold(Vector3<f64>),
    /// Climb to a point; the only guidance that leaves the ground.
    Takeoff(Vector3<f64>),
    /// Fly to a point. `ff` is a feed-forward velocity that also moves the
    /// target (GUIDED position+velocity), zeroed after `ff_until`.
    Position {
        target: Vector3<f64>,
        ff: Vector3<f64>,
        ff_until: f64,
    },
    /// Fly a velocity until `until`, then stop (GUIDED velocity timeout).
    Velocity { vel: Vector3<f64>, until: f64 },
    /// Manual modes without a pilot: brake horizontally, hold altitude `z`.
    Manual { z: f64 },
    /// Descend to the ground above `xy`.
    Land { xy: Vector2<f64> },
    /// Return to launch.
    Rtl(RtlPhase),
    /// Orbit `center` (clockwise), currently at `angle` from it.
    Circle { center: Vector3<f64>, angle: f64 },
}

/// The stages of RTL.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum RtlPhase {
    /// Climb to return altitude `z` (NED) above the current point.
    Climb { z: f64 },
    /// Fly home at altitude `z`.
    Return { z: f64 },
    /// Hover above home at `z` until sim time `until`.
    Loiter { z: f64, until: f64 },
}

/// One step's demand on the position controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Demand {
    /// Desired NED velocity, m/s.
    pub vel: Vector3<f64>,
    /// The demand may lift the vehicle off the ground.
    pub lift_off: bool,
}

impl Vehicle {
    /// Compute this step's demand, advancing guidance state (RTL phases, the
    /// circle angle, expired feed-forward).
    pub(super) fn demand(&mut self, dt: f64) -> Demand {
        let limits = self.limits();
        let now = self.time_s;
        let pos = self.pos;
        let hold =
            |target: &Vector3<f64>| position_demand(&pos, target, &Vector3::zeros(), &limits, dt);
        let mut lift_off = false;
        // Guidance is Copy: work on a copy and store the successor state at the end.
        let mut next = self.guidance;
        let vel = match self.guidance {
            Guidance::Hold(target) => hold(&target),
            Guidance::Takeoff(target) => {
                lift_off = true;
                if (pos - target).norm() < ARRIVED_M {
                    next = Guidance::Hold(target);
                }
                hold(&target)
            }
            Guidance::Position {
                target,
                ff,
                ff_until,
            } => {
                let ff = if now >= ff_until {
                    Vector3::zeros()
                } else {
                    ff
                };
                let target = target + ff * dt;
                next = Guidance::Position {
                    target,
                    ff,
                    ff_until,
                };
                position_demand(&pos, &target, &ff, &limits, dt)
            }
            Guidance::Velocity { vel, until } => {
                if now >= until {
                    next = Guidance::Velocity {
                        vel: Vector3::zeros(),
                        until,
                    };
                    Vector3::zeros()
                } else {
                    limits.clamp_velocity(vel)
                }
            }
            Guidance::Manual { z } => {
                let mut v = hold(&Vector3::new(pos.x, pos.y, z));
                // No pilot input: centred sticks brake to a stop.
                v.x = 0.0;
                v.y = 0.0;
                v
            }
            Guidance::Land { xy } => {
                let mut v = hold(&Vector3::new(xy.x, xy.y, pos.z));
                v.z = if self.height_above_ground() > LAND_ALT_LOW_M {
                    limits.speed_down
                } else {
                    self.params.land_speed
                };
                v
            }
            Guidance::Rtl(phase) => {
                let home = self.home.unwrap_or_else(Vector3::zeros);
                match phase {
                    RtlPhase::Climb { z } => {
                        if (pos.z - z).abs() < ARRIVED_M {
                            next = Guidance::Rtl(RtlPhase::Return { z });
                        }
                        hold(&Vector3::new(pos.x, pos.y, z))
                    }
                    RtlPhase::Return { z } => {
                        let target = Vector3::new(home.x, home.y, z);
                        if (pos - target).norm() < ARRIVED_M && self.vel.norm() < 0.3 {
                            next = Guidance::Rtl(RtlPhase::Loiter {
                                z,
                                until: now + RTL_LOITER_S,
                            });
                        }
                        hold(&target)
                    }
                    RtlPhase::Loiter { z, until } => {
                        if now >= until {
                            next = Guidance::Land {
                                xy: Vector2::new(home.x, home.y),
                            };
                        }
                        hold(&Vector3::new(home.x, home.y, z))
                    }
                }
            }
            Guidance::Circle { center, angle } => {
                let angle = angle + CIRCLE_RATE_RAD_S * dt;
                next = Guidance::Circle { center, angle };
                let (s, c) = angle.sin_cos();
                let target = center + Vector3::new(c, s, 0.0) * CIRCLE_RADIUS_M;
                let ff = Vector3::new(-s, c, 0.0) * (CIRCLE_RADIUS_M * CIRCLE_RATE_RAD_S);
                position_demand(&pos, &target, &ff, &limits, dt)
            }
        };
        self.guidance = next;
        Demand { vel, lift_off }
    }

    /// Guidance for entering `self.mode` now.
    pub(super) fn guidance_for_mode(&mut self) -> Guidance {
        use super::FlightMode as M;
        let limits = self.limits();
        let stop = if self.landed {
            self.pos
        } else {
            super::control::stopping_point(&self.pos, &self.vel, limits.accel)
        };
        match self.mode {
            M::Stabilize | M::Acro | M::AltHold => Guidance::Manual { z: stop.z },
            M::Guided | M::Loiter | M::PosHold | M::Brake | M::Auto => Guidance::Hold(stop),
            M::Land => Guidance::Land {
                xy: Vector2::new(stop.x, stop.y),
            },
            M::Rtl if self.landed => Guidance::Land {
                xy: Vector2::new(self.pos.x, self.pos.y),
            },
            M::Rtl => {
                let home_z = self.home.map_or(0.0, |h| h.z);
                Guidance::Rtl(RtlPhase::Climb {
                    z: self.pos.z.min(home_z - self.params.rtl_alt_m),
                })
            }
            M::Circle => {
                // ArduCopter puts the centre one radius ahead of the nose.
                let (s, c) = self.att.yaw.sin_cos();
                let center = stop + Vector3::new(c, s, 0.0) * CIRCLE_RADIUS_M;
                self.yaw_mode = YawMode::Face(center);
                Guidance::Circle {
                    center,
                    angle: self.att.yaw + std::f64::consts::PI,
                }
            }
        }
    }

    /// Speed/acceleration limits, with any DO_CHANGE_SPEED override.
    pub(super) fn limits(&self) -> Limits {
        Limits {
            speed_xy: self.speed_override.xy.unwrap_or(self.params.max_speed_xy),
            speed_up: self.speed_override.up.unwrap_or(self.params.max_speed_up),
            speed_down: self
                .speed_override
                .down
                .unwrap_or(self.params.max_speed_down),
            accel: self.params.max_accel,
        }
    }
}
