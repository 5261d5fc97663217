use nalgebra::Vector3;

use super::*;
use crate::shots::rewind::{Breadcrumbs, Rewind, ARRIVED_M};

/// A setpoint `toward` the wish, within the acceleration limit (what a pilot's
/// sticks through ArduCopter's shaping look like).
fn ramp(cmd: &mut Vector3<f64>, wish: Vector3<f64>) {
    let max = f64::from(LIMITS.max_accel_mps2 * DT) * 0.99;
    let d = wish - *cmd;
    *cmd += if d.norm() > max {
        d * (max / d.norm())
    } else {
        d
    };
}

fn guidance(v: &Vector3<f64>) -> Guidance {
    Guidance {
        velocity_ned_mps: [v.x as f32, v.y as f32, v.z as f32],
        ..Guidance::HOVER
    }
}

/// Distance from `p` to the polyline.
fn to_polyline(path: &[Vector3<f64>], p: &Vector3<f64>) -> f64 {
    path.windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let d = b - a;
            let t = if d.norm_squared() > 0.0 {
                ((p - a).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (a + d * t - p).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Fly the rewind until done (or `secs`): the largest distance from `path`.
fn rewind(m: &mut PointMass, r: &mut Rewind, path: &[Vector3<f64>], speed: f32, secs: f64) -> f64 {
    let mut worst = 0.0_f64;
    let mut progress = 0.0;
    for _ in 0..ticks(secs) {
        let g = r.step(&m.view(), DT, speed, &LIMITS);
        assert_eq!((g.roi, g.yaw_deg, g.gimbal_pitch_deg), (None, None, None));
        m.fly(&g);
        worst = worst.max(to_polyline(path, &m.pos));
        assert!(r.progress() >= progress, "progress went back");
        progress = r.progress();
        if r.done() {
            break;
        }
    }
    worst
}

#[test]
fn rewind_retraces_a_flown_path_within_a_metre_and_a_half() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
        let mut crumbs = Breadcrumbs::default();
        let mut cmd = Vector3::zeros();
        // East, a climbing turn north, a swerve west: what a pilot might fly.
        let legs = [
            (Vector3::new(0.0, 5.0, 0.0), 6.0),
            (Vector3::new(4.0, 2.0, -1.5), 5.0),
            (Vector3::new(3.0, -4.0, 0.0), 6.0),
            (Vector3::new(0.0, 0.0, 0.0), 3.0),
        ];
        let mut flown = vec![m.pos];
        for (wish, secs) in legs {
            for _ in 0..ticks(secs) {
                ramp(&mut cmd, wish);
                m.fly(&guidance(&cmd));
                crumbs.record(&m.view().position);
                flown.push(m.pos);
            }
        }
        let here = m.pos;
        let mut r = Rewind::new(&crumbs, 60.0, &m.view());
        assert!((r.length_m() - 60.0).abs() < 1e-3);
        let worst = rewind(&mut m, &mut r, &flown, 5.0, 120.0);
        assert!(r.done(), "{dynamics:?}: not done, {}", r.progress());
        assert!(worst < 1.5, "{dynamics:?}: {worst} m off the path");
        let end = m.ned(&r.end());
        assert!((m.pos - end).norm() < ARRIVED_M, "{dynamics:?}");
        // 60 m of path back from where it began.
        assert!((here - end).norm() > 20.0);
        // Done: it holds the end.
        for _ in 0..ticks(5.0) {
            let g = r.step(&m.view(), DT, 5.0, &LIMITS);
            m.fly(&g);
        }
        assert!((m.pos - end).norm() < 0.1, "{dynamics:?}");
    }
}

#[test]
fn rewind_takes_square_corners_of_sparse_crumbs_without_cutting_them() {
    // A square of crumbs 2 m apart with right-angle corners: harsher than anything
    // flown.
    let mut crumbs = Breadcrumbs::new(1.0, 2000);
    let mut path = Vec::new();
    let corners = [
        Vector3::new(0.0, 0.0, -10.0),
        Vector3::new(0.0, 30.0, -10.0),
        Vector3::new(30.0, 30.0, -10.0),
        Vector3::new(30.0, 0.0, -15.0),
    ];
    for w in corners.windows(2) {
        for i in 0..15 {
            path.push(w[0] + (w[1] - w[0]) * (f64::from(i) / 15.0));
        }
    }
    path.push(corners[3]);
    for dynamics in DYNAMICS {
        let m0 = PointMass::new(Vector3::zeros(), dynamics);
        crumbs.clear();
        for p in &path {
            crumbs.record(&m0.to_geo(*p));
        }
        let mut m = PointMass::new(corners[3], dynamics);
        let mut r = Rewind::new(&crumbs, 1000.0, &m.view());
        let back: Vec<Vector3<f64>> = path.iter().rev().copied().collect();
        let worst = rewind(&mut m, &mut r, &back, 5.0, 120.0);
        assert!(r.done(), "{dynamics:?}");
        assert!(worst < 1.5, "{dynamics:?}: {worst}");
        assert!((m.pos - corners[0]).norm() < ARRIVED_M);
    }
}

#[test]
fn rewind_pauses_on_the_path_and_resumes() {
    let mut crumbs = Breadcrumbs::default();
    let m0 = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    for i in 0..=80 {
        crumbs.record(&m0.to_geo(Vector3::new(f64::from(i), 0.0, -10.0)));
    }
    let mut m = PointMass::new(Vector3::new(80.0, 0.0, -10.0), DYNAMICS[3]);
    let mut r = Rewind::new(&crumbs, 50.0, &m.view());
    let line = [
        Vector3::new(80.0, 0.0, -10.0),
        Vector3::new(30.0, 0.0, -10.0),
    ];
    rewind(&mut m, &mut r, &line, 5.0, 5.0);
    let moving = m.pos;
    rewind(&mut m, &mut r, &line, 0.0, 6.0);
    let held = m.pos;
    assert!((held - moving).norm() < 10.0);
    rewind(&mut m, &mut r, &line, 0.0, 10.0);
    assert!((m.pos - held).norm() < 0.1, "paused: stays");
    assert!(!r.done());
    let worst = rewind(&mut m, &mut r, &line, 3.0, 60.0);
    assert!(r.done());
    assert!(worst < 0.2, "{worst}");
    assert!((m.pos - line[1]).norm() < ARRIVED_M);
}
