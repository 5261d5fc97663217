//! skymesh-geo against two references: map_3d (ECEF, ENU, NED) and
//! geographiclib-rs (geodesic distance and azimuth, exact to nanometres).

use geographiclib_rs::{Geodesic, InverseGeodesic};
use map_3d::Ellipsoid;
use proptest::prelude::*;
use skymesh_geo::{bearing_deg, ground_distance_m, Geodetic, LocalFrame};

fn close(a: [f64; 3], b: (f64, f64, f64), tol: f64) -> bool {
    (a[0] - b.0).abs() < tol && (a[1] - b.1).abs() < tol && (a[2] - b.2).abs() < tol
}

proptest! {
    #[test]
    fn ecef_matches_map_3d(lat in -90.0f64..90.0, lon in -180.0f64..180.0, alt in -500.0f64..20_000.0) {
        let p = Geodetic::new(lat, lon, alt);
        let ours = p.to_ecef();
        let theirs = map_3d::geodetic2ecef(lat.to_radians(), lon.to_radians(), alt, Ellipsoid::WGS84);
        prop_assert!(close(ours, theirs, 1e-6), "{ours:?} vs {theirs:?}");
        // ECEF → geodetic round trip: micrometres.
        let back = Geodetic::from_ecef(ours);
        prop_assert!((back.lat_deg - lat).abs() < 1e-11 && (back.alt_m - alt).abs() < 1e-6, "{back:?}");
        prop_assert!(lat.abs() > 89.999_999 || ((back.lon_deg - lon + 540.0).rem_euclid(360.0) - 180.0).abs() < 1e-11);
    }

    #[test]
    fn cartesian_enu_and_ned_match_map_3d(
        lat0 in -85.0f64..85.0, lon0 in -180.0f64..180.0, alt0 in -100.0f64..3000.0,
        dn in -20_000.0f64..20_000.0, de in -20_000.0f64..20_000.0, du in -500.0f64..2000.0,
    ) {
        let f = LocalFrame::new(Geodetic::new(lat0, lon0, alt0));
        let p = f.geodetic_of_enu([de, dn, du]);
        let theirs = map_3d::geodetic2enu(
            p.lat_deg.to_radians(), p.lon_deg.to_radians(), p.alt_m,
            lat0.to_radians(), lon0.to_radians(), alt0, Ellipsoid::WGS84,
        );
        prop_assert!(close(f.enu_of(&p), theirs, 1e-6));
        prop_assert!(close([de, dn, du], theirs, 1e-6), "{:?} vs {theirs:?}", [de, dn, du]);
        let ned = map_3d::geodetic2ned(
            p.lat_deg.to_radians(), p.lon_deg.to_radians(), p.alt_m,
            lat0.to_radians(), lon0.to_radians(), alt0, Ellipsoid::WGS84,
        );
        prop_assert!(close(f.ned_of(&p), ned, 1e-6));
    }

    #[test]
    fn local_level_round_trips_and_is_the_tangent_plane(
        lat0 in -85.0f64..85.0, lon0 in -180.0f64..180.0, alt0 in -100.0f64..3000.0,
        n in -20_000.0f64..20_000.0, e in -20_000.0f64..20_000.0, d in -2000.0f64..500.0,
    ) {
        let f = LocalFrame::new(Geodetic::new(lat0, lon0, alt0));
        let p = f.from_ned([n, e, d]);
        prop_assert!((-180.0..180.0).contains(&p.lon_deg) && p.lat_deg.abs() <= 90.0);
        let back = f.to_ned(&p);
        prop_assert!((back[0] - n).abs() < 1e-6 && (back[1] - e).abs() < 1e-6 && (back[2] - d).abs() < 1e-9,
            "{:?} → {back:?}", [n, e, d]);
        // North/east are map_3d's tangent-plane coordinates of the point on the ellipsoid.
        let theirs = map_3d::geodetic2enu(
            p.lat_deg.to_radians(), p.lon_deg.to_radians(), 0.0,
            lat0.to_radians(), lon0.to_radians(), 0.0, Ellipsoid::WGS84,
        );
        prop_assert!((theirs.0 - e).abs() < 1e-6 && (theirs.1 - n).abs() < 1e-6);
    }

    #[test]
    fn distance_and_bearing_match_the_geodesic(
        lat in -80.0f64..80.0, lon in -180.0f64..180.0,
        az in 0.0f64..360.0, s in 1.0f64..10_000.0,
    ) {
        let a = Geodetic::new(lat, lon, 0.0);
        let b = skymesh_geo::offset(&a, az, s);
        let (s12, azi1, _azi2, _a12): (f64, f64, f64, f64) =
            Geodesic::wgs84().inverse(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg);
        // The tangent plane shortens a line by s³/(6R²): 4 mm at 10 km.
        let ours = ground_distance_m(&a, &b);
        prop_assert!((ours - s12).abs() < 1e-3 + s.powi(3) / 6.0 / 6.3e6f64.powi(2), "{ours} vs {s12}");
        let diff = (bearing_deg(&a, &b) - azi1 + 540.0).rem_euclid(360.0) - 180.0;
        prop_assert!(diff.abs() < 1e-4, "{} vs {azi1}", bearing_deg(&a, &b));
    }
}
