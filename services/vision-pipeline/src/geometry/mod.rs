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
use skymesh_ipc_types::frame::{CapturePose, FrameHeader};

/// Farthest horizontal distance, metres, at which a ray–ground intersection is
/// reported; beyond it a flat plane at the vehicle's height is not a terrain model.
pub const MAX_GROUND_RANGE_M: f64 = 20_000.0;

/// DigiView's fixed-point scale of a normalised offset (`i16 = value × 32767`).
pub const OFFSET_SCALE: f64 = 32767.0;

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

mod model;
pub use model::{CameraModel, Lens, Offset};

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
mod tests;
