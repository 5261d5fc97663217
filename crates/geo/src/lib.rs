//! WGS-84 geodesy for every skymesh service: geodetic ↔ ECEF ↔ a local tangent frame
//! (north/east/down or east/north/up metres around an origin), and the bearings,
//! distances and offsets built on it. One earth model, so two services that convert
//! the same point get the same metres.
//!
//! Two kinds of local coordinates, both in the tangent plane at the origin:
//!
//! - **Local level** ([`LocalFrame::to_ned`], [`LocalFrame::to_ne`], …): north and east
//!   are the exact tangent-plane coordinates of the point's latitude/longitude on the
//!   ellipsoid, and down is the altitude difference. It is what autopilots and every
//!   caller here mean by "local NED": a point at the origin's altitude is at down 0
//!   however far away, and the altitude datum (MSL, above home, ellipsoid) does not
//!   matter because only differences are used. Horizontal metres differ from arc
//!   length on the ellipsoid by s³/(6R²) (4 mm at 10 km) and from metres at flight
//!   height by h/R (1.6e-5 at 100 m).
//! - **Cartesian** ([`LocalFrame::enu_of`], [`LocalFrame::geodetic_of_enu`]): the
//!   ECEF difference rotated into the tangent frame, exact in 3-D (a point at the
//!   origin's altitude 1 km away is 7.8 cm below the plane). Here the altitude must
//!   be the ellipsoidal height.
//!
//! Local-level → geodetic is solved by Newton's method on the exact forward map
//! (three or four steps to a nanometre). Longitudes come back in −180..180.

/// WGS-84 semi-major axis, metres.
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS-84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared.
pub const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// Newton steps are stopped once the correction is below this, metres.
const SOLVE_TOLERANCE_M: f64 = 1e-9;
const SOLVE_MAX_STEPS: usize = 10;
/// Below this cos(latitude) a degree of longitude is treated as this long (poles).
const MIN_COS_LAT: f64 = 1e-9;

/// A geodetic position: latitude and longitude in degrees (north and east positive),
/// altitude in metres (the caller's datum; see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_m: f64,
}

impl Geodetic {
    pub const fn new(lat_deg: f64, lon_deg: f64, alt_m: f64) -> Self {
        Geodetic {
            lat_deg,
            lon_deg,
            alt_m,
        }
    }

    /// Earth-centred, earth-fixed x, y, z metres (`alt_m` taken as ellipsoidal height).
    pub fn to_ecef(&self) -> [f64; 3] {
        let t = Trig::of(self.lat_deg, self.lon_deg);
        ecef(&t, self.alt_m)
    }

    /// The geodetic position of ECEF x, y, z metres (altitude: ellipsoidal height).
    pub fn from_ecef([x, y, z]: [f64; 3]) -> Geodetic {
        let p = x.hypot(y);
        // Fixed-point iteration φ ← atan2(z + e²·N(φ)·sin φ, p): each step gains about
        // three digits near the surface; at the axis it gives ±90° at once.
        let mut lat = z.atan2(p * (1.0 - WGS84_E2));
        for _ in 0..8 {
            let s = lat.sin();
            let n = WGS84_A / (1.0 - WGS84_E2 * s * s).sqrt();
            let next = (z + WGS84_E2 * n * s).atan2(p);
            let done = (next - lat).abs() < 1e-15;
            lat = next;
            if done {
                break;
            }
        }
        let (s, c) = lat.sin_cos();
        // Height along the normal, stable at every latitude.
        let alt = p * c + z * s - WGS84_A * (1.0 - WGS84_E2 * s * s).sqrt();
        Geodetic {
            lat_deg: lat.to_degrees(),
            lon_deg: wrap_lon(y.atan2(x).to_degrees()),
            alt_m: alt,
        }
    }
}

/// Sines and cosines of a latitude and longitude.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Trig {
    sin_lat: f64,
    cos_lat: f64,
    sin_lon: f64,
    cos_lon: f64,
}

impl Trig {
    fn of(lat_deg: f64, lon_deg: f64) -> Trig {
        let (sin_lat, cos_lat) = lat_deg.to_radians().sin_cos();
        let (sin_lon, cos_lon) = lon_deg.to_radians().sin_cos();
        Trig {
            sin_lat,
            cos_lat,
            sin_lon,
            cos_lon,
        }
    }

    /// Prime-vertical radius of curvature N, metres.
    fn prime_vertical(&self) -> f64 {
        WGS84_A / (1.0 - WGS84_E2 * self.sin_lat * self.sin_lat).sqrt()
    }

    /// Meridian radius of curvature M, metres.
    fn meridian(&self) -> f64 {
        let w = 1.0 - WGS84_E2 * self.sin_lat * self.sin_lat;
        WGS84_A * (1.0 - WGS84_E2) / (w * w.sqrt())
    }

    fn east(&self) -> [f64; 3] {
        [-self.sin_lon, self.cos_lon, 0.0]
    }

    fn north(&self) -> [f64; 3] {
        [
            -self.sin_lat * self.cos_lon,
            -self.sin_lat * self.sin_lon,
            self.cos_lat,
        ]
    }

    fn up(&self) -> [f64; 3] {
        [
            self.cos_lat * self.cos_lon,
            self.cos_lat * self.sin_lon,
            self.sin_lat,
        ]
    }
}

fn ecef(t: &Trig, alt_m: f64) -> [f64; 3] {
    let n = t.prime_vertical();
    [
        (n + alt_m) * t.cos_lat * t.cos_lon,
        (n + alt_m) * t.cos_lat * t.sin_lon,
        (n * (1.0 - WGS84_E2) + alt_m) * t.sin_lat,
    ]
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Degrees of longitude into −180..180.
fn wrap_lon(lon_deg: f64) -> f64 {
    if (-180.0..180.0).contains(&lon_deg) {
        lon_deg
    } else {
        (lon_deg + 180.0).rem_euclid(360.0) - 180.0
    }
}

/// Degrees into 0..360.
fn wrap_360(deg: f64) -> f64 {
    let d = deg.rem_euclid(360.0);
    if d >= 360.0 {
        0.0
    } else {
        d
    }
}

/// The tangent frame at an origin (see the module doc for its two kinds of
/// coordinates). Cheap to copy; the origin's trigonometry is computed once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    origin: Geodetic,
    /// The origin's ECEF position at its altitude (Cartesian coordinates).
    ecef0: [f64; 3],
    /// The origin's ECEF position on the ellipsoid (local-level coordinates).
    surface0: [f64; 3],
    east: [f64; 3],
    north: [f64; 3],
    up: [f64; 3],
}

impl LocalFrame {
    /// The frame centred on `origin` (its altitude is down 0 / up 0).
    pub fn new(origin: Geodetic) -> Self {
        let t = Trig::of(origin.lat_deg, origin.lon_deg);
        LocalFrame {
            origin,
            ecef0: ecef(&t, origin.alt_m),
            surface0: ecef(&t, 0.0),
            east: t.east(),
            north: t.north(),
            up: t.up(),
        }
    }

    pub fn origin(&self) -> Geodetic {
        self.origin
    }

    fn project(&self, ecef: &[f64; 3], from: &[f64; 3]) -> [f64; 3] {
        let d = [ecef[0] - from[0], ecef[1] - from[1], ecef[2] - from[2]];
        [dot(&self.east, &d), dot(&self.north, &d), dot(&self.up, &d)]
    }

    /// Local level: north, east metres of a latitude/longitude (degrees).
    pub fn to_ne(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        let t = Trig::of(lat_deg, lon_deg);
        let [e, n, _] = self.project(&ecef(&t, 0.0), &self.surface0);
        [n, e]
    }

    /// Local level: the latitude and longitude (degrees) of north, east metres.
    pub fn from_ne(&self, north: f64, east: f64) -> (f64, f64) {
        // Start from the radii of curvature at the origin, then Newton on the exact
        // map; its Jacobian's columns are the point's north and east unit vectors
        // scaled by M and N·cos φ, seen in the origin's east/north axes.
        let t0 = Trig::of(self.origin.lat_deg, self.origin.lon_deg);
        let mut lat = self.origin.lat_deg.to_radians() + north / t0.meridian();
        let mut lon = self.origin.lon_deg.to_radians()
            + east / (t0.prime_vertical() * t0.cos_lat.max(MIN_COS_LAT));
        for _ in 0..SOLVE_MAX_STEPS {
            let (sin_lat, cos_lat) = lat.sin_cos();
            let (sin_lon, cos_lon) = lon.sin_cos();
            let t = Trig {
                sin_lat,
                cos_lat,
                sin_lon,
                cos_lon,
            };
            let [e, n, _] = self.project(&ecef(&t, 0.0), &self.surface0);
            let (dn, de) = (north - n, east - e);
            let (pn, pe) = (t.north(), t.east());
            let m = t.meridian();
            let nc = t.prime_vertical() * cos_lat.max(MIN_COS_LAT);
            // d(e, n) = J · d(lat, lon)
            let (j11, j12) = (dot(&self.east, &pn) * m, dot(&self.east, &pe) * nc);
            let (j21, j22) = (dot(&self.north, &pn) * m, dot(&self.north, &pe) * nc);
            let det = j11 * j22 - j12 * j21;
            let (dlat, dlon) = if det.abs() > f64::MIN_POSITIVE {
                ((j22 * de - j12 * dn) / det, (j11 * dn - j21 * de) / det)
            } else {
                (dn / m, 0.0)
            };
            lat = (lat + dlat).clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
            lon += dlon;
            if dn.hypot(de) < SOLVE_TOLERANCE_M {
                break;
            }
        }
        (lat.to_degrees(), wrap_lon(lon.to_degrees()))
    }

    /// Local level: north, east, down metres of `p` (down = origin altitude − altitude).
    pub fn to_ned(&self, p: &Geodetic) -> [f64; 3] {
        let [n, e] = self.to_ne(p.lat_deg, p.lon_deg);
        [n, e, self.origin.alt_m - p.alt_m]
    }

    /// Local level: the position of north, east, down metres.
    pub fn from_ned(&self, [n, e, d]: [f64; 3]) -> Geodetic {
        let (lat_deg, lon_deg) = self.from_ne(n, e);
        Geodetic {
            lat_deg,
            lon_deg,
            alt_m: self.origin.alt_m - d,
        }
    }

    /// Local level: east, north, up metres of `p` (up = altitude − origin altitude).
    pub fn to_enu(&self, p: &Geodetic) -> [f64; 3] {
        let [n, e, d] = self.to_ned(p);
        [e, n, -d]
    }

    /// Local level: the position of east, north, up metres.
    pub fn from_enu(&self, [e, n, u]: [f64; 3]) -> Geodetic {
        self.from_ned([n, e, -u])
    }

    /// Cartesian: east, north, up metres of `p` (ellipsoidal heights).
    pub fn enu_of(&self, p: &Geodetic) -> [f64; 3] {
        self.project(&p.to_ecef(), &self.ecef0)
    }

    /// Cartesian: the position of east, north, up metres (ellipsoidal height).
    pub fn geodetic_of_enu(&self, [e, n, u]: [f64; 3]) -> Geodetic {
        let x = |i: usize| self.ecef0[i] + self.east[i] * e + self.north[i] * n + self.up[i] * u;
        Geodetic::from_ecef([x(0), x(1), x(2)])
    }

    /// Cartesian: north, east, down metres of `p`.
    pub fn ned_of(&self, p: &Geodetic) -> [f64; 3] {
        let [e, n, u] = self.enu_of(p);
        [n, e, -u]
    }

    /// Cartesian: the position of north, east, down metres.
    pub fn geodetic_of_ned(&self, [n, e, d]: [f64; 3]) -> Geodetic {
        self.geodetic_of_enu([e, n, -d])
    }
}

/// North and east metres from `from` to `to` in the tangent plane at `from`.
pub fn north_east(from: &Geodetic, to: &Geodetic) -> [f64; 2] {
    LocalFrame::new(*from).to_ne(to.lat_deg, to.lon_deg)
}

/// Horizontal distance, metres (tangent plane at `a`).
pub fn ground_distance_m(a: &Geodetic, b: &Geodetic) -> f64 {
    let [n, e] = north_east(a, b);
    n.hypot(e)
}

/// Distance including the altitude difference, metres.
pub fn distance_m(a: &Geodetic, b: &Geodetic) -> f64 {
    ground_distance_m(a, b).hypot(b.alt_m - a.alt_m)
}

/// Bearing from `from` to `to`, degrees 0..360 clockwise from north (0 when the
/// points coincide): the azimuth in the tangent plane at `from`.
pub fn bearing_deg(from: &Geodetic, to: &Geodetic) -> f64 {
    let [n, e] = north_east(from, to);
    if n == 0.0 && e == 0.0 {
        return 0.0;
    }
    wrap_360(e.atan2(n).to_degrees())
}

/// The point `distance_m` from `p` along `bearing_deg` (clockwise from north), at
/// `p`'s altitude.
pub fn offset(p: &Geodetic, bearing_deg: f64, distance_m: f64) -> Geodetic {
    let (s, c) = bearing_deg.to_radians().sin_cos();
    LocalFrame::new(*p).from_ned([distance_m * c, distance_m * s, 0.0])
}

#[cfg(test)]
mod tests {
    use super::*;

    const CMAC: Geodetic = Geodetic::new(-35.363_261, 149.165_230, 584.0);

    #[test]
    fn the_origin_is_zero_and_axes_point_north_and_east() {
        let f = LocalFrame::new(CMAC);
        let [n, e, d] = f.to_ned(&CMAC);
        assert!(n.abs() < 1e-9 && e.abs() < 1e-9 && d == 0.0);
        let north = f.from_ned([100.0, 0.0, 0.0]);
        assert!(north.lat_deg > CMAC.lat_deg && (north.lon_deg - CMAC.lon_deg).abs() < 1e-12);
        let east = f.from_ned([0.0, 100.0, -10.0]);
        assert!(east.lon_deg > CMAC.lon_deg && east.alt_m == 594.0);
    }

    #[test]
    fn a_degree_is_wgs84_long() {
        // 0.01° at the equator: 1 105.74 m of meridian, 1 113.19 m of equator.
        let eq = Geodetic::new(0.0, 0.0, 0.0);
        let f = LocalFrame::new(eq);
        assert!((f.to_ne(0.01, 0.0)[0] - 1105.74).abs() < 0.01);
        assert!((f.to_ne(0.0, 0.01)[1] - 1113.19).abs() < 0.01);
    }

    #[test]
    fn longitudes_wrap_across_the_antimeridian() {
        let a = Geodetic::new(10.0, 179.9995, 0.0);
        let b = Geodetic::new(10.0, -179.9995, 0.0);
        assert!((bearing_deg(&a, &b) - 90.0).abs() < 1e-3);
        assert!((ground_distance_m(&a, &b) - 109.6).abs() < 0.1);
        let back = LocalFrame::new(a).from_ne(0.0, 200.0);
        assert!(back.1 < -179.99 && back.1 >= -180.0, "{back:?}");
    }

    #[test]
    fn poles_stay_finite() {
        let f = LocalFrame::new(Geodetic::new(90.0, 0.0, 0.0));
        let (lat, lon) = f.from_ne(100.0, 50.0);
        assert!(lat.is_finite() && lon.is_finite() && lat <= 90.0);
        let p = Geodetic::from_ecef([0.0, 0.0, 6_356_752.314_245 + 10.0]);
        assert!((p.lat_deg - 90.0).abs() < 1e-12 && (p.alt_m - 10.0).abs() < 1e-6);
    }

    #[test]
    fn offsets_and_bearings_agree() {
        for b in [0.0, 33.0, 145.0, 260.0, 359.0] {
            let p = offset(&CMAC, b, 250.0);
            assert!((ground_distance_m(&CMAC, &p) - 250.0).abs() < 1e-6);
            let got = bearing_deg(&CMAC, &p);
            let diff = (got - b + 540.0).rem_euclid(360.0) - 180.0;
            assert!(diff.abs() < 1e-6, "{b} → {got}");
            assert_eq!(p.alt_m, CMAC.alt_m);
        }
        let up = Geodetic {
            alt_m: CMAC.alt_m + 40.0,
            ..offset(&CMAC, 90.0, 30.0)
        };
        assert!((distance_m(&CMAC, &up) - 50.0).abs() < 1e-6);
        assert_eq!(bearing_deg(&CMAC, &CMAC), 0.0);
    }

    #[test]
    fn cartesian_drops_below_the_plane() {
        let f = LocalFrame::new(CMAC);
        let far = f.from_ned([1000.0, 0.0, 0.0]);
        let [_, _, d] = f.ned_of(&far);
        // 1 km away at the same height: about 1000²/(2R) = 7.8 cm below the plane.
        assert!((d - 0.0787).abs() < 0.002, "{d}");
    }
}
