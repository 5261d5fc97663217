//! Geofence geometry: polygons in a local tangent plane, inside tests, distances
//! perpendicular to the boundary (clearance of points and segments), the distance
//! along a ray to the first boundary crossing. Pure. The velocity envelope built on
//! them is in [`super::fence_stopping`].
//!
//! **Clearance** of a point inside the fence is a lower bound of its distance to the
//! nearest point outside: the smallest distance to any keep-out's boundary, and to
//! the boundary of the keep-in that contains it (with several overlapping keep-ins,
//! the largest of those). A segment is *clear by `r`* when it starts inside and every
//! point of it has clearance ≥ `r` (so it crosses no boundary): the fence shrunk by
//! the margin is where the clearance is at least the margin.
//!
//! **Frame.** Vertices and vehicle positions are projected onto the plane tangent to
//! the WGS-84 ellipsoid at the first vertex of the first polygon (x north, y east,
//! metres; [`skymesh_geo::LocalFrame`], the workspace's one geodesy). Both go through
//! the same projection, so inside/outside is decided consistently; the tangent plane
//! shortens distances from the origin by s³/(6R²), 4 mm at 10 km. Fences are assumed
//! to be smaller than a few tens of kilometres.
//!
//! **Inside** means inside at least one keep-in polygon (if there are any), outside
//! every keep-out polygon, and `floor ≤ alt_rel ≤ ceiling`. Polygons may be convex or
//! concave, in either winding; a self-intersecting polygon is read with the even-odd
//! rule.

use nalgebra::Vector2;
use skymesh_ipc_types::{FenceError, FenceKind, GeofenceSet};

/// A point or direction in the local plane: x north, y east, metres.
pub type Ne = Vector2<f64>;

/// Shorter crossings than this are the same crossing (a ray through a vertex).
const SAME_CROSSING_M: f64 = 1e-6;

/// The tangent-plane projection around an origin (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame(skymesh_geo::LocalFrame);

impl LocalFrame {
    pub fn new(lat0_deg: f64, lon0_deg: f64) -> Self {
        LocalFrame(skymesh_geo::LocalFrame::new(skymesh_geo::Geodetic::new(
            lat0_deg, lon0_deg, 0.0,
        )))
    }

    /// Latitude/longitude in degrees → local north/east metres.
    pub fn to_local(&self, lat_deg: f64, lon_deg: f64) -> Ne {
        let [n, e] = self.0.to_ne(lat_deg, lon_deg);
        Ne::new(n, e)
    }
}

fn cross(a: Ne, b: Ne) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Squared distance from `p` to the segment `a`–`b`.
pub(super) fn point_segment_dist2(p: Ne, a: Ne, b: Ne) -> f64 {
    let e = b - a;
    let len2 = e.norm_squared();
    let u = if len2 > 0.0 {
        ((p - a).dot(&e) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + e * u - p).norm_squared()
}

/// The segments `a`–`b` and `c`–`d` cross at a point inside both.
fn segments_cross(a: Ne, b: Ne, c: Ne, d: Ne) -> bool {
    let (d1, d2) = (cross(b - a, c - a), cross(b - a, d - a));
    let (d3, d4) = (cross(d - c, a - c), cross(d - c, b - c));
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// Squared distance between the segments `a`–`b` and `c`–`d` (0 when they cross).
fn segment_dist2(a: Ne, b: Ne, c: Ne, d: Ne) -> f64 {
    if segments_cross(a, b, c, d) {
        return 0.0;
    }
    point_segment_dist2(a, c, d)
        .min(point_segment_dist2(b, c, d))
        .min(point_segment_dist2(c, a, b))
        .min(point_segment_dist2(d, a, b))
}

/// One fence polygon in the local plane.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    pub kind: FenceKind,
    pts: Vec<Ne>,
    min: Ne,
    max: Ne,
}

impl Polygon {
    pub fn new(kind: FenceKind, pts: Vec<Ne>) -> Self {
        let min = pts.iter().fold(Ne::repeat(f64::INFINITY), |m, p| m.inf(p));
        let max = pts
            .iter()
            .fold(Ne::repeat(f64::NEG_INFINITY), |m, p| m.sup(p));
        Polygon {
            kind,
            pts,
            min,
            max,
        }
    }

    /// Edges as (start, end), closing the ring.
    pub fn edges(&self) -> impl Iterator<Item = (Ne, Ne)> + '_ {
        let n = self.pts.len();
        (0..n).map(move |i| (self.pts[i], self.pts[(i + 1) % n]))
    }

    /// Even-odd crossing test (convex, concave, either winding).
    pub fn contains(&self, p: Ne) -> bool {
        if p.x < self.min.x || p.x > self.max.x || p.y < self.min.y || p.y > self.max.y {
            return false;
        }
        let mut inside = false;
        for (a, b) in self.edges() {
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
                if p.x < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Adds the distances `t > 0` at which the ray `p + t·dir` crosses an edge.
    fn ray_crossings(&self, p: Ne, dir: Ne, out: &mut Vec<f64>) {
        for (a, b) in self.edges() {
            let e = b - a;
            let denom = cross(dir, e);
            if denom.abs() < 1e-12 {
                continue; // parallel: touching along an edge changes nothing by itself
            }
            let ap = a - p;
            let t = cross(ap, e) / denom;
            let u = cross(ap, dir) / denom;
            if t > 0.0 && (0.0..=1.0).contains(&u) {
                out.push(t);
            }
        }
    }

    /// The point of the boundary nearest to `p`.
    fn nearest_boundary_point(&self, p: Ne) -> Ne {
        let mut best = (f64::INFINITY, p);
        for (a, b) in self.edges() {
            let e = b - a;
            let len2 = e.norm_squared();
            let u = if len2 > 0.0 {
                ((p - a).dot(&e) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = a + e * u;
            let d = (q - p).norm_squared();
            if d < best.0 {
                best = (d, q);
            }
        }
        best.1
    }

    /// Distance from `p` to the boundary (perpendicular to the nearest edge).
    pub fn boundary_distance(&self, p: Ne) -> f64 {
        self.edges()
            .map(|(a, b)| point_segment_dist2(p, a, b))
            .fold(f64::INFINITY, f64::min)
            .sqrt()
    }

    /// Every point of the segment `a`–`b` is at least `r` from the boundary (and so
    /// the segment crosses no edge). Edges whose bounding box is farther than `r`
    /// from the segment's are skipped without computing a distance.
    pub fn segment_clear_of_boundary(&self, a: Ne, b: Ne, r: f64) -> bool {
        let lo = a.inf(&b) - Ne::repeat(r);
        let hi = a.sup(&b) + Ne::repeat(r);
        if self.max.x < lo.x || self.min.x > hi.x || self.max.y < lo.y || self.min.y > hi.y {
            return true;
        }
        let r2 = r * r;
        self.edges().all(|(c, d)| {
            if c.x.max(d.x) < lo.x
                || c.x.min(d.x) > hi.x
                || c.y.max(d.y) < lo.y
                || c.y.min(d.y) > hi.y
            {
                return true;
            }
            if segments_cross(a, b, c, d) {
                return false;
            }
            // Touching the boundary is not clear, even for r = 0.
            let d2 = segment_dist2(a, b, c, d);
            d2 > 0.0 && d2 >= r2
        })
    }

    /// The fractions `u` in (0, 1) at which the segment `a`–`b` crosses an edge.
    fn segment_crossings(&self, a: Ne, b: Ne, out: &mut Vec<f64>) {
        let dir = b - a;
        for (c, d) in self.edges() {
            let e = d - c;
            let denom = cross(dir, e);
            if denom.abs() < 1e-12 {
                continue;
            }
            let ca = c - a;
            let t = cross(ca, e) / denom;
            let u = cross(ca, dir) / denom;
            if (0.0..=1.0).contains(&u) && t > 0.0 && t < 1.0 {
                out.push(t);
            }
        }
    }
}

/// A validated, projected geofence.
#[derive(Debug, Clone, PartialEq)]
pub struct Fence {
    pub frame: LocalFrame,
    pub polygons: Vec<Polygon>,
    pub ceiling_m: f32,
    pub floor_m: f32,
}

impl Fence {
    /// Validates and projects `set`; `Ok(None)` when it is disabled (no fence).
    pub fn compile(set: &GeofenceSet) -> Result<Option<Fence>, FenceError> {
        let rings = set.polygons()?;
        if set.enabled == 0 {
            return Ok(None);
        }
        let origin = rings.first().map_or([0.0, 0.0], |(_, v)| v[0]);
        let frame = LocalFrame::new(origin[0], origin[1]);
        let polygons = rings
            .iter()
            .map(|(kind, vertices)| {
                let pts = vertices
                    .iter()
                    .map(|[lat, lon]| frame.to_local(*lat, *lon))
                    .collect();
                Polygon::new(*kind, pts)
            })
            .collect();
        Ok(Some(Fence {
            frame,
            polygons,
            ceiling_m: set.ceiling_m,
            floor_m: set.floor_m,
        }))
    }

    fn has_keep_in(&self) -> bool {
        self.polygons.iter().any(|p| p.kind == FenceKind::KeepIn)
    }

    fn in_keep_in(&self, p: Ne) -> bool {
        !self.has_keep_in()
            || self
                .polygons
                .iter()
                .any(|poly| poly.kind == FenceKind::KeepIn && poly.contains(p))
    }

    /// Horizontally inside the envelope.
    pub fn contains(&self, p: Ne) -> bool {
        self.in_keep_in(p)
            && !self
                .polygons
                .iter()
                .any(|poly| poly.kind == FenceKind::KeepOut && poly.contains(p))
    }

    pub fn altitude_ok(&self, alt_rel_m: f32) -> bool {
        (self.floor_m..=self.ceiling_m).contains(&alt_rel_m)
    }

    /// From `p` (inside), the distance along unit `dir` to where the ray first
    /// leaves the envelope; `None` if it never does. `scratch` avoids an allocation
    /// per call.
    pub fn exit_distance(&self, p: Ne, dir: Ne, scratch: &mut Vec<f64>) -> Option<f64> {
        scratch.clear();
        for poly in &self.polygons {
            poly.ray_crossings(p, dir, scratch);
        }
        scratch.sort_unstable_by(f64::total_cmp);
        scratch.dedup_by(|later, earlier| *later - *earlier < SAME_CROSSING_M);
        // Between consecutive crossings the ray is wholly inside or wholly outside:
        // test one point per stretch, in order.
        for (i, &t) in scratch.iter().enumerate() {
            let next = scratch.get(i + 1).copied().unwrap_or(t + 1.0);
            if !self.contains(p + dir * (0.5 * (t + next))) {
                return Some(t);
            }
        }
        None
    }

    /// From `p` (outside), the unit direction to the nearest boundary point of the
    /// area it violates: the nearest keep-in when outside every keep-in, else the
    /// nearest edge of the keep-out(s) it is in. `None` if `p` is inside.
    pub fn way_back(&self, p: Ne) -> Option<Ne> {
        let violated: Vec<&Polygon> = if !self.in_keep_in(p) {
            self.polygons
                .iter()
                .filter(|poly| poly.kind == FenceKind::KeepIn)
                .collect()
        } else {
            self.polygons
                .iter()
                .filter(|poly| poly.kind == FenceKind::KeepOut && poly.contains(p))
                .collect()
        };
        let q = violated
            .iter()
            .map(|poly| poly.nearest_boundary_point(p))
            .min_by(|a, b| (a - p).norm_squared().total_cmp(&(b - p).norm_squared()))?;
        (q - p).try_normalize(1e-9)
    }

    /// Clearance of `p` (see the module doc): 0 when outside.
    pub fn clearance(&self, p: Ne) -> f64 {
        let mut keep_in: Option<f64> = None;
        let mut out = f64::INFINITY;
        for poly in &self.polygons {
            match poly.kind {
                FenceKind::KeepOut => {
                    if poly.contains(p) {
                        return 0.0;
                    }
                    out = out.min(poly.boundary_distance(p));
                }
                FenceKind::KeepIn => {
                    let c = if poly.contains(p) {
                        poly.boundary_distance(p)
                    } else {
                        0.0
                    };
                    keep_in = Some(keep_in.map_or(c, |k| k.max(c)));
                }
            }
        }
        out.min(keep_in.unwrap_or(f64::INFINITY))
    }

    /// The segment `a`–`b` is clear by `r` (see the module doc): it starts inside,
    /// stays within one keep-in that contains `a` (when there are keep-ins) and out
    /// of every keep-out, at least `r` from each of their boundaries.
    pub fn segment_clear(&self, a: Ne, b: Ne, r: f64) -> bool {
        let mut has_keep_in = false;
        let mut in_keep_in = false;
        for poly in &self.polygons {
            match poly.kind {
                FenceKind::KeepOut => {
                    if poly.contains(a) || !poly.segment_clear_of_boundary(a, b, r) {
                        return false;
                    }
                }
                FenceKind::KeepIn => {
                    has_keep_in = true;
                    in_keep_in =
                        in_keep_in || (poly.contains(a) && poly.segment_clear_of_boundary(a, b, r));
                }
            }
        }
        in_keep_in || !has_keep_in
    }

    /// The segment `a`–`b` stays at least `r` from every keep-out (and out of them).
    pub fn segment_clear_of_keep_outs(&self, a: Ne, b: Ne, r: f64) -> bool {
        self.polygons
            .iter()
            .filter(|poly| poly.kind == FenceKind::KeepOut)
            .all(|poly| !poly.contains(a) && poly.segment_clear_of_boundary(a, b, r))
    }

    /// In a keep-out.
    pub fn in_keep_out(&self, p: Ne) -> bool {
        self.polygons
            .iter()
            .any(|poly| poly.kind == FenceKind::KeepOut && poly.contains(p))
    }

    /// Adds the fractions in (0, 1) at which `a`–`b` crosses a keep-in edge.
    pub fn keep_in_crossings(&self, a: Ne, b: Ne, out: &mut Vec<f64>) {
        for poly in &self.polygons {
            if poly.kind == FenceKind::KeepIn {
                poly.segment_crossings(a, b, out);
            }
        }
    }

    /// The nearest point of any polygon's boundary to `p`, `None` without polygons.
    pub fn nearest_boundary(&self, p: Ne) -> Option<Ne> {
        self.polygons
            .iter()
            .map(|poly| poly.nearest_boundary_point(p))
            .min_by(|a, b| (a - p).norm_squared().total_cmp(&(b - p).norm_squared()))
    }
}

/// How hard the envelope brakes, from the arbiter settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// Deceleration (and acceleration) the vehicle is assumed to manage, m/s².
    pub decel_mps2: f64,
    /// Horizontal distance kept from the boundary, m.
    pub margin_m: f64,
    /// Vertical distance kept from ceiling and floor, m.
    pub vertical_margin_m: f64,
    /// Control lag: the current velocity is assumed to continue for this long (plus
    /// the position fix's age) before a new setpoint takes effect, s.
    pub response_s: f64,
}

/// A position fix older than this (s) is not trusted to move toward a boundary.
pub const MAX_FIX_AGE_S: f32 = 0.5;

/// Why a velocity was changed (formatted only when it was).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Limit {
    /// Horizontal speed cut so the stop stays the margin inside.
    Boundary {
        from: f64,
        to: f64,
    },
    /// Even a stop now would end within the margin: commanded back in.
    BackIn {
        clearance_m: f64,
    },
    /// Outside: only the component back toward the fence kept.
    Outside,
    /// The position fix is too old to move toward a boundary.
    StaleFix {
        age_s: f32,
    },
    Ceiling,
    Floor,
}

impl core::fmt::Display for Limit {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Limit::Boundary { from, to } => write!(f, "fence: {from:.1}->{to:.1} m/s"),
            Limit::BackIn { clearance_m } => {
                write!(f, "fence {clearance_m:.1} m: braking back in")
            }
            Limit::Outside => f.write_str("outside fence: only back in"),
            Limit::StaleFix { age_s } => write!(f, "fix {age_s:.1} s old: no motion to fence"),
            Limit::Ceiling => f.write_str("fence ceiling"),
            Limit::Floor => f.write_str("fence floor"),
        }
    }
}

/// Fastest speed from which the vehicle still stops within `room_m`.
pub fn stoppable(room_m: f64, decel: f64) -> f64 {
    (2.0 * decel * room_m.max(0.0)).sqrt()
}
