//! The DJI side of flight task progress: heights (DJI's ellipsoid heights ↔ metres
//! above home), rounding, and the planned path as the document's trajectory points.
//! The rules of the tasks themselves are the shot engine's task runner's.
//!
//! Heights: DJI sends ellipsoid heights (WGS-84); MAVLink `GoTo` takes metres above
//! home. `rel = ellipsoid − geoid_undulation − home_msl`, where `home_msl` is the
//! vehicle's home altitude above mean sea level (`VehicleStatus`, else derived from
//! `VehicleState`: `alt_msl − alt_rel`) and `geoid_undulation` the vehicle's own
//! (GPS_RAW_INT `alt_ellipsoid − alt`, `VehicleState::geoid_undulation_m`); the
//! configured `[flight] geoid_undulation_m` only while the autopilot reports none.

use std::sync::atomic::{AtomicBool, Ordering};

use dji_proto::PathPoint;
use skymesh_ipc_types::TaskPoint;

use crate::link::Snapshot;

/// Converts between DJI ellipsoid heights and heights above home.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heights {
    /// Home altitude above mean sea level, m.
    pub home_msl_m: f64,
    /// Ellipsoid − MSL, m.
    pub undulation_m: f64,
}

/// Ellipsoid − MSL where the vehicle is: the autopilot's (`alt_ellipsoid_valid`),
/// else `fallback_m` (the configured value; logged once per process).
pub fn undulation(s: &Snapshot, fallback_m: f64) -> f64 {
    static FALLBACK_LOGGED: AtomicBool = AtomicBool::new(false);
    match s.state {
        Some(v) if v.alt_ellipsoid_valid != 0 && v.geoid_undulation_m.is_finite() => {
            f64::from(v.geoid_undulation_m)
        }
        _ => {
            if !FALLBACK_LOGGED.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    geoid_undulation_m = fallback_m,
                    "the autopilot reports no ellipsoid altitude: DJI heights use the configured geoid undulation"
                );
            }
            fallback_m
        }
    }
}

impl Heights {
    /// From the latest samples; `None` without a home or a position. The undulation
    /// is the vehicle's, else `fallback_undulation_m` (see [`undulation`]).
    pub fn from_snapshot(s: &Snapshot, fallback_undulation_m: f64) -> Option<Heights> {
        let home = match (s.status, s.state) {
            (Some(st), _) if st.home_valid != 0 && st.home_alt_msl_m.is_finite() => {
                f64::from(st.home_alt_msl_m)
            }
            (_, Some(v)) if v.position_valid != 0 => {
                f64::from(v.alt_msl_m) - f64::from(v.alt_rel_m)
            }
            _ => return None,
        };
        home.is_finite().then(|| Heights {
            home_msl_m: home,
            undulation_m: undulation(s, fallback_undulation_m),
        })
    }

    pub fn rel_from_ellipsoid(&self, h: f64) -> f64 {
        h - self.undulation_m - self.home_msl_m
    }

    pub fn ellipsoid_from_rel(&self, rel: f64) -> f64 {
        rel + self.home_msl_m + self.undulation_m
    }
}

/// One decimal (the document's `step: 0.1`).
pub fn round1(x: f64) -> f64 {
    if x.is_finite() {
        (x * 10.0).round() / 10.0
    } else {
        0.0
    }
}

/// The points still to fly as the document's trajectory points (ellipsoid heights,
/// 6 decimals of a degree, 0.1 m).
pub fn path_points(points: &[TaskPoint], h: &Heights) -> Vec<PathPoint> {
    let deg6 = |x: f64| (x * 1e6).round() / 1e6;
    points
        .iter()
        .map(|p| PathPoint {
            latitude: deg6(p.lat_deg),
            longitude: deg6(p.lon_deg),
            height: round1(h.ellipsoid_from_rel(f64::from(p.alt_rel_m))),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{VehicleState, VehicleStatus};

    fn snapshot(alt_rel: f32) -> Snapshot {
        Snapshot {
            state: Some(VehicleState {
                position_valid: 1,
                lat_deg: -35.363_261,
                lon_deg: 149.165_230,
                alt_msl_m: 584.0 + alt_rel,
                alt_rel_m: alt_rel,
                position_stamp_ns: 1_000,
                ..Default::default()
            }),
            status: Some(VehicleStatus::default()),
            ..Default::default()
        }
    }

    #[test]
    fn heights_convert_between_ellipsoid_and_home_relative() {
        let mut s = snapshot(10.0);
        let h = Heights::from_snapshot(&s, 20.0).unwrap();
        assert_eq!(h.home_msl_m, 584.0, "derived from the state without a home");
        assert_eq!(h.rel_from_ellipsoid(654.0), 50.0);
        assert_eq!(h.ellipsoid_from_rel(50.0), 654.0);
        let st = s.status.as_mut().unwrap();
        st.home_valid = 1;
        st.home_alt_msl_m = 600.0;
        assert_eq!(Heights::from_snapshot(&s, 0.0).unwrap().home_msl_m, 600.0);
        assert_eq!(Heights::from_snapshot(&Snapshot::default(), 0.0), None);
        // The autopilot's undulation wins over the configured one.
        let v = s.state.as_mut().unwrap();
        v.alt_ellipsoid_valid = 1;
        v.geoid_undulation_m = 19.5;
        let h = Heights::from_snapshot(&s, 20.0).unwrap();
        assert_eq!(h.undulation_m, 19.5);
        assert_eq!(h.rel_from_ellipsoid(669.5), 50.0);
        // A flag without a value falls back.
        s.state.as_mut().unwrap().geoid_undulation_m = f32::NAN;
        assert_eq!(Heights::from_snapshot(&s, 20.0).unwrap().undulation_m, 20.0);
    }

    #[test]
    fn path_points_are_ellipsoid_heights_rounded() {
        assert_eq!(round1(12.345), 12.3);
        assert_eq!(round1(f64::INFINITY), 0.0);
        let h = Heights {
            home_msl_m: 584.0,
            undulation_m: 10.0,
        };
        let p = |lat_deg, alt_rel_m| TaskPoint {
            lat_deg,
            lon_deg: 149.165_230_4,
            alt_rel_m,
            reserved: 0,
        };
        let pts = path_points(&[p(-35.363_261_2, 30.0), p(-35.0, 0.0)], &h);
        assert_eq!(pts.len(), 2);
        assert_eq!(pts[0].height, 624.0);
        assert_eq!(pts[0].latitude, -35.363261);
        assert_eq!(pts[0].longitude, 149.16523);
        assert_eq!(pts[1].height, 594.0);
    }
}
