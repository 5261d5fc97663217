use nalgebra::{Vector2, Vector3};
use skymesh_ipc_types::FenceKind;

use super::*;
use crate::shots::fence::{
    contains, stopping_distance, validate_zone, Fence, FenceError, FenceVerdict, FenceZone,
    FenceZoneError, HOLD_MARGIN_M,
};
use crate::shots::motion::{toward, Lim};
use crate::shots::zipline::Zipline;

/// A ring of `[lat, lon]` from NE metres around home.
fn ring(m: &PointMass, ne: &[(f64, f64)]) -> Vec<[f64; 2]> {
    ne.iter()
        .map(|&(n, e)| {
            let g = m.to_geo(Vector3::new(n, e, 0.0));
            [g.lat_deg, g.lon_deg]
        })
        .collect()
}

fn square(c: (f64, f64), half: f64) -> Vec<(f64, f64)> {
    vec![
        (c.0 - half, c.1 - half),
        (c.0 - half, c.1 + half),
        (c.0 + half, c.1 + half),
        (c.0 + half, c.1 - half),
    ]
}

fn zone(m: &PointMass, kind: FenceKind, poly: &[(f64, f64)], sub: &[(f64, f64)]) -> FenceZone {
    FenceZone {
        kind,
        polygon: ring(m, poly),
        sub_polygon: ring(m, sub),
    }
}

fn at(m: &PointMass, n: f64, e: f64, vel: [f32; 3]) -> VehicleView {
    VehicleView {
        position: m.to_geo(Vector3::new(n, e, -10.0)),
        vel_ned_mps: vel,
        ..m.view()
    }
}

fn ne(m: &PointMass, p: &GeoPoint) -> Vector2<f64> {
    m.ned(p).xy()
}

#[test]
fn zones_are_validated() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let sq = square((0.0, 0.0), 10.0);
    let good = zone(&m, FenceKind::KeepIn, &sq, &square((0.0, 0.0), 8.0));
    assert_eq!(validate_zone(&good), Ok(()));
    let too_few = FenceZone {
        polygon: good.polygon[..2].to_vec(),
        sub_polygon: good.sub_polygon[..2].to_vec(),
        ..good.clone()
    };
    assert_eq!(
        validate_zone(&too_few),
        Err(FenceZoneError::TooFewVertices { count: 2 })
    );
    let mismatch = FenceZone {
        sub_polygon: good.sub_polygon[..3].to_vec(),
        ..good.clone()
    };
    assert_eq!(
        validate_zone(&mismatch),
        Err(FenceZoneError::CountMismatch { polygon: 4, sub: 3 })
    );
    let mut nan = good.clone();
    nan.sub_polygon[2][1] = f64::NAN;
    assert_eq!(validate_zone(&nan), Err(FenceZoneError::BadCoordinate));
    let mut far = good.clone();
    far.polygon[0][0] = 91.0;
    assert_eq!(validate_zone(&far), Err(FenceZoneError::BadCoordinate));
    let bow = zone(
        &m,
        FenceKind::KeepOut,
        &[(0.0, 0.0), (10.0, 10.0), (0.0, 10.0), (10.0, 0.0)],
        &sq,
    );
    assert_eq!(
        validate_zone(&bow),
        Err(FenceZoneError::SelfIntersecting { sub: false })
    );
    let dup = zone(
        &m,
        FenceKind::KeepIn,
        &sq,
        &[(0.0, 0.0), (0.0, 0.0), (5.0, 5.0), (5.0, 0.0)],
    );
    assert_eq!(
        validate_zone(&dup),
        Err(FenceZoneError::SelfIntersecting { sub: true })
    );
    let flat = zone(
        &m,
        FenceKind::KeepIn,
        &[(0.0, 0.0), (5.0, 0.0), (10.0, 0.0)],
        &[(0.0, 0.0), (5.0, 1.0), (10.0, 0.0)],
    );
    assert!(validate_zone(&flat).is_err());
    // A concave polygon is fine.
    let l = [
        (0.0, 0.0),
        (0.0, 20.0),
        (10.0, 20.0),
        (10.0, 10.0),
        (20.0, 10.0),
        (20.0, 0.0),
    ];
    assert_eq!(validate_zone(&zone(&m, FenceKind::KeepIn, &l, &l)), Ok(()));
    assert_eq!(
        FenceZone::from_app(7, &good.polygon, &good.sub_polygon),
        Err(FenceZoneError::UnknownType(7))
    );
    assert_eq!(
        FenceZone::from_app(1, &good.polygon, &good.sub_polygon).map(|z| z.kind),
        Ok(FenceKind::KeepOut)
    );
    // The fence names the first bad zone.
    assert_eq!(
        Fence::new(vec![good.clone(), mismatch]).err(),
        Some(FenceError {
            zone: 1,
            error: FenceZoneError::CountMismatch { polygon: 4, sub: 3 }
        })
    );
    let fence = Fence::new(vec![good]).expect("valid");
    assert_eq!(fence.len(), 1);
    assert!(Fence::new(Vec::new()).is_ok_and(|f| f.is_empty()));
}

#[test]
fn allowed_is_inside_some_keep_in_and_outside_every_keep_out() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let fence = Fence::new(vec![
        zone(
            &m,
            FenceKind::KeepIn,
            &square((0.0, 0.0), 50.0),
            &square((0.0, 0.0), 45.0),
        ),
        zone(
            &m,
            FenceKind::KeepIn,
            &square((0.0, 120.0), 30.0),
            &square((0.0, 120.0), 25.0),
        ),
        zone(
            &m,
            FenceKind::KeepOut,
            &square((0.0, 0.0), 10.0),
            &square((0.0, 0.0), 15.0),
        ),
    ])
    .expect("valid");
    let p = |n: f64, e: f64| m.to_geo(Vector3::new(n, e, -10.0));
    assert!(fence.contains(&p(30.0, 30.0)));
    assert!(fence.contains(&p(0.0, 130.0)), "the second keep-in");
    // An edge's midpoint as the fence sees it: the fence works in the tangent plane at
    // its first vertex, where a straight edge of the point mass's plane bends by
    // ~0.1 mm (the flat-earth frames this used before were scalings of each other).
    let edge_middle = |zone: usize| {
        let v = &fence.zones()[zone].polygon;
        let geo = |q: &[f64; 2]| crate::shots::geo::GeoPoint {
            lat_deg: q[0],
            lon_deg: q[1],
            alt_rel_m: 0.0,
        };
        let f = crate::shots::geo::LocalFrame::new(geo(&fence.zones()[0].polygon[0]));
        f.to_geo(&((f.to_ned(&geo(&v[2])) + f.to_ned(&geo(&v[3]))) / 2.0))
    };
    assert!(fence.contains(&edge_middle(0)), "on the edge");
    assert!(!fence.contains(&p(0.0, 70.0)), "between the keep-ins");
    assert!(!fence.contains(&p(5.0, 5.0)), "in the keep-out");
    assert!(!fence.contains(&edge_middle(2)), "on the keep-out's edge");
    assert!(Fence::empty().contains(&p(1e4, 1e4)));
    // Only keep-outs: everywhere else is allowed.
    let only_out = Fence::new(vec![zone(
        &m,
        FenceKind::KeepOut,
        &square((0.0, 0.0), 10.0),
        &square((0.0, 0.0), 15.0),
    )])
    .expect("valid");
    assert!(only_out.contains(&p(500.0, -500.0)));
    assert!(!only_out.contains(&p(0.0, 0.0)));
}

#[test]
fn the_check_predicts_the_stop_and_names_the_hold_point() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let fence = Fence::new(vec![
        zone(
            &m,
            FenceKind::KeepIn,
            &square((0.0, 0.0), 50.0),
            &square((0.0, 0.0), 45.0),
        ),
        zone(
            &m,
            FenceKind::KeepOut,
            &square((0.0, 30.0), 5.0),
            &square((0.0, 30.0), 8.0),
        ),
    ])
    .expect("valid");
    assert_eq!(stopping_distance(5.0, 2.5), 5.0);
    assert_eq!(stopping_distance(2.0, 0.0), 2.0, "nonsense: 1 m/s²");
    // Standing still inside: clear; moving slowly, far from everything: clear.
    assert_eq!(
        fence.check(&at(&m, 0.0, 0.0, [0.0; 3]), 0.0, 0.2),
        FenceVerdict::Clear
    );
    assert_eq!(
        fence.check(&at(&m, 0.0, 0.0, [1.0, 0.0, 0.0]), 0.2, 0.2),
        FenceVerdict::Clear
    );
    // North at 5 m/s, 40 m from the keep-in edge at 50: stop 5 + latency 1 → 46: clear;
    // at 44: 50.5 → breach; held on the sub-polygon (45) nearest where it would cross.
    let v = at(&m, 40.0, 0.0, [5.0, 0.0, 0.0]);
    assert_eq!(
        fence.check(&v, stopping_distance(5.0, 2.5), 0.2),
        FenceVerdict::Clear
    );
    let v = at(&m, 44.0, 10.0, [5.0, 0.0, 0.0]);
    match fence.check(&v, stopping_distance(5.0, 2.5), 0.3) {
        FenceVerdict::Breach {
            polygon,
            kind,
            hold_point,
        } => {
            assert_eq!((polygon, kind), (0, FenceKind::KeepIn));
            let h = ne(&m, &hold_point);
            assert!((h - Vector2::new(45.0, 10.0)).norm() < 0.01, "{h:?}");
            assert_eq!(hold_point.alt_rel_m, v.position.alt_rel_m);
        }
        other => panic!("{other:?}"),
    }
    // East toward the keep-out at 25..35 (sub-polygon from 22): from 18, stopping
    // 3.2 m + 1.2 m late is short of 25; from 23 it is not, and the outer
    // sub-polygon edge (22) holds it.
    let v = at(&m, 2.0, 18.0, [0.0, 4.0, 0.0]);
    assert_eq!(
        fence.check(&v, stopping_distance(4.0, 2.5), 0.3),
        FenceVerdict::Clear
    );
    let v = at(&m, 2.0, 23.0, [0.0, 4.0, 0.0]);
    match fence.check(&v, stopping_distance(4.0, 2.5), 0.3) {
        FenceVerdict::Breach {
            polygon,
            kind,
            hold_point,
        } => {
            assert_eq!((polygon, kind), (1, FenceKind::KeepOut));
            let h = ne(&m, &hold_point);
            assert!((h - Vector2::new(2.0, 22.0)).norm() < 0.01, "{h:?}");
            assert!(fence.contains(&hold_point));
        }
        other => panic!("{other:?}"),
    }
    // Fast enough to jump a thin keep-out entirely: still a breach.
    let thin = Fence::new(vec![zone(
        &m,
        FenceKind::KeepOut,
        &[(-10.0, 20.0), (-10.0, 21.0), (10.0, 21.0), (10.0, 20.0)],
        &[(-12.0, 18.0), (-12.0, 23.0), (12.0, 23.0), (12.0, 18.0)],
    )])
    .expect("valid");
    let v = at(&m, 0.0, 10.0, [0.0, 5.0, 0.0]);
    assert!(matches!(
        thin.check(&v, 20.0, 0.2),
        FenceVerdict::Breach { polygon: 0, .. }
    ));
    // Moving away from the edge: clear, however fast.
    let v = at(&m, 0.0, 10.0, [0.0, -5.0, 0.0]);
    assert_eq!(thin.check(&v, 20.0, 0.2), FenceVerdict::Clear);
    // Already outside the keep-in (pushed out): a breach, held back inside.
    let v = at(&m, 60.0, 0.0, [0.0; 3]);
    match fence.check(&v, 0.0, 0.2) {
        FenceVerdict::Breach { hold_point, .. } => {
            let h = ne(&m, &hold_point);
            assert!((h - Vector2::new(45.0, 0.0)).norm() < 0.01, "{h:?}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_sub_polygon_on_the_wrong_side_falls_back_to_a_margin_off_the_edge() {
    let m = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    // A keep-out whose "sub-polygon" lies inside it.
    let fence = Fence::new(vec![zone(
        &m,
        FenceKind::KeepOut,
        &square((0.0, 30.0), 10.0),
        &square((0.0, 30.0), 5.0),
    )])
    .expect("valid");
    let v = at(&m, 0.0, 10.0, [0.0, 5.0, 0.0]);
    match fence.check(&v, 10.0, 0.3) {
        FenceVerdict::Breach { hold_point, .. } => {
            let h = ne(&m, &hold_point);
            assert!(
                (h - Vector2::new(0.0, 20.0 - HOLD_MARGIN_M)).norm() < 0.01,
                "{h:?}"
            );
        }
        other => panic!("{other:?}"),
    }
}

/// Fly a zipline toward the fence, checking every tick as the engine does; on a
/// breach, fly to the hold point. Returns (closest approach to the forbidden side:
/// the largest depth, hold point, final position).
fn fly_into(
    m: &mut PointMass,
    fence: &Fence,
    yaw: f32,
    forbidden: impl Fn(&Vector2<f64>) -> f64,
) -> (f64, Option<Vector2<f64>>, Vector3<f64>) {
    let lim = Lim::new(&LIMITS);
    let view = VehicleView {
        camera_yaw_deg: yaw,
        ..m.view()
    };
    let mut zip = Zipline::new(&view, false);
    let mut hold: Option<GeoPoint> = None;
    let mut depth = f64::NEG_INFINITY;
    let mut last = Vector3::zeros();
    for _ in 0..ticks(40.0) {
        let v = m.view();
        if hold.is_none() {
            // The engine's numbers: planning deceleration, lag plus a tick or two.
            let speed = f64::from(v.vel_ned_mps[0]).hypot(f64::from(v.vel_ned_mps[1]));
            let stop = stopping_distance(speed, lim.plan_accel());
            if let FenceVerdict::Breach { hold_point, .. } = fence.check(&v, stop, 0.5) {
                hold = Some(hold_point);
            }
        }
        let g = match hold {
            None => zip.step(&v, DT, 5.0, &LIMITS),
            Some(h) => {
                // Fly to the hold point, the setpoint continuous with the shot's.
                let pos = m.ned(&v.position);
                let wish = lim.clamp(toward(&pos, &m.ned(&h), &lim, f64::from(DT)));
                let max = lim.accel * f64::from(DT) * 0.999;
                let d = wish - last;
                let vel = if d.norm() > max {
                    last + d * (max / d.norm())
                } else {
                    wish
                };
                Guidance {
                    velocity_ned_mps: [vel.x as f32, vel.y as f32, vel.z as f32],
                    ..Guidance::HOVER
                }
            }
        };
        let c = g.velocity_ned_mps;
        last = Vector3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]));
        m.fly(&g);
        depth = depth.max(forbidden(&m.pos.xy()));
    }
    (depth, hold.map(|h| ne(m, &h)), m.pos)
}

#[test]
fn a_shot_flown_at_a_keep_out_stops_before_it_and_holds_on_the_sub_polygon() {
    let m0 = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let out = square((0.0, 60.0), 10.0);
    let fence = Fence::new(vec![zone(
        &m0,
        FenceKind::KeepOut,
        &out,
        &square((0.0, 60.0), 14.0),
    )])
    .expect("valid");
    let ring_ne: Vec<Vector2<f64>> = out.iter().map(|&(n, e)| Vector2::new(n, e)).collect();
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(3.0, 0.0, -10.0), dynamics);
        // Depth into the keep-out: > 0 once inside its western edge at 50.
        let (depth, hold, end) = fly_into(&mut m, &fence, 90.0, |p| {
            if contains(&ring_ne, p) {
                p.y - 50.0
            } else {
                -1.0
            }
        });
        assert!(
            depth < 0.0,
            "{dynamics:?}: entered the keep-out by {depth} m"
        );
        let hold = hold.expect("the fence was breached");
        assert!((hold - Vector2::new(3.0, 46.0)).norm() < 0.01, "{hold:?}");
        assert!((end.xy() - hold).norm() < 0.3, "{dynamics:?}: held {end:?}");
    }
}

#[test]
fn a_shot_flown_out_of_a_keep_in_stops_inside_and_comes_back_to_the_sub_polygon() {
    let m0 = PointMass::new(Vector3::zeros(), DYNAMICS[0]);
    let fence = Fence::new(vec![zone(
        &m0,
        FenceKind::KeepIn,
        &square((0.0, 0.0), 40.0),
        &square((0.0, 0.0), 35.0),
    )])
    .expect("valid");
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(-5.0, 0.0, -10.0), dynamics);
        // North: outside once past 40.
        let (depth, hold, end) = fly_into(&mut m, &fence, 0.0, |p| p.x - 40.0);
        assert!(depth < 0.0, "{dynamics:?}: left the keep-in by {depth} m");
        let hold = hold.expect("the fence was breached");
        assert!((hold.x - 35.0).abs() < 0.01, "{hold:?}");
        assert!((end.xy() - hold).norm() < 0.3, "{dynamics:?}");
    }
}
