//! Closed-loop tests of the shots against a small point-mass vehicle: velocity
//! follows the setpoint with a first-order lag, acceleration limited like
//! ArduCopter's (2.5 m/s²), stepped at the engine's 25 Hz; optionally the shot sees
//! the vehicle 100 ms late, as telemetry would show it.

mod cable;
mod fence;
mod follow;
mod multipoint;
mod orbit;
mod pano;
mod rewind;
mod selfie;
mod sitescan;
mod zipline;

use std::collections::VecDeque;

use nalgebra::Vector3;

use super::geo::{GeoPoint, LocalFrame};
use super::{Guidance, Limits, VehicleView};

/// The engine's tick.
pub const DT: f32 = 0.04;

/// The vehicle's acceleration limit (ArduCopter WPNAV_ACCEL 250 cm/s²).
pub const ACCEL: f64 = 2.5;

pub const LIMITS: Limits = Limits {
    max_speed_mps: 5.0,
    max_accel_mps2: 2.5,
    max_climb_mps: 2.5,
    position_gain: 1.0,
};

/// Home: ArduPilot SITL's CMAC field.
pub const HOME: GeoPoint = GeoPoint {
    lat_deg: -35.363_261,
    lon_deg: 149.165_230,
    alt_rel_m: 0.0,
};

/// How the simulated vehicle responds.
#[derive(Debug, Clone, Copy)]
pub struct Dynamics {
    /// First-order time constant of velocity tracking, seconds (0 = only the
    /// acceleration limit, like vehicle-sim).
    pub tau_s: f64,
    /// How late the shot sees the vehicle, seconds.
    pub delay_s: f64,
}

/// The variants every closed-loop test runs against.
pub const DYNAMICS: [Dynamics; 4] = [
    Dynamics {
        tau_s: 0.0,
        delay_s: 0.0,
    },
    Dynamics {
        tau_s: 0.3,
        delay_s: 0.0,
    },
    Dynamics {
        tau_s: 0.5,
        delay_s: 0.0,
    },
    Dynamics {
        tau_s: 0.4,
        delay_s: 0.1,
    },
];

/// A point-mass multicopter in a NED frame around [`HOME`].
#[derive(Debug)]
pub struct PointMass {
    frame: LocalFrame,
    pub pos: Vector3<f64>,
    pub vel: Vector3<f64>,
    dynamics: Dynamics,
    /// Views the shot has yet to see (newest last).
    seen: VecDeque<VehicleView>,
    /// The last setpoint, for the smoothness checks.
    last_cmd: Option<[f32; 3]>,
    pub heading_deg: f32,
    /// Steps taken.
    pub steps: usize,
}

impl PointMass {
    /// At rest at `pos` (NED metres from home).
    pub fn new(pos: Vector3<f64>, dynamics: Dynamics) -> Self {
        let mut m = PointMass {
            frame: LocalFrame::new(HOME),
            pos,
            vel: Vector3::zeros(),
            dynamics,
            seen: VecDeque::new(),
            last_cmd: None,
            heading_deg: 0.0,
            steps: 0,
        };
        let now = m.true_view();
        let delay_steps = (dynamics.delay_s / f64::from(DT)).round() as usize;
        m.seen.extend(std::iter::repeat_n(now, delay_steps + 1));
        m
    }

    pub fn geo(&self) -> GeoPoint {
        self.frame.to_geo(&self.pos)
    }

    pub fn ned(&self, p: &GeoPoint) -> Vector3<f64> {
        self.frame.to_ned(p)
    }

    pub fn to_geo(&self, ned: Vector3<f64>) -> GeoPoint {
        self.frame.to_geo(&ned)
    }

    fn true_view(&self) -> VehicleView {
        VehicleView {
            position: self.geo(),
            vel_ned_mps: [self.vel.x as f32, self.vel.y as f32, self.vel.z as f32],
            heading_deg: self.heading_deg,
            camera_pitch_deg: 0.0,
            camera_yaw_deg: self.heading_deg,
        }
    }

    /// What the shot sees this tick (possibly delayed).
    pub fn view(&self) -> VehicleView {
        *self.seen.front().expect("the queue is never empty")
    }

    /// Fly one tick of `g`, checking it obeys [`LIMITS`].
    pub fn fly(&mut self, g: &Guidance) {
        let c = g.velocity_ned_mps;
        assert!(c.iter().all(|x| x.is_finite()), "setpoint {c:?}");
        let h = f64::from(c[0]).hypot(f64::from(c[1]));
        assert!(
            h <= f64::from(LIMITS.max_speed_mps) + 1e-4,
            "horizontal {h}"
        );
        assert!(f64::from(c[2].abs()) <= f64::from(LIMITS.max_climb_mps) + 1e-4);
        if let Some(prev) = self.last_cmd {
            let step =
                ((c[0] - prev[0]).powi(2) + (c[1] - prev[1]).powi(2) + (c[2] - prev[2]).powi(2))
                    .sqrt();
            assert!(
                step <= LIMITS.max_accel_mps2 * DT + 1e-5,
                "setpoint jumped {step} m/s at step {}: {prev:?} → {c:?}",
                self.steps
            );
        }
        self.last_cmd = Some(c);
        self.step(Vector3::new(
            f64::from(c[0]),
            f64::from(c[1]),
            f64::from(c[2]),
        ));
    }

    fn step(&mut self, cmd: Vector3<f64>) {
        let dt = f64::from(DT);
        let want = if self.dynamics.tau_s > 0.0 {
            (cmd - self.vel) * (dt / self.dynamics.tau_s).min(1.0)
        } else {
            cmd - self.vel
        };
        let max = ACCEL * dt;
        let dv = if want.norm() > max {
            want * (max / want.norm())
        } else {
            want
        };
        let v2 = self.vel + dv;
        self.pos += (self.vel + v2) * 0.5 * dt;
        self.vel = v2;
        self.steps += 1;
        let now = self.true_view();
        self.seen.push_back(now);
        self.seen.pop_front();
    }
}

/// Horizontal distance between two NED points.
pub fn ground(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// Seconds → ticks.
pub fn ticks(s: f64) -> usize {
    (s / f64::from(DT)).round() as usize
}
