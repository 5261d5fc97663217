use nalgebra::Vector3;

use super::*;
use crate::shots::cable::{CableCam, CablePoint, CABLE_MIN_LENGTH_M};

fn point(m: &PointMass, ned: Vector3<f64>, yaw_deg: f32, pitch_deg: f32) -> CablePoint {
    CablePoint {
        position: m.to_geo(ned),
        yaw_deg,
        pitch_deg,
    }
}

/// Distance of `p` from the infinite line through `a` and `b`, and how far along it.
fn line_error(a: &Vector3<f64>, b: &Vector3<f64>, p: &Vector3<f64>) -> (f64, f64) {
    let u = (b - a).normalize();
    let along = (p - a).dot(&u);
    ((p - a - u * along).norm(), along)
}

/// Fly the cable for `secs`: (max cross-track error, max along, min along).
fn fly_cable(
    m: &mut PointMass,
    cable: &mut CableCam,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    cruise: f32,
    secs: f64,
) -> (f64, f64, f64) {
    let (mut cross, mut max_along, mut min_along) = (0.0_f64, f64::NEG_INFINITY, f64::INFINITY);
    for _ in 0..ticks(secs) {
        let g = cable.step(&m.view(), DT, cruise, &LIMITS);
        assert_eq!(g.roi, None);
        m.fly(&g);
        let (c, along) = line_error(a, b, &m.pos);
        cross = cross.max(c);
        max_along = max_along.max(along);
        min_along = min_along.min(along);
    }
    (cross, max_along, min_along)
}

#[test]
fn cable_flies_from_a_to_b_and_back_stopping_at_the_ends() {
    let a = Vector3::new(0.0, 0.0, -10.0);
    let b = Vector3::new(40.0, 30.0, -20.0);
    let len = (b - a).norm();
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(a, dynamics);
        let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, b, 90.0, -30.0));
        assert!((f64::from(cable.length_m()) - len).abs() < 0.01);
        let (cross, max_along, _) = fly_cable(&mut m, &mut cable, &a, &b, 4.0, 30.0);
        assert!(cross < 0.5, "{dynamics:?}: {cross} m off the cable");
        assert!(
            max_along - len < 0.5,
            "{dynamics:?}: overshot b by {}",
            max_along - len
        );
        assert!(
            (m.pos - b).norm() < 0.3,
            "{dynamics:?}: stopped {} from b",
            (m.pos - b).norm()
        );
        assert!(m.vel.norm() < 0.05);
        assert!(cable.parameter() > 0.99);
        // Back with a negative speed.
        let (cross, _, min_along) = fly_cable(&mut m, &mut cable, &a, &b, -4.0, 30.0);
        assert!(cross < 0.5, "{dynamics:?}: {cross}");
        assert!(
            min_along > -0.5,
            "{dynamics:?}: overshot a by {}",
            -min_along
        );
        assert!(
            (m.pos - a).norm() < 0.3,
            "{dynamics:?}: {}",
            (m.pos - a).norm()
        );
        assert!(cable.parameter() < 0.01);
    }
}

#[test]
fn cable_cruises_at_the_speed_asked_within_the_limits() {
    let a = Vector3::new(0.0, 0.0, -10.0);
    let b = Vector3::new(0.0, 100.0, -10.0);
    let mut m = PointMass::new(a, DYNAMICS[1]);
    let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, b, 0.0, 0.0));
    fly_cable(&mut m, &mut cable, &a, &b, 3.0, 8.0);
    assert!((m.vel.y - 3.0).abs() < 0.05, "{}", m.vel.y);
    // Above the speed limit: the limit.
    fly_cable(&mut m, &mut cable, &a, &b, 9.0, 5.0);
    assert!((m.vel.y - 5.0).abs() < 0.05, "{}", m.vel.y);
    // A steep cable climbs no faster than the climb limit.
    let top = Vector3::new(1.0, 0.0, -60.0);
    let mut m = PointMass::new(a, DYNAMICS[1]);
    let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, top, 0.0, 0.0));
    fly_cable(&mut m, &mut cable, &a, &top, 5.0, 10.0);
    assert!((m.vel.z + 2.5).abs() < 0.05, "{}", m.vel.z);
}

#[test]
fn cable_pulls_an_offset_vehicle_onto_the_line() {
    let a = Vector3::new(0.0, 0.0, -10.0);
    let b = Vector3::new(60.0, 0.0, -10.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(10.0, 6.0, -13.0), dynamics);
        let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, b, 0.0, 0.0));
        fly_cable(&mut m, &mut cable, &a, &b, 4.0, 8.0);
        let (cross, ..) = fly_cable(&mut m, &mut cable, &a, &b, 4.0, 20.0);
        assert!(cross < 0.3, "{dynamics:?}: {cross}");
        assert!((m.pos - b).norm() < 0.3);
    }
}

#[test]
fn cable_pause_brakes_and_holds_then_resumes() {
    let a = Vector3::new(0.0, 0.0, -10.0);
    let b = Vector3::new(0.0, 80.0, -10.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(a, dynamics);
        let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, b, 0.0, 0.0));
        fly_cable(&mut m, &mut cable, &a, &b, 5.0, 6.0);
        // Braking from 5 m/s at the planning deceleration: about 8 m.
        let (_, max_along, _) = fly_cable(&mut m, &mut cable, &a, &b, 0.0, 6.0);
        let held = m.pos;
        let (_, max_after, _) = fly_cable(&mut m, &mut cable, &a, &b, 0.0, 20.0);
        assert!(
            (m.pos - held).norm() < 0.1,
            "{dynamics:?}: drifted {}",
            (m.pos - held).norm()
        );
        assert!(max_after <= max_along + 0.5);
        assert!(m.vel.norm() < 0.05);
        fly_cable(&mut m, &mut cable, &a, &b, 5.0, 30.0);
        assert!((m.pos - b).norm() < 0.3);
    }
}

#[test]
fn cable_speed_sign_picks_the_end() {
    let a = Vector3::new(0.0, 0.0, -10.0);
    let b = Vector3::new(30.0, 0.0, -10.0);
    // At a, asked to go further towards a: stays at a.
    let mut m = PointMass::new(a, DYNAMICS[1]);
    let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, b, 0.0, 0.0));
    let (_, max_along, min_along) = fly_cable(&mut m, &mut cable, &a, &b, -4.0, 5.0);
    assert!(
        max_along < 0.01 && min_along > -0.01,
        "{min_along}..{max_along}"
    );
    // Started past b, positive speed comes back to b and stops there.
    let mut m = PointMass::new(Vector3::new(40.0, 0.0, -10.0), DYNAMICS[1]);
    fly_cable(&mut m, &mut cable, &a, &b, 4.0, 15.0);
    assert!((m.pos - b).norm() < 0.3);
}

#[test]
fn interpolated_camera_turns_the_requested_way() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let a = point(&m, Vector3::new(0.0, 0.0, -10.0), 350.0, 0.0);
    let b = point(&m, Vector3::new(50.0, 0.0, -10.0), 10.0, -40.0);
    assert!(CableCam::default_yaw_clockwise(&a, &b));
    assert!(!CableCam::default_yaw_clockwise(&b, &a));
    let mut cable = CableCam::new(a, b);
    assert!(cable.yaw_clockwise());
    let (yaw, pitch) = cable.camera_at(0.5);
    assert!(
        yaw.abs() < 1e-3 || (yaw - 360.0).abs() < 1e-3,
        "clockwise passes 0°: {yaw}"
    );
    assert!((pitch + 20.0).abs() < 1e-4);
    assert!((cable.camera_at(0.25).0 - 355.0).abs() < 1e-3);
    assert!((cable.camera_at(1.0).0 - 10.0).abs() < 1e-3);
    cable.set_camera(true, false);
    let (yaw, _) = cable.camera_at(0.5);
    assert!(
        (yaw - 180.0).abs() < 1e-3,
        "counter-clockwise passes 180°: {yaw}"
    );
    assert!((cable.camera_at(0.25).0 - 265.0).abs() < 1e-3);
    assert!((cable.camera_at(0.0).0 - 350.0).abs() < 1e-3);
    // Exactly opposite: clockwise; the same yaw either way: no turn.
    let c = CablePoint {
        yaw_deg: 170.0,
        ..a
    };
    assert!(CableCam::default_yaw_clockwise(&a, &c));
    let mut same = CableCam::new(
        a,
        CablePoint {
            yaw_deg: 350.0,
            ..b
        },
    );
    same.set_camera(true, false);
    assert!((same.camera_at(0.7).0 - 350.0).abs() < 1e-3);
}

#[test]
fn cable_camera_follows_the_position_or_the_pilot() {
    let a = Vector3::new(0.0, 0.0, -10.0);
    let b = Vector3::new(40.0, 0.0, -10.0);
    let mut m = PointMass::new(Vector3::new(10.0, 0.0, -10.0), DYNAMICS[0]);
    let mut cable = CableCam::new(point(&m, a, 0.0, 0.0), point(&m, b, 80.0, -80.0));
    let g = cable.step(&m.view(), DT, 0.0, &LIMITS);
    assert!((cable.parameter() - 0.25).abs() < 1e-3);
    assert!((g.yaw_deg.unwrap_or(f32::NAN) - 20.0).abs() < 0.01, "{g:?}");
    assert!((g.gimbal_pitch_deg.unwrap_or(f32::NAN) + 20.0).abs() < 0.01);
    m.fly(&g);
    cable.set_camera(false, true);
    let g = cable.step(&m.view(), DT, 0.0, &LIMITS);
    assert_eq!((g.roi, g.yaw_deg, g.gimbal_pitch_deg), (None, None, None));
}

#[test]
fn a_zero_length_cable_is_too_short_and_only_holds() {
    let m0 = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let a = point(&m0, Vector3::new(0.0, 0.0, -10.0), 0.0, 0.0);
    let near = point(&m0, Vector3::new(1.5, 1.5, -10.5), 0.0, 0.0);
    let far = point(&m0, Vector3::new(2.6, 0.0, -10.0), 0.0, 0.0);
    assert!(CableCam::too_short(&a, &a));
    assert!(CableCam::too_short(&a, &near));
    assert!(!CableCam::too_short(&a, &far));
    assert_eq!(CABLE_MIN_LENGTH_M, 2.5);
    let mut m = PointMass::new(Vector3::new(1.0, 0.0, -10.0), DYNAMICS[1]);
    let mut cable = CableCam::new(a, a);
    assert_eq!(cable.length_m(), 0.0);
    for _ in 0..ticks(10.0) {
        let g = cable.step(&m.view(), DT, 4.0, &LIMITS);
        m.fly(&g);
        assert_eq!(cable.parameter(), 0.0);
    }
    assert!(
        (m.pos - Vector3::new(0.0, 0.0, -10.0)).norm() < 0.05,
        "holds at a"
    );
}
