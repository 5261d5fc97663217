//! The curve: centripetal Catmull-Rom segments as cubic polynomials and the
//! arc-length table over them (see the parent module for the method).

use nalgebra::Vector3;

use super::{SplineError, MAX_KEYPOINTS, MAX_NODES, MIN_SEGMENT_M, NODE_SPACING_M};

/// Centripetal parametrisation exponent.
const ALPHA: f64 = 0.5;

/// Fewest table sub-intervals per segment.
const MIN_NODES_PER_SEGMENT: usize = 8;

/// 5-point Gauss-Legendre abscissae and weights on [−1, 1].
const GL_X: [f64; 5] = [
    0.0,
    -0.538_469_310_105_683_1,
    0.538_469_310_105_683_1,
    -0.906_179_845_938_664,
    0.906_179_845_938_664,
];
const GL_W: [f64; 5] = [
    0.568_888_888_888_888_9,
    0.478_628_670_499_366_5,
    0.478_628_670_499_366_5,
    0.236_926_885_056_189_1,
    0.236_926_885_056_189_1,
];

/// One segment as `a + bτ + cτ² + dτ³`, τ ∈ [0, 1].
#[derive(Debug, Clone, Copy)]
pub(super) struct Cubic([Vector3<f64>; 4]);

impl Cubic {
    pub(super) fn pos(&self, t: f64) -> Vector3<f64> {
        let [a, b, c, d] = &self.0;
        ((d * t + c) * t + b) * t + a
    }

    pub(super) fn d1(&self, t: f64) -> Vector3<f64> {
        let [_, b, c, d] = &self.0;
        (d * (3.0 * t) + c * 2.0) * t + b
    }

    pub(super) fn d2(&self, t: f64) -> Vector3<f64> {
        let [_, _, c, d] = &self.0;
        d * (6.0 * t) + c * 2.0
    }

    /// Arc length from `a` to `b` (5-point Gauss-Legendre).
    fn arc(&self, a: f64, b: f64) -> f64 {
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        half * GL_X
            .iter()
            .zip(GL_W)
            .map(|(x, w)| w * self.d1(mid + half * x).norm())
            .sum::<f64>()
    }
}

/// An arc-length table node: segment `seg` at parameter `tau` is `s` metres along.
#[derive(Debug, Clone, Copy)]
pub(super) struct Node {
    pub(super) s: f64,
    seg: usize,
    tau: f64,
    pos: Vector3<f64>,
}

/// A centripetal Catmull-Rom spline through NED points, parametrised by arc length.
#[derive(Debug, Clone)]
pub struct Spline {
    pub(super) segs: Vec<Cubic>,
    /// Table nodes, `s` strictly increasing; a segment boundary appears once, as τ = 0
    /// of the later segment (the last node is τ = 1 of the last segment).
    pub(super) nodes: Vec<Node>,
    /// `s` of each input point.
    key_s: Vec<f64>,
    length: f64,
}

impl Spline {
    /// The spline through `points` (NED metres), in order.
    pub fn new(points: &[Vector3<f64>]) -> Result<Spline, SplineError> {
        let n = points.len();
        if n < 2 {
            return Err(SplineError::TooFewKeypoints { count: n });
        }
        if n > MAX_KEYPOINTS {
            return Err(SplineError::TooManyKeypoints {
                count: n,
                max: MAX_KEYPOINTS,
            });
        }
        if let Some(index) = points.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(SplineError::NonFinite { index });
        }
        for (index, w) in points.windows(2).enumerate() {
            let distance_m = (w[1] - w[0]).norm();
            if distance_m < MIN_SEGMENT_M {
                return Err(SplineError::Coincident { index, distance_m });
            }
        }
        let segs = hermite_segments(points);
        // Node count per segment from its length, within the overall budget.
        let approx: Vec<f64> = segs
            .iter()
            .map(|c| {
                (0..16)
                    .map(|k| c.arc(k as f64 / 16.0, (k + 1) as f64 / 16.0))
                    .sum()
            })
            .collect();
        let total: f64 = approx.iter().sum();
        let spacing = NODE_SPACING_M.max(total / (MAX_NODES - MIN_NODES_PER_SEGMENT * n) as f64);
        let mut nodes = Vec::new();
        let mut key_s = Vec::with_capacity(n);
        let mut s = 0.0;
        for (seg, c) in segs.iter().enumerate() {
            key_s.push(s);
            let count = ((approx[seg] / spacing).ceil() as usize).max(MIN_NODES_PER_SEGMENT);
            for k in 0..count {
                let tau = k as f64 / count as f64;
                nodes.push(Node {
                    s,
                    seg,
                    tau,
                    pos: c.pos(tau),
                });
                s += c.arc(tau, (k + 1) as f64 / count as f64);
            }
        }
        let last = segs.len() - 1;
        nodes.push(Node {
            s,
            seg: last,
            tau: 1.0,
            pos: segs[last].pos(1.0),
        });
        key_s.push(s);
        Ok(Spline {
            segs,
            nodes,
            key_s,
            length: s,
        })
    }

    /// Total arc length, metres.
    pub fn length_m(&self) -> f64 {
        self.length
    }

    /// How many points the spline passes through.
    pub fn keypoint_count(&self) -> usize {
        self.key_s.len()
    }

    /// Arc length at point `i` (the end for an index past it).
    pub fn keypoint_s(&self, i: usize) -> f64 {
        self.key_s.get(i).copied().unwrap_or(self.length)
    }

    /// Position at `s` (clamped to the path), NED.
    pub fn position(&self, s: f64) -> Vector3<f64> {
        let (seg, t) = self.locate(s);
        self.segs[seg].pos(t)
    }

    /// Unit tangent (direction of increasing `s`) at `s`.
    pub fn tangent(&self, s: f64) -> Vector3<f64> {
        let (seg, t) = self.locate(s);
        let d = self.segs[seg].d1(t);
        let n = d.norm();
        if n > 1e-12 {
            d / n
        } else {
            // Never for centripetal Catmull-Rom; keep a direction anyway.
            let c = self.segs[seg].pos(1.0) - self.segs[seg].pos(0.0);
            c / c.norm().max(1e-12)
        }
    }

    /// Curvature at `s`, 1/m.
    pub fn curvature(&self, s: f64) -> f64 {
        let (seg, t) = self.locate(s);
        curvature_of(&self.segs[seg], t)
    }

    /// The `s` nearest to `p`, searched within `window` (metres along, clamped to the
    /// path) or over the whole path.
    pub fn closest_s(&self, p: &Vector3<f64>, window: Option<(f64, f64)>) -> f64 {
        let (lo, hi) = match window {
            Some((a, b)) if a.is_finite() && b.is_finite() => (
                a.clamp(0.0, self.length),
                b.clamp(0.0, self.length).max(a.clamp(0.0, self.length)),
            ),
            _ => (0.0, self.length),
        };
        let first = self.node_index(lo);
        let last = (self.node_index(hi) + 1).min(self.nodes.len() - 1);
        let mut best = (f64::INFINITY, lo);
        for node in &self.nodes[first..=last] {
            let d = (node.pos - p).norm_squared();
            if d < best.0 && node.s >= lo - 1e-9 && node.s <= hi + 1e-9 {
                best = (d, node.s);
            }
        }
        for s in [lo, hi] {
            let d = (self.position(s) - p).norm_squared();
            if d < best.0 {
                best = (d, s);
            }
        }
        // Refine between the neighbouring nodes (golden section on the distance).
        let k = self.node_index(best.1);
        let a = self.nodes[k.saturating_sub(1)].s.max(lo);
        let b = self.nodes[(k + 2).min(self.nodes.len() - 1)].s.min(hi);
        let dist = |s: f64| (self.position(s) - p).norm_squared();
        let (mut a, mut b) = (a, b.max(a));
        let g = 0.5 * (5f64.sqrt() - 1.0);
        let mut c = b - g * (b - a);
        let mut d = a + g * (b - a);
        let (mut fc, mut fd) = (dist(c), dist(d));
        for _ in 0..40 {
            if fc < fd {
                b = d;
                d = c;
                fd = fc;
                c = b - g * (b - a);
                fc = dist(c);
            } else {
                a = c;
                c = d;
                fc = fd;
                d = a + g * (b - a);
                fd = dist(d);
            }
        }
        let refined = 0.5 * (a + b);
        if dist(refined) <= best.0 {
            refined
        } else {
            best.1
        }
    }

    /// Position at parameter `tau` of segment `seg` (between points `seg` and
    /// `seg + 1`).
    #[cfg(test)]
    pub(crate) fn param_position(&self, seg: usize, tau: f64) -> Vector3<f64> {
        self.segs[seg].pos(tau)
    }

    /// d position / dτ of segment `seg`.
    #[cfg(test)]
    pub(crate) fn param_derivative(&self, seg: usize, tau: f64) -> Vector3<f64> {
        self.segs[seg].d1(tau)
    }

    /// The table nodes' arc lengths.
    pub(super) fn node_s(&self) -> impl Iterator<Item = f64> + '_ {
        self.nodes.iter().map(|n| n.s)
    }

    /// Index of the last node at or before `s` (never the final node).
    pub(super) fn node_index(&self, s: f64) -> usize {
        self.nodes
            .partition_point(|n| n.s <= s)
            .saturating_sub(1)
            .min(self.nodes.len() - 2)
    }

    /// Segment and parameter range of table interval `k` (node k → k + 1).
    pub(super) fn interval(&self, k: usize) -> (usize, f64, f64) {
        let (a, b) = (&self.nodes[k], &self.nodes[k + 1]);
        let tb = if b.seg == a.seg { b.tau } else { 1.0 };
        (a.seg, a.tau, tb)
    }

    /// `s` → (segment, τ).
    pub(super) fn locate(&self, s: f64) -> (usize, f64) {
        let s = if s.is_finite() {
            s.clamp(0.0, self.length)
        } else {
            0.0
        };
        let k = self.node_index(s);
        let (seg, ta, tb) = self.interval(k);
        let (sa, sb) = (self.nodes[k].s, self.nodes[k + 1].s);
        let r = s - sa;
        if sb - sa <= 0.0 || r <= 0.0 {
            return (seg, ta);
        }
        let c = &self.segs[seg];
        let mut t = ta + (tb - ta) * (r / (sb - sa)).clamp(0.0, 1.0);
        for _ in 0..6 {
            let f = c.arc(ta, t) - r;
            let speed = c.d1(t).norm();
            if f.abs() < 1e-10 || speed <= 1e-12 {
                break;
            }
            t = (t - f / speed).clamp(ta, tb);
        }
        (seg, t)
    }
}

/// The cubic Hermite form of the centripetal Catmull-Rom through `p` (≥ 2 points,
/// consecutive ones distinct), phantom end points reflected.
fn hermite_segments(p: &[Vector3<f64>]) -> Vec<Cubic> {
    let n = p.len();
    // q: phantom, p₀ … pₙ₋₁, phantom.
    let mut q = Vec::with_capacity(n + 2);
    q.push(p[0] * 2.0 - p[1]);
    q.extend_from_slice(p);
    q.push(p[n - 1] * 2.0 - p[n - 2]);
    let mut t = vec![0.0];
    for w in q.windows(2) {
        let prev = t[t.len() - 1];
        t.push(prev + (w[1] - w[0]).norm().powf(ALPHA));
    }
    // Derivative with respect to the knot parameter at q[j], j = 1..=n.
    let m = |j: usize| -> Vector3<f64> {
        (q[j] - q[j - 1]) / (t[j] - t[j - 1]) - (q[j + 1] - q[j - 1]) / (t[j + 1] - t[j - 1])
            + (q[j + 1] - q[j]) / (t[j + 1] - t[j])
    };
    (1..n)
        .map(|j| {
            let h = t[j + 1] - t[j];
            let (p0, p1) = (q[j], q[j + 1]);
            let (m0, m1) = (m(j) * h, m(j + 1) * h);
            Cubic([
                p0,
                m0,
                p0 * -3.0 - m0 * 2.0 + p1 * 3.0 - m1,
                p0 * 2.0 + m0 - p1 * 2.0 + m1,
            ])
        })
        .collect()
}

pub(super) fn curvature_of(c: &Cubic, t: f64) -> f64 {
    let d1 = c.d1(t);
    let n = d1.norm();
    if n <= 1e-12 {
        return f64::INFINITY;
    }
    d1.cross(&c.d2(t)).norm() / (n * n * n)
}
