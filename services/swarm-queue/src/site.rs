//! The site frame: x east, y north, z up, metres around a configured origin, and
//! the conversions between it and what the vehicles speak.
//!
//! Horizontal: the plane tangent to the WGS-84 ellipsoid at the origin
//! ([`skymesh_geo::LocalFrame`], the workspace's one geodesy): exact round trips,
//! distances from the origin shortened by s³/(6R²), 4 mm at the 10 km the commands
//! allow.
//!
//! Vertical: `z` is height above the origin's altitude (AMSL). A vehicle flies
//! relative to its home, so a target's `alt_rel = z + origin_alt_msl − home_alt_msl`
//! with the vehicle's home altitude taken from its state
//! (`alt_msl_m − alt_rel_m`), and a tracked `z = alt_msl_m − origin_alt_msl`.
//!
//! Angles: GroundControl's yaw is counter-clockwise degrees from x (east); a compass
//! heading is clockwise from north, so `heading = 90° − yaw`. Attitude quaternions
//! come body (forward-right-down) → NED from the autopilot and go out body
//! (forward-left-up) → site ENU, the ROS convention, so a vehicle facing north at
//! rest reads yaw 90°.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion};
use skymesh_geo::{Geodetic, LocalFrame};
use skymesh_runtime::angle;

/// The site frame around one origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteFrame {
    frame: LocalFrame,
}

impl SiteFrame {
    /// The frame centred on latitude/longitude (degrees) and an altitude above mean
    /// sea level (metres).
    pub fn new(lat_deg: f64, lon_deg: f64, alt_msl_m: f64) -> Self {
        SiteFrame {
            frame: LocalFrame::new(Geodetic::new(lat_deg, lon_deg, alt_msl_m)),
        }
    }

    /// Latitude, longitude (degrees) and altitude AMSL (metres) of the origin.
    pub fn origin(&self) -> (f64, f64, f64) {
        let o = self.frame.origin();
        (o.lat_deg, o.lon_deg, o.alt_m)
    }

    fn alt0(&self) -> f64 {
        self.frame.origin().alt_m
    }

    /// Geodetic → site x (east), y (north), metres.
    pub fn to_site_xy(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        let [n, e] = self.frame.to_ne(lat_deg, lon_deg);
        [e, n]
    }

    /// Site x (east), y (north) → latitude, longitude in degrees.
    pub fn to_geodetic(&self, x: f64, y: f64) -> (f64, f64) {
        self.frame.from_ne(y, x)
    }

    /// Site `z` of an altitude above mean sea level.
    pub fn z_of_msl(&self, alt_msl_m: f64) -> f64 {
        alt_msl_m - self.alt0()
    }

    /// Altitude above home of site height `z` for a vehicle whose home is at
    /// `home_alt_msl_m`.
    pub fn alt_rel_of_z(&self, z: f64, home_alt_msl_m: f64) -> f64 {
        z + self.alt0() - home_alt_msl_m
    }

    /// Altitude above mean sea level of site height `z`.
    pub fn msl_of_z(&self, z: f64) -> f64 {
        z + self.alt0()
    }
}

/// Normalises degrees into −180..=180 (−180 excluded).
pub fn wrap_deg(d: f32) -> f32 {
    angle::wrap_180_upper(f64::from(d)) as f32
}

/// GroundControl yaw (CCW degrees from east) → compass heading (CW from north, 0..360).
pub fn heading_of_yaw(yaw_ccw_deg: f32) -> f32 {
    let h = (90.0 - yaw_ccw_deg).rem_euclid(360.0);
    if h >= 360.0 {
        0.0
    } else {
        h
    }
}

/// Compass heading (CW degrees from north) → GroundControl yaw (CCW from east, −180..=180).
pub fn yaw_of_heading(heading_deg: f32) -> f32 {
    wrap_deg(90.0 - heading_deg)
}

/// NED → ENU of the frame, and FLU → FRD of the body: proper rotations (det +1).
const NED_TO_ENU: [[f64; 3]; 3] = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
const FLU_TO_FRD: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];

fn m(a: [[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| a[r][c])
}

/// Autopilot attitude (`w, x, y, z`, body FRD → NED) → site attitude
/// (`x, y, z, w`, body FLU → ENU). A non-finite or zero quaternion gives identity
/// in NED (facing north, level).
pub fn enu_quaternion(q_ned_wxyz: [f32; 4]) -> [f32; 4] {
    let [w, x, y, z] = q_ned_wxyz.map(f64::from);
    let q = Quaternion::new(w, x, y, z);
    let q = if q.coords.iter().all(|v| v.is_finite()) && q.norm() > 1e-6 {
        UnitQuaternion::from_quaternion(q)
    } else {
        UnitQuaternion::identity()
    };
    let r_ned_frd = q.to_rotation_matrix().into_inner();
    let r = m(NED_TO_ENU) * r_ned_frd * m(FLU_TO_FRD);
    let out = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let c = out.into_inner().coords; // x, y, z, w
    let mut v = [c.x as f32, c.y as f32, c.z as f32, c.w as f32];
    // One sign for the same rotation: w ≥ 0.
    if v[3] < 0.0 {
        v = v.map(|a| -a);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cmac() -> SiteFrame {
        SiteFrame::new(-35.363261, 149.165230, 584.0)
    }

    #[test]
    fn the_origin_is_zero_and_axes_point_east_and_north() {
        let f = cmac();
        let [x, y] = f.to_site_xy(-35.363261, 149.165230);
        assert!(x.abs() < 1e-9 && y.abs() < 1e-9);
        let (lat, lon) = f.to_geodetic(100.0, 0.0);
        // The tangent plane's east axis leaves the parallel (a great circle, not a
        // rhumb line): 5e-9° of latitude 100 m out.
        assert!(
            lon > 149.165230 && (lat - -35.363261).abs() < 1e-8,
            "x is east"
        );
        let (lat, lon) = f.to_geodetic(0.0, 100.0);
        assert!(
            lat > -35.363261 && (lon - 149.165230).abs() < 1e-12,
            "y is north"
        );
        // 1e-3 degrees of latitude is about 111 m.
        let [_, y] = f.to_site_xy(-35.362261, 149.165230);
        assert!((y - 110.9).abs() < 0.5, "{y}");
    }

    #[test]
    fn heights_are_above_the_origin_and_relative_to_home() {
        let f = cmac();
        assert_eq!(f.z_of_msl(590.0), 6.0);
        assert_eq!(f.msl_of_z(6.0), 590.0);
        // A vehicle whose home is 2 m above the origin flies z = 5 at 3 m above home.
        assert_eq!(f.alt_rel_of_z(5.0, 586.0), 3.0);
    }

    #[test]
    fn yaw_and_heading_convert_both_ways() {
        assert_eq!(heading_of_yaw(90.0), 0.0);
        assert_eq!(heading_of_yaw(0.0), 90.0);
        assert_eq!(heading_of_yaw(180.0), 270.0);
        assert_eq!(heading_of_yaw(-90.0), 180.0);
        assert_eq!(yaw_of_heading(0.0), 90.0);
        assert_eq!(yaw_of_heading(90.0), 0.0);
        assert_eq!(yaw_of_heading(270.0), 180.0);
        assert_eq!(yaw_of_heading(180.0), -90.0);
        assert_eq!(wrap_deg(540.0), 180.0);
        assert_eq!(wrap_deg(-190.0), 170.0);
    }

    fn yaw_of(q: [f32; 4]) -> f32 {
        let [x, y, z, w] = q.map(f64::from);
        let uq = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        uq.euler_angles().2.to_degrees() as f32
    }

    #[test]
    fn quaternions_turn_from_ned_to_enu() {
        // Level, facing north: yaw 90° CCW from east.
        let q = enu_quaternion([1.0, 0.0, 0.0, 0.0]);
        assert!((yaw_of(q) - 90.0).abs() < 1e-4, "{q:?}");
        // Facing east (heading 90°): yaw 0.
        let h = 45f32.to_radians();
        let q = enu_quaternion([h.cos(), 0.0, 0.0, h.sin()]);
        assert!(yaw_of(q).abs() < 1e-4, "{q:?}");
        // Facing west (heading 270°): yaw 180.
        let h = 135f32.to_radians();
        let q = enu_quaternion([h.cos(), 0.0, 0.0, h.sin()]);
        assert!((yaw_of(q).abs() - 180.0).abs() < 1e-3, "{q:?}");
        // Garbage in: identity attitude, never NaN.
        let q = enu_quaternion([f32::NAN, 0.0, 0.0, 0.0]);
        assert!(q.iter().all(|v| v.is_finite()));
        assert!((yaw_of(q) - 90.0).abs() < 1e-4);
    }

    #[test]
    fn a_nose_up_pitch_stays_nose_up() {
        // Pitch +20° (nose up) facing north, in NED: rotation about body y (right).
        let p = 10f32.to_radians();
        let q = enu_quaternion([p.cos(), 0.0, p.sin(), 0.0]);
        let [x, y, z, w] = q.map(f64::from);
        let uq = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        let forward = uq * nalgebra::Vector3::x();
        assert!(forward.z > 0.3 && forward.y > 0.9, "{forward:?}");
    }

    proptest! {
        #[test]
        fn geodetic_round_trips_within_a_millimetre(
            lat0 in -80.0f64..80.0, lon0 in -180.0f64..180.0,
            x in -10_000.0f64..10_000.0, y in -10_000.0f64..10_000.0,
        ) {
            let f = SiteFrame::new(lat0, lon0, 0.0);
            let (lat, lon) = f.to_geodetic(x, y);
            prop_assert!((-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon));
            let [x2, y2] = f.to_site_xy(lat, lon);
            prop_assert!((x2 - x).abs() < 1e-3 && (y2 - y).abs() < 1e-3, "{x},{y} → {x2},{y2}");
        }

        #[test]
        fn yaw_heading_round_trips(yaw in -180.0f32..180.0) {
            let back = yaw_of_heading(heading_of_yaw(yaw));
            prop_assert!(wrap_deg(back - yaw).abs() < 1e-3, "{yaw} → {back}");
        }
    }

    #[test]
    fn ten_km_of_equirectangular_is_close_to_the_great_circle() {
        // Haversine distance of a point 7 km east and 7 km north of the origin.
        let f = cmac();
        let (lat, lon) = f.to_geodetic(7_000.0, 7_000.0);
        let r = 6_371_008.8;
        let (p1, p2) = ((-35.363261f64).to_radians(), lat.to_radians());
        let dl = (lon - 149.165230).to_radians();
        let a = ((p2 - p1) / 2.0).sin().powi(2) + p1.cos() * p2.cos() * (dl / 2.0).sin().powi(2);
        let d = 2.0 * r * a.sqrt().asin();
        let flat = (2.0f64).sqrt() * 7_000.0;
        assert!((d - flat).abs() / flat < 0.005, "{d} vs {flat}");
    }
}
