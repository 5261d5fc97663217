//! Unit and property tests of the spline, its arc-length table, speed profile and
//! camera interpolation.

use nalgebra::Vector3;
use proptest::prelude::*;

use super::*;
use crate::shots::geo::{GeoPoint, LocalFrame};

const HOME: GeoPoint = GeoPoint {
    lat_deg: -35.363_261,
    lon_deg: 149.165_230,
    alt_rel_m: 0.0,
};

const LIMITS: Limits = Limits {
    max_speed_mps: 5.0,
    max_accel_mps2: 2.5,
    max_climb_mps: 2.5,
    position_gain: 1.0,
};

fn keypoints(ned: &[Vector3<f64>], cam: &[(f32, f32)]) -> Vec<Keypoint> {
    let frame = LocalFrame::new(HOME);
    ned.iter()
        .enumerate()
        .map(|(i, p)| {
            let (pitch_deg, yaw_deg) = cam.get(i).copied().unwrap_or((0.0, 0.0));
            Keypoint {
                position: frame.to_geo(p),
                pitch_deg,
                yaw_deg,
            }
        })
        .collect()
}

fn path(ned: &[Vector3<f64>]) -> SplinePath {
    SplinePath::new(&keypoints(ned, &[]), &LIMITS).expect("valid path")
}

fn l_shape() -> Vec<Vector3<f64>> {
    vec![
        Vector3::new(0.0, 0.0, -10.0),
        Vector3::new(30.0, 0.0, -10.0),
        Vector3::new(30.0, 30.0, -10.0),
    ]
}

#[test]
fn two_keypoints_make_a_straight_line() {
    let a = Vector3::new(3.0, -4.0, -10.0);
    let b = Vector3::new(43.0, 26.0, -20.0);
    let sp = Spline::new(&[a, b]).expect("spline");
    let len = (b - a).norm();
    assert!((sp.length_m() - len).abs() < 1e-9, "{}", sp.length_m());
    let dir = (b - a) / len;
    for i in 0..=20 {
        let s = len * f64::from(i) / 20.0;
        assert!((sp.position(s) - (a + dir * s)).norm() < 1e-9);
        assert!((sp.tangent(s) - dir).norm() < 1e-9);
        assert!(sp.curvature(s) < 1e-9);
    }
    assert_eq!(sp.keypoint_count(), 2);
    assert_eq!(sp.keypoint_s(1), sp.length_m());
    // Clamped outside, NaN at the start.
    assert!((sp.position(-5.0) - a).norm() < 1e-9);
    assert!((sp.position(len + 5.0) - b).norm() < 1e-9);
    assert!((sp.position(f64::NAN) - a).norm() < 1e-9);
}

#[test]
fn bad_keypoints_are_refused_with_the_reason() {
    let p = Vector3::new(0.0, 0.0, -10.0);
    assert_eq!(
        Spline::new(&[p]).err(),
        Some(SplineError::TooFewKeypoints { count: 1 })
    );
    assert_eq!(
        SplinePath::new(&[], &LIMITS).err(),
        Some(SplineError::TooFewKeypoints { count: 0 })
    );
    let q = Vector3::new(0.001, 0.0, -10.0);
    assert!(matches!(
        Spline::new(&[p, q]),
        Err(SplineError::Coincident { index: 0, .. })
    ));
    assert_eq!(
        Spline::new(&[p, Vector3::new(f64::NAN, 0.0, 0.0)]).err(),
        Some(SplineError::NonFinite { index: 1 })
    );
    let many: Vec<_> = (0..=MAX_KEYPOINTS)
        .map(|i| Vector3::new(i as f64 * 5.0, 0.0, -10.0))
        .collect();
    assert_eq!(
        Spline::new(&many).err(),
        Some(SplineError::TooManyKeypoints {
            count: MAX_KEYPOINTS + 1,
            max: MAX_KEYPOINTS
        })
    );
    let mut kps = keypoints(&l_shape(), &[]);
    kps[2].yaw_deg = f32::INFINITY;
    assert_eq!(
        SplinePath::new(&kps, &LIMITS).err(),
        Some(SplineError::NonFinite { index: 2 })
    );
    let msg = SplineError::Coincident {
        index: 3,
        distance_m: 0.001,
    }
    .to_string();
    assert!(msg.contains("3 and 4"), "{msg}");
}

#[test]
fn l_shape_rounds_its_corner_and_keypoints_have_their_u() {
    let pts = l_shape();
    let p = path(&pts);
    let sp = p.spline();
    // Longer than the two legs' chords… but not by much: the corner is rounded.
    assert!(
        p.length_m() > 60.0 && p.length_m() < 66.0,
        "{}",
        p.length_m()
    );
    // NED from keypoint 0.
    for (i, k) in pts.iter().enumerate() {
        assert!((sp.position(sp.keypoint_s(i)) - (k - pts[0])).norm() < 1e-6);
    }
    // Symmetric L: the corner keypoint is half way.
    assert_eq!(p.keypoint_u(0), Some(0.0));
    assert!((p.keypoint_u(1).unwrap_or(f64::NAN) - 0.5).abs() < 1e-6);
    assert_eq!(p.keypoint_u(2), Some(1.0));
    assert_eq!(p.keypoint_u(3), None);
    // The turn is tightest at the corner; the profile slows for it.
    let corner = sp.keypoint_s(1);
    assert!(sp.curvature(corner) > sp.curvature(5.0));
    let v_corner = p.speed_limit(corner);
    assert!(v_corner < 4.0, "{v_corner}");
    assert!(v_corner <= p.curvature_limit(corner) + 1e-9);
    assert!((p.speed_limit(0.0) - 5.0).abs() < 1e-6, "straight start");
    // The geodetic point at u = 0.5 is the corner.
    let frame = LocalFrame::new(p.keypoints()[0].position);
    assert!(
        (frame.to_ned(&p.position_at_u(0.5)) - frame.to_ned(&p.keypoints()[1].position)).norm()
            < 0.01
    );
}

#[test]
fn closest_s_finds_the_foot_point() {
    let p = path(&l_shape());
    let sp = p.spline();
    for s in [0.0, 7.5, 20.0, 31.7, 45.0, sp.length_m()] {
        let on = sp.position(s);
        let t = sp.tangent(s);
        // Sideways (perpendicular, horizontal) by 1.5 m.
        let side = Vector3::new(-t.y, t.x, 0.0).normalize() * 1.5;
        let got = sp.closest_s(&(on + side), None);
        assert!((got - s).abs() < 0.05, "{s} → {got}");
        let windowed = sp.closest_s(&(on + side), Some((s - 2.0, s + 2.0)));
        assert!((windowed - s).abs() < 0.05, "{s} → {windowed}");
    }
    // A window away from the point: its nearest end.
    let got = sp.closest_s(&sp.position(50.0), Some((0.0, 10.0)));
    assert!((got - 10.0).abs() < 1e-6, "{got}");
}

#[test]
fn camera_turns_the_shorter_way_between_keypoints() {
    let kps = keypoints(&l_shape(), &[(0.0, 350.0), (-40.0, 10.0), (-20.0, 200.0)]);
    let p = SplinePath::new(&kps, &LIMITS).expect("path");
    let (pitch, yaw) = p.camera_at(0.25);
    assert!((pitch + 20.0).abs() < 1e-3, "{pitch}");
    assert!(
        yaw.abs() < 1e-3 || (yaw - 360.0).abs() < 1e-3,
        "through north: {yaw}"
    );
    assert!((p.camera_at(0.0).1 - 350.0).abs() < 1e-3);
    assert!((p.camera_at(0.5).1 - 10.0).abs() < 1e-3);
    assert!((p.camera_at(0.5).0 + 40.0).abs() < 1e-3);
    // 10° → 200°: 190° clockwise is longer; counter-clockwise through 285°.
    let (pitch, yaw) = p.camera_at(0.75);
    assert!((pitch + 30.0).abs() < 1e-3);
    assert!((yaw - 285.0).abs() < 1e-3, "{yaw}");
    assert!((p.camera_at(1.0).1 - 200.0).abs() < 1e-3);
    // Exactly opposite: clockwise.
    let kps = keypoints(&l_shape()[..2], &[(0.0, 10.0), (0.0, 190.0)]);
    let p2 = SplinePath::new(&kps, &LIMITS).expect("path");
    assert!(
        (p2.camera_at(0.5).1 - 100.0).abs() < 1e-3,
        "{:?}",
        p2.camera_at(0.5)
    );
    // Outside and NaN: clamped.
    assert_eq!(p.camera_at(7.0), p.camera_at(1.0));
    assert_eq!(p.camera_at(f64::NAN), p.camera_at(0.0));
}

#[test]
fn durations_are_trapezoids_on_a_straight_path() {
    let p = path(&[
        Vector3::new(0.0, 0.0, -10.0),
        Vector3::new(50.0, 0.0, -10.0),
    ]);
    // Planning acceleration 0.6 × 2.5 = 1.5 m/s²: 5 m/s after 3.33 s and 8.33 m.
    let ramp_t = 5.0 / 1.5;
    let ramp_d = 0.5 * 1.5 * ramp_t * ramp_t;
    let fastest = 2.0 * ramp_t + (50.0 - 2.0 * ramp_d) / 5.0;
    let d = p.durations(0.5);
    assert!(
        (f64::from(d.min_time_s) - fastest).abs() < 0.01 * fastest,
        "{d:?} vs {fastest}"
    );
    let slow = 2.0 * (0.5 / 1.5) + (50.0 - 0.5 * 0.5 / 1.5) / 0.5;
    assert!(
        (f64::from(d.max_time_s) - slow).abs() < 0.01 * slow,
        "{d:?} vs {slow}"
    );
    // The cruise speed for a time inverts the trip time.
    for t in [20.0, 35.0, 60.0] {
        let v = p.cruise_for_time(t, 0.5);
        assert!((p.trip_time_s(v) - t).abs() < 0.01, "{t} s → {v} m/s");
    }
    assert_eq!(p.cruise_for_time(1.0, 0.5), p.max_speed_mps());
    assert_eq!(p.cruise_for_time(1e6, 0.5), 0.5);
    assert_eq!(p.cruise_for_time(f64::NAN, 0.5), p.max_speed_mps());
    // A steep path is flown at the climb limit.
    let up = path(&[Vector3::new(0.0, 0.0, 0.0), Vector3::new(0.0, 0.0, -40.0)]);
    assert!((up.max_speed_mps() - 2.5).abs() < 1e-9);
}

#[test]
fn a_turning_path_takes_longer_than_its_length_at_full_speed() {
    let p = path(&l_shape());
    let d = p.durations(0.5);
    let straight = path(&[
        Vector3::new(0.0, 0.0, -10.0),
        Vector3::new(p.length_m(), 0.0, -10.0),
    ]);
    assert!(d.min_time_s > straight.durations(0.5).min_time_s);
    assert!(d.max_time_s > d.min_time_s);
    assert!(f64::from(d.max_time_s) > p.length_m() / 0.5);
}

/// Keypoints: 2..=6 points in a 300 m box, neighbours at least the recording minimum
/// apart.
fn arb_points() -> impl Strategy<Value = Vec<Vector3<f64>>> {
    prop::collection::vec((-150.0..150.0f64, -150.0..150.0f64, -60.0..0.0f64), 2..=6)
        .prop_map(|v| {
            v.into_iter()
                .map(|(x, y, z)| Vector3::new(x, y, z))
                .collect::<Vec<_>>()
        })
        .prop_filter("neighbours apart", |p: &Vec<Vector3<f64>>| {
            p.windows(2)
                .all(|w| (w[1] - w[0]).norm() >= KEYPOINT_MIN_SPACING_M)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn passes_through_every_keypoint(pts in arb_points()) {
        let sp = Spline::new(&pts).expect("spline");
        for (i, p) in pts.iter().enumerate() {
            let at = sp.position(sp.keypoint_s(i));
            prop_assert!((at - p).norm() < 1e-6, "keypoint {i}: {at:?} vs {p:?}");
        }
        prop_assert!(sp.keypoint_s(0) == 0.0);
        prop_assert!((sp.keypoint_s(pts.len() - 1) - sp.length_m()).abs() < 1e-9);
    }

    #[test]
    fn position_and_velocity_are_continuous_at_keypoints(pts in arb_points()) {
        let sp = Spline::new(&pts).expect("spline");
        for i in 1..pts.len() - 1 {
            // The segments meet with one position and one direction.
            let end = sp.param_position(i - 1, 1.0);
            let start = sp.param_position(i, 0.0);
            prop_assert!((end - start).norm() < 1e-9);
            let d_end = sp.param_derivative(i - 1, 1.0).normalize();
            let d_start = sp.param_derivative(i, 0.0).normalize();
            prop_assert!((d_end - d_start).norm() < 1e-9, "{d_end:?} vs {d_start:?}");
            // And by arc length: just before and just after the keypoint agree.
            // The tangent turns no more than the curvature there allows (a jump would
            // not shrink with h).
            let k = sp.keypoint_s(i);
            let h = 1e-6;
            prop_assert!((sp.position(k + h) - sp.position(k - h)).norm() <= 2.0 * h + 1e-9);
            let (t0, t1) = (sp.tangent(k - h), sp.tangent(k + h));
            let kappa = sp.curvature(k - h).max(sp.curvature(k + h));
            prop_assert!(
                (t0 - t1).norm() <= 3.0 * h * kappa + 1e-6,
                "tangent jumps at {i}: {t0:?} → {t1:?} (κ {kappa})"
            );
        }
    }

    #[test]
    fn arc_length_agrees_with_dense_sampling(pts in arb_points()) {
        let sp = Spline::new(&pts).expect("spline");
        let n = 2000;
        let mut chords = 0.0;
        for seg in 0..pts.len() - 1 {
            for k in 0..n {
                let a = sp.param_position(seg, k as f64 / n as f64);
                let b = sp.param_position(seg, (k + 1) as f64 / n as f64);
                chords += (b - a).norm();
            }
        }
        let len = sp.length_m();
        prop_assert!((len - chords).abs() <= 0.005 * len, "{len} vs sampled {chords}");
        // Chords never exceed the arc.
        prop_assert!(chords <= len * (1.0 + 1e-9));
    }

    #[test]
    fn parametrisation_is_by_arc_length_and_moves_forward(
        pts in arb_points(),
        fracs in prop::collection::vec(0.0..1.0f64, 20),
    ) {
        let p = SplinePath::new(&keypoints(&pts, &[]), &LIMITS).expect("path");
        let sp = p.spline();
        let len = sp.length_m();
        let h = 0.01;
        for f in fracs {
            let s = f * (len - h);
            let step = sp.position(s + h) - sp.position(s);
            // Moves about ds per ds (never more), and forward along the tangent.
            prop_assert!(step.norm() <= h * (1.0 + 1e-6), "{} per {h}", step.norm());
            prop_assert!(step.norm() >= h * 0.995, "{} per {h} at {s}", step.norm());
            prop_assert!(step.dot(&sp.tangent(s)) > 0.0);
            prop_assert!(p.u_of_s(s + h) > p.u_of_s(s));
        }
        // Keypoint uPositions strictly increase from 0 to 1.
        let us: Vec<f64> = (0..pts.len()).filter_map(|i| p.keypoint_u(i)).collect();
        prop_assert_eq!(us.len(), pts.len());
        prop_assert!(us[0] == 0.0 && us[us.len() - 1] == 1.0);
        prop_assert!(us.windows(2).all(|w| w[1] > w[0]), "{us:?}");
    }

    #[test]
    fn speed_profile_never_exceeds_the_curvature_limit(
        pts in arb_points(),
        fracs in prop::collection::vec(0.0..=1.0f64, 50),
    ) {
        let p = SplinePath::new(&keypoints(&pts, &[]), &LIMITS).expect("path");
        let sp = p.spline();
        let lim = *p.profile_limits();
        for f in fracs {
            let s = f * sp.length_m();
            let v = p.speed_limit(s);
            prop_assert!(v >= 0.0 && v.is_finite());
            prop_assert!(v <= p.curvature_limit(s) + 1e-9, "{v} above {} at {s}", p.curvature_limit(s));
            // Lateral acceleration within its limit.
            prop_assert!(v * v * sp.curvature(s) <= lim.lateral_accel_mps2 * (1.0 + 1e-9) + 1e-12);
            // Within the speed and climb limits along the tangent.
            let t = sp.tangent(s);
            prop_assert!(v * t.x.hypot(t.y) <= lim.speed_mps + 1e-9);
            prop_assert!(v * t.z.abs() <= lim.climb_mps + 1e-9);
        }
        // The table is acceleration-limited: v² changes by at most 2·a·Δs.
        let nodes = p.envelope_nodes();
        for w in nodes.windows(2) {
            let (ds, dv2) = (w[1].0 - w[0].0, (w[1].1 * w[1].1 - w[0].1 * w[0].1).abs());
            prop_assert!(dv2 <= 2.0 * lim.accel_mps2 * ds * (1.0 + 1e-9) + 1e-12);
        }
        // Durations bracket the path: no faster than the fastest speed allows.
        let d = p.durations(0.5);
        prop_assert!(f64::from(d.min_time_s) >= sp.length_m() / p.max_speed_mps() * (1.0 - 1e-6));
        prop_assert!(d.max_time_s >= d.min_time_s);
    }
}
