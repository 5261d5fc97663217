//! Geodetic ↔ local NED conversion.
//!
//! Flat earth around the EKF origin, with ArduPilot's own scaling constant, so
//! positions the simulator reports convert back exactly the way ArduPilot's
//! `Location::get_distance_NE` would on a real vehicle over the few kilometres a
//! simulated flight covers.

use nalgebra::Vector3;
use skymesh_runtime::angle::wrap_180;
pub use skymesh_runtime::angle::{wrap_2pi, wrap_pi};

/// Metres per degree of latitude (ArduPilot `LOCATION_SCALING_FACTOR` × 1e7).
const METRES_PER_DEGREE: f64 = 111_318.845_021_450_34;

/// A WGS84 position with altitude above mean sea level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoPoint {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Altitude above mean sea level, metres.
    pub alt_msl_m: f64,
}

impl GeoPoint {
    /// Latitude in degrees × 1e7, as MAVLink carries it.
    pub fn lat_e7(&self) -> i32 {
        deg_to_e7(self.lat_deg)
    }

    /// Longitude in degrees × 1e7, as MAVLink carries it.
    pub fn lon_e7(&self) -> i32 {
        deg_to_e7(self.lon_deg)
    }
}

/// Degrees → degrees × 1e7, saturating (the cast saturates; inputs are validated
/// to ±180° anyway).
pub fn deg_to_e7(deg: f64) -> i32 {
    (deg * 1e7).round() as i32
}

/// The local tangent frame: north/east/down metres from `origin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    origin: GeoPoint,
    /// Metres per degree of longitude at the origin's latitude.
    metres_per_deg_lon: f64,
}

impl LocalFrame {
    /// A frame centred on `origin`.
    pub fn new(origin: GeoPoint) -> Self {
        // Clamp like ArduPilot's longitude_scale so the poles don't divide by zero.
        let scale = origin.lat_deg.to_radians().cos().max(0.01);
        Self {
            origin,
            metres_per_deg_lon: METRES_PER_DEGREE * scale,
        }
    }

    /// The frame's origin (the EKF origin).
    pub fn origin(&self) -> GeoPoint {
        self.origin
    }

    /// Local NED metres → geodetic.
    pub fn to_geo(&self, ned: &Vector3<f64>) -> GeoPoint {
        GeoPoint {
            lat_deg: self.origin.lat_deg + ned.x / METRES_PER_DEGREE,
            lon_deg: wrap_180(self.origin.lon_deg + ned.y / self.metres_per_deg_lon),
            alt_msl_m: self.origin.alt_msl_m - ned.z,
        }
    }

    /// Geodetic → local NED metres.
    pub fn to_ned(&self, geo: &GeoPoint) -> Vector3<f64> {
        Vector3::new(
            (geo.lat_deg - self.origin.lat_deg) * METRES_PER_DEGREE,
            wrap_180(geo.lon_deg - self.origin.lon_deg) * self.metres_per_deg_lon,
            self.origin.alt_msl_m - geo.alt_msl_m,
        )
    }
}

/// Bearing from `from` to `to` in the NE plane, radians clockwise from north.
pub fn bearing(from: &Vector3<f64>, to: &Vector3<f64>) -> f64 {
    (to.y - from.y).atan2(to.x - from.x)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmac() -> GeoPoint {
        GeoPoint {
            lat_deg: -35.363_261,
            lon_deg: 149.165_230,
            alt_msl_m: 584.0,
        }
    }

    #[test]
    fn round_trip() {
        let f = LocalFrame::new(cmac());
        let p = Vector3::new(123.4, -567.8, -42.0);
        let back = f.to_ned(&f.to_geo(&p));
        assert!((back - p).norm() < 1e-6, "{back:?}");
        assert!((f.to_geo(&p).alt_msl_m - 626.0).abs() < 1e-9);
    }

    #[test]
    fn hundred_metres_north_is_about_0_0009_degrees() {
        let f = LocalFrame::new(cmac());
        let g = f.to_geo(&Vector3::new(100.0, 0.0, 0.0));
        assert!((g.lat_deg - cmac().lat_deg - 0.000_898_3).abs() < 1e-6);
        assert_eq!(g.lon_deg, cmac().lon_deg);
    }

    #[test]
    fn antimeridian() {
        let f = LocalFrame::new(GeoPoint {
            lat_deg: 0.0,
            lon_deg: 179.9999,
            alt_msl_m: 0.0,
        });
        let g = f.to_geo(&Vector3::new(0.0, 100.0, 0.0));
        assert!(g.lon_deg < -179.99, "{g:?}");
        assert!((f.to_ned(&g).y - 100.0).abs() < 1e-6);
    }

    #[test]
    fn bearing_is_clockwise_from_north() {
        use std::f64::consts::PI;
        let b = bearing(&Vector3::zeros(), &Vector3::new(0.0, 1.0, 0.0));
        assert!((b - PI / 2.0).abs() < 1e-12);
    }
}
