//! Angle wrapping, one definition for every service (heading, yaw, bearing and
//! longitude arithmetic). Half-open ranges: the lower end is included, the upper
//! end is not, including for the tiny negative inputs whose `rem_euclid` rounds up
//! to the full turn.

use std::f64::consts::{PI, TAU};

/// Radians into `[−π, π)`.
pub fn wrap_pi(rad: f64) -> f64 {
    let w = (rad + PI).rem_euclid(TAU) - PI;
    if w >= PI {
        w - TAU
    } else {
        w
    }
}

/// Radians into `[0, 2π)`.
pub fn wrap_2pi(rad: f64) -> f64 {
    let w = rad.rem_euclid(TAU);
    if w >= TAU {
        0.0
    } else {
        w
    }
}

/// Degrees into `[−180, 180)`.
pub fn wrap_180(deg: f64) -> f64 {
    let w = (deg + 180.0).rem_euclid(360.0) - 180.0;
    if w >= 180.0 {
        w - 360.0
    } else {
        w
    }
}

/// Degrees into `(−180, 180]`: [`wrap_180`] keeping +180 rather than −180, for yaws
/// reported in that range (the gimbal yaw in `PayloadState`, DJI gimbal payloads).
pub fn wrap_180_upper(deg: f64) -> f64 {
    let w = wrap_180(deg);
    if w <= -180.0 {
        w + 360.0
    } else {
        w
    }
}

/// Degrees into `[0, 360)`.
pub fn wrap_360(deg: f64) -> f64 {
    let w = deg.rem_euclid(360.0);
    if w >= 360.0 {
        0.0
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn radians() {
        assert!(close(wrap_pi(3.0 * PI / 2.0), -FRAC_PI_2));
        assert!(close(wrap_pi(-3.0 * PI / 2.0), FRAC_PI_2));
        assert_eq!(wrap_pi(PI), -PI, "upper end excluded");
        assert_eq!(wrap_pi(-PI), -PI);
        assert!(close(wrap_pi(7.0 * TAU + 0.5), 0.5));
        assert!(close(wrap_2pi(-FRAC_PI_2), 3.0 * FRAC_PI_2));
        assert_eq!(wrap_2pi(TAU), 0.0);
        for x in [-1e-20, -1e-17, 1e-20, -PI - 1e-17, PI - 1e-17] {
            let w = wrap_pi(x);
            assert!((-PI..PI).contains(&w), "{x} → {w}");
            let w = wrap_2pi(x);
            assert!((0.0..TAU).contains(&w), "{x} → {w}");
        }
    }

    #[test]
    fn degrees() {
        assert_eq!(wrap_180(190.0), -170.0);
        assert_eq!(wrap_180(-180.0), -180.0);
        assert_eq!(wrap_180(180.0), -180.0);
        assert_eq!(wrap_180(-190.0), 170.0);
        assert_eq!(wrap_180_upper(180.0), 180.0);
        assert_eq!(wrap_180_upper(-180.0), 180.0);
        assert_eq!(wrap_180_upper(-190.0), 170.0);
        assert_eq!(wrap_180_upper(190.0), -170.0);
        assert_eq!(wrap_360(-10.0), 350.0);
        assert_eq!(wrap_360(-1e-20), 0.0);
        assert_eq!(wrap_360(720.0), 0.0);
        for x in [-1e-20, -1e-14, 180.0 - 1e-14, -180.0 - 1e-14, 1e-20] {
            let w = wrap_180(x);
            assert!((-180.0..180.0).contains(&w), "{x} → {w}");
            let w = wrap_180_upper(x);
            assert!(w > -180.0 && w <= 180.0, "{x} → {w}");
            let w = wrap_360(x);
            assert!((0.0..360.0).contains(&w), "{x} → {w}");
        }
    }
}
