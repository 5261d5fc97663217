//! The camera model ([`CameraModel`]): pixel ↔ ray through the lens models of the
//! module doc, and DigiView's normalised picture [`Offset`]s.

use nalgebra::{Point2, Unit, Vector3};
use skymesh_ipc_types::frame::{CameraIntrinsics, FrameHeader, LensModel};

use super::{GeometryError, OFFSET_SCALE};

/// Newton iterations for inverting a lens model.
const MAX_NEWTON_ITERATIONS: usize = 50;
/// Convergence of the pinhole undistortion, normalised image units (1e-9 px at f = 1000).
const NEWTON_TOLERANCE: f64 = 1e-12;

/// A lens projection with its distortion coefficients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lens {
    /// Pinhole with radial-tangential distortion (zeros = ideal pinhole).
    Pinhole { k1: f64, k2: f64, p1: f64, p2: f64 },
    /// Equidistant fisheye, `θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸)`.
    Fisheye { k: [f64; 4] },
}

impl Lens {
    /// An undistorted pinhole.
    pub const IDEAL_PINHOLE: Lens = Lens::Pinhole {
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
    };
}

/// A normalised DigiView offset from the centre of the picture (see the module doc:
/// x right, y up, ±1 at the edges).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Offset {
    pub x: f64,
    pub y: f64,
}

impl Offset {
    /// From the wire's `i16 = value × 32767` (−32768 clamps to −1).
    pub fn from_wire(x: i16, y: i16) -> Offset {
        let f = |v: i16| (f64::from(v) / OFFSET_SCALE).clamp(-1.0, 1.0);
        Offset { x: f(x), y: f(y) }
    }

    /// To the wire's `i16 = value × 32767`, clamped to −1..1 (NaN → 0).
    pub fn to_wire(self) -> (i16, i16) {
        let f = |v: f64| {
            if v.is_nan() {
                0
            } else {
                // In range by the clamp: the cast cannot saturate.
                (v.clamp(-1.0, 1.0) * OFFSET_SCALE).round() as i16
            }
        };
        (f(self.x), f(self.y))
    }
}

/// A camera's projection: image size, intrinsics and lens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    width: f64,
    height: f64,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    lens: Lens,
    /// Where the lens polynomial stops increasing (its fold): beyond it the projection
    /// is not one-to-one. Pinhole: the largest undistorted `r²`; fisheye: the largest
    /// θ (≤ π). Infinite when the polynomial never folds.
    pub(super) fold: f64,
}

impl CameraModel {
    /// A model from explicit intrinsics (pixels of a `width × height` image).
    pub fn new(
        width: f64,
        height: f64,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        lens: Lens,
    ) -> Result<CameraModel, GeometryError> {
        if !(width.is_finite() && height.is_finite() && width > 0.0 && height > 0.0) {
            return Err(GeometryError::ImageSize { width, height });
        }
        let ok = fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0;
        let coefficients: &[f64] = match &lens {
            Lens::Pinhole { k1, k2, p1, p2 } => &[*k1, *k2, *p1, *p2],
            Lens::Fisheye { k } => k,
        };
        if !ok || !cx.is_finite() || !cy.is_finite() || !coefficients.iter().all(|c| c.is_finite())
        {
            return Err(GeometryError::Intrinsics { fx, fy, cx, cy });
        }
        let fold = match lens {
            Lens::Pinhole { k1, k2, .. } => radial_fold_r2(k1, k2),
            Lens::Fisheye { k } => equidistant_fold(k),
        };
        Ok(CameraModel {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            lens,
            fold,
        })
    }

    /// An ideal pinhole with square pixels, the principal point at the image centre and
    /// horizontal field of view `hfov_rad` (edge to edge), as a rectified virtual view.
    pub fn from_hfov(width: f64, height: f64, hfov_rad: f64) -> Result<CameraModel, GeometryError> {
        let f = width / 2.0 / (hfov_rad / 2.0).tan();
        if !(hfov_rad > 0.0 && hfov_rad < std::f64::consts::PI) {
            return Err(GeometryError::Intrinsics {
                fx: f,
                fy: f,
                cx: width / 2.0,
                cy: height / 2.0,
            });
        }
        CameraModel::new(
            width,
            height,
            f,
            f,
            width / 2.0,
            height / 2.0,
            Lens::IDEAL_PINHOLE,
        )
    }

    /// The model a frame header describes (its size and intrinsics).
    pub fn from_header(header: &FrameHeader) -> Result<CameraModel, GeometryError> {
        CameraModel::from_intrinsics(
            &header.intrinsics,
            f64::from(header.width),
            f64::from(header.height),
        )
    }

    /// The model of `intrinsics` for a `width × height` image.
    pub fn from_intrinsics(
        intrinsics: &CameraIntrinsics,
        width: f64,
        height: f64,
    ) -> Result<CameraModel, GeometryError> {
        if intrinsics.valid == 0 {
            return Err(GeometryError::NoIntrinsics);
        }
        let k = intrinsics.k.map(f64::from);
        let lens = match LensModel::try_from(intrinsics.lens_model) {
            Ok(LensModel::Pinhole) => Lens::Pinhole {
                k1: k[0],
                k2: k[1],
                p1: k[2],
                p2: k[3],
            },
            Ok(LensModel::Fisheye) => Lens::Fisheye { k },
            Err(_) => return Err(GeometryError::LensModel(intrinsics.lens_model)),
        };
        CameraModel::new(
            width,
            height,
            f64::from(intrinsics.fx),
            f64::from(intrinsics.fy),
            f64::from(intrinsics.cx),
            f64::from(intrinsics.cy),
            lens,
        )
    }

    pub fn width(&self) -> f64 {
        self.width
    }

    pub fn height(&self) -> f64 {
        self.height
    }

    pub fn lens(&self) -> Lens {
        self.lens
    }

    /// Whether `pixel` lies in the image (`0..width` × `0..height`).
    pub fn contains(&self, pixel: &Point2<f64>) -> bool {
        (0.0..=self.width).contains(&pixel.x) && (0.0..=self.height).contains(&pixel.y)
    }

    /// The pixel at a normalised offset from the picture's centre.
    pub fn offset_to_pixel(&self, offset: Offset) -> Point2<f64> {
        Point2::new(
            (1.0 + offset.x) / 2.0 * self.width,
            (1.0 - offset.y) / 2.0 * self.height,
        )
    }

    /// The normalised offset of a pixel from the picture's centre.
    pub fn pixel_to_offset(&self, pixel: &Point2<f64>) -> Offset {
        Offset {
            x: 2.0 * pixel.x / self.width - 1.0,
            y: 1.0 - 2.0 * pixel.y / self.height,
        }
    }

    /// The unit ray (camera frame) through `pixel`, or `None` where the lens model
    /// has no inverse (outside the fisheye's monotonic range, non-converging
    /// undistortion, non-finite input).
    pub fn pixel_to_ray(&self, pixel: &Point2<f64>) -> Option<Unit<Vector3<f64>>> {
        let ad = (pixel.x - self.cx) / self.fx;
        let bd = (pixel.y - self.cy) / self.fy;
        if !ad.is_finite() || !bd.is_finite() {
            return None;
        }
        let ray = match self.lens {
            Lens::Pinhole { k1, k2, p1, p2 } => {
                let (a, b) = undistort_radtan(ad, bd, [k1, k2, p1, p2], self.fold)?;
                Vector3::new(1.0, a, b)
            }
            Lens::Fisheye { k } => {
                let theta_d = ad.hypot(bd);
                if theta_d == 0.0 {
                    Vector3::x()
                } else {
                    let theta = solve_equidistant(theta_d, k, self.fold)?;
                    let s = theta.sin() / theta_d;
                    Vector3::new(theta.cos(), s * ad, s * bd)
                }
            }
        };
        Unit::try_new(ray, 0.0)
    }

    /// The pixel where a camera-frame direction appears (possibly outside the image;
    /// see [`CameraModel::contains`]), or `None` if the lens cannot see it: behind a
    /// pinhole, past the fisheye's monotonic range, zero or non-finite direction.
    pub fn ray_to_pixel(&self, ray: &Vector3<f64>) -> Option<Point2<f64>> {
        if !ray.iter().all(|v| v.is_finite()) || ray.norm() == 0.0 {
            return None;
        }
        let (ad, bd) = match self.lens {
            Lens::Pinhole { k1, k2, p1, p2 } => {
                if ray.x <= 0.0 {
                    return None;
                }
                let (a, b) = (ray.y / ray.x, ray.z / ray.x);
                let (ad, bd, j) = distort_radtan(a, b, [k1, k2, p1, p2]);
                // Past the fold of the polynomial the image is no longer one-to-one.
                if a * a + b * b >= self.fold || j[0][0] * j[1][1] - j[0][1] * j[1][0] <= 0.0 {
                    return None;
                }
                (ad, bd)
            }
            Lens::Fisheye { k } => {
                let r = ray.y.hypot(ray.z);
                if r == 0.0 {
                    if ray.x > 0.0 {
                        (0.0, 0.0)
                    } else {
                        return None;
                    }
                } else {
                    let theta = r.atan2(ray.x);
                    if theta >= self.fold {
                        return None;
                    }
                    let (theta_d, _) = equidistant(theta, k);
                    (theta_d * ray.y / r, theta_d * ray.z / r)
                }
            }
        };
        let pixel = Point2::new(self.fx * ad + self.cx, self.fy * bd + self.cy);
        (pixel.x.is_finite() && pixel.y.is_finite()).then_some(pixel)
    }
}

/// Radial-tangential distortion of normalised `(a, b)`: the distorted point and the
/// Jacobian `[[da'/da, da'/db], [db'/da, db'/db]]`.
fn distort_radtan(a: f64, b: f64, [k1, k2, p1, p2]: [f64; 4]) -> (f64, f64, [[f64; 2]; 2]) {
    let r2 = a * a + b * b;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
    // d(radial)/d(r²), times d(r²)/da = 2a, d(r²)/db = 2b.
    let dradial = k1 + 2.0 * k2 * r2;
    let (drad_da, drad_db) = (dradial * 2.0 * a, dradial * 2.0 * b);
    let ad = a * radial + 2.0 * p1 * a * b + p2 * (r2 + 2.0 * a * a);
    let bd = b * radial + p1 * (r2 + 2.0 * b * b) + 2.0 * p2 * a * b;
    let jacobian = [
        [
            radial + a * drad_da + 2.0 * p1 * b + 6.0 * p2 * a,
            a * drad_db + 2.0 * p1 * a + 2.0 * p2 * b,
        ],
        [
            b * drad_da + 2.0 * p1 * a + 2.0 * p2 * b,
            radial + b * drad_db + 6.0 * p1 * b + 2.0 * p2 * a,
        ],
    ];
    (ad, bd, jacobian)
}

/// The smallest undistorted `r²` where the radial distortion `r(1 + k1 r² + k2 r⁴)`
/// stops increasing (`1 + 3 k1 r² + 5 k2 r⁴ = 0`), or infinity.
pub(super) fn radial_fold_r2(k1: f64, k2: f64) -> f64 {
    let roots = if k2 == 0.0 {
        [-1.0 / (3.0 * k1), f64::NAN]
    } else {
        let disc = 9.0 * k1 * k1 - 20.0 * k2;
        if disc < 0.0 {
            return f64::INFINITY;
        }
        let sq = disc.sqrt();
        [
            (-3.0 * k1 - sq) / (10.0 * k2),
            (-3.0 * k1 + sq) / (10.0 * k2),
        ]
    };
    roots
        .into_iter()
        .filter(|s| s.is_finite() && *s > 0.0)
        .fold(f64::INFINITY, f64::min)
}

/// Inverts [`distort_radtan`] by Newton's method from the distorted point, keeping the
/// iterates inside the fold (`r² < fold_r2`, where the mapping is one-to-one).
fn undistort_radtan(ad: f64, bd: f64, k: [f64; 4], fold_r2: f64) -> Option<(f64, f64)> {
    if k == [0.0; 4] {
        return Some((ad, bd));
    }
    let (mut a, mut b) = (ad, bd);
    // Start inside the fold (a distorted radius can exceed it for barrel lenses).
    while a * a + b * b >= fold_r2 {
        a *= 0.5;
        b *= 0.5;
    }
    for _ in 0..MAX_NEWTON_ITERATIONS {
        let (fa, fb, j) = distort_radtan(a, b, k);
        let (ea, eb) = (fa - ad, fb - bd);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if !det.is_finite() || det <= 1e-12 {
            // Singular, or past the fold (the projection would not map back here).
            return None;
        }
        if ea.abs() < NEWTON_TOLERANCE && eb.abs() < NEWTON_TOLERANCE {
            return Some((a, b));
        }
        let mut da = (j[1][1] * ea - j[0][1] * eb) / det;
        let mut db = (-j[1][0] * ea + j[0][0] * eb) / det;
        // Damp a step that would leave the one-to-one region.
        let mut halvings = 0;
        while (a - da).powi(2) + (b - db).powi(2) >= fold_r2 {
            da *= 0.5;
            db *= 0.5;
            halvings += 1;
            if halvings > 60 {
                return None;
            }
        }
        a -= da;
        b -= db;
        if !a.is_finite() || !b.is_finite() {
            return None;
        }
    }
    None
}

/// The equidistant polynomial `θd(θ)` and its slope `dθd/dθ`.
pub(super) fn equidistant(theta: f64, [k1, k2, k3, k4]: [f64; 4]) -> (f64, f64) {
    let t2 = theta * theta;
    let poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
    let slope = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
    (theta * poly, slope)
}

/// The smallest θ in `0..=π` where the equidistant polynomial stops increasing, or π
/// (scan, then bisection on the slope's sign change).
pub(super) fn equidistant_fold(k: [f64; 4]) -> f64 {
    let pi = std::f64::consts::PI;
    const STEPS: u32 = 4096;
    let mut previous = 0.0;
    for step in 1..=STEPS {
        let theta = pi * f64::from(step) / f64::from(STEPS);
        if equidistant(theta, k).1 <= 0.0 {
            let (mut lo, mut hi) = (previous, theta);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if equidistant(mid, k).1 > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return lo;
        }
        previous = theta;
    }
    pi
}

/// Solves `θd(θ) = theta_d` for θ in `0..fold` (where the polynomial increases) by
/// bisection; `None` if `theta_d` lies beyond the polynomial's value at the fold.
fn solve_equidistant(theta_d: f64, k: [f64; 4], fold: f64) -> Option<f64> {
    if !(theta_d >= 0.0 && theta_d <= equidistant(fold, k).0) {
        return None;
    }
    let (mut lo, mut hi) = (0.0, fold);
    // 64 halvings of ≤ π: below f64 resolution.
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if equidistant(mid, k).0 < theta_d {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}
