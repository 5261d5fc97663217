//! Geofence geometry: polygons in a local tangent plane, inside tests, the distance
//! along a ray to the first boundary crossing, and the velocity envelope. Pure.
//!
//! **Frame.** Vertices and vehicle positions are projected onto a plane tangent to
//! the ellipsoid at the first vertex of the first polygon (x north, y east, metres;
//! WGS84 meridional and normal radii of curvature at that latitude). Both go through
//! the same projection, so inside/outside is decided consistently; what the flat-earth
//! approximation distorts is distance, by a relative error of about tan(φ₀)·Δφ (Δφ the
//! north-south extent from the origin in radians): 0.03 % within 1 km and 0.3 %
//! within 10 km below 60° latitude — centimetres at fence scales, far below GNSS
//! error. Fences are assumed to be smaller than a few tens of kilometres and away
//! from the poles and the antimeridian (longitudes are unwrapped around the origin).
//!
//! **Inside** means inside at least one keep-in polygon (if there are any), outside
//! every keep-out polygon, and `floor ≤ alt_rel ≤ ceiling`. Polygons may be convex or
//! concave, in either winding; a self-intersecting polygon is read with the even-odd
//! rule.

use nalgebra::Vector2;
use skymesh_ipc_types::{FenceError, FenceKind, GeofenceSet};

/// A point or direction in the local plane: x north, y east, metres.
pub type Ne = Vector2<f64>;

const WGS84_A: f64 = 6_378_137.0;
const WGS84_E2: f64 = 6.694_379_990_14e-3;
/// Shorter crossings than this are the same crossing (a ray through a vertex).
const SAME_CROSSING_M: f64 = 1e-6;

/// Flat-earth projection around an origin (see the module doc for its error).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    lat0_deg: f64,
    lon0_deg: f64,
    m_per_deg_lat: f64,
    m_per_deg_lon: f64,
}

impl LocalFrame {
    pub fn new(lat0_deg: f64, lon0_deg: f64) -> Self {
        let phi = lat0_deg.to_radians();
        let w = (1.0 - WGS84_E2 * phi.sin().powi(2)).sqrt();
        let meridional = WGS84_A * (1.0 - WGS84_E2) / w.powi(3);
        let normal = WGS84_A / w;
        LocalFrame {
            lat0_deg,
            lon0_deg,
            m_per_deg_lat: meridional.to_radians(),
            m_per_deg_lon: (normal * phi.cos()).to_radians(),
        }
    }

    /// Latitude/longitude in degrees → local north/east metres.
    pub fn to_local(&self, lat_deg: f64, lon_deg: f64) -> Ne {
        let dlon = (lon_deg - self.lon0_deg + 540.0).rem_euclid(360.0) - 180.0;
        Ne::new(
            (lat_deg - self.lat0_deg) * self.m_per_deg_lat,
            dlon * self.m_per_deg_lon,
        )
    }
}

fn cross(a: Ne, b: Ne) -> f64 {
    a.x * b.y - a.y * b.x
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
}

/// How hard the envelope brakes, from the arbiter settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// Deceleration the vehicle is assumed to manage, m/s².
    pub decel_mps2: f64,
    /// Horizontal distance kept from the boundary, m.
    pub margin_m: f64,
    /// Vertical distance kept from ceiling and floor, m.
    pub vertical_margin_m: f64,
    /// Telemetry age plus control lag: the current velocity is assumed to continue
    /// for this long before a new setpoint takes effect, s.
    pub response_s: f64,
}

/// Why a velocity was reduced (formatted only when it was).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Limit {
    /// Speed toward the horizontal boundary cut to stop `room_m` before it.
    Boundary {
        room_m: f64,
        from: f64,
        to: f64,
    },
    /// Outside: only the component back toward the fence kept.
    Outside,
    Ceiling,
    Floor,
}

impl core::fmt::Display for Limit {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Limit::Boundary { room_m, from, to } => {
                write!(f, "fence {room_m:.1} m: {from:.1}->{to:.1} m/s")
            }
            Limit::Outside => f.write_str("outside fence: only back in"),
            Limit::Ceiling => f.write_str("fence ceiling"),
            Limit::Floor => f.write_str("fence floor"),
        }
    }
}

/// Fastest speed from which the vehicle still stops within `room_m`.
fn stoppable(room_m: f64, decel: f64) -> f64 {
    (2.0 * decel * room_m.max(0.0)).sqrt()
}

impl Fence {
    /// Limits a NED velocity setpoint so the vehicle at `pos`/`alt_rel_m`, moving at
    /// `current` (NED), stops before the envelope: along the commanded horizontal
    /// direction the speed is at most √(2·a·d), d = distance to the first boundary
    /// crossing − margin − the distance covered during the response time; outside,
    /// only the component back toward the fence is kept; vertically the same against
    /// ceiling and floor. Returns the velocity and the first limit applied.
    pub fn limit_velocity(
        &self,
        env: &Envelope,
        pos: Ne,
        alt_rel_m: f32,
        current: [f32; 3],
        command: [f32; 3],
        scratch: &mut Vec<f64>,
    ) -> ([f32; 3], Option<Limit>) {
        let mut limit = None;
        let mut out = command;
        let cmd_h = Ne::new(command[0].into(), command[1].into());
        let cur_h = Ne::new(current[0].into(), current[1].into());
        let speed = cmd_h.norm();
        if speed > 1e-3 {
            let dir = cmd_h / speed;
            let new_h = if self.contains(pos) {
                let toward = cur_h.dot(&dir).max(0.0);
                match self.exit_distance(pos, dir, scratch) {
                    Some(d) => {
                        let room = d - env.margin_m - toward * env.response_s;
                        let allowed = stoppable(room, env.decel_mps2);
                        if speed > allowed {
                            limit = Some(Limit::Boundary {
                                room_m: room.max(0.0),
                                from: speed,
                                to: allowed,
                            });
                            dir * allowed
                        } else {
                            cmd_h
                        }
                    }
                    None => cmd_h,
                }
            } else {
                let back = self.way_back(pos).unwrap_or_else(Ne::zeros);
                let kept = back * cmd_h.dot(&back).max(0.0);
                if (kept - cmd_h).norm() > 1e-3 {
                    limit = Some(Limit::Outside);
                }
                kept
            };
            out[0] = new_h.x as f32;
            out[1] = new_h.y as f32;
        }
        // Vertical, NED: positive down.
        let up = -f64::from(command[2]);
        let cur_up = -f64::from(current[2]);
        let alt = f64::from(alt_rel_m);
        let (ceiling, floor) = (f64::from(self.ceiling_m), f64::from(self.floor_m));
        let vertical = if up > 0.0 {
            let room = ceiling - env.vertical_margin_m - alt - cur_up.max(0.0) * env.response_s;
            let allowed = if alt > ceiling {
                0.0
            } else {
                stoppable(room, env.decel_mps2)
            };
            (up > allowed).then_some((allowed, Limit::Ceiling))
        } else if up < 0.0 {
            let room = alt - floor - env.vertical_margin_m - (-cur_up).max(0.0) * env.response_s;
            let allowed = if alt < floor {
                0.0
            } else {
                stoppable(room, env.decel_mps2)
            };
            (-up > allowed).then_some((-allowed, Limit::Floor))
        } else {
            None
        };
        if let Some((allowed_up, why)) = vertical {
            out[2] = -allowed_up as f32;
            limit = limit.or(Some(why));
        }
        (out, limit)
    }
}

/// A position fix older than this (s) is not trusted to move toward a boundary.
pub const MAX_FIX_AGE_S: f32 = 0.5;
