//! The multipoint cable cam's path: a Catmull-Rom spline through the recorded
//! keypoints, parametrised by arc length, with the speed the vehicle may fly along
//! it and the camera interpolated between keypoints.
//!
//! Contract (what `multipoint.rs` and the engine use):
//!
//! - [`SplinePath::new`]`(keypoints, limits)` builds the path through ≥ 2
//!   [`Keypoint`]s (at most [`MAX_KEYPOINTS`]; finite numbers; consecutive keypoints
//!   more than [`MIN_SEGMENT_M`] apart, else [`SplineError`]). The engine refuses a
//!   recorded keypoint closer than [`KEYPOINT_MIN_SPACING_M`] to its neighbour
//!   (SOLO_SPLINE_POINT status −2) before it gets here.
//! - Positions: `s` is metres along the path, `0..=length_m()`; `u = s / length` is
//!   the app's uPosition (`0` at keypoint 0, `1` at the last). [`SplinePath::keypoint_u`]
//!   is each keypoint's uPosition for SOLO_SPLINE_POINT in play mode.
//! - [`SplinePath::durations`] answers SOLO_SPLINE_DURATIONS: the rest-to-rest time
//!   at the fastest the profile allows, and at the minimum cruise speed.
//! - [`SplinePath::camera_at`]`(u)` → (pitch, yaw) interpolated linearly in `u`
//!   between keypoints, yaw the shorter way round.
//! - [`SplinePath::speed_limit`]`(s)` is what the controller may fly at `s`.
//!
//! Geometry: centripetal Catmull-Rom (knot spacing `|Pᵢ₊₁ − Pᵢ|^½`, Barry–Goldman),
//! which has no cusps or self-intersections within a segment, written per segment as
//! a cubic Hermite polynomial whose tangents are the global-knot derivatives, so the
//! curve is C1 in the knot parameter and its unit tangent is continuous at every
//! keypoint. The end tangents come from phantom points reflected through the ends
//! (`P₋₁ = 2P₀ − P₁`): the path leaves keypoint 0 heading at keypoint 1 and arrives
//! at the last one from the one before, and two keypoints give a straight line.
//! Worked on in a local NED frame centred on keypoint 0.
//!
//! Arc length: every segment is cut into sub-intervals about [`NODE_SPACING_M`] long
//! (at most [`MAX_NODES`] in all), each integrated with 5-point Gauss-Legendre; `s →
//! (segment, τ)` finds the sub-interval by bisection and solves the rest by Newton
//! with the same quadrature, so `position(s)` moves exactly `ds` per `ds`.
//!
//! Speed: at `s` the vehicle may fly at most `√(a_lat / κ(s))` (lateral acceleration
//! limit), the speed and climb limits along the tangent, and, between those, no
//! faster than it can still brake to them at the planning deceleration (a forward and
//! a backward pass over the nodes, each node taking the worst of the points sampled
//! around it). Durations fly that profile from rest to rest.

mod curve;
mod profile;

use super::geo::{wrap_180, wrap_360, GeoPoint, LocalFrame};
use super::Limits;
use profile::Profile;

pub use curve::Spline;
pub use profile::ProfileLimits;

/// Keypoints closer to their neighbour than this are "too close" (SOLO_SPLINE_POINT
/// status −2); metres, 3-D (ShotManager's WAYPOINT_NEARNESS_THRESHOLD).
pub const KEYPOINT_MIN_SPACING_M: f64 = 2.5;

/// Consecutive keypoints closer than this have no direction between them: the spline
/// refuses them, metres.
pub const MIN_SEGMENT_M: f64 = 0.01;

/// The most keypoints a path may have.
pub const MAX_KEYPOINTS: usize = 100;

/// Arc-length table spacing, metres (coarser for paths longer than `MAX_NODES` of
/// these).
pub const NODE_SPACING_M: f64 = 0.25;

/// The arc-length table never grows beyond this many nodes.
pub const MAX_NODES: usize = 40_000;

/// Why a path cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SplineError {
    #[error("a path needs at least 2 keypoints, got {count}")]
    TooFewKeypoints { count: usize },
    #[error("a path has at most {max} keypoints, got {count}")]
    TooManyKeypoints { count: usize, max: usize },
    #[error("keypoint {index} has a non-finite position or camera angle")]
    NonFinite { index: usize },
    #[error("keypoints {index} and {next} are only {distance_m:.3} m apart", next = index + 1)]
    Coincident { index: usize, distance_m: f64 },
}

/// One recorded keypoint: where the vehicle was and where its camera looked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keypoint {
    /// Position, altitude above home.
    pub position: GeoPoint,
    /// Camera pitch, degrees (down negative).
    pub pitch_deg: f32,
    /// Camera yaw, degrees 0..360, earth frame.
    pub yaw_deg: f32,
}

/// SOLO_SPLINE_DURATIONS: how long the whole path takes, rest to rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Durations {
    /// At the fastest the speed profile allows.
    pub min_time_s: f32,
    /// At the minimum cruise speed.
    pub max_time_s: f32,
}

/// A recorded path ready to fly: keypoints, the spline through them in a NED frame
/// at keypoint 0, and its speed profile.
#[derive(Debug, Clone)]
pub struct SplinePath {
    frame: LocalFrame,
    keypoints: Vec<Keypoint>,
    spline: Spline,
    /// Keypoint yaws unwrapped so consecutive ones differ by at most 180°.
    yaw_unwrapped: Vec<f64>,
    profile: Profile,
}

impl SplinePath {
    /// The path through `keypoints` in order, its speed profile planned with the
    /// planning share of `limits`.
    pub fn new(keypoints: &[Keypoint], limits: &Limits) -> Result<SplinePath, SplineError> {
        SplinePath::with_profile(keypoints, ProfileLimits::from_limits(limits))
    }

    /// The path with explicit profile limits.
    pub fn with_profile(
        keypoints: &[Keypoint],
        lim: ProfileLimits,
    ) -> Result<SplinePath, SplineError> {
        let Some(first) = keypoints.first() else {
            return Err(SplineError::TooFewKeypoints { count: 0 });
        };
        if let Some(index) = keypoints.iter().position(|k| {
            !(k.position.lat_deg.is_finite()
                && k.position.lon_deg.is_finite()
                && k.position.alt_rel_m.is_finite()
                && k.pitch_deg.is_finite()
                && k.yaw_deg.is_finite())
        }) {
            return Err(SplineError::NonFinite { index });
        }
        let frame = LocalFrame::new(first.position);
        let points: Vec<_> = keypoints
            .iter()
            .map(|k| frame.to_ned(&k.position))
            .collect();
        let spline = Spline::new(&points)?;
        let mut yaw_unwrapped = Vec::with_capacity(keypoints.len());
        for k in keypoints {
            let yaw = f64::from(k.yaw_deg);
            let next = match yaw_unwrapped.last() {
                Some(&prev) => {
                    // Exactly opposite turns clockwise, as the cable cam does.
                    let turn = wrap_180(yaw - prev);
                    prev + if turn == -180.0 { 180.0 } else { turn }
                }
                None => wrap_360(yaw),
            };
            yaw_unwrapped.push(next);
        }
        let profile = Profile::new(&spline, lim);
        Ok(SplinePath {
            frame,
            keypoints: keypoints.to_vec(),
            spline,
            yaw_unwrapped,
            profile,
        })
    }

    /// The keypoints, in order.
    pub fn keypoints(&self) -> &[Keypoint] {
        &self.keypoints
    }

    /// The spline, NED metres from keypoint 0.
    pub fn spline(&self) -> &Spline {
        &self.spline
    }

    /// The NED frame (origin keypoint 0).
    pub fn frame(&self) -> &LocalFrame {
        &self.frame
    }

    /// The limits the profile was planned with.
    pub fn profile_limits(&self) -> &ProfileLimits {
        self.profile.limits()
    }

    /// Path length, metres.
    pub fn length_m(&self) -> f64 {
        self.spline.length_m()
    }

    /// uPosition of keypoint `i` (0 for the first, 1 for the last); `None` past the
    /// end.
    pub fn keypoint_u(&self, i: usize) -> Option<f64> {
        if i >= self.keypoints.len() {
            return None;
        }
        if i + 1 == self.keypoints.len() {
            return Some(1.0);
        }
        Some(self.u_of_s(self.spline.keypoint_s(i)))
    }

    /// `s` → `u` (clamped to 0..=1).
    pub fn u_of_s(&self, s: f64) -> f64 {
        let l = self.length_m();
        if l > 0.0 && s.is_finite() {
            (s / l).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// `u` → `s` (clamped to the path; NaN is 0).
    pub fn s_of_u(&self, u: f64) -> f64 {
        if u.is_finite() {
            u.clamp(0.0, 1.0) * self.length_m()
        } else {
            0.0
        }
    }

    /// The geodetic point at `u`.
    pub fn position_at_u(&self, u: f64) -> GeoPoint {
        self.frame.to_geo(&self.spline.position(self.s_of_u(u)))
    }

    /// Camera (pitch, yaw) at `u`: linear in `u` between the neighbouring keypoints'
    /// recorded attitudes, yaw the shorter way round (exactly opposite: clockwise);
    /// yaw in 0..360.
    pub fn camera_at(&self, u: f64) -> (f32, f32) {
        let u = if u.is_finite() {
            u.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let n = self.keypoints.len();
        let ku = |i: usize| self.keypoint_u(i).unwrap_or(1.0);
        let mut i = 0;
        while i + 2 < n && ku(i + 1) <= u {
            i += 1;
        }
        let (u0, u1) = (ku(i), ku(i + 1));
        let f = if u1 > u0 {
            ((u - u0) / (u1 - u0)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (k0, k1) = (&self.keypoints[i], &self.keypoints[i + 1]);
        let pitch = f64::from(k0.pitch_deg) + f * f64::from(k1.pitch_deg - k0.pitch_deg);
        let (y0, y1) = (self.yaw_unwrapped[i], self.yaw_unwrapped[i + 1]);
        let yaw = wrap_360(y0 + f * (y1 - y0));
        (pitch as f32, yaw as f32)
    }

    /// The curvature limit at `s`: √(a_lat / κ(s)), m/s (infinite on a straight).
    pub fn curvature_limit(&self, s: f64) -> f64 {
        self.profile.limits().curvature(self.spline.curvature(s))
    }

    /// The speed the vehicle may fly at `s`, m/s: the acceleration-limited envelope,
    /// never above the curvature limit or the speed and climb limits at `s`.
    pub fn speed_limit(&self, s: f64) -> f64 {
        self.profile.speed_at(&self.spline, s)
    }

    /// The envelope's nodes: (s, speed).
    #[cfg(test)]
    pub(crate) fn envelope_nodes(&self) -> Vec<(f64, f64)> {
        self.profile.nodes(&self.spline)
    }

    /// The fastest the profile allows anywhere, m/s.
    pub fn max_speed_mps(&self) -> f64 {
        self.profile.max()
    }

    /// Seconds to fly the whole path from rest to rest at `cruise_mps` (the profile
    /// where slower).
    pub fn trip_time_s(&self, cruise_mps: f64) -> f64 {
        self.profile.trip_time(&self.spline, cruise_mps)
    }

    /// SOLO_SPLINE_DURATIONS: rest to rest at the fastest, and at `min_cruise_mps`.
    pub fn durations(&self, min_cruise_mps: f64) -> Durations {
        Durations {
            min_time_s: self.trip_time_s(f64::INFINITY) as f32,
            max_time_s: self.trip_time_s(min_cruise_mps) as f32,
        }
    }

    /// The cruise speed that flies the whole path in `desired_s` seconds, within
    /// `min_cruise_mps ..= the fastest` (SOLO_SPLINE_PATH_SETTINGS desiredTime).
    pub fn cruise_for_time(&self, desired_s: f64, min_cruise_mps: f64) -> f64 {
        let max = self.max_speed_mps();
        let min = if min_cruise_mps.is_finite() {
            min_cruise_mps.clamp(0.0, max)
        } else {
            0.0
        };
        if !desired_s.is_finite() || desired_s <= self.trip_time_s(max) {
            return max;
        }
        if min > 0.0 && desired_s >= self.trip_time_s(min) {
            return min;
        }
        // Trip time falls as the cruise speed rises: bisect.
        let (mut lo, mut hi) = (min, max);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if self.trip_time_s(mid) > desired_s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }
}

#[cfg(test)]
mod tests;
