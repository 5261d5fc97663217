//! Geodetic ↔ local NED conversion around the EKF origin: the workspace's WGS-84
//! geodesy ([`skymesh_geo::LocalFrame`], local level: north/east in the tangent
//! plane, down the altitude difference). The positions the simulator reports are
//! where a GNSS would put the metres it flew, in the model every service converts
//! them back with (ArduPilot's own flat sphere differs by 0.3 % north–south).

use nalgebra::Vector3;
pub use skymesh_runtime::angle::{wrap_2pi, wrap_pi};

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
    frame: skymesh_geo::LocalFrame,
}

impl LocalFrame {
    /// A frame centred on `origin`.
    pub fn new(origin: GeoPoint) -> Self {
        Self {
            origin,
            frame: skymesh_geo::LocalFrame::new(skymesh_geo::Geodetic::new(
                origin.lat_deg,
                origin.lon_deg,
                origin.alt_msl_m,
            )),
        }
    }

    /// The frame's origin (the EKF origin).
    pub fn origin(&self) -> GeoPoint {
        self.origin
    }

    /// Local NED metres → geodetic.
    pub fn to_geo(&self, ned: &Vector3<f64>) -> GeoPoint {
        let g = self.frame.from_ned((*ned).into());
        GeoPoint {
            lat_deg: g.lat_deg,
            lon_deg: g.lon_deg,
            alt_msl_m: g.alt_m,
        }
    }

    /// Geodetic → local NED metres.
    pub fn to_ned(&self, geo: &GeoPoint) -> Vector3<f64> {
        Vector3::from(self.frame.to_ned(&skymesh_geo::Geodetic::new(
            geo.lat_deg,
            geo.lon_deg,
            geo.alt_msl_m,
        )))
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
        // WGS-84's meridian at 35.4° S: 0.000 901 3° per 100 m (ArduPilot's sphere,
        // which the simulator used before, reads 0.000 898 3°).
        let f = LocalFrame::new(cmac());
        let g = f.to_geo(&Vector3::new(100.0, 0.0, 0.0));
        assert!((g.lat_deg - cmac().lat_deg - 0.000_901_3).abs() < 1e-7);
        assert!((g.lon_deg - cmac().lon_deg).abs() < 1e-12);
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
