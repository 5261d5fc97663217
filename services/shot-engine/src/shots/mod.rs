//! Shot geometry: what each Solo shot (orbit, follow, cable cam, selfie) asks of the
//! vehicle, one tick at a time.
//!
//! Pure code: no I/O, no clocks, no bus. The engine builds a [`VehicleView`] from the
//! latest `VehicleState` (and `PayloadState`), calls the active shot's `step` with the
//! tick's `dt` (and, for follow, monotonic seconds), and turns the [`Guidance`] into
//! `VehicleCommand`s: a velocity setpoint every tick, camera commands on change.
//!
//! Every shot obeys [`Limits`]: the horizontal speed never exceeds `max_speed_mps`,
//! the vertical `max_climb_mps`, and the setpoint changes by at most
//! `max_accel_mps2 · dt` per step, so a shot never asks for a jerk the vehicle cannot
//! fly (see `motion.rs`).
//!
//! Conventions: positions are geodetic ([`GeoPoint`], altitude above home), worked on
//! in a local NED frame ([`LocalFrame`]); velocities are NED m/s; angles are degrees,
//! yaw clockwise from north. A positive orbit cruise speed turns counter-clockwise
//! seen from above (the Solo app's right arrow); a positive cable speed flies
//! towards the second point. Cruise speed 0 is a pause: brake, then hold the point
//! where the vehicle stopped. The controllers assume the vehicle follows a velocity
//! setpoint within about 0.3 s (`motion::VELOCITY_LAG_S`) and prove it in
//! `sim_tests/` against a point mass with lag, the acceleration limit and late
//! telemetry.

pub mod cable;
pub mod fence;
pub mod follow;
pub mod geo;
mod line;
mod motion;
pub mod multipoint;
pub mod orbit;
pub mod pano;
pub mod rewind;
pub mod selfie;
pub mod sitescan;
pub mod spline;
pub mod zipline;

pub use cable::{CableCam, CablePoint, CABLE_MIN_LENGTH_M};
pub use fence::{
    stopping_distance, validate_zone, Fence, FenceError, FenceVerdict, FenceZone, FenceZoneError,
};
pub use follow::{Follow, FollowMode, DEFAULT_STALE_AFTER_S, MIN_FOLLOW_DISTANCE_M};
pub use geo::{bearing_deg, distance_m, ground_distance_m, offset, GeoPoint, LocalFrame};
pub use multipoint::{Multipoint, MultipointError, PlaybackEvent};
pub use orbit::{Orbit, MIN_ORBIT_RADIUS_M};
pub use pano::{Pano, PanoKind, PanoOptions, PanoPhase, PanoStation, PanoStep};
pub use rewind::{Breadcrumbs, Rewind, BREADCRUMB_CAPACITY, BREADCRUMB_SPACING_M};
pub use selfie::{Selfie, SelfiePhase};
pub use sitescan::{
    body_to_ned, photo_spacing_m, ScanConfig, SiteScanError, SiteStep, StructureScan, Survey,
    SurveyConfig, SurveyLane,
};
pub use spline::{Durations, Keypoint, SplineError, SplinePath, KEYPOINT_MIN_SPACING_M};
pub use zipline::Zipline;

/// Camera pitch above this (shallower than 60° down) cannot find the ground in a
/// useful distance: the projected ROI is then [`FAILED_ROI_DISTANCE_M`] ahead
/// (ShotManager's `SHALLOW_ANGLE_THRESHOLD`).
pub const SHALLOW_ANGLE_THRESHOLD_DEG: f32 = -60.0;

/// How far ahead along the camera yaw a shallow camera's projected ROI lies, metres
/// (ShotManager's `FAILED_ROI_DISTANCE`).
pub const FAILED_ROI_DISTANCE_M: f64 = 20.0;

/// What the engine knows about the vehicle this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleView {
    /// Position, altitude relative to home.
    pub position: GeoPoint,
    /// Velocity north, east, down, m/s.
    pub vel_ned_mps: [f32; 3],
    /// Heading, degrees 0..360.
    pub heading_deg: f32,
    /// Camera attitude: pitch (down negative, −90 straight down) and yaw in the earth
    /// frame (deg, 0..360). From PayloadState when the gimbal reports; else pitch 0 and
    /// yaw = heading.
    pub camera_pitch_deg: f32,
    /// See `camera_pitch_deg`.
    pub camera_yaw_deg: f32,
}

impl VehicleView {
    /// The view from the latest vehicle state (at `position`, already checked for
    /// freshness by the caller) and, when the gimbal reports, its attitude.
    pub fn from_samples(
        position: GeoPoint,
        state: &skymesh_ipc_types::VehicleState,
        payload: Option<&skymesh_ipc_types::PayloadState>,
    ) -> VehicleView {
        let heading = if state.heading_deg.is_finite() {
            state.heading_deg.rem_euclid(360.0)
        } else {
            0.0
        };
        let (pitch, yaw) = match payload.filter(|p| p.is_gimbal_valid()) {
            Some(p) => (
                p.gimbal_pitch_deg,
                (heading + p.gimbal_yaw_deg).rem_euclid(360.0),
            ),
            None => (0.0, heading),
        };
        VehicleView {
            position,
            vel_ned_mps: state.vel_ned_mps,
            heading_deg: heading,
            camera_pitch_deg: pitch,
            camera_yaw_deg: yaw,
        }
    }
}

/// What a shot asks for this tick. The engine turns it into VehicleCommands (a
/// VelocityNed setpoint every tick; SetRoi/ClearRoi, SetYaw and Gimbal only when they
/// change meaningfully).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guidance {
    /// Velocity setpoint, NED m/s, already within [`Limits`].
    pub velocity_ned_mps: [f32; 3],
    /// Point the camera (nose + gimbal) at this; `None` = leave the camera to
    /// `yaw_deg`/`gimbal_pitch_deg`, or to the pilot when those are `None` too.
    pub roi: Option<GeoPoint>,
    /// Vehicle (camera) yaw, degrees 0..360, earth frame.
    pub yaw_deg: Option<f32>,
    /// Gimbal pitch, degrees (down negative).
    pub gimbal_pitch_deg: Option<f32>,
}

impl Guidance {
    /// Stand still, camera left alone.
    pub const HOVER: Guidance = Guidance {
        velocity_ned_mps: [0.0; 3],
        roi: None,
        yaw_deg: None,
        gimbal_pitch_deg: None,
    };
}

/// Limits every shot obeys (from config).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Horizontal speed, m/s.
    pub max_speed_mps: f32,
    /// Acceleration: the setpoint changes by at most this × dt per step, m/s².
    pub max_accel_mps2: f32,
    /// Vertical speed (up and down), m/s.
    pub max_climb_mps: f32,
    /// Position-error gain, 1/s: metres of error → m/s of correction.
    pub position_gain: f32,
}

/// The projected ROI the spec describes (Orbit section): camera pitch > −60°
/// (shallow) → the point 20 m away along the camera yaw at the vehicle's altitude
/// (FAILED_ROI_DISTANCE); else the intersection of the camera ray with the ground
/// (alt 0). A vehicle at or below the ground projects to the point below it.
pub fn projected_roi(v: &VehicleView) -> GeoPoint {
    let pitch = if v.camera_pitch_deg.is_finite() {
        v.camera_pitch_deg
    } else {
        0.0
    };
    let yaw = f64::from(if v.camera_yaw_deg.is_finite() {
        v.camera_yaw_deg
    } else {
        v.heading_deg
    });
    let yaw = if yaw.is_finite() { yaw } else { 0.0 };
    if pitch > SHALLOW_ANGLE_THRESHOLD_DEG {
        return geo::offset(&v.position, yaw, FAILED_ROI_DISTANCE_M);
    }
    // Steeper than 60° down: the ray hits the ground alt / tan(depression) ahead.
    let alt = f64::from(v.position.alt_rel_m).max(0.0);
    let depression = f64::from(-pitch).clamp(60.0, 90.0).to_radians();
    let ahead = alt / depression.tan();
    let ground = geo::offset(&v.position, yaw, ahead);
    GeoPoint {
        alt_rel_m: 0.0,
        ..ground
    }
}

#[cfg(test)]
mod sim_tests;

#[cfg(test)]
mod tests {
    use super::*;

    const HOME: GeoPoint = GeoPoint {
        lat_deg: -35.363_261,
        lon_deg: 149.165_230,
        alt_rel_m: 10.0,
    };

    fn view(pitch: f32, yaw: f32) -> VehicleView {
        VehicleView {
            position: HOME,
            vel_ned_mps: [0.0; 3],
            heading_deg: 0.0,
            camera_pitch_deg: pitch,
            camera_yaw_deg: yaw,
        }
    }

    #[test]
    fn shallow_camera_projects_twenty_metres_ahead_along_its_yaw() {
        for (pitch, yaw) in [(0.0, 0.0), (-30.0, 90.0), (-59.9, 225.0), (15.0, 359.0)] {
            let roi = projected_roi(&view(pitch, yaw));
            assert!((ground_distance_m(&HOME, &roi) - 20.0).abs() < 0.01);
            let b = bearing_deg(&HOME, &roi);
            assert!(
                geo::wrap_180(b - f64::from(yaw)).abs() < 0.01,
                "{yaw} → {b}"
            );
            assert_eq!(roi.alt_rel_m, HOME.alt_rel_m, "at the vehicle's altitude");
        }
    }

    #[test]
    fn steep_camera_projects_onto_the_ground() {
        // Straight down from 10 m: right below.
        let roi = projected_roi(&view(-90.0, 123.0));
        assert!(ground_distance_m(&HOME, &roi) < 0.01);
        assert_eq!(roi.alt_rel_m, 0.0);
        // 60° down from 10 m: 10 / tan 60° = 5.77 m ahead.
        let roi = projected_roi(&view(-60.0, 90.0));
        assert!((ground_distance_m(&HOME, &roi) - 5.774).abs() < 0.01);
        assert!((bearing_deg(&HOME, &roi) - 90.0).abs() < 0.01);
        // 75° down: 2.68 m.
        let roi = projected_roi(&view(-75.0, 0.0));
        assert!((ground_distance_m(&HOME, &roi) - 2.679).abs() < 0.01);
        // Beyond straight down is still straight down; on the ground, right below.
        assert!(ground_distance_m(&HOME, &projected_roi(&view(-120.0, 0.0))) < 0.01);
        let landed = VehicleView {
            position: GeoPoint {
                alt_rel_m: -1.0,
                ..HOME
            },
            ..view(-80.0, 0.0)
        };
        assert!(ground_distance_m(&HOME, &projected_roi(&landed)) < 0.01);
    }

    #[test]
    fn projected_roi_survives_a_camera_without_numbers() {
        let v = VehicleView {
            heading_deg: 90.0,
            ..view(f32::NAN, f32::NAN)
        };
        let roi = projected_roi(&v);
        assert!((bearing_deg(&HOME, &roi) - 90.0).abs() < 0.01);
        assert!((ground_distance_m(&HOME, &roi) - 20.0).abs() < 0.01);
    }
}
