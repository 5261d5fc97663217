//! The camera gimbal: a stabilised pitch/yaw mount that slews toward its target
//! at a finite rate, within the Solo gimbal's travel.
//!
//! Angles follow gimbal protocol v2's "vehicle frame": pitch is relative to the
//! horizon (negative = camera down), yaw is relative to the nose (clockwise
//! positive) and there is no roll.
//!
//! While the vehicle has a region of interest the gimbal points at it and
//! explicit angle or rate targets are ignored: the ROI wins until it is cleared
//! (by DO_SET_ROI_NONE, a zero location, or a mode change). Then the gimbal holds
//! where it points until the next explicit target. The explicit targets received
//! meanwhile are still recorded in [`super::Payload::mount`].

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::geo::{bearing, wrap_pi};

/// Lowest pitch, radians (straight down).
pub const PITCH_MIN: f64 = -PI / 2.0;
/// Highest pitch, radians (30° above the horizon).
pub const PITCH_MAX: f64 = PI / 6.0;
/// Yaw travel either side of the nose, radians. The mount cannot turn through
/// the back, so moving from +170° to −170° goes the long way, through 0.
pub const YAW_LIMIT: f64 = PI;

/// Closer than this horizontally to the ROI, its bearing is meaningless and the
/// gimbal keeps its yaw (the pitch still goes toward straight down).
const ROI_MIN_DIST_M: f64 = 0.5;

/// Which way a yaw angle is measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum YawFrame {
    /// Relative to the vehicle's nose.
    Vehicle,
    /// Relative to north (the gimbal compensates for the vehicle turning).
    Earth,
}

/// What the gimbal was last told to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GimbalTarget {
    /// Keep the current angles.
    Hold,
    /// Slew to these angles, radians (pitch clamped to the travel).
    Angles {
        /// Pitch, radians, negative down.
        pitch: f64,
        /// Yaw, radians, clockwise positive.
        yaw: f64,
        /// What `yaw` is relative to.
        yaw_frame: YawFrame,
    },
    /// Turn at these rates, rad/s (limited by the slew rate) until the travel ends.
    Rates {
        /// Pitch rate, rad/s (positive up).
        pitch: f64,
        /// Yaw rate, rad/s (positive clockwise).
        yaw: f64,
    },
}

/// Where the gimbal points now, and how fast it moved in the last step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GimbalAttitude {
    /// Pitch above the horizon, radians (negative = down).
    pub pitch: f64,
    /// Yaw relative to the nose, radians in [-π, π] (clockwise positive).
    pub yaw: f64,
    /// Pitch rate, rad/s.
    pub pitch_rate: f64,
    /// Yaw rate relative to the vehicle, rad/s.
    pub yaw_rate: f64,
}

impl GimbalAttitude {
    /// The attitude as a MAVLink quaternion `[w, x, y, z]` (Hamilton, rotation
    /// from the vehicle frame; roll 0, then pitch about y, yaw about z).
    pub fn quaternion(&self) -> [f32; 4] {
        let (sp, cp) = (self.pitch / 2.0).sin_cos();
        let (sy, cy) = (self.yaw / 2.0).sin_cos();
        [
            (cp * cy) as f32,
            (-sp * sy) as f32,
            (sp * cy) as f32,
            (cp * sy) as f32,
        ]
    }

    /// Angular velocity in the vehicle frame, rad/s (x forward, y right, z down):
    /// the pitch rate turns about the camera's own (yawed) pitch axis.
    pub fn angular_velocity(&self) -> Vector3<f64> {
        let (sy, cy) = self.yaw.sin_cos();
        Vector3::new(-self.pitch_rate * sy, self.pitch_rate * cy, self.yaw_rate)
    }
}

/// Angles that point the camera from `pos` at `roi` (both local NED) for a
/// vehicle heading `vehicle_yaw`: pitch = atan2(roi height − vehicle height,
/// horizontal distance), negative when the ROI is below; yaw relative to the
/// nose, `None` when the ROI is (nearly) straight below or above.
pub fn aim_at(pos: &Vector3<f64>, roi: &Vector3<f64>, vehicle_yaw: f64) -> (f64, Option<f64>) {
    let horizontal = (roi.x - pos.x).hypot(roi.y - pos.y);
    // NED: z grows downward, so the ROI's height above the vehicle is −Δz.
    let pitch = (-(roi.z - pos.z)).atan2(horizontal);
    let yaw = (horizontal >= ROI_MIN_DIST_M).then(|| wrap_pi(bearing(pos, roi) - vehicle_yaw));
    (pitch, yaw)
}

/// The simulated gimbal.
#[derive(Debug, Clone, PartialEq)]
pub struct Gimbal {
    /// Slew rate limit, rad/s.
    slew_rate: f64,
    att: GimbalAttitude,
    target: GimbalTarget,
    /// Pointed at the ROI in the last step (so an ROI clear stops it there).
    tracking_roi: bool,
}

impl Gimbal {
    /// Level and facing forward, holding.
    pub fn new(slew_rate: f64) -> Self {
        Self {
            slew_rate,
            att: GimbalAttitude::default(),
            target: GimbalTarget::Hold,
            tracking_roi: false,
        }
    }

    /// Current attitude.
    pub fn attitude(&self) -> GimbalAttitude {
        self.att
    }

    /// The explicit target (ignored while an ROI is set).
    pub fn target(&self) -> GimbalTarget {
        self.target
    }

    /// Set an explicit target; it takes effect once no ROI is set.
    pub fn set_target(&mut self, target: GimbalTarget) {
        self.target = target;
        // A command after an ROI was cleared (before the next step noticed) is the
        // newer intent: the step must not replace it with `Hold`.
        self.tracking_roi = false;
    }

    /// Advance by `dt` seconds. `roi_aim` is [`aim_at`]'s answer while the
    /// vehicle has an ROI, `None` otherwise.
    pub fn step(&mut self, vehicle_yaw: f64, roi_aim: Option<(f64, Option<f64>)>, dt: f64) {
        if !(dt > 0.0 && dt.is_finite()) {
            return;
        }
        let (pitch_goal, yaw_goal) = match roi_aim {
            Some((pitch, yaw)) => {
                self.tracking_roi = true;
                (pitch, yaw.unwrap_or(self.att.yaw))
            }
            None => {
                if self.tracking_roi {
                    // The ROI was cleared: stay pointed where it left the camera.
                    self.tracking_roi = false;
                    self.target = GimbalTarget::Hold;
                }
                self.goal(vehicle_yaw, dt)
            }
        };
        let limit = self.slew_rate * dt;
        let pitch_goal = clamp_finite(pitch_goal, PITCH_MIN, PITCH_MAX, self.att.pitch);
        let yaw_goal = clamp_finite(yaw_goal, -YAW_LIMIT, YAW_LIMIT, self.att.yaw);
        let pitch = slew(self.att.pitch, pitch_goal, limit);
        // No wrap: the travel ends at ±180°, so the difference is the way to go.
        let yaw = slew(self.att.yaw, yaw_goal, limit);
        self.att = GimbalAttitude {
            pitch,
            yaw,
            pitch_rate: (pitch - self.att.pitch) / dt,
            yaw_rate: (yaw - self.att.yaw) / dt,
        };
    }

    /// Where the explicit target wants the camera this step.
    fn goal(&self, vehicle_yaw: f64, dt: f64) -> (f64, f64) {
        match self.target {
            GimbalTarget::Hold => (self.att.pitch, self.att.yaw),
            GimbalTarget::Angles {
                pitch,
                yaw,
                yaw_frame,
            } => {
                let yaw = match yaw_frame {
                    YawFrame::Vehicle => yaw,
                    YawFrame::Earth => wrap_pi(yaw - vehicle_yaw),
                };
                (pitch, yaw)
            }
            GimbalTarget::Rates { pitch, yaw } => {
                let rate = |r: f64| if r.is_finite() { r * dt } else { 0.0 };
                (self.att.pitch + rate(pitch), self.att.yaw + rate(yaw))
            }
        }
    }
}

/// One step from `from` toward `to` of at most `limit`, landing exactly on `to`.
fn slew(from: f64, to: f64, limit: f64) -> f64 {
    if (to - from).abs() <= limit {
        to
    } else {
        from + (to - from).clamp(-limit, limit)
    }
}

/// `x` within `[min, max]`; `fallback` if `x` is not a number.
fn clamp_finite(x: f64, min: f64, max: f64, fallback: f64) -> f64 {
    if x.is_nan() {
        fallback
    } else {
        x.clamp(min, max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    const DT: f64 = 0.01;

    fn run(g: &mut Gimbal, vehicle_yaw: f64, aim: Option<(f64, Option<f64>)>, secs: f64) {
        for _ in 0..(secs / DT).round() as usize {
            g.step(vehicle_yaw, aim, DT);
        }
    }

    fn deg(rad: f64) -> f64 {
        rad.to_degrees()
    }

    #[test]
    fn slews_at_the_configured_rate_and_stops_on_target() {
        let mut g = Gimbal::new(90f64.to_radians());
        g.set_target(GimbalTarget::Angles {
            pitch: -60f64.to_radians(),
            yaw: 45f64.to_radians(),
            yaw_frame: YawFrame::Vehicle,
        });
        run(&mut g, 0.0, None, 0.5);
        let a = g.attitude();
        assert!((deg(a.pitch) + 45.0).abs() < 1e-6, "{}", deg(a.pitch));
        assert!((deg(a.yaw) - 45.0).abs() < 1e-6, "{}", deg(a.yaw));
        assert!((deg(a.pitch_rate) + 90.0).abs() < 1e-6);
        run(&mut g, 0.0, None, 1.0);
        let a = g.attitude();
        assert!((deg(a.pitch) + 60.0).abs() < 1e-9);
        assert_eq!((a.pitch_rate, a.yaw_rate), (0.0, 0.0));
    }

    #[test]
    fn a_target_set_right_after_an_roi_clear_is_kept() {
        let mut g = Gimbal::new(PI);
        // Tracking an ROI below and to the right.
        run(&mut g, 0.0, Some((-0.5, Some(0.5))), 1.0);
        // The ROI is cleared and a new angle arrives before the next step.
        g.set_target(GimbalTarget::Angles {
            pitch: 0.0,
            yaw: 0.0,
            yaw_frame: YawFrame::Vehicle,
        });
        run(&mut g, 0.0, None, 1.0);
        let a = g.attitude();
        assert!(
            deg(a.pitch).abs() < 1e-6 && deg(a.yaw).abs() < 1e-6,
            "{a:?}"
        );
    }

    #[test]
    fn travel_is_limited() {
        let mut g = Gimbal::new(PI);
        g.set_target(GimbalTarget::Angles {
            pitch: 1.5,
            yaw: 0.0,
            yaw_frame: YawFrame::Vehicle,
        });
        run(&mut g, 0.0, None, 2.0);
        assert!((g.attitude().pitch - PITCH_MAX).abs() < 1e-12);
        g.set_target(GimbalTarget::Rates {
            pitch: -10.0,
            yaw: 10.0,
        });
        run(&mut g, 0.0, None, 5.0);
        assert!((g.attitude().pitch - PITCH_MIN).abs() < 1e-12);
        assert!((g.attitude().yaw - YAW_LIMIT).abs() < 1e-12);
        // From +170° to −170° the long way round, through the nose.
        g.set_target(GimbalTarget::Angles {
            pitch: 0.0,
            yaw: -170f64.to_radians(),
            yaw_frame: YawFrame::Vehicle,
        });
        run(&mut g, 0.0, None, 0.5);
        assert!(
            deg(g.attitude().yaw).abs() < 95.0,
            "{}",
            deg(g.attitude().yaw)
        );
    }

    #[test]
    fn earth_frame_yaw_compensates_the_heading() {
        let mut g = Gimbal::new(PI);
        g.set_target(GimbalTarget::Angles {
            pitch: 0.0,
            yaw: 90f64.to_radians(),
            yaw_frame: YawFrame::Earth,
        });
        run(&mut g, 30f64.to_radians(), None, 2.0);
        assert!((deg(g.attitude().yaw) - 60.0).abs() < 1e-6);
    }

    #[test]
    fn roi_below_wins_then_clearing_holds() {
        let mut g = Gimbal::new(90f64.to_radians());
        // 20 m up, ROI 40 m north on the ground.
        let pos = Vector3::new(0.0, 0.0, -20.0);
        let roi = Vector3::new(40.0, 0.0, 0.0);
        let aim = aim_at(&pos, &roi, 0.0);
        let expected = -(20f64 / 40.0).atan();
        assert!((aim.0 - expected).abs() < 1e-12);
        assert_eq!(aim.1, Some(0.0));
        // An explicit target is ignored while the ROI is set.
        g.set_target(GimbalTarget::Angles {
            pitch: 0.3,
            yaw: 1.0,
            yaw_frame: YawFrame::Vehicle,
        });
        run(&mut g, 0.0, Some(aim), 2.0);
        let a = g.attitude();
        assert!((a.pitch - expected).abs() < 2f64.to_radians());
        assert!(a.yaw.abs() < 1e-9);
        // Cleared: holds there.
        run(&mut g, 0.0, None, 2.0);
        assert!((g.attitude().pitch - expected).abs() < 2f64.to_radians());
        assert_eq!(g.target(), GimbalTarget::Hold);
    }

    #[test]
    fn roi_straight_below_keeps_yaw() {
        let pos = Vector3::new(5.0, 5.0, -30.0);
        let (pitch, yaw) = aim_at(&pos, &Vector3::new(5.0, 5.0, 0.0), 1.0);
        assert!((pitch + PI / 2.0).abs() < 1e-12);
        assert_eq!(yaw, None);
        // ROI east while the nose points north: yaw +90°.
        let (_, yaw) = aim_at(&pos, &Vector3::new(5.0, 50.0, -30.0), 0.0);
        assert!((deg(yaw.unwrap_or(0.0)) - 90.0).abs() < 1e-9);
    }

    #[test]
    fn quaternion_matches_nalgebra_and_pitch_down_is_negative() {
        for (p, y) in [(-0.5, 0.3), (0.2, -2.0), (-PI / 2.0, PI)] {
            let a = GimbalAttitude {
                pitch: p,
                yaw: y,
                ..GimbalAttitude::default()
            };
            let q = a.quaternion();
            let n = UnitQuaternion::from_euler_angles(0.0, p, y);
            let expect = [n.w, n.i, n.j, n.k];
            for (got, want) in q.iter().zip(expect) {
                assert!((f64::from(*got) - want).abs() < 1e-6, "{q:?} vs {expect:?}");
            }
        }
        // Camera down 90°: the forward axis maps to +z (down, NED).
        let down = GimbalAttitude {
            pitch: -PI / 2.0,
            ..GimbalAttitude::default()
        };
        let [w, x, y, z] = down.quaternion().map(f64::from);
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let fwd = q * Vector3::x();
        assert!((fwd.z - 1.0).abs() < 1e-6, "{fwd:?}");
    }
}
