//! Site Scan geometry: Inspect's body-frame velocities, Scan's structure orbits and
//! Survey's lawnmower.
//!
//! Contract (for the engine):
//! - Inspect: [`body_to_ned`]`(vx, vy, vz, heading)` turns SOLO_INSPECT_MOVE_VEHICLE's
//!   body-frame velocity (x forward, y right, z down) into NED.
//! - Camera spacing: a photo `d` metres from its subject with field of view `fov`
//!   covers `2·d·tan(fov/2)`; neighbouring photos overlapping by `overlap` (0..1) are
//!   [`photo_spacing_m`] = `2·d·tan(fov/2)·(1 − overlap)` apart.
//! - Scan: [`StructureScan::new`]`(center, view, cfg)` circles `center` (its
//!   latitude/longitude; the altitude is ignored) at `cfg.radius_m` (else the
//!   vehicle's ground distance, at least [`MIN_SCAN_RADIUS_M`]) at levels from the
//!   vehicle's altitude downwards, `altitude_step_m` apart, none below
//!   `min_altitude_m` (the first level is the start altitude even when lower). At
//!   each level: move onto the circle (radially and vertically, no circling yet),
//!   then one full turn; camera on the centre at the level's altitude (horizontal
//!   view); a photo (`trigger`) at the start of the turn and every
//!   [`StructureScan::trigger_spacing_m`] of arc (= [`photo_spacing_m`] at the
//!   radius with `cfg.hfov_deg` and `cfg.overlap`). Then the next level; after the
//!   last, `done` and it holds. [`StructureScan::step`]`(view, dt, speed, limits)`:
//!   positive speed counter-clockwise seen from above (as the orbit), 0 = pause
//!   (no photo, no next phase: hold the point on the current level's circle), turns
//!   within the planning share of `max_accel`.
//! - Survey: [`Survey::new`]`(polygon, cfg)` covers the polygon (convex or concave,
//!   not self-intersecting) with lanes along `cfg.heading_deg` (None: along its
//!   longest edge) at `cfg.altitude_m` above home, camera straight down, image width
//!   across the lanes: lane spacing = `photo_spacing_m(altitude, hfov, sidelap)`,
//!   photo spacing along a lane = `photo_spacing_m(altitude, vfov, overlap)`. Each
//!   lane owns the strip of ± spacing/2 around it and runs over every part of the
//!   polygon within that strip (so every point of the polygon is within spacing/2 of a
//!   lane); a lane over a concave polygon is split where the strip leaves it. Lanes
//!   are flown nearest end first (from the first lane on one side: boustrophedon on a
//!   convex polygon, one lobe after the other on a concave one; the transit between
//!   lobes is a straight line and may cross outside the polygon). Photos at each lane's
//!   start, every photo spacing, and at its end when the last was more than half a
//!   spacing before. Those lanes may reach up to spacing/2 outside the polygon where
//!   an edge is slanted to them: a polygon inside a keep-in fence needs that much
//!   room, or [`Survey::new_within`] (each lane its own line clipped to the polygon:
//!   no lane outside it — the transit between lobes of a concave polygon may be —
//!   covering spacing/2 across the lanes only).
//!   [`Survey::step`]`(view, dt, speed, limits)` flies to the first lane,
//!   then lane by lane (stopping at each end), camera pitch −90; `done` after the last
//!   lane, then it holds. [`Survey::lanes`] lists the lanes in flying order.
//! - Both report `progress` 0..1 (turns / lane length flown).

mod lanes;
mod scan;
mod survey;

use super::Guidance;

pub use scan::{ScanConfig, StructureScan, MAX_SCAN_LEVELS, MIN_SCAN_RADIUS_M};
pub use survey::{Survey, SurveyConfig, SurveyLane, MAX_SURVEY_LANES};

/// On station (circle radius, altitude, lane start) this close, metres.
const ON_STATION_M: f64 = 1.0;

/// Body-frame velocity (x forward, y right, z down; m/s) → NED with the vehicle's
/// heading (degrees). A heading without a number counts as north.
pub fn body_to_ned(vx: f32, vy: f32, vz: f32, heading_deg: f32) -> [f32; 3] {
    let h = if heading_deg.is_finite() {
        f64::from(heading_deg).to_radians()
    } else {
        0.0
    };
    let (s, c) = h.sin_cos();
    let (x, y) = (f64::from(vx), f64::from(vy));
    [(x * c - y * s) as f32, (x * s + y * c) as f32, vz]
}

/// Distance between photos `distance_m` from their subject with field of view
/// `fov_deg` overlapping by `overlap` (0..1): `2·d·tan(fov/2)·(1 − overlap)`.
pub fn photo_spacing_m(distance_m: f64, fov_deg: f64, overlap: f64) -> f64 {
    2.0 * distance_m * (fov_deg.to_radians() / 2.0).tan() * (1.0 - overlap)
}

/// Why a scan or survey cannot be flown.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SiteScanError {
    #[error("{what} = {value} is out of range")]
    Config { what: &'static str, value: f32 },
    #[error("the survey polygon has {0} vertices; it needs at least 3")]
    TooFewVertices(usize),
    #[error("the survey polygon has a vertex without finite coordinates")]
    BadCoordinate,
    #[error("the survey polygon crosses itself or has no area")]
    BadPolygon,
    #[error("{count} {what} exceed the most flown ({max})")]
    TooLarge {
        what: &'static str,
        count: usize,
        max: usize,
    },
}

fn check(what: &'static str, value: f32, ok: impl Fn(f32) -> bool) -> Result<f64, SiteScanError> {
    if value.is_finite() && ok(value) {
        Ok(f64::from(value))
    } else {
        Err(SiteScanError::Config { what, value })
    }
}

/// What a site-scan step asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteStep {
    pub guidance: Guidance,
    /// Take a photo now.
    pub trigger: bool,
    /// 0..1.
    pub progress: f32,
    /// Finished (holding).
    pub done: bool,
}
