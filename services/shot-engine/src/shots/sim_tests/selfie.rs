use nalgebra::Vector3;

use super::*;
use crate::shots::selfie::{Selfie, SelfiePhase};

/// Fly the selfie for `secs` or until `until` is reached; returns the closest
/// approach to `far` and the fastest horizontal speed.
fn fly_selfie(
    m: &mut PointMass,
    selfie: &mut Selfie,
    roi: &GeoPoint,
    far: &Vector3<f64>,
    cruise: f32,
    secs: f64,
    until: Option<SelfiePhase>,
) -> (f64, f64) {
    let (mut closest, mut fastest) = (f64::INFINITY, 0.0_f64);
    for _ in 0..ticks(secs) {
        let g = selfie.step(&m.view(), DT, cruise, &LIMITS);
        assert_eq!(g.roi, Some(*roi), "camera on the ROI");
        m.fly(&g);
        closest = closest.min((m.pos - far).norm());
        fastest = fastest.max(m.vel.xy().norm());
        if until == Some(selfie.phase()) {
            break;
        }
    }
    (closest, fastest)
}

#[test]
fn selfie_flies_near_far_near_at_the_cruise_speed() {
    let near = Vector3::new(5.0, 5.0, -5.0);
    let far = Vector3::new(45.0, 35.0, -25.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -3.0), dynamics);
        let roi = m.to_geo(Vector3::zeros());
        let mut selfie = Selfie::new(m.to_geo(near), m.to_geo(far), roi);
        assert_eq!(selfie.phase(), SelfiePhase::ToNear);
        fly_selfie(
            &mut m,
            &mut selfie,
            &roi,
            &far,
            3.0,
            30.0,
            Some(SelfiePhase::Out),
        );
        assert_eq!(selfie.phase(), SelfiePhase::Out, "{dynamics:?}");
        assert!((m.pos - near).norm() < 1.5);
        let (closest, fastest) = fly_selfie(
            &mut m,
            &mut selfie,
            &roi,
            &far,
            3.0,
            60.0,
            Some(SelfiePhase::Back),
        );
        assert_eq!(selfie.phase(), SelfiePhase::Back);
        // 3 m/s along a track that climbs 20 m in 54: horizontal 2.8 m/s.
        assert!((2.6..=3.0).contains(&fastest), "{dynamics:?}: {fastest}");
        let (closest_back, _) = fly_selfie(
            &mut m,
            &mut selfie,
            &roi,
            &far,
            3.0,
            60.0,
            Some(SelfiePhase::Done),
        );
        assert!(
            closest.min(closest_back) < 1.5,
            "{dynamics:?}: far missed by {closest}"
        );
        assert_eq!(selfie.phase(), SelfiePhase::Done);
        // Done: settle at near and stay.
        fly_selfie(&mut m, &mut selfie, &roi, &far, 3.0, 10.0, None);
        assert!(
            (m.pos - near).norm() < 0.3,
            "{dynamics:?}: {}",
            (m.pos - near).norm()
        );
        assert!(m.vel.norm() < 0.05);
        assert!(selfie.parameter() < 0.01);
    }
}

#[test]
fn selfie_pauses_and_resumes_and_ignores_the_speed_sign() {
    let near = Vector3::new(0.0, 0.0, -5.0);
    let far = Vector3::new(0.0, 60.0, -5.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(near, dynamics);
        let roi = m.to_geo(Vector3::new(-10.0, 0.0, 0.0));
        let mut selfie = Selfie::new(m.to_geo(near), m.to_geo(far), roi);
        fly_selfie(&mut m, &mut selfie, &roi, &far, -4.0, 8.0, None);
        assert_eq!(selfie.phase(), SelfiePhase::Out);
        assert!(m.vel.y > 3.9, "{dynamics:?}: {}", m.vel.y);
        let p = selfie.parameter();
        assert!(p > 0.3 && p < 0.7, "{p}");
        fly_selfie(&mut m, &mut selfie, &roi, &far, 0.0, 5.0, None);
        let held = m.pos;
        fly_selfie(&mut m, &mut selfie, &roi, &far, 0.0, 10.0, None);
        assert!((m.pos - held).norm() < 0.1, "{dynamics:?}");
        assert_eq!(selfie.phase(), SelfiePhase::Out);
        fly_selfie(
            &mut m,
            &mut selfie,
            &roi,
            &far,
            4.0,
            60.0,
            Some(SelfiePhase::Done),
        );
        assert_eq!(selfie.phase(), SelfiePhase::Done);
    }
}

#[test]
fn selfie_pause_before_reaching_near_holds_too() {
    let near = Vector3::new(30.0, 0.0, -5.0);
    let far = Vector3::new(60.0, 0.0, -15.0);
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -5.0), DYNAMICS[3]);
    let roi = m.to_geo(Vector3::zeros());
    let mut selfie = Selfie::new(m.to_geo(near), m.to_geo(far), roi);
    fly_selfie(&mut m, &mut selfie, &roi, &far, 3.0, 3.0, None);
    fly_selfie(&mut m, &mut selfie, &roi, &far, 0.0, 5.0, None);
    let held = m.pos;
    fly_selfie(&mut m, &mut selfie, &roi, &far, 0.0, 10.0, None);
    assert!((m.pos - held).norm() < 0.1);
    assert_eq!(selfie.phase(), SelfiePhase::ToNear);
}

#[test]
fn a_zero_length_selfie_ends_at_near() {
    let near = Vector3::new(10.0, 0.0, -5.0);
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -5.0), DYNAMICS[1]);
    let roi = m.to_geo(Vector3::zeros());
    let mut selfie = Selfie::new(m.to_geo(near), m.to_geo(near), roi);
    fly_selfie(&mut m, &mut selfie, &roi, &near, 3.0, 30.0, None);
    assert_eq!(selfie.phase(), SelfiePhase::Done);
    assert!((m.pos - near).norm() < 0.1);
}
