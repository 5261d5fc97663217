//! The speed profile: pointwise limits (curvature, speed, climb) sampled over the
//! arc-length table, made acceleration-limited both ways.

use nalgebra::Vector3;

use super::curve::{curvature_of, Spline};
use crate::shots::motion::Lim;
use crate::shots::Limits;

/// Curvature samples inside each table sub-interval (besides its ends).
const INTERIOR_SAMPLES: usize = 3;

/// The limits a speed profile plans with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileLimits {
    /// Horizontal speed, m/s.
    pub speed_mps: f64,
    /// Vertical speed, m/s.
    pub climb_mps: f64,
    /// Lateral acceleration in turns: v ≤ √(a_lat / κ), m/s².
    pub lateral_accel_mps2: f64,
    /// Acceleration and braking along the path, m/s².
    pub accel_mps2: f64,
}

impl ProfileLimits {
    /// The shot limits' planning share (what every shot turns and brakes with).
    pub fn from_limits(l: &Limits) -> ProfileLimits {
        let lim = Lim::new(l);
        ProfileLimits {
            speed_mps: lim.speed,
            climb_mps: lim.climb,
            lateral_accel_mps2: lim.plan_accel(),
            accel_mps2: lim.plan_accel(),
        }
    }

    /// The largest speed along unit direction `t` within the speed and climb limits.
    pub(super) fn along(&self, t: &Vector3<f64>) -> f64 {
        let h = t.x.hypot(t.y);
        let mut v = f64::INFINITY;
        if h > 1e-9 {
            v = v.min(self.speed_mps / h);
        }
        if t.z.abs() > 1e-9 {
            v = v.min(self.climb_mps / t.z.abs());
        }
        if v.is_finite() {
            v
        } else {
            0.0
        }
    }

    /// The pointwise limit for tangent `t` and curvature `k`.
    pub(super) fn pointwise(&self, t: &Vector3<f64>, k: f64) -> f64 {
        self.along(t).min(self.curvature(k))
    }

    pub(super) fn curvature(&self, k: f64) -> f64 {
        if k > 0.0 {
            (self.lateral_accel_mps2.max(0.0) / k).sqrt()
        } else {
            f64::INFINITY
        }
    }
}

/// The speed envelope over a spline's table nodes.
#[derive(Debug, Clone)]
pub(super) struct Profile {
    lim: ProfileLimits,
    /// Speed at each table node, m/s (acceleration-limited both ways).
    v: Vec<f64>,
}

impl Profile {
    pub(super) fn new(sp: &Spline, lim: ProfileLimits) -> Profile {
        Profile {
            v: envelope(sp, &lim),
            lim,
        }
    }

    pub(super) fn limits(&self) -> &ProfileLimits {
        &self.lim
    }

    /// The envelope interpolated at `s`, never above the pointwise limit there.
    pub(super) fn speed_at(&self, sp: &Spline, s: f64) -> f64 {
        let s = if s.is_finite() {
            s.clamp(0.0, sp.length_m())
        } else {
            0.0
        };
        let k = sp.node_index(s);
        let (sa, sb) = (sp.nodes[k].s, sp.nodes[k + 1].s);
        let f = if sb > sa { (s - sa) / (sb - sa) } else { 0.0 };
        // v² is linear in s under constant acceleration.
        let (va, vb) = (self.v[k], self.v[k + 1]);
        let table = (va * va + f * (vb * vb - va * va)).max(0.0).sqrt();
        let (seg, t) = sp.locate(s);
        let c = &sp.segs[seg];
        let d = c.d1(t);
        table.min(
            self.lim
                .pointwise(&(d / d.norm().max(1e-12)), curvature_of(c, t)),
        )
    }

    /// The fastest anywhere, m/s.
    pub(super) fn max(&self) -> f64 {
        self.v.iter().copied().fold(0.0, f64::max)
    }

    /// Rest to rest at `cruise` (the envelope where slower), seconds.
    pub(super) fn trip_time(&self, sp: &Spline, cruise: f64) -> f64 {
        let cruise = if cruise.is_nan() {
            0.0
        } else {
            cruise.max(0.0)
        };
        let s: Vec<f64> = sp.node_s().collect();
        let mut v: Vec<f64> = self.v.iter().map(|e| e.min(cruise)).collect();
        let last = v.len() - 1;
        v[0] = 0.0;
        v[last] = 0.0;
        accel_passes(&s, &mut v, self.lim.accel_mps2);
        // Constant acceleration between nodes: Δt = 2·Δs / (v₀ + v₁).
        s.windows(2)
            .zip(v.windows(2))
            .map(|(s, v)| 2.0 * (s[1] - s[0]) / (v[0] + v[1]).max(1e-9))
            .sum()
    }

    #[cfg(test)]
    pub(super) fn nodes(&self, sp: &Spline) -> Vec<(f64, f64)> {
        sp.node_s().zip(self.v.iter().copied()).collect()
    }
}

/// The speed envelope at every node: the worst pointwise limit around it, then
/// acceleration-limited both ways.
fn envelope(sp: &Spline, lim: &ProfileLimits) -> Vec<f64> {
    let n = sp.nodes.len();
    // Worst limit over each interval (its ends and interior samples).
    let interval: Vec<f64> = (0..n - 1)
        .map(|k| {
            let (seg, ta, tb) = sp.interval(k);
            let c = &sp.segs[seg];
            (0..=INTERIOR_SAMPLES + 1)
                .map(|i| {
                    let t = ta + (tb - ta) * i as f64 / (INTERIOR_SAMPLES + 1) as f64;
                    let d = c.d1(t);
                    lim.pointwise(&(d / d.norm().max(1e-12)), curvature_of(c, t))
                })
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let mut v: Vec<f64> = (0..n)
        .map(|k| {
            let before = if k > 0 {
                interval[k - 1]
            } else {
                f64::INFINITY
            };
            let after = interval.get(k).copied().unwrap_or(f64::INFINITY);
            let v = before.min(after);
            if v.is_finite() {
                v
            } else {
                0.0
            }
        })
        .collect();
    let s: Vec<f64> = sp.node_s().collect();
    accel_passes(&s, &mut v, lim.accel_mps2);
    v
}

/// Limit `v` so that v² changes by at most 2·a·Δs between nodes, both ways.
fn accel_passes(s: &[f64], v: &mut [f64], accel: f64) {
    let a = accel.max(0.0);
    for k in 1..v.len() {
        let reach = (v[k - 1] * v[k - 1] + 2.0 * a * (s[k] - s[k - 1])).sqrt();
        v[k] = v[k].min(reach);
    }
    for k in (0..v.len().saturating_sub(1)).rev() {
        let reach = (v[k + 1] * v[k + 1] + 2.0 * a * (s[k + 1] - s[k])).sqrt();
        v[k] = v[k].min(reach);
    }
}
