//! Geometry of [`super::geofence`]: polygons in local metres unless a test is about
//! the projection. The envelope on top of it: `fence_envelope_tests`.

use super::geofence::*;
use skymesh_ipc_types::{FenceKind, GeofenceSet};

fn ne(x: f64, y: f64) -> Ne {
    Ne::new(x, y)
}

fn poly(kind: FenceKind, pts: &[(f64, f64)]) -> Polygon {
    Polygon::new(kind, pts.iter().map(|&(x, y)| ne(x, y)).collect())
}

fn square(kind: FenceKind, half: f64) -> Polygon {
    poly(
        kind,
        &[(-half, -half), (half, -half), (half, half), (-half, half)],
    )
}

/// A U open to the north: x (north) 0..30, y (east) 0..30, notch x 10..30, y 10..20.
fn u_shape() -> Polygon {
    poly(
        FenceKind::KeepIn,
        &[
            (0.0, 0.0),
            (30.0, 0.0),
            (30.0, 10.0),
            (10.0, 10.0),
            (10.0, 20.0),
            (30.0, 20.0),
            (30.0, 30.0),
            (0.0, 30.0),
        ],
    )
}

fn fence(polygons: Vec<Polygon>) -> Fence {
    Fence {
        frame: LocalFrame::new(0.0, 0.0),
        polygons,
        ceiling_m: 50.0,
        floor_m: -5.0,
    }
}

#[test]
fn point_in_convex_and_concave_polygons_in_either_winding() {
    let sq = square(FenceKind::KeepIn, 10.0);
    assert!(sq.contains(ne(0.0, 0.0)));
    assert!(sq.contains(ne(9.9, -9.9)));
    assert!(!sq.contains(ne(10.1, 0.0)));
    assert!(!sq.contains(ne(0.0, -30.0)));
    let u = u_shape();
    assert!(u.contains(ne(5.0, 15.0)), "the base of the U");
    assert!(
        u.contains(ne(20.0, 5.0)) && u.contains(ne(20.0, 25.0)),
        "its arms"
    );
    assert!(!u.contains(ne(20.0, 15.0)), "the notch");
    let mut reversed: Vec<(f64, f64)> = vec![
        (0.0, 0.0),
        (30.0, 0.0),
        (30.0, 10.0),
        (10.0, 10.0),
        (10.0, 20.0),
        (30.0, 20.0),
        (30.0, 30.0),
        (0.0, 30.0),
    ];
    reversed.reverse();
    let r = poly(FenceKind::KeepIn, &reversed);
    for p in [ne(5.0, 15.0), ne(20.0, 15.0), ne(20.0, 5.0), ne(-1.0, 5.0)] {
        assert_eq!(r.contains(p), u.contains(p), "{p:?}");
    }
}

#[test]
fn keep_out_inside_keep_in() {
    let f = fence(vec![
        square(FenceKind::KeepIn, 100.0),
        poly(
            FenceKind::KeepOut,
            &[(20.0, -5.0), (30.0, -5.0), (30.0, 5.0), (20.0, 5.0)],
        ),
    ]);
    assert!(f.contains(ne(0.0, 0.0)));
    assert!(!f.contains(ne(25.0, 0.0)), "in the keep-out");
    assert!(!f.contains(ne(150.0, 0.0)), "outside the keep-in");
    let mut s = Vec::new();
    let d = f.exit_distance(ne(0.0, 0.0), ne(1.0, 0.0), &mut s).unwrap();
    assert!((d - 20.0).abs() < 1e-9, "stops at the keep-out, {d}");
    let d = f
        .exit_distance(ne(0.0, 0.0), ne(-1.0, 0.0), &mut s)
        .unwrap();
    assert!((d - 100.0).abs() < 1e-9, "{d}");
    // Beside the keep-out, northward: the keep-in edge.
    let d = f
        .exit_distance(ne(0.0, 10.0), ne(1.0, 0.0), &mut s)
        .unwrap();
    assert!((d - 100.0).abs() < 1e-9, "{d}");
    // Only keep-outs: a ray that misses them never leaves.
    let open = fence(vec![square(FenceKind::KeepOut, 5.0)]);
    assert!(open.contains(ne(50.0, 50.0)));
    assert_eq!(
        open.exit_distance(ne(50.0, 0.0), ne(1.0, 0.0), &mut s),
        None
    );
    let d = open
        .exit_distance(ne(50.0, 0.0), ne(-1.0, 0.0), &mut s)
        .unwrap();
    assert!((d - 45.0).abs() < 1e-9, "{d}");
}

#[test]
fn exit_distance_along_rays_in_a_concave_polygon() {
    let f = fence(vec![u_shape()]);
    let mut s = Vec::new();
    // From the west arm eastward: leaves into the notch at y = 10.
    let d = f
        .exit_distance(ne(20.0, 5.0), ne(0.0, 1.0), &mut s)
        .unwrap();
    assert!((d - 5.0).abs() < 1e-9, "{d}");
    // In the base eastward: stays inside across the whole base.
    let d = f.exit_distance(ne(5.0, 1.0), ne(0.0, 1.0), &mut s).unwrap();
    assert!((d - 29.0).abs() < 1e-9, "{d}");
    // Diagonal through a reflex vertex (10, 10): crossing exactly at a vertex.
    let dir = ne(1.0, 1.0).normalize();
    let d = f.exit_distance(ne(5.0, 5.0), dir, &mut s).unwrap();
    assert!((d - 5.0 * 2f64.sqrt()).abs() < 1e-6, "{d}");
    // Along an edge-aligned line through the notch mouth: leaves at x = 30.
    let d = f
        .exit_distance(ne(5.0, 25.0), ne(1.0, 0.0), &mut s)
        .unwrap();
    assert!((d - 25.0).abs() < 1e-9, "{d}");
}

#[test]
fn way_back_points_to_the_nearest_boundary_of_the_violated_area() {
    let f = fence(vec![
        square(FenceKind::KeepIn, 10.0),
        poly(
            FenceKind::KeepOut,
            &[(-2.0, -2.0), (2.0, -2.0), (2.0, 6.0), (-2.0, 6.0)],
        ),
    ]);
    let back = f.way_back(ne(15.0, 0.0)).unwrap();
    assert!((back - ne(-1.0, 0.0)).norm() < 1e-9, "{back:?}");
    let back = f.way_back(ne(0.5, 0.0)).unwrap();
    assert!(
        (back - ne(1.0, 0.0)).norm() < 1e-9,
        "out of the keep-out northward: {back:?}"
    );
    assert_eq!(f.way_back(ne(5.0, 5.0)), None, "inside");
}

#[test]
fn the_local_frame_matches_great_circle_distances() {
    let frame = LocalFrame::new(-35.363261, 149.165230);
    let p = frame.to_local(-35.363261 + 0.009, 149.165230 + 0.011);
    // Haversine on a sphere of the local mean radius.
    let (lat1, lon1) = ((-35.363261f64).to_radians(), 149.165230f64.to_radians());
    let (lat2, lon2) = ((-35.354261f64).to_radians(), 149.176230f64.to_radians());
    let h = ((lat2 - lat1) / 2.0).sin().powi(2)
        + lat1.cos() * lat2.cos() * ((lon2 - lon1) / 2.0).sin().powi(2);
    let great_circle = 2.0 * 6_371_000.0 * h.sqrt().asin();
    let rel = (p.norm() - great_circle).abs() / great_circle;
    assert!(
        rel < 3e-3,
        "about 1.4 km: {} vs {great_circle} ({rel})",
        p.norm()
    );
    assert!(
        (p.x - 999.0).abs() < 2.0,
        "0.009° of latitude ≈ 999 m: {}",
        p.x
    );
    // Across the antimeridian the longitude difference is unwrapped.
    let f = LocalFrame::new(0.0, 179.9999);
    assert!(f.to_local(0.0, -179.9999).y > 0.0);
}

#[test]
fn a_geofence_sample_compiles_or_is_refused() {
    let mut set = GeofenceSet {
        enabled: 1,
        ..Default::default()
    };
    assert!(set.push_polygon(
        FenceKind::KeepIn,
        &[
            [-35.0, 149.0],
            [-35.0, 149.01],
            [-34.99, 149.01],
            [-34.99, 149.0]
        ],
    ));
    let f = Fence::compile(&set).unwrap().unwrap();
    assert!(f.contains(f.frame.to_local(-34.995, 149.005)));
    assert!(!f.contains(f.frame.to_local(-34.985, 149.005)));
    set.polygons[0].vertices[2][1] = f64::INFINITY;
    assert!(Fence::compile(&set).is_err());
    set.polygons[0].vertices[2][1] = 149.01;
    set.enabled = 0;
    assert_eq!(Fence::compile(&set).unwrap(), None, "disabled clears");
}

#[test]
fn clearance_is_perpendicular_and_segments_must_keep_it() {
    let f = fence(vec![
        square(FenceKind::KeepIn, 50.0),
        poly(
            FenceKind::KeepOut,
            &[(20.0, -5.0), (30.0, -5.0), (30.0, 5.0), (20.0, 5.0)],
        ),
    ]);
    assert!((f.clearance(ne(0.0, 45.0)) - 5.0).abs() < 1e-9, "east wall");
    assert!((f.clearance(ne(17.0, 0.0)) - 3.0).abs() < 1e-9, "keep-out");
    assert_eq!(f.clearance(ne(25.0, 0.0)), 0.0, "in the keep-out");
    assert_eq!(f.clearance(ne(60.0, 0.0)), 0.0, "outside");
    // A segment at 10 degrees to the north wall: 2 m from it at its end, not along
    // the ray (which would still be 11.5 m).
    let a = ne(40.0, -40.0);
    let b = a + ne(10f64.to_radians().sin(), 10f64.to_radians().cos())
        * (8.0 / 10f64.to_radians().sin());
    assert!((b.x - 48.0).abs() < 1e-9);
    assert!(f.segment_clear(a, b, 1.99));
    assert!(!f.segment_clear(a, b, 2.01));
    // Crossing the keep-out's corner region: not clear even by 0.
    assert!(!f.segment_clear(ne(15.0, -10.0), ne(35.0, 10.0), 0.0));
    // Overlapping keep-ins: clearance from the one that holds the point.
    let two = fence(vec![
        poly(
            FenceKind::KeepIn,
            &[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)],
        ),
        poly(
            FenceKind::KeepIn,
            &[(0.0, 8.0), (10.0, 8.0), (10.0, 30.0), (0.0, 30.0)],
        ),
    ]);
    assert!((two.clearance(ne(5.0, 20.0)) - 5.0).abs() < 1e-9);
    assert!(
        two.segment_clear(ne(5.0, 9.0), ne(5.0, 20.0), 1.0),
        "within the second"
    );
}
