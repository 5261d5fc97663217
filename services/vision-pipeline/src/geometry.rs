//! Camera geometry: pixel ↔ ray ↔ angles ↔ ground point. Pure functions, `f64`.
//!
//! # Frames
//!
//! - **Camera frame** (FRD, like the vehicle body): +X along the optical axis (the
//!   direction the camera looks), +Y to the right of the image, +Z towards the bottom
//!   of the image. A camera mounted with the identity [`Mount`] looks along the
//!   vehicle's nose with the image's right side on the vehicle's right.
//! - **Body frame**: the vehicle's forward-right-down frame (MAVLink / NED convention).
//! - **NED**: local north-east-down at the vehicle. A vehicle attitude rotates body
//!   vectors into NED; a [`Mount`] rotates camera vectors into the body frame, so the
//!   camera's attitude is `q_ned←cam = q_ned←body × q_body←cam` ([`CameraPose::new`]).
//!   A frame's header already carries `q_ned←cam`
//!   ([`skymesh_ipc_types::CapturePose::attitude_q`], gimbal included) and the
//!   vehicle's heading ([`CameraPose::from_capture`]).
//!
//! # Pixels and offsets
//!
//! Pixel coordinates are continuous: the image spans `0..width` × `0..height`, `u` to
//! the right, `v` down, and the centre of pixel `(i, j)` is `(i + 0.5, j + 0.5)`. The
//! intrinsics (`fx, fy, cx, cy`) are in the same coordinates.
//!
//! DigiView's normalised offsets ([`Offset`], on the wire `i16 = value × 32767`) are
//! measured from the centre of the picture: `x` = −1 at the left edge, +1 at the right
//! edge; `y` = +1 at the top edge, −1 at the bottom edge (the spec: "y_offset −0.5 will
//! move the aim down"). So ±1 are the edges of the view (CAM_OFFSET's "fraction of the
//! view"); CAM_TARGETING's prose example ("0.5 moves the aim right by half the view's
//! width") reads as twice that scale. The conversion lives only in
//! [`CameraModel::offset_to_pixel`] and [`CameraModel::pixel_to_offset`].
//!
//! # Angles
//!
//! [`YawPitch`] is Tait-Bryan yaw then pitch of a direction in a FRD-like frame: yaw =
//! `atan2(right, forward)` in −π..π (positive to the right / clockwise seen from
//! above), pitch = elevation above the frame's X-Y plane in −π/2..π/2 (positive up).
//! Relative to the camera that frame is the camera frame (0, 0 = the optical axis);
//! globally it is NED: yaw from true north (east = +π/2), pitch from the horizon;
//! relative to the heading it is NED turned by the vehicle's yaw (DigiView's
//! `rel_frame_of_reference` 1): yaw from the nose, pitch from the horizon.
//!
//! # Lens models (from [`CameraIntrinsics`])
//!
//! With normalised image coordinates `a = Y/X`, `b = Z/X` of a camera-frame ray:
//! - **Pinhole** with radial-tangential distortion (OpenCV; `k = [k1, k2, p1, p2]`):
//!   `r² = a² + b²`, `a' = a(1 + k1 r² + k2 r⁴) + 2 p1 a b + p2 (r² + 2a²)`,
//!   `b' = b(1 + k1 r² + k2 r⁴) + p1 (r² + 2b²) + 2 p2 a b`, `u = fx a' + cx`,
//!   `v = fy b' + cy`. Only rays in front of the camera (X > 0) and inside the fold
//!   of the radial polynomial (the first `r²` where `1 + 3 k1 r² + 5 k2 r⁴ = 0`) with
//!   a positive Jacobian determinant project, so the mapping is one-to-one. Pixel →
//!   ray inverts the distortion with Newton's method on the 2×2 Jacobian, its steps
//!   kept inside the fold.
//! - **Equidistant fisheye** (OpenCV `fisheye`; `k = [k1, k2, k3, k4]`): θ = angle of
//!   the ray from the optical axis (`atan2(√(Y²+Z²), X)`, up to π, so lenses wider
//!   than 180° work), `θd = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`, the image point is
//!   `θd` along the ray's azimuth: `u = fx θd Y/r + cx`, `v = fy θd Z/r + cy`. A
//!   projection is only defined below the first θ where the polynomial stops
//!   increasing (`dθd/dθ = 0`, found once per model), so it is invertible; pixel → ray
//!   solves the polynomial for θ by bisection on that range.
//!
//! # Ground
//!
//! The ground is a plane `height_agl` metres below the vehicle in the local-level
//! tangent frame at the vehicle ([`skymesh_geo::LocalFrame`], WGS-84: the camera's
//! scene uses the same geodesy, so its truth and this geolocation agree). A ray at or above the horizon has no ground point; nor has one that meets
//! the ground further than [`MAX_GROUND_RANGE_M`] away, where a flat plane is no model
//! of the terrain.

use nalgebra::{Point2, Quaternion, Unit, UnitQuaternion, Vector3};
use skymesh_geo::{Geodetic, LocalFrame};
use skymesh_ipc_types::frame::{CameraIntrinsics, CapturePose, FrameHeader, LensModel};

/// Farthest horizontal distance, metres, at which a ray–ground intersection is
/// reported; beyond it a flat plane at the vehicle's height is not a terrain model.
pub const MAX_GROUND_RANGE_M: f64 = 20_000.0;

/// DigiView's fixed-point scale of a normalised offset (`i16 = value × 32767`).
pub const OFFSET_SCALE: f64 = 32767.0;

/// Newton iterations for inverting a lens model.
const MAX_NEWTON_ITERATIONS: usize = 50;
/// Convergence of the pinhole undistortion, normalised image units (1e-9 px at f = 1000).
const NEWTON_TOLERANCE: f64 = 1e-12;

/// Why a camera model or pose cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("the frame carries no calibrated intrinsics")]
    NoIntrinsics,
    #[error("unknown lens model {0}")]
    LensModel(u8),
    #[error("bad intrinsics: fx {fx}, fy {fy}, cx {cx}, cy {cy} (focal lengths must be finite and positive, all values finite)")]
    Intrinsics { fx: f64, fy: f64, cx: f64, cy: f64 },
    #[error("bad image size {width}x{height}")]
    ImageSize { width: f64, height: f64 },
    #[error("the frame carries no pose")]
    NoPose,
    #[error("attitude quaternion {0:?} is not finite or not near unit length")]
    Attitude([f64; 4]),
    #[error("bad position lat {lat_deg} lon {lon_deg} alt {alt_msl_m} (non-finite, or latitude beyond ±90°)")]
    Position {
        lat_deg: f64,
        lon_deg: f64,
        alt_msl_m: f64,
    },
}

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
    fold: f64,
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
fn radial_fold_r2(k1: f64, k2: f64) -> f64 {
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
fn equidistant(theta: f64, [k1, k2, k3, k4]: [f64; 4]) -> (f64, f64) {
    let t2 = theta * theta;
    let poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
    let slope = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
    (theta * poly, slope)
}

/// The smallest θ in `0..=π` where the equidistant polynomial stops increasing, or π
/// (scan, then bisection on the slope's sign change).
fn equidistant_fold(k: [f64; 4]) -> f64 {
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

/// Yaw and pitch of a direction, radians (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawPitch {
    /// `atan2(right, forward)`, −π..π.
    pub yaw: f64,
    /// Elevation, −π/2..π/2, positive up.
    pub pitch: f64,
}

impl YawPitch {
    /// The angles of a direction in a forward-right-down frame (`None` for zero or
    /// non-finite vectors).
    pub fn of(v: &Vector3<f64>) -> Option<YawPitch> {
        if !v.iter().all(|c| c.is_finite()) || v.norm() == 0.0 {
            return None;
        }
        Some(YawPitch {
            yaw: v.y.atan2(v.x),
            pitch: (-v.z).atan2(v.x.hypot(v.y)),
        })
    }

    /// The unit direction these angles describe.
    pub fn direction(&self) -> Unit<Vector3<f64>> {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        Unit::new_normalize(Vector3::new(cp * cy, cp * sy, -sp))
    }
}

/// Wraps an angle in radians to [−π, π) (the runtime's one implementation).
pub use skymesh_runtime::angle::wrap_pi;

/// How the camera is mounted on the vehicle: the rotation of camera-frame vectors into
/// the body frame (a gimbal's current attitude relative to the body, or a fixed mount).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mount {
    body_from_camera: UnitQuaternion<f64>,
}

impl Mount {
    /// Looking along the nose.
    pub fn forward() -> Mount {
        Mount {
            body_from_camera: UnitQuaternion::identity(),
        }
    }

    /// Looking straight down (pitch −90°), the image's top towards the nose.
    pub fn nadir() -> Mount {
        Mount::from_euler(0.0, -std::f64::consts::FRAC_PI_2, 0.0)
    }

    /// Tait-Bryan yaw (right positive), pitch (up positive), roll (right side down
    /// positive) of the camera relative to the body, radians: `Rz(yaw)·Ry(pitch)·Rx(roll)`.
    pub fn from_euler(yaw: f64, pitch: f64, roll: f64) -> Mount {
        Mount {
            body_from_camera: UnitQuaternion::from_euler_angles(roll, pitch, yaw),
        }
    }

    /// From a rotation of camera vectors into the body frame.
    pub fn from_quaternion(body_from_camera: UnitQuaternion<f64>) -> Mount {
        Mount { body_from_camera }
    }

    pub fn body_from_camera(&self) -> UnitQuaternion<f64> {
        self.body_from_camera
    }
}

/// The camera's attitude in NED (vehicle attitude × mount) and the vehicle's heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    ned_from_camera: UnitQuaternion<f64>,
    heading: f64,
}

impl CameraPose {
    /// From the vehicle attitude (body → NED) and the mount.
    pub fn new(ned_from_body: UnitQuaternion<f64>, mount: &Mount) -> CameraPose {
        CameraPose {
            ned_from_camera: ned_from_body * mount.body_from_camera,
            heading: ned_from_body.euler_angles().2,
        }
    }

    /// From a wire quaternion `[w, x, y, z]` (body → NED), which must be finite and
    /// within 1 % of unit length (it is then normalised).
    pub fn from_attitude_q(q: [f32; 4], mount: &Mount) -> Result<CameraPose, GeometryError> {
        let q = q.map(f64::from);
        let quaternion = Quaternion::new(q[0], q[1], q[2], q[3]);
        let norm = quaternion.norm();
        if !norm.is_finite() || (norm - 1.0).abs() > 0.01 {
            return Err(GeometryError::Attitude(q));
        }
        Ok(CameraPose::new(
            UnitQuaternion::from_quaternion(quaternion),
            mount,
        ))
    }

    /// From a frame's header: `pose.attitude_q` is already the camera's orientation
    /// (camera → NED, gimbal included) and `vehicle_heading_deg` the nose.
    pub fn from_capture(header: &FrameHeader) -> Result<CameraPose, GeometryError> {
        let pose = &header.pose;
        if pose.valid == 0 {
            return Err(GeometryError::NoPose);
        }
        let camera = CameraPose::from_attitude_q(
            pose.attitude_q,
            &Mount::from_quaternion(UnitQuaternion::identity()),
        )?;
        let heading = f64::from(header.vehicle_heading_deg);
        if !heading.is_finite() {
            return Err(GeometryError::Attitude(pose.attitude_q.map(f64::from)));
        }
        Ok(CameraPose {
            ned_from_camera: camera.ned_from_camera,
            heading: wrap_pi(heading.to_radians()),
        })
    }

    /// From a camera → NED orientation and the vehicle's heading (radians), e.g. a
    /// virtual camera's published aim.
    pub fn from_parts(ned_from_camera: UnitQuaternion<f64>, heading: f64) -> CameraPose {
        CameraPose {
            ned_from_camera,
            heading: wrap_pi(heading),
        }
    }

    pub fn ned_from_camera(&self) -> UnitQuaternion<f64> {
        self.ned_from_camera
    }

    /// The vehicle's heading (yaw from true north), radians, −π..π.
    pub fn heading(&self) -> f64 {
        self.heading
    }

    pub fn camera_to_ned(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.ned_from_camera * v
    }

    pub fn ned_to_camera(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.ned_from_camera.inverse_transform_vector(v)
    }
}

/// A direction seen through the camera, in DigiView's three frames (CAM_OFFSET,
/// DETECTED_ROI), and as a NED unit vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Direction {
    /// Relative to the camera's centre axis (`rel_frame_of_reference` 2).
    pub camera: YawPitch,
    /// Yaw relative to the vehicle's heading, pitch from the horizon (`rel_frame` 1).
    pub heading: YawPitch,
    /// Yaw from true north, pitch from the horizon (`yaw_global`, `pitch_global`).
    pub global: YawPitch,
    /// The ray in NED.
    pub ned: Unit<Vector3<f64>>,
}

impl Direction {
    /// The angles of a camera-frame ray seen from `pose`.
    pub fn of_camera_ray(pose: &CameraPose, ray: &Vector3<f64>) -> Option<Direction> {
        let camera = YawPitch::of(ray)?;
        let ned = Unit::try_new(pose.camera_to_ned(ray), 0.0)?;
        let global = YawPitch::of(&ned)?;
        Some(Direction {
            camera,
            heading: YawPitch {
                yaw: wrap_pi(global.yaw - pose.heading),
                pitch: global.pitch,
            },
            global,
            ned,
        })
    }

    /// CAM_OFFSET: the direction through `pixel`.
    pub fn of_pixel(
        model: &CameraModel,
        pose: &CameraPose,
        pixel: &Point2<f64>,
    ) -> Option<Direction> {
        Direction::of_camera_ray(pose, &model.pixel_to_ray(pixel)?.into_inner())
    }

    /// CAM_OFFSET: the direction at a normalised offset from the picture's centre.
    pub fn of_offset(model: &CameraModel, pose: &CameraPose, offset: Offset) -> Option<Direction> {
        Direction::of_pixel(model, pose, &model.offset_to_pixel(offset))
    }
}

/// A geodetic position: degrees, and metres above mean sea level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoPosition {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_msl_m: f64,
}

impl GeoPosition {
    /// The vehicle's position in a frame's capture pose.
    pub fn from_capture(pose: &CapturePose) -> Result<GeoPosition, GeometryError> {
        if pose.valid == 0 {
            return Err(GeometryError::NoPose);
        }
        let p = GeoPosition {
            lat_deg: pose.lat_deg,
            lon_deg: pose.lon_deg,
            alt_msl_m: f64::from(pose.alt_m),
        };
        let ok = p.lat_deg.is_finite()
            && p.lon_deg.is_finite()
            && p.alt_msl_m.is_finite()
            && p.lat_deg.abs() <= 90.0;
        if !ok {
            return Err(GeometryError::Position {
                lat_deg: p.lat_deg,
                lon_deg: p.lon_deg,
                alt_msl_m: p.alt_msl_m,
            });
        }
        Ok(p)
    }

    /// North, east, down metres from `self` to `other` (local-level tangent frame at
    /// `self`: down is the altitude difference).
    pub fn ned_to(&self, other: &GeoPosition) -> Vector3<f64> {
        Vector3::from(self.frame().to_ned(&other.geodetic()))
    }

    /// The position `ned` metres (north, east, down) from `self`.
    pub fn offset_by(&self, ned: &Vector3<f64>) -> GeoPosition {
        let g = self.frame().from_ned((*ned).into());
        GeoPosition {
            lat_deg: g.lat_deg,
            lon_deg: g.lon_deg,
            alt_msl_m: g.alt_m,
        }
    }

    fn geodetic(&self) -> Geodetic {
        Geodetic::new(self.lat_deg, self.lon_deg, self.alt_msl_m)
    }

    fn frame(&self) -> LocalFrame {
        LocalFrame::new(self.geodetic())
    }
}

/// Where a ray meets the ground (DETECTED_ROI's latitude, longitude, altitude and
/// distance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundHit {
    /// The ground point; its altitude is the ground's, above mean sea level.
    pub position: GeoPosition,
    /// North, east, down metres from the vehicle to the point.
    pub ned: Vector3<f64>,
    /// Slant distance from the vehicle (camera), metres.
    pub distance_m: f64,
}

/// Intersects a NED ray from the vehicle at `vehicle` with the ground plane
/// `height_agl_m` below it (relative altitude, e.g. `VehicleState::alt_rel_m`: height
/// above home, taken as height above the ground under the vehicle). `None` when the ray points at or above
/// the horizon, the height is not positive and finite, or the point lies beyond
/// [`MAX_GROUND_RANGE_M`].
pub fn intersect_ground(
    vehicle: &GeoPosition,
    height_agl_m: f64,
    ray_ned: &Vector3<f64>,
) -> Option<GroundHit> {
    if !(height_agl_m.is_finite() && height_agl_m > 0.0) {
        return None;
    }
    let ray = Unit::try_new(*ray_ned, 0.0)?;
    if !ray.iter().all(|c| c.is_finite()) || ray.z <= 0.0 {
        return None;
    }
    let distance_m = height_agl_m / ray.z;
    let ned = ray.into_inner() * distance_m;
    if !distance_m.is_finite() || ned.x.hypot(ned.y) > MAX_GROUND_RANGE_M {
        return None;
    }
    Some(GroundHit {
        position: vehicle.offset_by(&ned),
        ned,
        distance_m,
    })
}

/// Geolocates the point seen at `pixel`: its direction and, below the horizon, its
/// ground point.
pub fn locate_pixel(
    model: &CameraModel,
    pose: &CameraPose,
    vehicle: &GeoPosition,
    height_agl_m: f64,
    pixel: &Point2<f64>,
) -> Option<(Direction, Option<GroundHit>)> {
    let direction = Direction::of_pixel(model, pose, pixel)?;
    let hit = intersect_ground(vehicle, height_agl_m, &direction.ned);
    Some((direction, hit))
}

/// The pixel where a geodetic point appears (coordinal aiming, tests), or `None` if the
/// lens cannot see it.
pub fn pixel_of_position(
    model: &CameraModel,
    pose: &CameraPose,
    vehicle: &GeoPosition,
    target: &GeoPosition,
) -> Option<Point2<f64>> {
    model.ray_to_pixel(&pose.ned_to_camera(&vehicle.ned_to(target)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    const W: f64 = 1920.0;
    const H: f64 = 1080.0;

    fn vehicle() -> GeoPosition {
        GeoPosition {
            lat_deg: 47.397_742,
            lon_deg: 8.545_594,
            alt_msl_m: 538.0,
        }
    }

    fn pinhole_90() -> CameraModel {
        CameraModel::from_hfov(W, H, FRAC_PI_2).unwrap()
    }

    fn distorted_pinhole() -> CameraModel {
        CameraModel::new(
            W,
            H,
            1000.0,
            1002.0,
            955.0,
            545.0,
            Lens::Pinhole {
                k1: -0.12,
                k2: 0.03,
                p1: 0.001,
                p2: -0.0007,
            },
        )
        .unwrap()
    }

    fn fisheye() -> CameraModel {
        // ~190° diagonal: f = 600 px, θd at the corner ≈ 1.84 rad.
        CameraModel::new(
            W,
            H,
            600.0,
            600.0,
            960.0,
            540.0,
            Lens::Fisheye {
                k: [0.02, -0.005, 0.001, -0.0001],
            },
        )
        .unwrap()
    }

    fn attitude(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(
            roll_deg.to_radians(),
            pitch_deg.to_radians(),
            yaw_deg.to_radians(),
        )
    }

    fn close(a: f64, b: f64, tolerance: f64) -> bool {
        (a - b).abs() <= tolerance
    }

    #[test]
    fn nadir_centre_pixel_sees_the_point_below() {
        let model = pinhole_90();
        let pose = CameraPose::new(attitude(0.0, 0.0, 30.0), &Mount::nadir());
        let centre = model.offset_to_pixel(Offset { x: 0.0, y: 0.0 });
        assert_eq!(centre, Point2::new(960.0, 540.0));
        let (direction, hit) = locate_pixel(&model, &pose, &vehicle(), 50.0, &centre).unwrap();
        assert!(close(direction.global.pitch, -FRAC_PI_2, 1e-12));
        assert!(close(direction.camera.yaw, 0.0, 1e-12));
        assert!(close(direction.camera.pitch, 0.0, 1e-12));
        let hit = hit.unwrap();
        assert!(close(hit.distance_m, 50.0, 1e-9));
        assert!(hit.ned.xy().norm() < 1e-9);
        assert!(close(hit.position.lat_deg, vehicle().lat_deg, 1e-12));
        assert!(close(hit.position.lon_deg, vehicle().lon_deg, 1e-12));
        assert!(close(hit.position.alt_msl_m, 538.0 - 50.0, 1e-9));
    }

    #[test]
    fn edge_of_a_90_degree_pinhole_is_45_degrees() {
        let model = pinhole_90();
        let pose = CameraPose::new(attitude(0.0, 0.0, 30.0), &Mount::forward());
        let right = Direction::of_offset(&model, &pose, Offset { x: 1.0, y: 0.0 }).unwrap();
        assert!(close(right.camera.yaw, FRAC_PI_4, 1e-12));
        assert!(close(right.camera.pitch, 0.0, 1e-12));
        assert!(close(right.heading.yaw, FRAC_PI_4, 1e-12));
        assert!(close(right.global.yaw, 75f64.to_radians(), 1e-12));
        let left = Direction::of_pixel(&model, &pose, &Point2::new(0.0, 540.0)).unwrap();
        assert!(close(left.camera.yaw, -FRAC_PI_4, 1e-12));
        // y = +1 is the top edge: up, atan(540 / 960).
        let top = Direction::of_offset(&model, &pose, Offset { x: 0.0, y: 1.0 }).unwrap();
        assert!(close(top.camera.pitch, (540.0f64 / 960.0).atan(), 1e-12));
        assert!(close(top.global.pitch, (540.0f64 / 960.0).atan(), 1e-12));
    }

    #[test]
    fn global_yaw_wraps_through_south() {
        let model = pinhole_90();
        let pose = CameraPose::new(attitude(0.0, 0.0, 170.0), &Mount::forward());
        let d = Direction::of_offset(&model, &pose, Offset { x: 1.0, y: 0.0 }).unwrap();
        assert!(close(d.global.yaw, (215.0f64 - 360.0).to_radians(), 1e-12));
        assert!(close(d.heading.yaw, FRAC_PI_4, 1e-12));
    }

    fn assert_round_trips(model: &CameraModel) {
        let mut checked = 0;
        for j in 0..=27 {
            for i in 0..=48 {
                let pixel = Point2::new(f64::from(i) * 40.0, f64::from(j) * 40.0);
                let ray = model
                    .pixel_to_ray(&pixel)
                    .unwrap_or_else(|| panic!("no ray at {pixel}"));
                let back = model.ray_to_pixel(&ray).unwrap();
                assert!((back - pixel).norm() < 1e-6, "{pixel} → {back}");
                checked += 1;
            }
        }
        assert_eq!(checked, 49 * 28);
    }

    #[test]
    fn pixel_ray_pixel_round_trips_pinhole() {
        assert_round_trips(&pinhole_90());
        assert_round_trips(&distorted_pinhole());
    }

    #[test]
    fn pixel_ray_pixel_round_trips_fisheye() {
        let model = fisheye();
        assert_round_trips(&model);
        // The corner is beyond 90° from the axis: the fisheye sees behind its plane.
        let corner = model.pixel_to_ray(&Point2::new(0.0, 0.0)).unwrap();
        assert!(corner.x < 0.0);
    }

    #[test]
    fn fisheye_is_equidistant() {
        let model = CameraModel::new(
            W,
            H,
            500.0,
            500.0,
            960.0,
            540.0,
            Lens::Fisheye { k: [0.0; 4] },
        )
        .unwrap();
        // 60° to the right of the axis lands at f·θ from the centre.
        let ray = Vector3::new(60f64.to_radians().cos(), 60f64.to_radians().sin(), 0.0);
        let pixel = model.ray_to_pixel(&ray).unwrap();
        assert!(close(pixel.x, 960.0 + 500.0 * PI / 3.0, 1e-9));
        assert!(close(pixel.y, 540.0, 1e-9));
        // Straight back is not imaged; neither is anything behind a pinhole.
        assert!(model.ray_to_pixel(&Vector3::new(-1.0, 0.0, 0.0)).is_none());
        assert!(pinhole_90()
            .ray_to_pixel(&Vector3::new(-1.0, 0.2, 0.0))
            .is_none());
    }

    #[test]
    fn rays_past_the_lens_fold_do_not_project() {
        // Barrel distortion whose radial polynomial folds at r² ≈ 3.7 and rises again
        // past r² ≈ 16.5: a ray at r = 4.5 would otherwise land back inside the image.
        let model = CameraModel::new(
            W,
            H,
            1333.5,
            1334.8,
            967.0,
            535.0,
            Lens::Pinhole {
                k1: -0.111,
                k2: 0.0033,
                p1: 0.0,
                p2: 0.0,
            },
        )
        .unwrap();
        let slope = 1.0 - 3.0 * 0.111 * model.fold + 5.0 * 0.0033 * model.fold.powi(2);
        assert!(close(slope, 0.0, 1e-12) && (3.0..4.0).contains(&model.fold));
        assert!(model.ray_to_pixel(&Vector3::new(1.0, 4.5, 0.0)).is_none());
        assert!(model.ray_to_pixel(&Vector3::new(1.0, 1.5, 0.0)).is_some());
        assert_eq!(radial_fold_r2(0.0, 0.0), f64::INFINITY);
        assert!(close(radial_fold_r2(-0.1, 0.0), 10.0 / 3.0, 1e-12));
        // A fisheye polynomial that peaks: θ past the peak is not imaged, nor is a
        // pixel beyond the polynomial's maximum.
        let k = [-0.1, 0.0, 0.0, 0.0];
        let fold = equidistant_fold(k);
        assert!(close(fold, (1.0f64 / 0.3).sqrt(), 1e-9), "{fold}");
        let fisheye =
            CameraModel::new(W, H, 500.0, 500.0, 960.0, 540.0, Lens::Fisheye { k }).unwrap();
        let past = Vector3::new((fold + 0.1).cos(), (fold + 0.1).sin(), 0.0);
        assert!(fisheye.ray_to_pixel(&past).is_none());
        let peak = equidistant(fold, k).0;
        assert!(fisheye
            .pixel_to_ray(&Point2::new(960.0 + 500.0 * (peak + 0.01), 540.0))
            .is_none());
    }

    #[test]
    fn ground_target_50m_north_at_50m_height() {
        let model = pinhole_90();
        // Camera pitched 45° down, facing north: the target is on the optical axis.
        let pose = CameraPose::new(
            attitude(0.0, 0.0, 0.0),
            &Mount::from_euler(0.0, -FRAC_PI_4, 0.0),
        );
        let v = vehicle();
        let target = v.offset_by(&Vector3::new(50.0, 0.0, 50.0));
        let pixel = pixel_of_position(&model, &pose, &v, &target).unwrap();
        assert!((pixel - Point2::new(960.0, 540.0)).norm() < 1e-6, "{pixel}");
        // 10 m east of that: camera frame (100/√2, 10, 0) → u = cx + f·10/(100/√2).
        let target_east = v.offset_by(&Vector3::new(50.0, 10.0, 50.0));
        let pixel_east = pixel_of_position(&model, &pose, &v, &target_east).unwrap();
        let expected_u = 960.0 + 960.0 * 10.0 / (100.0 / 2f64.sqrt());
        assert!(close(pixel_east.x, expected_u, 1e-6), "{pixel_east}");
        assert!(close(pixel_east.y, 540.0, 1e-6), "{pixel_east}");

        for (target, pixel) in [(target, pixel), (target_east, pixel_east)] {
            let (direction, hit) = locate_pixel(&model, &pose, &v, 50.0, &pixel).unwrap();
            let hit = hit.unwrap();
            let error = hit.position.ned_to(&target).norm();
            assert!(error < 0.01, "geolocated {error} m off");
            assert!(close(hit.distance_m, v.ned_to(&target).norm(), 0.01));
            let truth = YawPitch::of(&v.ned_to(&target)).unwrap();
            assert!(close(direction.global.yaw, truth.yaw, 1e-9));
            assert!(close(direction.global.pitch, truth.pitch, 1e-9));
        }
        assert!(close(
            locate_pixel(&model, &pose, &v, 50.0, &pixel)
                .unwrap()
                .0
                .global
                .pitch,
            -FRAC_PI_4,
            1e-9
        ));
    }

    #[test]
    fn ground_target_through_a_distorted_fisheye() {
        let model = fisheye();
        let pose = CameraPose::new(
            attitude(0.0, 0.0, 120.0),
            &Mount::from_euler(0.2, -0.9, 0.0),
        );
        let v = vehicle();
        let target = v.offset_by(&Vector3::new(-30.0, 45.0, 50.0));
        let pixel = pixel_of_position(&model, &pose, &v, &target).unwrap();
        assert!(model.contains(&pixel));
        let (_, hit) = locate_pixel(&model, &pose, &v, 50.0, &pixel).unwrap();
        assert!(hit.unwrap().position.ned_to(&target).norm() < 0.01);
    }

    #[test]
    fn vehicle_tilt_is_compensated() {
        let model = distorted_pinhole();
        let v = vehicle();
        let mount = Mount::from_euler(0.0, -0.6, 0.0);
        let target = v.offset_by(&Vector3::new(40.0, 25.0, 60.0));
        let truth = YawPitch::of(&v.ned_to(&target)).unwrap();
        let level = CameraPose::new(attitude(0.0, 0.0, 30.0), &mount);
        let tilted = CameraPose::new(attitude(12.0, -7.0, 30.0), &mount);
        let p_level = pixel_of_position(&model, &level, &v, &target).unwrap();
        let p_tilted = pixel_of_position(&model, &tilted, &v, &target).unwrap();
        // The tilt moves the target in the image...
        assert!((p_level - p_tilted).norm() > 50.0);
        // ...but not in the world.
        for (pose, pixel) in [(level, p_level), (tilted, p_tilted)] {
            let (d, hit) = locate_pixel(&model, &pose, &v, 60.0, &pixel).unwrap();
            assert!(close(d.global.yaw, truth.yaw, 1e-9));
            assert!(close(d.global.pitch, truth.pitch, 1e-9));
            assert!(hit.unwrap().position.ned_to(&target).norm() < 0.01);
        }
        let d_level = Direction::of_pixel(&model, &level, &p_level).unwrap();
        let d_tilted = Direction::of_pixel(&model, &tilted, &p_tilted).unwrap();
        assert!((d_level.camera.yaw - d_tilted.camera.yaw).abs() > 0.01);
    }

    #[test]
    fn no_ground_at_or_above_the_horizon() {
        let v = vehicle();
        assert!(intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, 0.0)).is_none());
        assert!(intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, -0.1)).is_none());
        assert!(intersect_ground(&v, 50.0, &Vector3::zeros()).is_none());
        // Grazing: 50 m down over > 20 km.
        assert!(intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, 0.001)).is_none());
        assert!(intersect_ground(&v, 0.0, &Vector3::new(0.0, 0.0, 1.0)).is_none());
        assert!(intersect_ground(&v, f64::NAN, &Vector3::new(0.0, 0.0, 1.0)).is_none());
        let hit = intersect_ground(&v, 50.0, &Vector3::new(1.0, 0.0, 1.0)).unwrap();
        assert!(close(hit.distance_m, 50.0 * 2f64.sqrt(), 1e-9));
        assert!(close(hit.ned.x, 50.0, 1e-9));
        // A forward camera's upper half looks at the sky.
        let model = pinhole_90();
        let pose = CameraPose::new(attitude(0.0, 0.0, 0.0), &Mount::forward());
        let (d, hit) = locate_pixel(&model, &pose, &v, 50.0, &Point2::new(960.0, 100.0)).unwrap();
        assert!(d.global.pitch > 0.0);
        assert!(hit.is_none());
    }

    #[test]
    fn offsets_and_wire_values() {
        let model = pinhole_90();
        assert_eq!(
            model.offset_to_pixel(Offset { x: -1.0, y: 1.0 }),
            Point2::new(0.0, 0.0)
        );
        assert_eq!(
            model.offset_to_pixel(Offset { x: 1.0, y: -1.0 }),
            Point2::new(W, H)
        );
        assert_eq!(Offset::from_wire(32767, -32767), Offset { x: 1.0, y: -1.0 });
        assert_eq!(Offset::from_wire(i16::MIN, 0), Offset { x: -1.0, y: 0.0 });
        assert_eq!(Offset { x: 0.5, y: -2.0 }.to_wire(), (16384, -32767));
        assert_eq!(
            Offset {
                x: f64::NAN,
                y: 0.0
            }
            .to_wire(),
            (0, 0)
        );
    }

    #[test]
    fn header_models_and_refusals() {
        let mut header = FrameHeader {
            width: 1280,
            height: 720,
            ..FrameHeader::default()
        };
        assert_eq!(
            CameraModel::from_header(&header),
            Err(GeometryError::NoIntrinsics)
        );
        header.intrinsics = CameraIntrinsics {
            fx: 640.0,
            fy: 640.0,
            cx: 640.0,
            cy: 360.0,
            k: [0.0; 4],
            lens_model: LensModel::Pinhole.to_wire(),
            valid: 1,
            reserved: [0; 2],
        };
        let model = CameraModel::from_header(&header).unwrap();
        let right = model.pixel_to_ray(&Point2::new(1280.0, 360.0)).unwrap();
        assert!(close(YawPitch::of(&right).unwrap().yaw, FRAC_PI_4, 1e-12));
        header.intrinsics.lens_model = LensModel::Fisheye.to_wire();
        assert!(matches!(
            CameraModel::from_header(&header).unwrap().lens(),
            Lens::Fisheye { .. }
        ));
        header.intrinsics.lens_model = 9;
        assert_eq!(
            CameraModel::from_header(&header),
            Err(GeometryError::LensModel(9))
        );
        header.intrinsics.lens_model = 0;
        header.intrinsics.fx = 0.0;
        assert!(matches!(
            CameraModel::from_header(&header),
            Err(GeometryError::Intrinsics { .. })
        ));

        assert_eq!(
            CameraPose::from_capture(&header),
            Err(GeometryError::NoPose)
        );
        header.pose.valid = 1;
        assert!(matches!(
            CameraPose::from_capture(&header),
            Err(GeometryError::Attitude(_))
        ));
        header.pose.attitude_q = [1.0, 0.0, 0.0, 0.0];
        header.pose.lat_deg = 47.0;
        header.pose.lon_deg = 8.0;
        header.pose.alt_m = 500.0;
        assert!(CameraPose::from_capture(&header).is_ok());
        assert_eq!(
            GeoPosition::from_capture(&header.pose),
            Ok(GeoPosition {
                lat_deg: 47.0,
                lon_deg: 8.0,
                alt_msl_m: 500.0
            })
        );
        header.pose.lat_deg = f64::NAN;
        assert!(GeoPosition::from_capture(&header.pose).is_err());
    }

    #[test]
    fn wrap_pi_stays_in_range() {
        assert!(close(wrap_pi(3.0 * PI / 2.0), -FRAC_PI_2, 1e-12));
        assert!(close(wrap_pi(-3.0 * PI / 2.0), FRAC_PI_2, 1e-12));
        assert!(close(wrap_pi(PI), -PI, 1e-12));
        assert!(close(wrap_pi(0.1), 0.1, 1e-15));
    }

    fn any_model() -> impl Strategy<Value = CameraModel> {
        prop_oneof![
            // Pinholes of 65..95° HFOV with distortion a calibration of such a lens
            // gives (monotonic over the whole image).
            (
                -0.12f64..0.05,
                -0.02f64..0.02,
                -0.002f64..0.002,
                -0.002f64..0.002,
                900.0f64..1500.0
            )
                .prop_map(|(k1, k2, p1, p2, f)| CameraModel::new(
                    W,
                    H,
                    f,
                    f * 1.001,
                    W / 2.0 + 7.0,
                    H / 2.0 - 5.0,
                    Lens::Pinhole { k1, k2, p1, p2 }
                )
                .unwrap()),
            // Fisheyes of up to ~195° diagonal with coefficients that keep the
            // polynomial increasing over the whole image.
            (
                -0.01f64..0.03,
                -0.002f64..0.002,
                -0.0003f64..0.0003,
                -0.00003f64..0.00003,
                650.0f64..1000.0
            )
                .prop_map(|(k1, k2, k3, k4, f)| CameraModel::new(
                    W,
                    H,
                    f,
                    f,
                    W / 2.0,
                    H / 2.0,
                    Lens::Fisheye {
                        k: [k1, k2, k3, k4]
                    }
                )
                .unwrap()),
        ]
        // A calibration describes a lens that covers its own image: the distortion
        // stays invertible out to the corners (not every random set of coefficients
        // does).
        .prop_filter("lens covers the image", |m| {
            [(0.0, 0.0), (W, 0.0), (0.0, H), (W, H)]
                .iter()
                .all(|&(u, v)| m.pixel_to_ray(&Point2::new(u, v)).is_some())
        })
    }

    /// The camera's synthetic scene and this geolocation share one geodesy: every
    /// ground point the camera renders at a pixel is geolocated back to where the
    /// scene put it, to well under 0.01 % of range (0.17 % when the scene was a sphere
    /// of the equatorial radius). What is left comes from the scene being one flat
    /// plane at its origin while geolocation works in the vehicle's tangent plane.
    #[test]
    fn camera_truth_and_geolocation_agree() {
        use skymesh_camera::synthetic::Synthetic;
        use skymesh_ipc_types::VehicleState;
        use skymesh_runtime::ServiceConfig;

        let text = skymesh_camera::RawConfig::DEFAULT_TOML
            .replace("pitch_deg = -90.0", "pitch_deg = -35.0");
        assert!(text.contains("pitch_deg = -35.0"));
        let settings: skymesh_camera::Settings =
            skymesh_runtime::config::parse::<skymesh_camera::RawConfig>(&text, "test").unwrap();
        let k = settings.intrinsics;
        let mut camera = Synthetic::new(settings.clone());
        let state = |lat_deg: f64, lon_deg: f64, alt_rel_m: f32, yaw_deg: f32| VehicleState {
            position_valid: 1,
            attitude_valid: 1,
            lat_deg,
            lon_deg,
            alt_msl_m: 584.0 + alt_rel_m,
            alt_rel_m,
            yaw_rad: yaw_deg.to_radians(),
            attitude_q: [1.0, 0.0, 0.0, 0.0],
            ..VehicleState::default()
        };
        // The first state is the scene's origin; the vehicle then flies 150 m out.
        camera.update_vehicle(&state(-35.363_261, 149.165_230, 0.0, 0.0));
        let height = 60.0;
        camera.update_vehicle(&state(-35.362_1, 149.166_5, height as f32, 40.0));
        let (_, cam, capture, heading) = camera.pose().unwrap();
        let origin = camera.origin().unwrap();
        let mut header = FrameHeader::default();
        header.set_geometry(
            settings.format,
            settings.width,
            settings.height,
            settings.stride(),
        );
        header.intrinsics = k.to_wire();
        header.pose = capture;
        header.vehicle_heading_deg = heading;

        let model = CameraModel::from_header(&header).unwrap();
        let pose = CameraPose::from_capture(&header).unwrap();
        let vehicle = GeoPosition::from_capture(&header.pose).unwrap();
        let (mut worst, mut hits) = (0.0f64, 0);
        for i in 0..=8 {
            for j in 0..=8 {
                let u = f64::from(settings.width - 1) * f64::from(i) / 8.0;
                let v = f64::from(settings.height - 1) * f64::from(j) / 8.0;
                let Some((north, east)) = cam.ground_at(&k, u, v) else {
                    continue;
                };
                let (lat_deg, lon_deg) = origin.to_latlon(north, east);
                let truth = GeoPosition {
                    lat_deg,
                    lon_deg,
                    alt_msl_m: origin.ground_alt_msl_m,
                };
                let (_, hit) =
                    locate_pixel(&model, &pose, &vehicle, height, &Point2::new(u, v)).unwrap();
                let hit = hit.expect("vision sees the ground the camera rendered");
                worst = worst.max(hit.position.ned_to(&truth).norm() / hit.distance_m);
                hits += 1;
            }
        }
        assert!(hits > 40, "{hits} ground pixels");
        assert!(worst < 2e-5, "{:.5} % of range", worst * 100.0);
    }

    proptest! {
        #[test]
        fn pixel_ray_pixel(model in any_model(), u in 0.0f64..W, v in 0.0f64..H) {
            let pixel = Point2::new(u, v);
            let ray = model.pixel_to_ray(&pixel).unwrap();
            prop_assert!((ray.norm() - 1.0).abs() < 1e-12);
            let back = model.ray_to_pixel(&ray).unwrap();
            prop_assert!((back - pixel).norm() < 1e-6, "{} → {}", pixel, back);
        }

        #[test]
        fn offset_pixel_offset(x in -1.0f64..1.0, y in -1.0f64..1.0) {
            let model = pinhole_90();
            let offset = model.pixel_to_offset(&model.offset_to_pixel(Offset { x, y }));
            prop_assert!(close(offset.x, x, 1e-12) && close(offset.y, y, 1e-12));
        }

        #[test]
        fn yaw_pitch_direction(yaw in (-PI + 1e-6)..(PI - 1e-6), pitch in (-FRAC_PI_2 + 1e-3)..(FRAC_PI_2 - 1e-3)) {
            let angles = YawPitch::of(&YawPitch { yaw, pitch }.direction()).unwrap();
            prop_assert!(close(angles.yaw, yaw, 1e-9) && close(angles.pitch, pitch, 1e-9));
        }

        #[test]
        fn ground_point_pixel_ground(
            model in any_model(),
            roll in -25.0f64..25.0,
            pitch in -25.0f64..25.0,
            yaw in -180.0f64..180.0,
            mount_pitch in -1.5f64..-0.3,
            north in -200.0f64..200.0,
            east in -200.0f64..200.0,
            height in 5.0f64..150.0,
        ) {
            let v = vehicle();
            let pose = CameraPose::new(attitude(roll, pitch, yaw), &Mount::from_euler(0.0, mount_pitch, 0.0));
            let target = v.offset_by(&Vector3::new(north, east, height));
            if let Some(pixel) = pixel_of_position(&model, &pose, &v, &target) {
                if model.contains(&pixel) {
                    let (_, hit) = locate_pixel(&model, &pose, &v, height, &pixel).unwrap();
                    let error = hit.unwrap().position.ned_to(&target).norm();
                    prop_assert!(error < 1e-3, "{} m off", error);
                }
            }
        }

        #[test]
        fn geodetic_offsets_round_trip(
            lat in -80.0f64..80.0,
            lon in -180.0f64..180.0,
            north in -3000.0f64..3000.0,
            east in -3000.0f64..3000.0,
            down in -500.0f64..500.0,
        ) {
            let origin = GeoPosition { lat_deg: lat, lon_deg: lon, alt_msl_m: 100.0 };
            let ned = Vector3::new(north, east, down);
            let back = origin.ned_to(&origin.offset_by(&ned));
            prop_assert!((back - ned).norm() < 1e-6);
        }
    }
}
