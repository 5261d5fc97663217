//! Rewind: breadcrumbs of the path flown, and flying back along them.
//!
//! Contract (for the engine):
//! - [`Breadcrumbs`]: call [`Breadcrumbs::record`] with the vehicle's position every
//!   tick it flies (not while rewinding); a crumb is kept each time the vehicle is
//!   `spacing_m` (3-D) from the last one kept. At most `capacity` crumbs (the oldest
//!   dropped first), so memory is bounded: [`BREADCRUMB_CAPACITY`] ×
//!   [`BREADCRUMB_SPACING_M`] = 2 km of path by default. Non-finite positions are
//!   ignored. [`Breadcrumbs::clear`] on landing, or whatever restarts the history.
//! - [`Rewind::new`]`(&crumbs, rewind_distance_m, view)` lays the path back: from the
//!   vehicle's position through the crumbs newest first, cut at `rewind_distance_m`
//!   of path (the last point interpolated), or wherever the crumbs run out.
//! - [`Rewind::step`]`(view, dt, speed, limits)` flies it at |speed| (0 = pause:
//!   hold the path point reached), slowing for corners (turn within the planning
//!   share of `max_accel`) and stopping at the end; the cross-track error is pulled
//!   back with the position gain. Camera: the pilot's (all `None`).
//! - [`Rewind::done`] once the vehicle has stopped at the end (within
//!   [`ARRIVED_M`]); then the step holds the end point. The engine then hovers or,
//!   with SOLO_REWIND_OPTIONS hover = 0, goes RTL (as the Solo does).

use std::collections::VecDeque;

use nalgebra::Vector3;

use super::geo::{distance_m, GeoPoint, LocalFrame};
use super::motion::{dt64, sqrt_controller, to_f32, toward, velocity, Lim, Shaper, VELOCITY_LAG_S};
use super::{Guidance, Limits, VehicleView};

/// Distance between crumbs, metres.
pub const BREADCRUMB_SPACING_M: f32 = 1.0;
/// Crumbs kept (the oldest dropped first).
pub const BREADCRUMB_CAPACITY: usize = 2000;
/// The end is reached this close, metres (and the vehicle slower than
/// [`STOPPED_MPS`]).
pub const ARRIVED_M: f64 = 0.5;
/// "Stopped", m/s.
pub const STOPPED_MPS: f64 = 0.3;
/// The steering chord reaches this far ahead of the path point reached (plus the
/// lag), metres.
const LOOK_AHEAD_M: f64 = 0.5;
/// Path points closer than this are merged, metres.
const MERGE_M: f64 = 0.05;

/// The recent path, oldest first.
#[derive(Debug, Clone)]
pub struct Breadcrumbs {
    points: VecDeque<GeoPoint>,
    spacing_m: f64,
    capacity: usize,
}

impl Default for Breadcrumbs {
    fn default() -> Self {
        Breadcrumbs::new(BREADCRUMB_SPACING_M, BREADCRUMB_CAPACITY)
    }
}

impl Breadcrumbs {
    /// A crumb every `spacing_m` (nonsense or below 0.1 → [`BREADCRUMB_SPACING_M`]),
    /// at most `capacity` (at least 2) kept.
    pub fn new(spacing_m: f32, capacity: usize) -> Breadcrumbs {
        let spacing = if spacing_m.is_finite() && spacing_m >= 0.1 {
            spacing_m
        } else {
            BREADCRUMB_SPACING_M
        };
        let capacity = capacity.max(2);
        Breadcrumbs {
            points: VecDeque::with_capacity(capacity.min(BREADCRUMB_CAPACITY)),
            spacing_m: f64::from(spacing),
            capacity,
        }
    }

    /// Offer the vehicle's position; true when it was kept as a crumb.
    pub fn record(&mut self, p: &GeoPoint) -> bool {
        if !(p.lat_deg.is_finite() && p.lon_deg.is_finite() && p.alt_rel_m.is_finite()) {
            return false;
        }
        if let Some(last) = self.points.back() {
            if distance_m(last, p) < self.spacing_m {
                return false;
            }
        }
        if self.points.len() >= self.capacity {
            self.points.pop_front();
        }
        self.points.push_back(*p);
        true
    }

    /// Forget the path.
    pub fn clear(&mut self) {
        self.points.clear();
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The newest crumb.
    pub fn newest(&self) -> Option<GeoPoint> {
        self.points.back().copied()
    }

    /// The crumbs, newest first.
    pub fn newest_first(&self) -> impl Iterator<Item = &GeoPoint> {
        self.points.iter().rev()
    }
}

/// Flying back along the crumbs.
#[derive(Debug, Clone)]
pub struct Rewind {
    /// NED around the vehicle's position when the rewind began.
    frame: LocalFrame,
    /// The path back, NED; the first point is where the rewind began.
    pts: Vec<Vector3<f64>>,
    /// Path length up to each point.
    cum: Vec<f64>,
    /// Progress along the path, metres (never decreases).
    s: f64,
    done: bool,
    shaper: Shaper,
}

impl Rewind {
    /// The path back from the vehicle's position through the crumbs (newest first),
    /// `rewind_distance_m` long at most (nonsense or negative → 0: hold here).
    pub fn new(crumbs: &Breadcrumbs, rewind_distance_m: f32, v: &VehicleView) -> Rewind {
        let frame = LocalFrame::new(v.position);
        let max = if rewind_distance_m.is_finite() {
            f64::from(rewind_distance_m).max(0.0)
        } else {
            0.0
        };
        let mut pts = vec![Vector3::zeros()];
        let mut cum = vec![0.0];
        for c in crumbs.newest_first() {
            let total = cum[cum.len() - 1];
            if total >= max {
                break;
            }
            let p = frame.to_ned(c);
            let last = pts[pts.len() - 1];
            let d = (p - last).norm();
            if d < MERGE_M {
                continue;
            }
            if total + d > max {
                pts.push(last + (p - last) * ((max - total) / d));
                cum.push(max);
                break;
            }
            pts.push(p);
            cum.push(total + d);
        }
        Rewind {
            frame,
            pts,
            cum,
            s: 0.0,
            done: false,
            shaper: Shaper::default(),
        }
    }

    /// Path length, metres.
    pub fn length_m(&self) -> f32 {
        self.len() as f32
    }

    fn len(&self) -> f64 {
        self.cum[self.cum.len() - 1]
    }

    /// The path back, first point where the rewind began.
    pub fn path(&self) -> Vec<GeoPoint> {
        self.pts.iter().map(|p| self.frame.to_geo(p)).collect()
    }

    /// Where the rewind ends.
    pub fn end(&self) -> GeoPoint {
        self.frame.to_geo(&self.pts[self.pts.len() - 1])
    }

    /// 0 at the start .. 1 at the end.
    pub fn progress(&self) -> f32 {
        let l = self.len();
        if l > 0.0 {
            (self.s / l).clamp(0.0, 1.0) as f32
        } else {
            1.0
        }
    }

    /// Stopped at the end.
    pub fn done(&self) -> bool {
        self.done
    }

    /// Fly back along the path at |speed| (see the module doc).
    pub fn step(&mut self, v: &VehicleView, dt_s: f32, speed: f32, lim: &Limits) -> Guidance {
        let lim = Lim::new(lim);
        let dt = dt64(dt_s);
        let pos = self.frame.to_ned(&v.position);
        let len = self.len();
        let end = self.pts[self.pts.len() - 1];
        let wish = if self.done {
            toward(&pos, &end, &lim, dt)
        } else {
            self.s = self.s.max(self.project(&pos));
            if len - self.s < ARRIVED_M
                && (pos - end).norm() < ARRIVED_M
                && velocity(v).norm() < STOPPED_MPS
            {
                self.done = true;
            }
            let commanded = self.shaper.current(v);
            self.wish(&pos, &commanded, speed, &lim, dt)
        };
        let vel = self.shaper.shape(wish, v, dt_s, &lim);
        Guidance {
            velocity_ned_mps: to_f32(&vel),
            ..Guidance::HOVER
        }
    }

    /// Index of the segment holding arc length `s` (segment i = pts[i]..pts[i+1]).
    fn segment_at(&self, s: f64) -> usize {
        let n = self.pts.len();
        if n < 2 {
            return 0;
        }
        let i = self.cum.partition_point(|&c| c <= s);
        i.saturating_sub(1).min(n - 2)
    }

    /// Arc length of the nearest path point to `pos`, searched from a metre behind
    /// the progress to a few metres ahead (a path crossing itself is not confused).
    fn project(&self, pos: &Vector3<f64>) -> f64 {
        let n = self.pts.len();
        if n < 2 {
            return 0.0;
        }
        let from = self.segment_at((self.s - 1.0).max(0.0));
        let mut best = (f64::INFINITY, self.s);
        for i in from..n - 1 {
            if self.cum[i] > self.s + 5.0 {
                break;
            }
            let (a, b) = (self.pts[i], self.pts[i + 1]);
            let seg = b - a;
            let l2 = seg.norm_squared();
            let t = if l2 > 0.0 {
                ((pos - a).dot(&seg) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = (a + seg * t - pos).norm();
            if d < best.0 {
                best = (d, self.cum[i] + t * (self.cum[i + 1] - self.cum[i]));
            }
        }
        best.1
    }

    /// Point and unit tangent at arc length `s`.
    fn at(&self, s: f64) -> (Vector3<f64>, Vector3<f64>) {
        if self.pts.len() < 2 {
            return (self.pts[0], Vector3::zeros());
        }
        let i = self.segment_at(s);
        let (a, b) = (self.pts[i], self.pts[i + 1]);
        let l = self.cum[i + 1] - self.cum[i];
        let t = if l > 0.0 {
            ((s - self.cum[i]) / l).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let dir = if l > 0.0 {
            (b - a) / l
        } else {
            Vector3::zeros()
        };
        (a + (b - a) * t, dir)
    }

    /// The fastest speed at `s` that can still slow for every corner ahead and stop
    /// at the end, braking `lead_m` early (how far the vehicle runs on while it
    /// follows a slower setpoint).
    fn speed_limit(&self, lim: &Lim, dt: f64, lead_m: f64) -> f64 {
        let a = lim.plan_accel();
        let len = self.len();
        let mut limit = sqrt_controller(len - self.s, lim.gain, a, dt);
        let horizon = lim.speed * lim.speed / (2.0 * a.max(1e-6)) + 2.0;
        let first = self.segment_at(self.s) + 1;
        for k in first..self.pts.len().saturating_sub(1) {
            let ahead = self.cum[k] - self.s;
            if ahead > horizon {
                break;
            }
            let corner = self.corner_speed(k, a);
            let room = (ahead - lead_m).max(0.0);
            limit = limit.min((corner * corner + 2.0 * a * room).sqrt());
        }
        limit
    }

    /// The speed that turns the corner at path point `k` within `accel`: the turn
    /// is read as the circle through the corner's neighbours (radius = shorter leg /
    /// (2 tan(θ/2)), θ the turn angle).
    fn corner_speed(&self, k: usize, accel: f64) -> f64 {
        let (a, b, c) = (self.pts[k - 1], self.pts[k], self.pts[k + 1]);
        let (u, w) = (b - a, c - b);
        let (lu, lw) = (u.norm(), w.norm());
        if lu <= 0.0 || lw <= 0.0 {
            return 0.0;
        }
        let cos = (u.dot(&w) / (lu * lw)).clamp(-1.0, 1.0);
        let theta = cos.acos();
        if theta < 1e-6 {
            return f64::INFINITY;
        }
        let radius = lu.min(lw) / (2.0 * (theta / 2.0).tan());
        (accel * radius).sqrt()
    }

    fn wish(
        &self,
        pos: &Vector3<f64>,
        commanded: &Vector3<f64>,
        speed: f32,
        lim: &Lim,
        dt: f64,
    ) -> Vector3<f64> {
        let (point, tangent) = self.at(self.s);
        // Steer along the chord to the path a lag ahead: a lagging vehicle starts
        // each turn when the path does instead of overshooting it.
        let lead = commanded.norm() * VELOCITY_LAG_S;
        let chord = self.at((self.s + lead + LOOK_AHEAD_M).min(self.len())).0 - point;
        let dir = if chord.norm() > 0.1 {
            chord.normalize()
        } else {
            tangent
        };
        let speed = if speed.is_finite() {
            f64::from(speed).abs()
        } else {
            0.0
        };
        let along = speed
            .min(lim.speed_along(&dir))
            .min(self.speed_limit(lim, dt, lead))
            .max(0.0);
        // Back onto the path point reached (the whole error: also holds it when
        // paused or when pushed back).
        let err = point - pos;
        let d = err.norm();
        let back = if d > 1e-9 {
            err * (sqrt_controller(d, lim.gain, lim.plan_accel(), dt) / d)
        } else {
            Vector3::zeros()
        };
        dir * along + back
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shots::geo::offset;

    const HOME: GeoPoint = GeoPoint {
        lat_deg: -35.363_261,
        lon_deg: 149.165_230,
        alt_rel_m: 10.0,
    };

    fn at(p: GeoPoint) -> VehicleView {
        VehicleView {
            position: p,
            vel_ned_mps: [0.0; 3],
            heading_deg: 0.0,
            camera_pitch_deg: 0.0,
            camera_yaw_deg: 0.0,
        }
    }

    #[test]
    fn crumbs_are_spaced_and_bounded() {
        // Spacing a hair under the metre steps, so float rounding keeps every one.
        let mut c = Breadcrumbs::new(0.99, 10);
        assert!(c.record(&HOME));
        assert!(!c.record(&offset(&HOME, 0.0, 0.5)), "too close");
        for i in 1..=30 {
            c.record(&offset(&HOME, 0.0, f64::from(i)));
        }
        assert_eq!(c.len(), 10, "oldest dropped");
        let newest = c.newest().map(|p| distance_m(&HOME, &p));
        assert!(newest.is_some_and(|d| (d - 30.0).abs() < 1e-3));
        let first = c.newest_first().nth(9).map(|p| distance_m(&HOME, p));
        assert!(first.is_some_and(|d| (d - 21.0).abs() < 1e-3), "{first:?}");
        assert!(!c.record(&GeoPoint {
            lat_deg: f64::NAN,
            ..HOME
        }));
        c.clear();
        assert!(c.is_empty());
        // Nonsense settings fall back to sane ones.
        let mut d = Breadcrumbs::new(f32::NAN, 0);
        for i in 0..5 {
            d.record(&offset(&HOME, 90.0, f64::from(i)));
        }
        assert_eq!(d.len(), 2);
    }

    #[test]
    fn the_path_back_is_cut_at_the_rewind_distance() {
        let mut c = Breadcrumbs::default();
        for i in 0..=50 {
            c.record(&offset(&HOME, 90.0, f64::from(i)));
        }
        let here = offset(&HOME, 90.0, 50.3);
        let r = Rewind::new(&c, 20.0, &at(here));
        assert!((r.length_m() - 20.0).abs() < 1e-3);
        assert!((distance_m(&r.end(), &offset(&HOME, 90.0, 30.3)) < 0.01));
        assert!(distance_m(&r.path()[0], &here) < 1e-6);
        assert_eq!(r.progress(), 0.0);
        // Longer than the crumbs: back to the oldest.
        let r = Rewind::new(&c, 500.0, &at(here));
        assert!(distance_m(&r.end(), &HOME) < 0.01);
        // No crumbs or no distance: a path of one point, flown as a hold.
        let mut r = Rewind::new(&Breadcrumbs::default(), 20.0, &at(here));
        assert_eq!(r.length_m(), 0.0);
        assert_eq!(r.progress(), 1.0);
        let lim = Limits {
            max_speed_mps: 5.0,
            max_accel_mps2: 2.5,
            max_climb_mps: 2.0,
            position_gain: 1.0,
        };
        let g = r.step(&at(here), 0.04, 3.0, &lim);
        assert_eq!(g.velocity_ned_mps, [0.0; 3]);
        assert!(r.done());
        assert_eq!(Rewind::new(&c, f32::NAN, &at(here)).length_m(), 0.0);
    }

    #[test]
    fn corners_are_taken_slower_than_straights() {
        let mut c = Breadcrumbs::default();
        // East 10 m, then north 10 m: flown back, a right angle at the middle.
        for i in 0..=10 {
            c.record(&offset(&HOME, 90.0, f64::from(i)));
        }
        let corner = offset(&HOME, 90.0, 10.0);
        for i in 1..=10 {
            c.record(&offset(&corner, 0.0, f64::from(i)));
        }
        let here = offset(&corner, 0.0, 10.0);
        let r = Rewind::new(&c, 100.0, &at(here));
        let k = r
            .pts
            .iter()
            .position(|p| (r.frame.to_geo(p).lat_deg - corner.lat_deg).abs() < 1e-9)
            .unwrap_or(0);
        assert!(k > 0);
        assert!(r.corner_speed(k, 1.5) < 1.0);
        assert!(r.corner_speed(k - 1, 1.5).is_infinite());
    }
}
