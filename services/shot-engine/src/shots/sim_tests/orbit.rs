use nalgebra::Vector3;
use skymesh_runtime::angle::wrap_pi;

use super::*;
use crate::shots::orbit::{Orbit, MIN_ORBIT_RADIUS_M};

/// Bearing of `p` seen from `c`, radians clockwise from north.
fn angle(c: &Vector3<f64>, p: &Vector3<f64>) -> f64 {
    (p.y - c.y).atan2(p.x - c.x)
}

/// Orbit for `secs`, returning (max radial error, max altitude error, turned
/// radians clockwise, last speed).
fn orbit_for(
    m: &mut PointMass,
    orbit: &mut Orbit,
    roi: &Vector3<f64>,
    radius: f64,
    alt: f64,
    cruise: f32,
    secs: f64,
) -> (f64, f64, f64) {
    let (mut max_r, mut max_alt, mut turned) = (0.0_f64, 0.0_f64, 0.0);
    let mut last = angle(roi, &m.pos);
    for _ in 0..ticks(secs) {
        let g = orbit.step(&m.view(), DT, cruise, &LIMITS);
        assert_eq!(g.roi, Some(orbit.roi()), "camera on the ROI");
        m.fly(&g);
        max_r = max_r.max((ground(&m.pos, roi) - radius).abs());
        max_alt = max_alt.max((-m.pos.z - alt).abs());
        let a = angle(roi, &m.pos);
        turned += wrap_pi(a - last);
        last = a;
    }
    (max_r, max_alt, turned)
}

#[test]
fn orbit_stays_on_the_circle_for_several_revolutions() {
    for dynamics in DYNAMICS {
        for cruise in [4.0_f32, -4.0] {
            let mut m = PointMass::new(Vector3::new(30.0, 0.0, -20.0), dynamics);
            let roi = Vector3::zeros();
            let mut orbit = Orbit::new(m.to_geo(roi), &m.view());
            assert!((orbit.radius_m() - 30.0).abs() < 0.01);
            // Three revolutions at 4 m/s on a 30 m circle take 141 s.
            let (r_err, alt_err, turned) =
                orbit_for(&mut m, &mut orbit, &roi, 30.0, 20.0, cruise, 150.0);
            assert!(r_err < 1.0, "{dynamics:?} {cruise}: radius off by {r_err}");
            assert!(
                alt_err < 0.3,
                "{dynamics:?} {cruise}: altitude off by {alt_err}"
            );
            let revolutions = turned / std::f64::consts::TAU;
            // Positive cruise is counter-clockwise: the clockwise angle shrinks.
            assert!(
                revolutions * f64::from(cruise.signum()) < -3.0,
                "{dynamics:?} {cruise}: {revolutions} revolutions"
            );
            assert!(
                (m.vel.xy().norm() - 4.0).abs() < 0.2,
                "speed {}",
                m.vel.xy().norm()
            );
        }
    }
}

#[test]
fn orbit_radius_error_stays_small_even_at_full_speed_on_a_small_circle() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(10.0, 0.0, -10.0), dynamics);
        let roi = Vector3::zeros();
        let mut orbit = Orbit::new(m.to_geo(roi), &m.view());
        // 8 m/s is beyond both the speed limit and what a 10 m circle turns at 2.5 m/s².
        let (r_err, alt_err, _) = orbit_for(&mut m, &mut orbit, &roi, 10.0, 10.0, 8.0, 60.0);
        assert!(r_err < 1.0, "{dynamics:?}: radius off by {r_err}");
        assert!(alt_err < 0.3);
    }
}

#[test]
fn orbit_speed_zero_brakes_and_holds_position() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 30.0, -15.0), dynamics);
        let roi = Vector3::zeros();
        let mut orbit = Orbit::new(m.to_geo(roi), &m.view());
        orbit_for(&mut m, &mut orbit, &roi, 30.0, 15.0, 4.0, 15.0);
        // Pause: brake within a few seconds, then stay.
        let (r_err, _, _) = orbit_for(&mut m, &mut orbit, &roi, 30.0, 15.0, 0.0, 5.0);
        assert!(r_err < 1.0);
        let held = m.pos;
        orbit_for(&mut m, &mut orbit, &roi, 30.0, 15.0, 0.0, 20.0);
        assert!(
            (m.pos - held).norm() < 0.3,
            "{dynamics:?}: drifted {}",
            (m.pos - held).norm()
        );
        assert!(m.vel.norm() < 0.05);
        // Resume.
        let (r_err, _, turned) = orbit_for(&mut m, &mut orbit, &roi, 30.0, 15.0, 4.0, 20.0);
        assert!(r_err < 1.0 && turned < -1.5, "{r_err} {turned}");
    }
}

#[test]
fn a_new_roi_restarts_the_orbit_at_the_new_distance() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(30.0, 0.0, -20.0), dynamics);
        let roi = Vector3::zeros();
        let mut orbit = Orbit::new(m.to_geo(roi), &m.view());
        orbit_for(&mut m, &mut orbit, &roi, 30.0, 20.0, 4.0, 20.0);
        // The new ROI 15 m from where the vehicle is now, to its east.
        let new_roi = m.pos + Vector3::new(0.0, 15.0, 20.0);
        orbit.set_roi(m.to_geo(new_roi), &m.view());
        let seen = ground(&m.ned(&m.view().position), &new_roi);
        assert!(
            (f64::from(orbit.radius_m()) - seen).abs() < 0.01,
            "{} vs {seen}",
            orbit.radius_m()
        );
        assert!((seen - 15.0).abs() < 0.5, "{dynamics:?}: {seen}");
        // The vehicle arrives with up to 4 m/s towards or away from the new ROI: that
        // takes a couple of metres to turn into the new circle.
        let (r_err, _, _) = orbit_for(&mut m, &mut orbit, &new_roi, 15.0, 20.0, 4.0, 5.0);
        assert!(r_err < 3.5, "{dynamics:?}: {r_err}");
        let (r_err, alt_err, turned) =
            orbit_for(&mut m, &mut orbit, &new_roi, 15.0, 20.0, 4.0, 60.0);
        assert!(r_err < 1.0, "{dynamics:?}: {r_err}");
        assert!(alt_err < 0.3);
        assert!(turned < -std::f64::consts::TAU, "{turned}");
    }
}

#[test]
fn orbit_right_above_the_roi_moves_out_to_the_minimum_radius() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[1]);
    let roi = Vector3::zeros();
    let facing_east = VehicleView {
        heading_deg: 90.0,
        ..m.view()
    };
    let mut orbit = Orbit::new(m.to_geo(roi), &facing_east);
    assert_eq!(orbit.radius_m(), MIN_ORBIT_RADIUS_M);
    let g = orbit.step(&facing_east, DT, 0.0, &LIMITS);
    // Facing east, "behind" is west.
    assert!(g.velocity_ned_mps[1] < 0.0, "{g:?}");
    m.fly(&g);
    orbit_for(&mut m, &mut orbit, &roi, 2.0, 10.0, 3.0, 10.0);
    let (r_err, _, turned) = orbit_for(&mut m, &mut orbit, &roi, 2.0, 10.0, 3.0, 30.0);
    assert!(r_err < 0.5, "{r_err}");
    assert!(turned < -std::f64::consts::TAU);
}

#[test]
fn orbit_ignores_nonsense_inputs() {
    let m = PointMass::new(Vector3::new(30.0, 0.0, -20.0), DYNAMICS[0]);
    let mut orbit = Orbit::new(m.to_geo(Vector3::zeros()), &m.view());
    for (dt, cruise) in [
        (f32::NAN, 4.0),
        (DT, f32::NAN),
        (-1.0, 4.0),
        (DT, f32::INFINITY),
    ] {
        let g = orbit.step(&m.view(), dt, cruise, &LIMITS);
        assert!(g.velocity_ned_mps.iter().all(|x| x.is_finite()), "{g:?}");
    }
}
