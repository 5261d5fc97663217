//! The app's geofence, checked ahead of the vehicle every tick.
//!
//! Contract (for the engine):
//! - A [`Fence`] is a list of [`FenceZone`]s, each a keep-in (app `type` 0,
//!   "inclusive") or keep-out (`type` 1, "exclusive") polygon (`coord`) with its
//!   sub-polygon (`subCoord`): for a keep-in the inner line where the vehicle is held
//!   after a breach, for a keep-out the outer one. Vertices are `[lat, lon]` degrees,
//!   implicitly closed, either winding. [`Fence::new`] validates every zone
//!   ([`validate_zone`]): ≥ 3 vertices, as many sub-polygon vertices as polygon
//!   vertices, finite coordinates within ±90°/±180°, and neither ring
//!   self-intersecting (no two non-adjacent edges touch, no zero-length edge, non-zero
//!   area). Edits (GEOFENCE_UPDATE_POLY) are made on [`Fence::zones`] and
//!   re-validated through [`Fence::new`].
//! - Allowed = inside at least one keep-in polygon (when there is any), outside every
//!   keep-out polygon (the arbiter's rule for `GeofenceSet`); a point on an edge is
//!   inside. Only horizontal: the Solo fence has no floor or ceiling.
//!   [`Fence::contains`] answers it for a point.
//! - [`Fence::check`]`(view, stopping_distance_m, latency_s)`: the vehicle's
//!   predicted path is the straight segment from its position to position +
//!   velocity·latency + `stopping_distance_m` along the horizontal velocity (a
//!   vehicle slower than 1 cm/s is only checked where it is). If any part of that
//!   segment is not allowed (exact: every edge crossing is found), the verdict is
//!   [`FenceVerdict::Breach`] with the zone responsible for the first part not
//!   allowed — the keep-out entered, or for leaving the keep-in area the keep-in that
//!   holds the vehicle now (else the nearest) — and the `hold_point`: the point of
//!   that zone's sub-polygon nearest the first position not allowed (for a keep-in
//!   the nearest point inside the sub-polygon, on its edge when outside it; for a
//!   keep-out the nearest point outside the sub-polygon, on its edge). When that
//!   point is itself not allowed (a sub-polygon drawn on the wrong side), the hold
//!   point is the nearest point on the zone's own edge moved [`HOLD_MARGIN_M`] to its
//!   safe side. The hold point has the vehicle's altitude; it is judged against its
//!   own zone only (overlapping zones are the app's to avoid). A vehicle already outside
//!   the allowed area is a breach too (so a pilot pushing out again re-asserts it).
//! - [`stopping_distance`]`(speed, max_accel)` = speed² / (2·max_accel), the
//!   distance the engine passes in.
//! - Geometry runs in a flat local frame at the first vertex of the first zone
//!   (`geo::LocalFrame`: centimetres over a few kilometres).

use nalgebra::{Vector2, Vector3};
use skymesh_ipc_types::FenceKind;

use super::geo::{GeoPoint, LocalFrame};
use super::VehicleView;

/// How far inside the safe side of a zone's edge the fallback hold point lies, m.
pub const HOLD_MARGIN_M: f64 = 2.0;
/// Below this horizontal speed the vehicle is checked only where it is, m/s.
const MOVING_MPS: f64 = 0.01;
/// Deceleration assumed when the given one is nonsense, m/s² (conservative).
const FALLBACK_ACCEL_MPS2: f64 = 1.0;

type Ne = Vector2<f64>;

/// One polygon of the app's fence and its sub-polygon.
#[derive(Debug, Clone, PartialEq)]
pub struct FenceZone {
    pub kind: FenceKind,
    /// The fence (`coord`): `[lat, lon]` degrees.
    pub polygon: Vec<[f64; 2]>,
    /// The hold line (`subCoord`): `[lat, lon]` degrees.
    pub sub_polygon: Vec<[f64; 2]>,
}

impl FenceZone {
    /// A zone from the app's `type` (0 keep-in, 1 keep-out) and rings; not yet
    /// validated (see [`validate_zone`]).
    pub fn from_app(
        kind: u8,
        polygon: &[[f64; 2]],
        sub_polygon: &[[f64; 2]],
    ) -> Result<FenceZone, FenceZoneError> {
        let kind = FenceKind::try_from(kind).map_err(|_| FenceZoneError::UnknownType(kind))?;
        Ok(FenceZone {
            kind,
            polygon: polygon.to_vec(),
            sub_polygon: sub_polygon.to_vec(),
        })
    }
}

/// Why a zone is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FenceZoneError {
    #[error("polygon type {0} is neither 0 (keep-in) nor 1 (keep-out)")]
    UnknownType(u8),
    #[error("{count} vertices; a polygon needs at least 3")]
    TooFewVertices { count: usize },
    #[error("{polygon} polygon vertices but {sub} sub-polygon vertices")]
    CountMismatch { polygon: usize, sub: usize },
    #[error("a coordinate is not a finite latitude/longitude")]
    BadCoordinate,
    #[error("the {} crosses itself or has a zero-length edge", ring_name(*.sub))]
    SelfIntersecting { sub: bool },
    #[error("the {} has no area", ring_name(*.sub))]
    NoArea { sub: bool },
}

fn ring_name(sub: bool) -> &'static str {
    if sub {
        "sub-polygon"
    } else {
        "polygon"
    }
}

/// Why a fence is refused: the first bad zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("fence polygon {zone}: {error}")]
pub struct FenceError {
    /// Index of the zone, in the order given.
    pub zone: usize,
    pub error: FenceZoneError,
}

/// The outcome of a predictive check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FenceVerdict {
    /// The predicted path stays allowed.
    Clear,
    /// It would not: hold at `hold_point`.
    Breach {
        /// Index of the zone responsible.
        polygon: usize,
        kind: FenceKind,
        hold_point: GeoPoint,
    },
}

/// A zone in the local frame.
#[derive(Debug, Clone)]
struct Local {
    kind: FenceKind,
    ring: Vec<Ne>,
    sub: Vec<Ne>,
}

/// A validated fence (possibly empty: everything allowed).
#[derive(Debug, Clone)]
pub struct Fence {
    zones: Vec<FenceZone>,
    frame: LocalFrame,
    local: Vec<Local>,
}

impl Default for Fence {
    fn default() -> Self {
        Fence::empty()
    }
}

impl Fence {
    /// No fence.
    pub fn empty() -> Fence {
        Fence {
            zones: Vec::new(),
            frame: LocalFrame::new(GeoPoint {
                lat_deg: 0.0,
                lon_deg: 0.0,
                alt_rel_m: 0.0,
            }),
            local: Vec::new(),
        }
    }

    /// Validate every zone (see [`validate_zone`]) and build the fence.
    pub fn new(zones: Vec<FenceZone>) -> Result<Fence, FenceError> {
        for (zone, z) in zones.iter().enumerate() {
            validate_zone(z).map_err(|error| FenceError { zone, error })?;
        }
        let Some(first) = zones.first().and_then(|z| z.polygon.first()) else {
            return Ok(Fence::empty());
        };
        let frame = LocalFrame::new(GeoPoint {
            lat_deg: first[0],
            lon_deg: first[1],
            alt_rel_m: 0.0,
        });
        let local = zones
            .iter()
            .map(|z| Local {
                kind: z.kind,
                ring: to_local(&frame, &z.polygon),
                sub: to_local(&frame, &z.sub_polygon),
            })
            .collect();
        Ok(Fence {
            zones,
            frame,
            local,
        })
    }

    /// The zones, as given.
    pub fn zones(&self) -> &[FenceZone] {
        &self.zones
    }

    pub fn is_empty(&self) -> bool {
        self.zones.is_empty()
    }

    pub fn len(&self) -> usize {
        self.zones.len()
    }

    /// Whether `p` is allowed (altitude ignored).
    pub fn contains(&self, p: &GeoPoint) -> bool {
        self.allowed(&self.ne(p))
    }

    /// The predictive check (see the module doc).
    pub fn check(&self, v: &VehicleView, stopping_distance_m: f64, latency_s: f64) -> FenceVerdict {
        if self.local.is_empty() {
            return FenceVerdict::Clear;
        }
        let pos = self.ne(&v.position);
        let c = |x: f32| if x.is_finite() { f64::from(x) } else { 0.0 };
        let vel = Ne::new(c(v.vel_ned_mps[0]), c(v.vel_ned_mps[1]));
        let speed = vel.norm();
        let pred = if speed > MOVING_MPS {
            let lat = if latency_s.is_finite() {
                latency_s.max(0.0)
            } else {
                0.0
            };
            let stop = if stopping_distance_m.is_finite() {
                stopping_distance_m.max(0.0)
            } else {
                0.0
            };
            pos + vel * lat + vel * (stop / speed)
        } else {
            pos
        };
        let Some(bad) = self.first_not_allowed(&pos, &pred) else {
            return FenceVerdict::Clear;
        };
        let polygon = self.responsible(&pos, &bad);
        let hold = self.hold_point(polygon, &bad);
        let mut hold_point = self.frame.to_geo(&Vector3::new(hold.x, hold.y, 0.0));
        hold_point.alt_rel_m = v.position.alt_rel_m;
        FenceVerdict::Breach {
            polygon,
            kind: self.local[polygon].kind,
            hold_point,
        }
    }

    fn ne(&self, p: &GeoPoint) -> Ne {
        let v = self.frame.to_ned(p);
        Ne::new(v.x, v.y)
    }

    fn allowed(&self, p: &Ne) -> bool {
        let mut any_in = false;
        let mut in_some = false;
        for z in &self.local {
            let inside = contains(&z.ring, p);
            match z.kind {
                FenceKind::KeepOut if inside => return false,
                FenceKind::KeepOut => {}
                FenceKind::KeepIn => {
                    any_in = true;
                    in_some |= inside;
                }
            }
        }
        !any_in || in_some
    }

    /// The first point of the segment `a → b` that is not allowed, if any: the
    /// segment is cut at every edge crossing and each piece judged at its middle
    /// (and its ends).
    fn first_not_allowed(&self, a: &Ne, b: &Ne) -> Option<Ne> {
        if !self.allowed(a) {
            return Some(*a);
        }
        let mut ts = vec![0.0, 1.0];
        if (b - a).norm() > 0.0 {
            for z in &self.local {
                for (p, q) in edges(&z.ring) {
                    if let Some(t) = crossing(a, b, &p, &q) {
                        ts.push(t);
                    }
                }
            }
        }
        ts.sort_by(f64::total_cmp);
        ts.dedup();
        for w in ts.windows(2) {
            let at = |t: f64| a + (b - a) * t;
            if !self.allowed(&at((w[0] + w[1]) / 2.0)) {
                // The piece begins on the edge crossed: a keep-out's edge is already
                // not allowed; past a keep-in's edge, a millimetre on.
                let start = at(w[0]);
                return Some(if self.allowed(&start) {
                    start + (b - a).normalize() * 1e-3
                } else {
                    start
                });
            }
            if !self.allowed(&at(w[1])) {
                return Some(at(w[1]));
            }
        }
        None
    }

    /// The zone that makes `bad` not allowed: a keep-out holding it, else the keep-in
    /// holding the vehicle now, else the keep-in nearest to it.
    fn responsible(&self, pos: &Ne, bad: &Ne) -> usize {
        if let Some(i) = self
            .local
            .iter()
            .position(|z| z.kind == FenceKind::KeepOut && contains(&z.ring, bad))
        {
            return i;
        }
        let keep_in = || {
            self.local
                .iter()
                .enumerate()
                .filter(|(_, z)| z.kind == FenceKind::KeepIn)
        };
        if let Some((i, _)) = keep_in().find(|(_, z)| contains(&z.ring, pos)) {
            return i;
        }
        keep_in()
            .map(|(i, z)| (i, (nearest_on_ring(&z.ring, pos) - pos).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(0, |(i, _)| i)
    }

    /// Where to hold after zone `i` was breached at `bad` (see the module doc).
    fn hold_point(&self, i: usize, bad: &Ne) -> Ne {
        let z = &self.local[i];
        let inside_sub = contains(&z.sub, bad);
        let on_sub = match z.kind {
            FenceKind::KeepIn if inside_sub => *bad,
            _ => nearest_on_ring(&z.sub, bad),
        };
        let zone_ok = |p: &Ne| match z.kind {
            FenceKind::KeepIn => contains(&z.ring, p),
            FenceKind::KeepOut => !contains(&z.ring, p),
        };
        if zone_ok(&on_sub) {
            return on_sub;
        }
        // The sub-polygon is on the wrong side: off the zone's own edge.
        let (edge, foot) = nearest_edge(&z.ring, bad);
        let (p, q) = edge;
        let d = q - p;
        let n = Ne::new(-d.y, d.x) / d.norm().max(1e-12);
        let a = foot + n * HOLD_MARGIN_M;
        if zone_ok(&a) {
            a
        } else {
            foot - n * HOLD_MARGIN_M
        }
    }
}

/// speed² / (2·max_accel), metres; a nonsense acceleration counts as 1 m/s².
pub fn stopping_distance(speed_mps: f64, max_accel_mps2: f64) -> f64 {
    let a = if max_accel_mps2.is_finite() && max_accel_mps2 > 0.0 {
        max_accel_mps2
    } else {
        FALLBACK_ACCEL_MPS2
    };
    let v = if speed_mps.is_finite() {
        speed_mps
    } else {
        0.0
    };
    v * v / (2.0 * a)
}

/// The checks [`Fence::new`] makes of each zone (see the module doc).
pub fn validate_zone(z: &FenceZone) -> Result<(), FenceZoneError> {
    let n = z.polygon.len();
    if n < 3 {
        return Err(FenceZoneError::TooFewVertices { count: n });
    }
    if z.sub_polygon.len() != n {
        return Err(FenceZoneError::CountMismatch {
            polygon: n,
            sub: z.sub_polygon.len(),
        });
    }
    let good = |p: &[f64; 2]| {
        p[0].is_finite() && p[1].is_finite() && p[0].abs() <= 90.0 && p[1].abs() <= 180.0
    };
    if !z.polygon.iter().chain(&z.sub_polygon).all(good) {
        return Err(FenceZoneError::BadCoordinate);
    }
    let frame = LocalFrame::new(GeoPoint {
        lat_deg: z.polygon[0][0],
        lon_deg: z.polygon[0][1],
        alt_rel_m: 0.0,
    });
    for (ring, sub) in [(&z.polygon, false), (&z.sub_polygon, true)] {
        let pts = to_local(&frame, ring);
        if self_intersecting(&pts) {
            return Err(FenceZoneError::SelfIntersecting { sub });
        }
        if area(&pts).abs() < 1e-6 {
            return Err(FenceZoneError::NoArea { sub });
        }
    }
    Ok(())
}

fn to_local(frame: &LocalFrame, ring: &[[f64; 2]]) -> Vec<Ne> {
    ring.iter()
        .map(|p| {
            let v = frame.to_ned(&GeoPoint {
                lat_deg: p[0],
                lon_deg: p[1],
                alt_rel_m: 0.0,
            });
            Ne::new(v.x, v.y)
        })
        .collect()
}

/// The ring's edges, closing one included.
fn edges(ring: &[Ne]) -> impl Iterator<Item = (Ne, Ne)> + '_ {
    (0..ring.len()).map(move |i| (ring[i], ring[(i + 1) % ring.len()]))
}

fn cross(a: &Ne, b: &Ne) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Signed area (shoelace).
pub(crate) fn area(ring: &[Ne]) -> f64 {
    edges(ring).map(|(p, q)| cross(&p, &q)).sum::<f64>() / 2.0
}

/// Inside or on the edge of `ring` (even-odd).
pub(crate) fn contains(ring: &[Ne], p: &Ne) -> bool {
    let mut inside = false;
    for (a, b) in edges(ring) {
        if on_segment(&a, &b, p) {
            return true;
        }
        if (a.y > p.y) != (b.y > p.y) {
            let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
            if p.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

fn on_segment(a: &Ne, b: &Ne, p: &Ne) -> bool {
    let d = b - a;
    let l = d.norm();
    if l < 1e-12 {
        return (p - a).norm() < 1e-9;
    }
    (cross(&d, &(p - a)) / l).abs() < 1e-9 && {
        let t = (p - a).dot(&d) / (l * l);
        (-1e-12..=1.0 + 1e-12).contains(&t)
    }
}

/// Where along `a → b` (0..=1) it meets segment `p → q`, if it does (parallel
/// overlaps are not crossings: the pieces' middles decide).
fn crossing(a: &Ne, b: &Ne, p: &Ne, q: &Ne) -> Option<f64> {
    let r = b - a;
    let s = q - p;
    let den = cross(&r, &s);
    if den.abs() < 1e-12 {
        return None;
    }
    let t = cross(&(p - a), &s) / den;
    let u = cross(&(p - a), &r) / den;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some(t)
}

/// Whether two closed segments share a point.
fn segments_touch(a: &Ne, b: &Ne, p: &Ne, q: &Ne) -> bool {
    let d1 = cross(&(b - a), &(p - a));
    let d2 = cross(&(b - a), &(q - a));
    let d3 = cross(&(q - p), &(a - p));
    let d4 = cross(&(q - p), &(b - p));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    on_segment(a, b, p) || on_segment(a, b, q) || on_segment(p, q, a) || on_segment(p, q, b)
}

/// Zero-length edges, or two non-adjacent edges that touch.
pub(crate) fn self_intersecting(ring: &[Ne]) -> bool {
    let n = ring.len();
    let e: Vec<(Ne, Ne)> = edges(ring).collect();
    if e.iter().any(|(p, q)| (q - p).norm() < 1e-6) {
        return true;
    }
    for i in 0..n {
        for j in i + 1..n {
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            if adjacent {
                // Adjacent edges share one vertex; they must not fold back onto
                // each other.
                let (a, b) = e[i];
                let (p, q) = e[j];
                let (shared, x, y) = if j == i + 1 { (b, a, q) } else { (a, b, p) };
                let (u, w) = (x - shared, y - shared);
                if cross(&u, &w).abs() < 1e-9 && u.dot(&w) > 0.0 {
                    return true;
                }
                continue;
            }
            if segments_touch(&e[i].0, &e[i].1, &e[j].0, &e[j].1) {
                return true;
            }
        }
    }
    false
}

/// The nearest point to `p` on segment `a → b`.
fn nearest_on_segment(a: &Ne, b: &Ne, p: &Ne) -> Ne {
    let d = b - a;
    let l2 = d.norm_squared();
    if l2 <= 0.0 {
        return *a;
    }
    a + d * ((p - a).dot(&d) / l2).clamp(0.0, 1.0)
}

/// The nearest edge of `ring` to `p`, and the nearest point on it.
fn nearest_edge(ring: &[Ne], p: &Ne) -> ((Ne, Ne), Ne) {
    let mut best = ((ring[0], ring[0]), ring[0], f64::INFINITY);
    for (a, b) in edges(ring) {
        let f = nearest_on_segment(&a, &b, p);
        let d = (f - p).norm();
        if d < best.2 {
            best = ((a, b), f, d);
        }
    }
    (best.0, best.1)
}

/// The nearest point to `p` on the edge of `ring`.
pub(crate) fn nearest_on_ring(ring: &[Ne], p: &Ne) -> Ne {
    nearest_edge(ring, p).1
}
