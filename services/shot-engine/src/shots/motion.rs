//! Control helpers every shot shares: the setpoint shaper that keeps each shot inside
//! [`Limits`], ArduPilot's square-root controller, and hold-point logic for pauses.

use nalgebra::{Vector2, Vector3};

use super::geo::LocalFrame;
use super::{Limits, VehicleView};

/// How long the vehicle takes to follow a velocity setpoint (first-order time
/// constant plus telemetry delay), seconds. Turning flight leads by this much: a
/// velocity command aimed `lag` ahead on the curve (the centripetal feed-forward)
/// keeps a lagging vehicle on the curve instead of drifting outward.
pub(crate) const VELOCITY_LAG_S: f64 = 0.3;

/// Share of `max_accel` a shot plans with (stopping, turning); the rest absorbs the
/// vehicle's lag and corrections.
pub(crate) const PLANNING_ACCEL_SHARE: f64 = 0.6;

/// A pause latches its hold point once the setpoint is this slow, m/s.
const LATCH_SPEED_MPS: f64 = 0.05;

/// Limits as f64, with nonsense (NaN, negative) turned into zero.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lim {
    pub speed: f64,
    pub accel: f64,
    pub climb: f64,
    pub gain: f64,
}

impl Lim {
    pub fn new(l: &Limits) -> Self {
        let clean = |x: f32| {
            if x.is_finite() && x > 0.0 {
                f64::from(x)
            } else {
                0.0
            }
        };
        Lim {
            speed: clean(l.max_speed_mps),
            accel: clean(l.max_accel_mps2),
            climb: clean(l.max_climb_mps),
            gain: clean(l.position_gain),
        }
    }

    /// The deceleration shots plan stops and turns with, m/s².
    pub fn plan_accel(&self) -> f64 {
        self.accel * PLANNING_ACCEL_SHARE
    }

    /// Scale a velocity down to the horizontal and vertical limits.
    pub fn clamp(&self, v: Vector3<f64>) -> Vector3<f64> {
        let xy = clamp_norm2(Vector2::new(v.x, v.y), self.speed);
        Vector3::new(xy.x, xy.y, v.z.clamp(-self.climb, self.climb))
    }

    /// The largest speed along unit direction `u` within both speed limits.
    pub fn speed_along(&self, u: &Vector3<f64>) -> f64 {
        let h = u.x.hypot(u.y);
        let mut s = f64::INFINITY;
        if h > 1e-9 {
            s = s.min(self.speed / h);
        }
        if u.z.abs() > 1e-9 {
            s = s.min(self.climb / u.z.abs());
        }
        if s.is_finite() {
            s
        } else {
            0.0
        }
    }
}

/// Turns a shot's wish into the setpoint actually sent: within the speed limits and
/// at most `max_accel · dt` away from the previous setpoint (the first one starts
/// from the vehicle's measured velocity, so entering a shot at speed is smooth).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Shaper {
    last: Option<Vector3<f64>>,
}

impl Shaper {
    /// The previous setpoint, or the vehicle's velocity before the first.
    pub fn current(&self, v: &VehicleView) -> Vector3<f64> {
        self.last.unwrap_or_else(|| velocity(v))
    }

    /// Shape `wish` into this step's setpoint.
    pub fn shape(
        &mut self,
        wish: Vector3<f64>,
        v: &VehicleView,
        dt: f32,
        lim: &Lim,
    ) -> Vector3<f64> {
        let wish = if finite3(&wish) {
            lim.clamp(wish)
        } else {
            Vector3::zeros()
        };
        let from = lim.clamp(self.current(v));
        let dt = if dt.is_finite() {
            f64::from(dt).clamp(0.0, 1.0)
        } else {
            0.0
        };
        // A hair under the limit so the f32 setpoints the engine sends stay within it.
        let max_step = lim.accel * dt * 0.999;
        let step = wish - from;
        let n = step.norm();
        let out = if n > max_step {
            from + step * (max_step / n)
        } else {
            wish
        };
        self.last = Some(out);
        out
    }
}

/// ArduPilot's `sqrt_controller`: the speed towards a target `error` away that still
/// stops there at deceleration `accel`, linear with gain `p` close in. Never more than
/// would cross the target within `dt`.
pub(crate) fn sqrt_controller(error: f64, p: f64, accel: f64, dt: f64) -> f64 {
    let out = if p <= 0.0 {
        if accel <= 0.0 {
            0.0
        } else {
            error.signum() * (2.0 * accel * error.abs()).sqrt()
        }
    } else if accel <= 0.0 {
        error * p
    } else {
        let linear = accel / (p * p);
        if error > linear {
            (2.0 * accel * (error - linear / 2.0)).sqrt()
        } else if error < -linear {
            -(2.0 * accel * (-error - linear / 2.0)).sqrt()
        } else {
            error * p
        }
    };
    if dt > 0.0 {
        let max = error.abs() / dt;
        out.clamp(-max, max)
    } else {
        out
    }
}

/// Where a coordinate moving at `speed` comes to rest braking at `accel`.
pub(crate) fn stopping_point(x: f64, speed: f64, accel: f64) -> f64 {
    if accel > 0.0 {
        x + speed * speed.abs() / (2.0 * accel)
    } else {
        x
    }
}

/// A 1-D hold for pauses: while paused the coordinate (along a cable, around an
/// orbit) decelerates to where it would stop and then holds that point, so wind or
/// drift while paused is corrected rather than accumulated.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Hold1 {
    target: Option<f64>,
}

impl Hold1 {
    /// Leave the pause.
    pub fn release(&mut self) {
        self.target = None;
    }

    /// The speed along the coordinate this step: `x` now, `commanded` the speed last
    /// commanded along it, `bounds` where the hold point must lie.
    pub fn speed(&mut self, x: f64, commanded: f64, bounds: (f64, f64), lim: &Lim, dt: f64) -> f64 {
        let target = *self.target.get_or_insert_with(|| {
            stopping_point(x, commanded, lim.plan_accel()).clamp(bounds.0, bounds.1.max(bounds.0))
        });
        sqrt_controller(target - x, lim.gain, lim.plan_accel(), dt)
    }
}

/// A 3-D hold: decelerate with the setpoint, latch the point once slow, then hold it.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct HoldPoint {
    point: Option<Vector3<f64>>,
}

impl HoldPoint {
    /// Forget the held point.
    pub fn release(&mut self) {
        self.point = None;
    }

    /// The held point, once latched.
    pub fn point(&self) -> Option<Vector3<f64>> {
        self.point
    }

    /// The velocity wish this step, `pos` now, `commanded` the previous setpoint.
    pub fn wish(
        &mut self,
        pos: &Vector3<f64>,
        commanded: &Vector3<f64>,
        lim: &Lim,
        dt: f64,
    ) -> Vector3<f64> {
        if self.point.is_none() && commanded.norm() <= LATCH_SPEED_MPS {
            self.point = Some(*pos);
        }
        match self.point {
            Some(p) => toward(pos, &p, lim, dt),
            None => Vector3::zeros(),
        }
    }
}

/// The velocity that flies from `pos` to `target` and stops there (square-root
/// profile horizontally and vertically).
pub(crate) fn toward(
    pos: &Vector3<f64>,
    target: &Vector3<f64>,
    lim: &Lim,
    dt: f64,
) -> Vector3<f64> {
    let err = target - pos;
    let exy = Vector2::new(err.x, err.y);
    let d = exy.norm();
    let a = lim.plan_accel();
    let vxy = if d > 1e-9 {
        exy * (sqrt_controller(d, lim.gain, a, dt) / d)
    } else {
        Vector2::zeros()
    };
    let vz = sqrt_controller(err.z, lim.gain, a, dt);
    Vector3::new(vxy.x, vxy.y, vz)
}

/// The vehicle's measured velocity (NaN read as zero).
pub(crate) fn velocity(v: &VehicleView) -> Vector3<f64> {
    let c = |x: f32| if x.is_finite() { f64::from(x) } else { 0.0 };
    Vector3::new(
        c(v.vel_ned_mps[0]),
        c(v.vel_ned_mps[1]),
        c(v.vel_ned_mps[2]),
    )
}

/// Scale `v` down to at most `max` long.
pub(crate) fn clamp_norm2(v: Vector2<f64>, max: f64) -> Vector2<f64> {
    let n = v.norm();
    if n > max && n > 0.0 {
        v * (max / n)
    } else {
        v
    }
}

pub(crate) fn finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// A setpoint as the engine sends it.
pub(crate) fn to_f32(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// `dt` as f64, zero when nonsense.
pub(crate) fn dt64(dt: f32) -> f64 {
    if dt.is_finite() && dt > 0.0 {
        f64::from(dt)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shots::geo::GeoPoint;

    const LIM: Limits = Limits {
        max_speed_mps: 5.0,
        max_accel_mps2: 2.5,
        max_climb_mps: 2.0,
        position_gain: 1.0,
    };

    fn moving(vel: [f32; 3]) -> VehicleView {
        VehicleView {
            position: GeoPoint {
                lat_deg: 0.0,
                lon_deg: 0.0,
                alt_rel_m: 0.0,
            },
            vel_ned_mps: vel,
            heading_deg: 0.0,
            camera_pitch_deg: 0.0,
            camera_yaw_deg: 0.0,
        }
    }

    #[test]
    fn shaper_starts_from_the_vehicle_and_limits_each_step() {
        let lim = Lim::new(&LIM);
        let v = moving([3.0, 0.0, 0.0]);
        let mut s = Shaper::default();
        let first = s.shape(Vector3::new(0.0, 3.0, 0.0), &v, 0.04, &lim);
        assert!((first - Vector3::new(3.0, 0.0, 0.0)).norm() <= 0.1 + 1e-9);
        assert!(first.x < 3.0 && first.y > 0.0);
        let mut prev = first;
        for _ in 0..100 {
            let next = s.shape(Vector3::new(0.0, 3.0, -9.0), &v, 0.04, &lim);
            assert!((next - prev).norm() <= 0.1 + 1e-9);
            prev = next;
        }
        assert!(
            (prev - Vector3::new(0.0, 3.0, -2.0)).norm() < 1e-9,
            "{prev:?}"
        );
    }

    #[test]
    fn shaper_clamps_speed_and_survives_nonsense() {
        let lim = Lim::new(&LIM);
        let v = moving([f32::NAN, 0.0, 0.0]);
        let mut s = Shaper::default();
        for _ in 0..200 {
            s.shape(Vector3::new(30.0, 40.0, 0.0), &v, 0.04, &lim);
        }
        let out = s.shape(Vector3::new(30.0, 40.0, 0.0), &v, 0.04, &lim);
        assert!((out.xy().norm() - 5.0).abs() < 1e-9);
        // NaN wish → stop; NaN or negative dt → no change at all.
        let held = s.shape(Vector3::new(f64::NAN, 0.0, 0.0), &v, f32::NAN, &lim);
        assert_eq!(held, out);
        let held = s.shape(Vector3::zeros(), &v, -1.0, &lim);
        assert_eq!(held, out);
        let slower = s.shape(Vector3::new(f64::NAN, 0.0, 0.0), &v, 0.04, &lim);
        assert!(slower.norm() < out.norm());
        // Nonsense limits: nothing moves.
        let none = Lim::new(&Limits {
            max_speed_mps: f32::NAN,
            max_accel_mps2: -1.0,
            max_climb_mps: 0.0,
            position_gain: f32::INFINITY,
        });
        let mut s = Shaper::default();
        assert_eq!(
            s.shape(Vector3::new(1.0, 1.0, 1.0), &moving([0.0; 3]), 0.04, &none),
            Vector3::zeros()
        );
    }

    #[test]
    fn sqrt_controller_is_continuous_and_never_crosses_the_target() {
        let lin = 1.5;
        let below = sqrt_controller(lin - 1e-9, 1.0, 1.5, 0.0);
        let above = sqrt_controller(lin + 1e-9, 1.0, 1.5, 0.0);
        assert!((below - above).abs() < 1e-6);
        assert!((sqrt_controller(0.001, 1000.0, 1.5, 0.1) - 0.01).abs() < 1e-12);
        assert!(sqrt_controller(-50.0, 1.0, 1.5, 0.04) < -10.0);
        assert_eq!(sqrt_controller(3.0, 0.0, 0.0, 0.04), 0.0);
        assert!((sqrt_controller(2.0, 0.0, 1.0, 0.0) - 2.0).abs() < 1e-12);
        assert!((sqrt_controller(2.0, 0.5, 0.0, 0.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn stopping_point_is_v_squared_over_two_a_ahead() {
        assert!((stopping_point(10.0, 4.0, 2.0) - 14.0).abs() < 1e-12);
        assert!((stopping_point(10.0, -4.0, 2.0) - 6.0).abs() < 1e-12);
        assert_eq!(stopping_point(10.0, 4.0, 0.0), 10.0);
    }

    #[test]
    fn speed_along_respects_both_limits() {
        let lim = Lim::new(&LIM);
        assert!((lim.speed_along(&Vector3::new(1.0, 0.0, 0.0)) - 5.0).abs() < 1e-12);
        assert!((lim.speed_along(&Vector3::new(0.0, 0.0, -1.0)) - 2.0).abs() < 1e-12);
        let diag = Vector3::new(1.0, 0.0, -1.0).normalize();
        assert!((lim.speed_along(&diag) - 2.0 * 2f64.sqrt()).abs() < 1e-9);
        assert_eq!(lim.speed_along(&Vector3::zeros()), 0.0);
    }
}

/// Closer to a centre than this the bearing from it is noise: the outward direction
/// latched when the circling began is used instead, metres.
pub(crate) const DIRECTION_MIN_M: f64 = 0.5;

/// Where a vehicle stands around a centre (circling shots: orbit, structure scan).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Radial {
    /// NED position in the centre's frame.
    pub p: Vector3<f64>,
    /// Horizontal distance from the centre.
    pub r: f64,
    /// Unit vector from the centre out to the vehicle (`fallback_out` when on it).
    pub out: Vector2<f64>,
    /// Counter-clockwise tangent seen from above (from north towards west).
    pub ccw: Vector2<f64>,
    /// Angle of `out`, radians (clockwise from north).
    pub angle: f64,
}

pub(crate) fn radial(frame: &LocalFrame, v: &VehicleView, fallback_out: Vector2<f64>) -> Radial {
    let p = frame.to_ned(&v.position);
    let h = Vector2::new(p.x, p.y);
    let r = h.norm();
    let out = if r > DIRECTION_MIN_M {
        h / r
    } else {
        fallback_out
    };
    Radial {
        p,
        r,
        out,
        ccw: Vector2::new(out.y, -out.x),
        angle: out.y.atan2(out.x),
    }
}
