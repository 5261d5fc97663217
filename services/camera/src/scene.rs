//! The synthetic scene's world: where the scene origin is, how targets move, and the
//! conversion between WGS84 and the scene's local north/east metres (the local-level
//! tangent frame at the origin, [`skymesh_geo::LocalFrame`]: the geodesy vision
//! geolocates with, so the scene's truth and vision's answers agree).

use skymesh_geo::{Geodetic, LocalFrame};

use crate::render::{PlacedTarget, Shape};

/// The scene origin: local north/east metres are measured from here, and the ground
/// plane is at `ground_alt_msl_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Origin {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub ground_alt_msl_m: f64,
}

impl Origin {
    fn frame(&self) -> LocalFrame {
        LocalFrame::new(Geodetic::new(
            self.lat_deg,
            self.lon_deg,
            self.ground_alt_msl_m,
        ))
    }

    /// North, east metres of a WGS84 position.
    pub fn to_ne(&self, lat_deg: f64, lon_deg: f64) -> (f64, f64) {
        let [n, e] = self.frame().to_ne(lat_deg, lon_deg);
        (n, e)
    }

    /// The WGS84 position of local north, east metres.
    pub fn to_latlon(&self, north: f64, east: f64) -> (f64, f64) {
        self.frame().from_ne(north, east)
    }
}

/// How a target moves on the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// Clockwise seen from above (north → east), on a circle,
    /// starting at `phase_deg` (bearing from the centre).
    Circle {
        center_ne_m: [f64; 2],
        radius_m: f64,
        speed_mps: f64,
        phase_deg: f64,
    },
    /// Back and forth between two points.
    Line {
        from_ne_m: [f64; 2],
        to_ne_m: [f64; 2],
        speed_mps: f64,
    },
}

/// A configured target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetSpec {
    pub id: u32,
    pub shape: Shape,
    pub size_m: f64,
    pub rgb: [u8; 3],
    pub motion: Motion,
}

/// A target at one instant: its placement and its velocity (north, east m/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetState {
    pub placed: PlacedTarget,
    pub vel_ne: [f64; 2],
}

impl TargetSpec {
    /// Where the target is `t_s` seconds after the scene started.
    pub fn at(&self, t_s: f64) -> TargetState {
        let (n, e, vn, ve) = match self.motion {
            Motion::Circle {
                center_ne_m,
                radius_m,
                speed_mps,
                phase_deg,
            } => {
                if radius_m <= 0.0 {
                    (center_ne_m[0], center_ne_m[1], 0.0, 0.0)
                } else {
                    let w = speed_mps / radius_m;
                    let b = phase_deg.to_radians() + w * t_s;
                    (
                        center_ne_m[0] + radius_m * b.cos(),
                        center_ne_m[1] + radius_m * b.sin(),
                        -speed_mps * b.sin(),
                        speed_mps * b.cos(),
                    )
                }
            }
            Motion::Line {
                from_ne_m,
                to_ne_m,
                speed_mps,
            } => {
                let (dn, de) = (to_ne_m[0] - from_ne_m[0], to_ne_m[1] - from_ne_m[1]);
                let len = (dn * dn + de * de).sqrt();
                if len <= 0.0 || speed_mps <= 0.0 {
                    (from_ne_m[0], from_ne_m[1], 0.0, 0.0)
                } else {
                    let s = (speed_mps * t_s).rem_euclid(2.0 * len);
                    let (along, sign) = if s <= len {
                        (s, 1.0)
                    } else {
                        (2.0 * len - s, -1.0)
                    };
                    let (un, ue) = (dn / len, de / len);
                    (
                        from_ne_m[0] + un * along,
                        from_ne_m[1] + ue * along,
                        sign * speed_mps * un,
                        sign * speed_mps * ue,
                    )
                }
            }
        };
        TargetState {
            placed: PlacedTarget {
                north: n,
                east: e,
                size_m: self.size_m,
                shape: self.shape,
                rgb: self.rgb,
            },
            vel_ne: [vn, ve],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latlon_round_trips_through_local_metres() {
        let o = Origin {
            lat_deg: 47.4,
            lon_deg: 8.5,
            ground_alt_msl_m: 400.0,
        };
        let (lat, lon) = o.to_latlon(120.0, -75.0);
        let (n, e) = o.to_ne(lat, lon);
        assert!((n - 120.0).abs() < 1e-6 && (e + 75.0).abs() < 1e-6);
        // 1e-3 degree of latitude at 47.4° is 111.18 m on WGS-84 (it read 111.3 m when
        // the scene was a sphere of the equatorial radius, 0.17 % off vision's geodesy).
        let (n, _) = o.to_ne(47.401, 8.5);
        assert!((n - 111.18).abs() < 0.01, "{n}");
    }

    fn spec(motion: Motion) -> TargetSpec {
        TargetSpec {
            id: 1,
            shape: Shape::Disc,
            size_m: 2.0,
            rgb: [1, 2, 3],
            motion,
        }
    }

    #[test]
    fn targets_move_on_their_circles_and_lines() {
        let c = spec(Motion::Circle {
            center_ne_m: [10.0, 0.0],
            radius_m: 20.0,
            speed_mps: 2.0,
            phase_deg: 0.0,
        });
        let s0 = c.at(0.0);
        assert_eq!((s0.placed.north, s0.placed.east), (30.0, 0.0));
        assert!((s0.vel_ne[1] - 2.0).abs() < 1e-9);
        // A quarter turn (π·20/2 m at 2 m/s) later it is due east of the centre.
        let q = c.at(std::f64::consts::PI * 5.0);
        assert!((q.placed.north - 10.0).abs() < 1e-9 && (q.placed.east - 20.0).abs() < 1e-9);

        let l = spec(Motion::Line {
            from_ne_m: [0.0, 0.0],
            to_ne_m: [0.0, 10.0],
            speed_mps: 1.0,
        });
        assert!((l.at(4.0).placed.east - 4.0).abs() < 1e-9);
        let back = l.at(14.0);
        assert!((back.placed.east - 6.0).abs() < 1e-9 && back.vel_ne[1] < 0.0);
    }
}
