//! Control laws of the point-mass model: ArduPilot's square-root position
//! controller, acceleration-limited velocity tracking, and the attitude a
//! multicopter needs to produce a given acceleration.

use nalgebra::{Vector2, Vector3};

/// Gravity, m/s².
pub const GRAVITY: f64 = 9.806_65;

/// Position-error gain in the linear region (ArduCopter PSC_POSXY_P / PSC_POSZ_P = 1).
pub const POS_P: f64 = 1.0;

/// Equivalent linear drag, 1/s: at cruise a multicopter tilts to hold speed
/// against drag, so attitude shows forward flight, not only acceleration.
const DRAG_PER_S: f64 = 0.3;

/// Roll/pitch follow their targets with this time constant, seconds.
const TILT_TAU_S: f64 = 0.12;

/// Maximum lean angle (ArduCopter ANGLE_MAX default 30°).
const MAX_TILT_RAD: f64 = 30.0 * std::f64::consts::PI / 180.0;

/// ArduPilot's `sqrt_controller`: the speed towards a target `error` metres away
/// that still allows stopping at deceleration `accel`, linear (gain `p`) close
/// in. Clamped so one step of `dt` can never cross the target.
pub fn sqrt_controller(error: f64, p: f64, accel: f64, dt: f64) -> f64 {
    let linear_dist = accel / (p * p);
    let out = if error > linear_dist {
        (2.0 * accel * (error - linear_dist / 2.0)).sqrt()
    } else if error < -linear_dist {
        -(2.0 * accel * (-error - linear_dist / 2.0)).sqrt()
    } else {
        error * p
    };
    if dt > 0.0 {
        let max = error.abs() / dt;
        out.clamp(-max, max)
    } else {
        out
    }
}

/// Limits of a velocity demand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Horizontal speed, m/s.
    pub speed_xy: f64,
    /// Climb rate, m/s (positive).
    pub speed_up: f64,
    /// Descent rate, m/s (positive).
    pub speed_down: f64,
    /// Acceleration, m/s².
    pub accel: f64,
}

impl Limits {
    /// Clamp a NED velocity demand to the speed limits.
    pub fn clamp_velocity(&self, v: Vector3<f64>) -> Vector3<f64> {
        let xy = clamp_norm(Vector2::new(v.x, v.y), self.speed_xy);
        Vector3::new(xy.x, xy.y, v.z.clamp(-self.speed_up, self.speed_down))
    }
}

/// The velocity that flies to `target` from `pos` and stops there (no
/// overshoot), plus a feed-forward velocity, within `limits`.
pub fn position_demand(
    pos: &Vector3<f64>,
    target: &Vector3<f64>,
    feed_forward: &Vector3<f64>,
    limits: &Limits,
    dt: f64,
) -> Vector3<f64> {
    let err = target - pos;
    let err_xy = Vector2::new(err.x, err.y);
    let dist = err_xy.norm();
    // Decelerate a little gentler than the limit so discrete steps and the
    // acceleration limit never lag the profile into an overshoot.
    let profile_accel = 0.9 * limits.accel;
    let v_xy = if dist > 1e-9 {
        err_xy * (sqrt_controller(dist, POS_P, profile_accel, dt) / dist)
    } else {
        Vector2::zeros()
    };
    let v_z = sqrt_controller(err.z, POS_P, profile_accel, dt);
    limits.clamp_velocity(Vector3::new(v_xy.x, v_xy.y, v_z) + feed_forward)
}

/// Move `vel` towards `demand` by at most `accel·dt` (horizontal and vertical
/// limited separately, as ArduCopter's position controller does).
pub fn track_velocity(
    vel: &Vector3<f64>,
    demand: &Vector3<f64>,
    accel: f64,
    dt: f64,
) -> Vector3<f64> {
    let dv = demand - vel;
    let dv_xy = clamp_norm(Vector2::new(dv.x, dv.y), accel * dt);
    let dv_z = dv.z.clamp(-accel * dt, accel * dt);
    vel + Vector3::new(dv_xy.x, dv_xy.y, dv_z)
}

/// Where the vehicle would stop if it braked now at `accel`.
pub fn stopping_point(pos: &Vector3<f64>, vel: &Vector3<f64>, accel: f64) -> Vector3<f64> {
    // v²/2a along the velocity vector, per axis group.
    let v_xy = Vector2::new(vel.x, vel.y);
    let stop_xy = v_xy * (v_xy.norm() / (2.0 * accel));
    let stop_z = vel.z * vel.z.abs() / (2.0 * accel);
    pos + Vector3::new(stop_xy.x, stop_xy.y, stop_z)
}

/// Scale `v` down to at most `max` length.
pub fn clamp_norm(v: Vector2<f64>, max: f64) -> Vector2<f64> {
    let n = v.norm();
    if n > max && n > 0.0 {
        v * (max / n)
    } else {
        v
    }
}

/// Euler attitude and body rates.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Attitude {
    /// Roll, radians (right wing down positive).
    pub roll: f64,
    /// Pitch, radians (nose up positive).
    pub pitch: f64,
    /// Yaw, radians clockwise from north, in [-π, π).
    pub yaw: f64,
    /// Body rates p, q, r, rad/s.
    pub rates: Vector3<f64>,
}

/// Roll and pitch a multicopter heading `yaw` needs to accelerate at `accel`
/// (NED) while flying at `vel` against drag, and the specific thrust it needs
/// (m/s², `GRAVITY` in a hover).
pub fn tilt_for(accel: &Vector3<f64>, vel: &Vector3<f64>, yaw: f64) -> (f64, f64, f64) {
    let ax = accel.x + DRAG_PER_S * vel.x;
    let ay = accel.y + DRAG_PER_S * vel.y;
    let (s, c) = yaw.sin_cos();
    let forward = ax * c + ay * s;
    let right = -ax * s + ay * c;
    let up = (GRAVITY - accel.z).max(0.1);
    let pitch = (-forward).atan2(up).clamp(-MAX_TILT_RAD, MAX_TILT_RAD);
    let roll = right
        .atan2((up * up + forward * forward).sqrt())
        .clamp(-MAX_TILT_RAD, MAX_TILT_RAD);
    let thrust = (forward * forward + right * right + up * up).sqrt();
    (roll, pitch, thrust)
}

/// Advance roll/pitch towards their targets (first-order lag), set yaw, and
/// derive body rates from the Euler angle change over `dt`.
pub fn update_attitude(
    att: &Attitude,
    roll_target: f64,
    pitch_target: f64,
    yaw: f64,
    dt: f64,
) -> Attitude {
    let k = (dt / TILT_TAU_S).min(1.0);
    let roll = att.roll + (roll_target - att.roll) * k;
    let pitch = att.pitch + (pitch_target - att.pitch) * k;
    let (d_roll, d_pitch, d_yaw) = if dt > 0.0 {
        (
            (roll - att.roll) / dt,
            (pitch - att.pitch) / dt,
            super::geo::wrap_pi(yaw - att.yaw) / dt,
        )
    } else {
        (0.0, 0.0, 0.0)
    };
    // Euler-rate → body-rate kinematics.
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let rates = Vector3::new(
        d_roll - d_yaw * sp,
        d_pitch * cr + d_yaw * sr * cp,
        -d_pitch * sr + d_yaw * cr * cp,
    );
    Attitude {
        roll,
        pitch,
        yaw,
        rates,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits {
        speed_xy: 5.0,
        speed_up: 2.5,
        speed_down: 1.5,
        accel: 2.5,
    };

    #[test]
    fn sqrt_controller_is_continuous_and_never_crosses() {
        let a = 2.5;
        let lin = a / (POS_P * POS_P);
        let below = sqrt_controller(lin - 1e-9, POS_P, a, 0.0);
        let above = sqrt_controller(lin + 1e-9, POS_P, a, 0.0);
        assert!((below - above).abs() < 1e-6);
        // 7 cm/s would cross a 1 mm error within one 100 ms step: clamped to 1 cm/s.
        assert!((sqrt_controller(0.001, 1000.0, a, 0.1) - 0.01).abs() < 1e-12);
        assert!(sqrt_controller(-50.0, POS_P, a, 0.01) < 0.0);
    }

    #[test]
    fn flies_to_a_point_without_overshoot() {
        let dt = 0.01;
        let mut pos = Vector3::zeros();
        let mut vel = Vector3::zeros();
        let target = Vector3::new(40.0, -30.0, -10.0);
        let mut max_along = 0.0_f64;
        let dir = target.normalize();
        for _ in 0..3000 {
            let d = position_demand(&pos, &target, &Vector3::zeros(), &LIMITS, dt);
            let v2 = track_velocity(&vel, &d, LIMITS.accel, dt);
            pos += (vel + v2) * 0.5 * dt;
            vel = v2;
            max_along = max_along.max(pos.dot(&dir));
            let vxy = (vel.x * vel.x + vel.y * vel.y).sqrt();
            assert!(vxy <= LIMITS.speed_xy + 1e-9);
            assert!(vel.z >= -LIMITS.speed_up - 1e-9);
        }
        assert!((pos - target).norm() < 0.05, "{pos:?}");
        assert!(max_along <= target.norm() + 0.05, "overshoot {max_along}");
    }

    #[test]
    fn stopping_point_is_ahead_by_v_squared_over_2a() {
        let p = stopping_point(&Vector3::zeros(), &Vector3::new(5.0, 0.0, -2.0), 2.5);
        assert!((p.x - 5.0).abs() < 1e-12);
        assert!((p.z + 0.8).abs() < 1e-12);
    }

    #[test]
    fn accelerating_north_pitches_nose_down() {
        let (roll, pitch, thrust) = tilt_for(&Vector3::new(2.5, 0.0, 0.0), &Vector3::zeros(), 0.0);
        assert!(pitch < -0.2 && roll.abs() < 1e-9);
        assert!(thrust > GRAVITY);
        // Facing east, accelerating north is a roll to the left.
        let (roll, pitch, _) = tilt_for(
            &Vector3::new(2.5, 0.0, 0.0),
            &Vector3::zeros(),
            std::f64::consts::FRAC_PI_2,
        );
        assert!(roll < -0.2 && pitch.abs() < 1e-9);
    }

    #[test]
    fn body_rates_follow_yaw_change() {
        let a = update_attitude(&Attitude::default(), 0.0, 0.0, 0.1, 0.1);
        assert!((a.rates.z - 1.0).abs() < 1e-9);
    }
}
