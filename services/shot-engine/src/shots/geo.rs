//! Geodetic helpers: a local tangent plane (north/east/down metres) around an origin,
//! distances, bearings and offsets, on the workspace's WGS-84 geodesy
//! ([`skymesh_geo`]): north/east exact in the tangent plane, down the altitude
//! difference, exact round trips.

use nalgebra::Vector3;
pub(crate) use skymesh_runtime::angle::{wrap_180, wrap_360};

/// A position: latitude/longitude in degrees, altitude in metres above home.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoPoint {
    /// Latitude, degrees (north positive).
    pub lat_deg: f64,
    /// Longitude, degrees (east positive).
    pub lon_deg: f64,
    /// Altitude above home, metres.
    pub alt_rel_m: f32,
}

impl GeoPoint {
    fn geodetic(&self) -> skymesh_geo::Geodetic {
        skymesh_geo::Geodetic::new(self.lat_deg, self.lon_deg, f64::from(self.alt_rel_m))
    }
}

/// Local tangent frame (local level: down is the altitude difference) around `origin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    origin: GeoPoint,
    frame: skymesh_geo::LocalFrame,
}

impl LocalFrame {
    /// A frame centred on `origin` (NED zero there, down relative to its altitude).
    pub fn new(origin: GeoPoint) -> Self {
        LocalFrame {
            origin,
            frame: skymesh_geo::LocalFrame::new(origin.geodetic()),
        }
    }

    /// The frame's origin.
    pub fn origin(&self) -> GeoPoint {
        self.origin
    }

    /// Geodetic → north, east, down metres from the origin.
    pub fn to_ned(&self, p: &GeoPoint) -> Vector3<f64> {
        let [n, e] = self.frame.to_ne(p.lat_deg, p.lon_deg);
        Vector3::new(
            n,
            e,
            f64::from(self.origin.alt_rel_m) - f64::from(p.alt_rel_m),
        )
    }

    /// North, east, down metres from the origin → geodetic.
    pub fn to_geo(&self, ned: &Vector3<f64>) -> GeoPoint {
        let (lat_deg, lon_deg) = self.frame.from_ne(ned.x, ned.y);
        GeoPoint {
            lat_deg,
            lon_deg,
            alt_rel_m: (f64::from(self.origin.alt_rel_m) - ned.z) as f32,
        }
    }
}

/// Straight-line distance including the altitude difference, metres.
pub fn distance_m(a: &GeoPoint, b: &GeoPoint) -> f64 {
    skymesh_geo::distance_m(&a.geodetic(), &b.geodetic())
}

/// Horizontal distance, metres.
pub fn ground_distance_m(a: &GeoPoint, b: &GeoPoint) -> f64 {
    skymesh_geo::ground_distance_m(&a.geodetic(), &b.geodetic())
}

/// Bearing from `from` to `to`, degrees 0..360, north = 0, clockwise (0 when the
/// points coincide).
pub fn bearing_deg(from: &GeoPoint, to: &GeoPoint) -> f64 {
    skymesh_geo::bearing_deg(&from.geodetic(), &to.geodetic())
}

/// The point `distance_m` from `p` along `bearing_deg`, at `p`'s altitude.
pub fn offset(p: &GeoPoint, bearing_deg: f64, distance_m: f64) -> GeoPoint {
    let g = skymesh_geo::offset(&p.geodetic(), bearing_deg, distance_m);
    GeoPoint {
        lat_deg: g.lat_deg,
        lon_deg: g.lon_deg,
        alt_rel_m: p.alt_rel_m,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CMAC: GeoPoint = GeoPoint {
        lat_deg: -35.363_261,
        lon_deg: 149.165_230,
        alt_rel_m: 0.0,
    };

    #[test]
    fn ned_geo_round_trip_at_one_km_is_under_a_centimetre() {
        let frame = LocalFrame::new(CMAC);
        for (n, e, d) in [
            (1000.0, 0.0, -50.0),
            (0.0, 1000.0, 0.0),
            (-707.1, -707.1, 10.0),
            (600.0, -800.0, -120.0),
        ] {
            let ned = Vector3::new(n, e, d);
            let back = frame.to_ned(&frame.to_geo(&ned));
            assert!((back - ned).norm() < 0.01, "{ned:?} → {back:?}");
            let geo = frame.to_geo(&ned);
            // The flat distance agrees with the frame's within a centimetre per km.
            let ground = ground_distance_m(&CMAC, &geo);
            assert!(
                (ground - n.hypot(e)).abs() < 0.5,
                "{ground} vs {}",
                n.hypot(e)
            );
        }
    }

    #[test]
    fn a_degree_of_latitude_is_wgs84_long() {
        // Meridian arc from 0° to 1° is 110 574 m; at 45° a degree is 111 132 m.
        let eq = GeoPoint {
            lat_deg: 0.0,
            lon_deg: 0.0,
            alt_rel_m: 0.0,
        };
        let north = GeoPoint {
            lat_deg: 0.01,
            ..eq
        };
        assert!((ground_distance_m(&eq, &north) - 1105.74).abs() < 0.1);
        let east = GeoPoint {
            lon_deg: 0.01,
            ..eq
        };
        assert!((ground_distance_m(&eq, &east) - 1113.19).abs() < 0.1);
    }

    #[test]
    fn bearings_of_known_points() {
        let n = offset(&CMAC, 0.0, 100.0);
        let e = offset(&CMAC, 90.0, 100.0);
        let s = offset(&CMAC, 180.0, 100.0);
        let w = offset(&CMAC, 270.0, 100.0);
        assert!(bearing_deg(&CMAC, &n).min(360.0 - bearing_deg(&CMAC, &n)) < 1e-6);
        assert!((bearing_deg(&CMAC, &e) - 90.0).abs() < 1e-6);
        assert!((bearing_deg(&CMAC, &s) - 180.0).abs() < 1e-6);
        assert!((bearing_deg(&CMAC, &w) - 270.0).abs() < 1e-6);
        // (0,0) → (1,1): great-circle initial bearing 45.19°.
        let o = GeoPoint {
            lat_deg: 0.0,
            lon_deg: 0.0,
            alt_rel_m: 0.0,
        };
        let ne = GeoPoint {
            lat_deg: 1.0,
            lon_deg: 1.0,
            alt_rel_m: 0.0,
        };
        assert!(
            (bearing_deg(&o, &ne) - 45.19).abs() < 0.05,
            "{}",
            bearing_deg(&o, &ne)
        );
        // Across the antimeridian: due east is still east (the geodesic's initial
        // azimuth to a point of the same parallel, 90° − Δλ·sin φ/2 = 89.99991°; the
        // flat earth this used before read exactly 90°).
        let a = GeoPoint {
            lat_deg: 10.0,
            lon_deg: 179.9995,
            alt_rel_m: 0.0,
        };
        let b = GeoPoint {
            lon_deg: -179.9995,
            ..a
        };
        assert!((bearing_deg(&a, &b) - 89.999_91).abs() < 1e-5);
        assert!((ground_distance_m(&a, &b) - 109.6).abs() < 0.5);
        assert_eq!(bearing_deg(&a, &a), 0.0);
    }

    #[test]
    fn offset_then_measure_gives_the_offset_back() {
        for bearing in [0.0, 33.0, 145.0, 260.0, 359.0] {
            let p = offset(&CMAC, bearing, 250.0);
            assert!((ground_distance_m(&CMAC, &p) - 250.0).abs() < 0.01);
            let b = bearing_deg(&CMAC, &p);
            let diff = wrap_180(b - bearing).abs();
            assert!(diff < 0.01, "{bearing} → {b}");
            assert_eq!(p.alt_rel_m, CMAC.alt_rel_m);
        }
    }

    #[test]
    fn distance_includes_altitude() {
        let up = GeoPoint {
            alt_rel_m: 40.0,
            ..offset(&CMAC, 90.0, 30.0)
        };
        assert!((distance_m(&CMAC, &up) - 50.0).abs() < 0.01);
        assert!((ground_distance_m(&CMAC, &up) - 30.0).abs() < 0.01);
    }
}
