//! Heading control: hold, slew by a signed angle (CONDITION_YAW, setpoint yaw),
//! fly a yaw rate until it expires, or face a point (ROI, CIRCLE centre).

use nalgebra::Vector3;

use super::geo::{bearing, wrap_pi};

/// Gain from heading error to yaw rate when facing a point, 1/s.
const FACE_P: f64 = 2.0;

/// Closer than this (horizontally) to the point it faces, the vehicle holds
/// heading: the bearing is meaningless straight above it.
const FACE_MIN_DIST_M: f64 = 1.0;

/// What the heading does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum YawMode {
    /// Keep the current heading.
    Hold,
    /// Turn by `remaining` radians (signed: positive clockwise) at `rate` rad/s.
    Slew {
        /// Angle still to turn, radians.
        remaining: f64,
        /// Turn rate, rad/s (positive).
        rate: f64,
    },
    /// Turn at `rate` rad/s until sim time `until`, then hold.
    Rate {
        /// Yaw rate, rad/s (positive clockwise).
        rate: f64,
        /// Sim time the rate expires, seconds.
        until: f64,
    },
    /// Keep the nose pointed at a local NED point.
    Face(Vector3<f64>),
}

impl YawMode {
    /// Slew to the absolute heading `target` the short way round.
    pub fn to_heading(current: f64, target: f64, rate: f64) -> Self {
        YawMode::Slew {
            remaining: wrap_pi(target - current),
            rate,
        }
    }

    /// Yaw rate for this step (rad/s, within `max_rate`), advancing the mode's
    /// own state; a finished slew or expired rate becomes `Hold`.
    pub fn step(&mut self, pos: &Vector3<f64>, yaw: f64, now: f64, max_rate: f64, dt: f64) -> f64 {
        if dt <= 0.0 {
            return 0.0;
        }
        match *self {
            YawMode::Hold => 0.0,
            YawMode::Slew { remaining, rate } => {
                let limit = rate.min(max_rate) * dt;
                let turn = remaining.clamp(-limit, limit);
                let left = remaining - turn;
                *self = if left.abs() < 1e-9 {
                    YawMode::Hold
                } else {
                    YawMode::Slew {
                        remaining: left,
                        rate,
                    }
                };
                turn / dt
            }
            YawMode::Rate { rate, until } => {
                if now >= until {
                    *self = YawMode::Hold;
                    0.0
                } else {
                    rate.clamp(-max_rate, max_rate)
                }
            }
            YawMode::Face(point) => {
                let dx = point.x - pos.x;
                let dy = point.y - pos.y;
                if (dx * dx + dy * dy).sqrt() < FACE_MIN_DIST_M {
                    return 0.0;
                }
                let err = wrap_pi(bearing(pos, &point) - yaw);
                // Never turn past the target within one step.
                let max_step = err.abs() / dt;
                (err * FACE_P)
                    .clamp(-max_rate, max_rate)
                    .clamp(-max_step, max_step)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn run(mode: &mut YawMode, mut yaw: f64, pos: Vector3<f64>, secs: f64) -> f64 {
        let dt = 0.01;
        let mut t = 0.0;
        while t < secs {
            yaw = wrap_pi(yaw + mode.step(&pos, yaw, t, 1.5, dt) * dt);
            t += dt;
        }
        yaw
    }

    #[test]
    fn slew_ends_on_target_and_holds() {
        let mut m = YawMode::to_heading(0.0, FRAC_PI_2, 1.0);
        let yaw = run(&mut m, 0.0, Vector3::zeros(), 3.0);
        assert!((yaw - FRAC_PI_2).abs() < 1e-6);
        assert_eq!(m, YawMode::Hold);
    }

    #[test]
    fn slew_the_long_way_round() {
        // 270° clockwise from north ends at west, passing east and south.
        let mut m = YawMode::Slew {
            remaining: 1.5 * PI,
            rate: 1.0,
        };
        let mid = run(&mut m, 0.0, Vector3::zeros(), 2.0);
        assert!(mid > 1.9, "went clockwise: {mid}");
        let end = run(&mut m, mid, Vector3::zeros(), 5.0);
        assert!((end + FRAC_PI_2).abs() < 1e-6, "{end}");
    }

    #[test]
    fn faces_a_point_and_rate_expires() {
        let mut m = YawMode::Face(Vector3::new(0.0, -10.0, 0.0));
        let yaw = run(&mut m, 0.0, Vector3::zeros(), 5.0);
        assert!((yaw + FRAC_PI_2).abs() < 1e-3, "{yaw}");

        let mut m = YawMode::Rate {
            rate: 0.5,
            until: 1.0,
        };
        let yaw = run(&mut m, 0.0, Vector3::zeros(), 3.0);
        assert!((yaw - 0.5).abs() < 0.02, "{yaw}");
        assert_eq!(m, YawMode::Hold);
    }
}
