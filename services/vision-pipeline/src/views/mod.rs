//! Virtual (user-controllable) cameras.
//!
//! A virtual camera is a view cut out of the physical camera's wide frame, aimed by
//! CAM_TARGETING (directional / coordinal / detection / single target, euler deltas,
//! lock flags, x/y offsets), CAM_OPTICS_AND_CONTROL (zoom, FOV, crop mode), gimbal
//! protocol v2 (angles, rates, ROI) and MAVLink zoom. [`VirtualCamera::aim`] turns
//! what it was told plus the vehicle's attitude into the view's orientation (camera →
//! NED, the camera frame of [`crate::geometry`]) once per frame.
//!
//! # Choices the document leaves open
//!
//! - **Orientation with lock flags.** The vehicle attitude is split into Tait-Bryan
//!   heading ψ, body pitch θ, body roll φ. The view is
//!   `Rz(yaw_v) · Ry(pitch_v) · Rx(roll_v)` with `yaw_v = yaw` if yaw is locked (global,
//!   from true north) else `ψ + yaw`; `pitch_v = pitch` if pitch is locked (from the
//!   horizon) else `θ + pitch`; `roll_v = 0` if roll is locked (level) else `φ`: each
//!   axis behaves like a gimbal axis that is either stabilised or follows the vehicle.
//!   The roll angle itself is stored and reported but not applied ("Roll is currently
//!   ignored").
//! - **Target modes** (coordinal, detection, single target) aim the optical axis at the
//!   target's direction with the view level (roll 0) if roll is locked, else rolled
//!   with the body.
//! - **Coordinal altitude.** DigiView's target altitude is relative to the vehicle: it
//!   is resolved against the vehicle's altitude *at each frame* (the target stays that
//!   far above/below the vehicle). [`VirtualCamera::roi`] (MAVLink) gives an absolute
//!   MSL altitude, kept as such; its `target_alt_rel_m` in the state is computed from
//!   the last known vehicle altitude (0 until one is known).
//! - **Detection mode.** CAM_TARGETING carries no detection id. Entering detection mode
//!   (every CAM_TARGETING SET with mode 2) makes the camera pick, at its next aim, the
//!   known detection whose direction is nearest the view's current centre (the last aim,
//!   or the vehicle's nose before the first aim), and store its id; it then follows that
//!   id. While the id is not found the view holds its last aim (`aim_valid` 0). The
//!   pipeline can name an id itself with [`VirtualCamera::follow_detection`].
//! - **Offsets** move the aim to the direction the un-offset view shows at that offset
//!   (the geometry's [`Offset`] convention: ±1 at the view's edges, y up), so
//!   [`cam_offset`] of the un-offset view at (x, y) is the offset view's centre. The
//!   vertical scale needs the view's aspect: [`VirtualCamera::set_view_size`] (16:9
//!   until told).
//! - **Zoom.** The zoom factor is `2^(zoom / 32)` (zoom −127..127: +127 ≈ 15.6× in,
//!   −127 ≈ 15.6× out), effective HFOV = `fov / factor` clamped to 0.1..3.14 rad (the
//!   FOV limits). MAVLink zoom: step = ±16 (√2×), continuous = ±32 per second (2× per
//!   second) at value ±1, range 0 % = −127 (widest) … 100 % = +127 (narrowest).
//! - **Panoramic** (crop mode 2): yaw linear across the width (`hfov` edge to edge), a
//!   pinhole vertically with the same angular scale at the centre row ([`view_ray`]).

use nalgebra::{Point2, Quaternion, Unit, UnitQuaternion, Vector3};
use skymesh_ipc_types::{
    CropMode, TargetingMode, VirtualCamState, LOCK_PITCH, LOCK_ROLL, LOCK_YAW,
};

use crate::geometry::{wrap_pi, CameraModel, CameraPose, Direction, GeoPosition, Offset, YawPitch};

/// Smallest and largest horizontal field of view honoured, radians (CAM_OPTICS_AND_CONTROL).
pub const FOV_MIN_RAD: f64 = 0.1;
/// The document's literal limit, not π.
#[allow(clippy::approx_constant)]
pub const FOV_MAX_RAD: f64 = 3.14;
/// DigiView zoom limits.
pub const ZOOM_MIN: f64 = -127.0;
pub const ZOOM_MAX: f64 = 127.0;
/// Zoom units per doubling of the magnification.
pub const ZOOM_PER_DOUBLING: f64 = 32.0;
/// MAVLink CAMERA_ZOOM_TYPE step (type 0): zoom units per step.
pub const ZOOM_STEP: f64 = 16.0;
/// MAVLink continuous zoom (type 1) at value ±1: zoom units per second.
pub const ZOOM_RATE_PER_S: f64 = 32.0;
/// Longest time step integrated at once (a stalled stream must not jump the aim).
const MAX_DT_S: f64 = 1.0;
/// Detection ids (0–253) probed when detection mode picks one.
const DETECTION_IDS: std::ops::RangeInclusive<u8> = 0..=253;
/// No detection chosen yet.
const NO_DETECTION: u8 = 255;

/// How to aim a virtual camera (a `ViewControl` of kind `Targeting`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Targeting {
    /// [`TargetingMode`] as stored on the wire.
    pub mode: u8,
    /// Add the angles to the current ones.
    pub euler_delta: bool,
    /// Radians, in the frames the lock flags select.
    pub yaw: f64,
    pub pitch: f64,
    pub roll: f64,
    /// `LOCK_*` bits.
    pub lock_flags: u8,
    /// Normalised −1..1 (x right, y up).
    pub x_offset: f64,
    pub y_offset: f64,
    /// Coordinal target: degrees, and metres relative to the vehicle.
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
}

/// A virtual camera's optics (a `ViewControl` of kind `Optics`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Optics {
    /// −127..127, 0 none, positive in.
    pub zoom: i8,
    /// Horizontal field of view, radians.
    pub fov: f64,
    /// [`CropMode`] as stored on the wire.
    pub crop_mode: u8,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ViewError {
    /// The document says the value leaves the setting unchanged.
    #[error("{0}")]
    Ignored(String),
    #[error("{0}")]
    Invalid(String),
}

/// What a camera needs to know to aim for one frame.
#[allow(missing_debug_implementations)]
pub struct AimContext<'a> {
    /// Vehicle attitude, body → NED.
    pub vehicle: UnitQuaternion<f64>,
    /// Vehicle position (camera position), if known.
    pub position: Option<GeoPosition>,
    /// Direction (NED) of a detection by id, if known.
    pub detection: &'a dyn Fn(u8) -> Option<Unit<Vector3<f64>>>,
    /// The single-target tracker's target (NED), if tracking.
    pub single_target: Option<Unit<Vector3<f64>>>,
    /// Seconds since the last aim (rates).
    pub dt_s: f64,
}

/// A coordinal target.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Target {
    /// DigiView: latitude, longitude, altitude relative to the vehicle (m).
    Relative { lat: f64, lon: f64, alt_rel: f64 },
    /// MAVLink ROI: an absolute position (MSL).
    Absolute(GeoPosition),
}

/// One virtual camera.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualCamera {
    mode: TargetingMode,
    euler_delta: bool,
    /// Angles in the frames the lock flags select (see the module doc), radians.
    yaw: f64,
    pitch: f64,
    roll: f64,
    lock_flags: u8,
    x_offset: f64,
    y_offset: f64,
    target: Option<Target>,
    detection_id: u8,
    /// DigiView zoom, kept continuous for rate zoom.
    zoom: f64,
    fov: f64,
    crop: CropMode,
    /// Gimbal rates (rad/s), integrated in directional mode until the next command.
    yaw_rate: f64,
    pitch_rate: f64,
    /// Continuous zoom, zoom units per second.
    zoom_rate: f64,
    /// The view's size in pixels (for the vertical offset scale).
    view_size: (f64, f64),
    /// The last orientation without and with the offsets.
    last_base: Option<UnitQuaternion<f64>>,
    last_aim: Option<UnitQuaternion<f64>>,
    aim_valid: bool,
    /// Vehicle heading and body pitch (radians) and position at the last aim.
    last_heading: Option<f64>,
    last_body_pitch: Option<f64>,
    last_position: Option<GeoPosition>,
}

impl VirtualCamera {
    /// Directional, looking ahead level (yaw 0 relative to the heading, pitch 0, no
    /// locks but pitch/roll), `fov_rad` horizontal, rectified.
    pub fn new(fov_rad: f64) -> VirtualCamera {
        let fov = if fov_rad.is_finite() {
            fov_rad.clamp(FOV_MIN_RAD, FOV_MAX_RAD)
        } else {
            FOV_MAX_RAD / 2.0
        };
        VirtualCamera {
            mode: TargetingMode::Directional,
            euler_delta: false,
            yaw: 0.0,
            pitch: 0.0,
            roll: 0.0,
            lock_flags: LOCK_PITCH | LOCK_ROLL,
            x_offset: 0.0,
            y_offset: 0.0,
            target: None,
            detection_id: NO_DETECTION,
            zoom: 0.0,
            fov,
            crop: CropMode::Rectified,
            yaw_rate: 0.0,
            pitch_rate: 0.0,
            zoom_rate: 0.0,
            view_size: (16.0, 9.0),
            last_base: None,
            last_aim: None,
            aim_valid: false,
            last_heading: None,
            last_body_pitch: None,
            last_position: None,
        }
    }

    /// A targeting request (already range-checked).
    pub fn set_targeting(&mut self, t: &Targeting) -> Result<(), ViewError> {
        let Ok(mode) = TargetingMode::try_from(t.mode) else {
            return Err(ViewError::Ignored(format!(
                "targeting mode {} is not one of 0-3; left unchanged",
                t.mode
            )));
        };
        let values = [
            t.yaw,
            t.pitch,
            t.roll,
            t.x_offset,
            t.y_offset,
            t.latitude,
            t.longitude,
            t.altitude,
        ];
        if !values.iter().all(|v| v.is_finite()) {
            return Err(ViewError::Invalid(
                "a targeting request with a non-finite value".into(),
            ));
        }
        if mode == TargetingMode::Coordinal && t.latitude.abs() > 90.0 {
            return Err(ViewError::Invalid(format!(
                "target latitude {} beyond ±90°",
                t.latitude
            )));
        }
        // Angles are stored in the frames the (new) lock flags select.
        self.reframe(t.lock_flags & (LOCK_YAW | LOCK_PITCH | LOCK_ROLL));
        if t.euler_delta {
            self.yaw = wrap_pi(self.yaw + t.yaw);
            self.pitch = clamp_pitch(self.pitch + t.pitch);
            self.roll = clamp_pitch(self.roll + t.roll);
        } else {
            self.yaw = wrap_pi(t.yaw);
            self.pitch = clamp_pitch(t.pitch);
            self.roll = clamp_pitch(t.roll);
        }
        self.euler_delta = t.euler_delta;
        self.x_offset = t.x_offset.clamp(-1.0, 1.0);
        self.y_offset = t.y_offset.clamp(-1.0, 1.0);
        self.mode = mode;
        match mode {
            TargetingMode::Coordinal => {
                self.target = Some(Target::Relative {
                    lat: t.latitude,
                    lon: t.longitude,
                    alt_rel: t.altitude,
                });
            }
            TargetingMode::Detection => self.detection_id = NO_DETECTION,
            TargetingMode::Directional | TargetingMode::SingleTarget => {}
        }
        self.yaw_rate = 0.0;
        self.pitch_rate = 0.0;
        Ok(())
    }

    /// An optics request (already range-checked). Zoom and crop mode are applied; a
    /// FOV outside 0.1..3.14 rad is left unchanged and reported as
    /// [`ViewError::Ignored`] (after applying the rest).
    pub fn set_optics(&mut self, o: &Optics) -> Result<(), ViewError> {
        let crop = match o.crop_mode {
            0 => CropMode::Default,
            1 => CropMode::Rectified,
            2 => CropMode::Panoramic,
            other => {
                return Err(ViewError::Invalid(format!(
                    "crop mode {other} is not one of 0-2"
                )))
            }
        };
        self.zoom = f64::from(o.zoom).clamp(ZOOM_MIN, ZOOM_MAX);
        self.zoom_rate = 0.0;
        self.crop = crop;
        if o.fov.is_finite() && (FOV_MIN_RAD..=FOV_MAX_RAD).contains(&o.fov) {
            self.fov = o.fov;
            Ok(())
        } else {
            Err(ViewError::Ignored(format!(
                "fov {} rad outside 0.1..3.14, left at {:.3}; zoom and crop mode applied",
                o.fov, self.fov
            )))
        }
    }

    /// Gimbal v2: angles (None = keep that axis) and rates (rad/s); yaw global or
    /// relative to the heading. Directional mode.
    pub fn gimbal(
        &mut self,
        yaw: Option<f64>,
        pitch: Option<f64>,
        yaw_rate: Option<f64>,
        pitch_rate: Option<f64>,
        yaw_global: bool,
    ) -> Result<(), ViewError> {
        let all = [yaw, pitch, yaw_rate, pitch_rate];
        if all.iter().flatten().any(|v| !v.is_finite()) {
            return Err(ViewError::Invalid(
                "gimbal attitude with a non-finite angle or rate".into(),
            ));
        }
        if self.mode != TargetingMode::Directional {
            self.hold_current_direction();
        }
        // Pitch is always from the horizon on gimbal v2; the roll lock is kept.
        let mut flags = (self.lock_flags & LOCK_ROLL) | LOCK_PITCH;
        if yaw_global {
            flags |= LOCK_YAW;
        }
        self.reframe(flags);
        if let Some(yaw) = yaw {
            self.yaw = wrap_pi(yaw);
        }
        if let Some(pitch) = pitch {
            self.pitch = clamp_pitch(pitch);
        }
        self.yaw_rate = yaw_rate.unwrap_or(0.0);
        self.pitch_rate = pitch_rate.unwrap_or(0.0);
        self.euler_delta = false;
        self.mode = TargetingMode::Directional;
        Ok(())
    }

    /// Gimbal v2 / DO_SET_ROI_LOCATION: coordinal at an absolute position.
    pub fn roi(&mut self, target: GeoPosition) {
        self.target = Some(Target::Absolute(target));
        self.mode = TargetingMode::Coordinal;
        self.yaw_rate = 0.0;
        self.pitch_rate = 0.0;
    }

    /// DO_SET_ROI_NONE: hold the current direction, directional.
    pub fn roi_none(&mut self) {
        self.hold_current_direction();
        self.yaw_rate = 0.0;
        self.pitch_rate = 0.0;
    }

    /// MAVLink zoom (CAMERA_ZOOM_TYPE `mode`, `value`).
    pub fn zoom_mavlink(&mut self, mode: u8, value: f32) -> Result<(), ViewError> {
        if !value.is_finite() {
            return Err(ViewError::Invalid(format!("zoom value {value}")));
        }
        let value = f64::from(value);
        match mode {
            0 => {
                if ![-1.0, 0.0, 1.0].contains(&value) {
                    return Err(ViewError::Invalid(format!(
                        "zoom step {value}: must be -1, 0 or 1"
                    )));
                }
                self.zoom = (self.zoom + value * ZOOM_STEP).clamp(ZOOM_MIN, ZOOM_MAX);
                self.zoom_rate = 0.0;
            }
            1 => {
                if !(-1.0..=1.0).contains(&value) {
                    return Err(ViewError::Invalid(format!(
                        "continuous zoom {value}: must be within -1..1"
                    )));
                }
                self.zoom_rate = value * ZOOM_RATE_PER_S;
            }
            2 => {
                if !(0.0..=100.0).contains(&value) {
                    return Err(ViewError::Invalid(format!(
                        "zoom range {value} %: must be within 0..100"
                    )));
                }
                self.zoom = ZOOM_MIN + (ZOOM_MAX - ZOOM_MIN) * value / 100.0;
                self.zoom_rate = 0.0;
            }
            3 => {
                return Err(ViewError::Invalid(
                    "zoom by focal length is not supported, virtual cameras have no focal length"
                        .into(),
                ))
            }
            other => {
                return Err(ViewError::Invalid(format!(
                    "unknown CAMERA_ZOOM_TYPE {other}"
                )))
            }
        }
        Ok(())
    }

    pub fn crop_mode(&self) -> CropMode {
        self.crop
    }

    pub fn targeting_mode(&self) -> TargetingMode {
        self.mode
    }

    /// The detection followed in detection mode (255 none yet).
    pub fn detection_id(&self) -> u8 {
        self.detection_id
    }

    /// Detection mode following `id` (chosen by the pipeline, e.g. from the sorted list).
    pub fn follow_detection(&mut self, id: u8) {
        self.mode = TargetingMode::Detection;
        self.detection_id = id;
        self.yaw_rate = 0.0;
        self.pitch_rate = 0.0;
    }

    /// The view's size in pixels (its aspect scales vertical offsets). Ignored if zero.
    pub fn set_view_size(&mut self, width: u16, height: u16) {
        if width > 0 && height > 0 {
            self.view_size = (f64::from(width), f64::from(height));
        }
    }

    /// The DigiView zoom as it stands (continuous zoom may leave it between steps).
    pub fn zoom(&self) -> f64 {
        self.zoom
    }

    /// The zoom factor `2^(zoom / 32)`.
    pub fn zoom_factor(&self) -> f64 {
        (self.zoom / ZOOM_PER_DOUBLING).exp2()
    }

    /// Horizontal field of view rendered (fov narrowed by zoom), radians.
    pub fn effective_hfov(&self) -> f64 {
        (self.fov / self.zoom_factor()).clamp(FOV_MIN_RAD, FOV_MAX_RAD)
    }

    /// The orientation of the last successful aim (what a view shows while `aim`
    /// returns `None`).
    pub fn last_aim(&self) -> Option<UnitQuaternion<f64>> {
        self.last_aim
    }

    /// The view's orientation (camera → NED) for this frame; `None` keeps the last aim
    /// (e.g. the detection is lost), or if there was none.
    pub fn aim(&mut self, ctx: &AimContext<'_>) -> Option<UnitQuaternion<f64>> {
        let dt = if ctx.dt_s.is_finite() {
            ctx.dt_s.clamp(0.0, MAX_DT_S)
        } else {
            0.0
        };
        if self.zoom_rate != 0.0 {
            self.zoom = (self.zoom + self.zoom_rate * dt).clamp(ZOOM_MIN, ZOOM_MAX);
        }
        let (body_roll, body_pitch, heading) = ctx.vehicle.euler_angles();
        let vehicle_ok = [body_roll, body_pitch, heading]
            .iter()
            .all(|v| v.is_finite());
        if !vehicle_ok {
            self.aim_valid = false;
            return None;
        }
        self.last_heading = Some(heading);
        self.last_body_pitch = Some(body_pitch);
        if let Some(p) = ctx.position {
            self.last_position = Some(p);
        }
        let roll_v = if self.lock_flags & LOCK_ROLL != 0 {
            0.0
        } else {
            body_roll
        };
        let base = match self.mode {
            TargetingMode::Directional => {
                if self.yaw_rate != 0.0 || self.pitch_rate != 0.0 {
                    self.yaw = wrap_pi(self.yaw + self.yaw_rate * dt);
                    self.pitch = clamp_pitch(self.pitch + self.pitch_rate * dt);
                }
                let yaw_v = if self.lock_flags & LOCK_YAW != 0 {
                    self.yaw
                } else {
                    heading + self.yaw
                };
                let pitch_v = if self.lock_flags & LOCK_PITCH != 0 {
                    self.pitch
                } else {
                    clamp_pitch(body_pitch + self.pitch)
                };
                Some(UnitQuaternion::from_euler_angles(roll_v, pitch_v, yaw_v))
            }
            TargetingMode::Coordinal => self
                .target_ned(ctx.position)
                .and_then(|d| look_along(&d, roll_v)),
            TargetingMode::Detection => {
                if self.detection_id == NO_DETECTION {
                    self.detection_id = self.pick_detection(ctx);
                }
                if self.detection_id == NO_DETECTION {
                    None
                } else {
                    (ctx.detection)(self.detection_id).and_then(|d| look_along(&d, roll_v))
                }
            }
            TargetingMode::SingleTarget => ctx.single_target.and_then(|d| look_along(&d, roll_v)),
        };
        let Some(base) = base else {
            self.aim_valid = false;
            return None;
        };
        let aim = self.apply_offsets(base);
        self.last_base = Some(base);
        self.last_aim = Some(aim);
        self.aim_valid = true;
        Some(aim)
    }

    /// The bus state: what it was told, the last aim, its rectangle in the output.
    pub fn state(&self, active: bool, rect: [u16; 4]) -> VirtualCamState {
        let (lat, lon, alt_rel) = match self.target {
            Some(Target::Relative { lat, lon, alt_rel }) => (lat, lon, alt_rel),
            Some(Target::Absolute(p)) => (
                p.lat_deg,
                p.lon_deg,
                self.last_position
                    .map_or(0.0, |v| p.alt_msl_m - v.alt_msl_m),
            ),
            None => (0.0, 0.0, 0.0),
        };
        let (q, view) = match self.last_aim {
            Some(q) => (
                [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
                YawPitch::of(&(q * Vector3::x())),
            ),
            None => ([0.0; 4], None),
        };
        VirtualCamState {
            targeting_mode: self.mode.to_wire(),
            euler_delta: u8::from(self.euler_delta),
            lock_flags: self.lock_flags,
            crop_mode: self.crop.to_wire(),
            // In range by the clamp.
            zoom: self.zoom.round().clamp(ZOOM_MIN, ZOOM_MAX) as i8,
            active: u8::from(active),
            detection_id: self.detection_id,
            aim_valid: u8::from(self.aim_valid),
            yaw_rad: self.yaw as f32,
            pitch_rad: self.pitch as f32,
            roll_rad: self.roll as f32,
            x_offset: self.x_offset as f32,
            y_offset: self.y_offset as f32,
            fov_rad: self.fov as f32,
            effective_hfov_rad: self.effective_hfov() as f32,
            target_alt_rel_m: alt_rel as f32,
            target_lat_deg: lat,
            target_lon_deg: lon,
            ned_from_cam_q: q,
            view_yaw_rad: view.map_or(0.0, |v| v.yaw as f32),
            view_pitch_rad: view.map_or(0.0, |v| v.pitch as f32),
            view_rect: rect,
        }
    }

    /// The coordinal target's NED offset from the vehicle.
    fn target_ned(&self, position: Option<GeoPosition>) -> Option<Vector3<f64>> {
        let vehicle = position?;
        let target = match self.target? {
            Target::Relative { lat, lon, alt_rel } => GeoPosition {
                lat_deg: lat,
                lon_deg: lon,
                alt_msl_m: vehicle.alt_msl_m + alt_rel,
            },
            Target::Absolute(p) => p,
        };
        let ned = vehicle.ned_to(&target);
        (ned.iter().all(|v| v.is_finite()) && ned.norm() > 1e-6).then_some(ned)
    }

    /// The known detection nearest the view's current centre.
    fn pick_detection(&self, ctx: &AimContext<'_>) -> u8 {
        let centre = self.last_aim.unwrap_or(ctx.vehicle) * Vector3::x();
        DETECTION_IDS
            .filter_map(|id| (ctx.detection)(id).map(|d| (id, d.dot(&centre))))
            .filter(|(_, cos)| cos.is_finite())
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(NO_DETECTION, |(id, _)| id)
    }

    /// Turns the base orientation so its axis is the direction the base view shows at
    /// the offset.
    fn apply_offsets(&self, base: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        if self.x_offset == 0.0 && self.y_offset == 0.0 {
            return base;
        }
        let (w, h) = self.view_size;
        let u = (1.0 + self.x_offset) / 2.0 * w;
        let v = (1.0 - self.y_offset) / 2.0 * h;
        match view_ray(self.crop, w, h, self.effective_hfov(), u, v) {
            Some(ray) => base * turn_to(&ray),
            None => base,
        }
    }

    /// Directional mode holding the direction of the last aim (offsets excluded).
    fn hold_current_direction(&mut self) {
        self.mode = TargetingMode::Directional;
        let Some(base) = self.last_base else {
            return;
        };
        let Some(dir) = YawPitch::of(&(base * Vector3::x())) else {
            return;
        };
        self.yaw = if self.lock_flags & LOCK_YAW != 0 {
            dir.yaw
        } else {
            wrap_pi(dir.yaw - self.last_heading.unwrap_or(0.0))
        };
        self.pitch = if self.lock_flags & LOCK_PITCH != 0 {
            dir.pitch
        } else {
            clamp_pitch(dir.pitch - self.last_body_pitch.unwrap_or(0.0))
        };
    }

    /// Changes the lock flags, converting the stored yaw/pitch into the new frames with
    /// the last known heading / body pitch (unchanged if none is known yet).
    fn reframe(&mut self, flags: u8) {
        let changed = self.lock_flags ^ flags;
        if changed & LOCK_YAW != 0 {
            if let Some(heading) = self.last_heading {
                self.yaw = if flags & LOCK_YAW != 0 {
                    wrap_pi(self.yaw + heading)
                } else {
                    wrap_pi(self.yaw - heading)
                };
            }
        }
        if changed & LOCK_PITCH != 0 {
            if let Some(body) = self.last_body_pitch {
                self.pitch = if flags & LOCK_PITCH != 0 {
                    clamp_pitch(self.pitch + body)
                } else {
                    clamp_pitch(self.pitch - body)
                };
            }
        }
        self.lock_flags = flags;
    }
}

fn clamp_pitch(p: f64) -> f64 {
    p.clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2)
}

/// The orientation whose optical axis is `d` (NED), rolled by `roll`.
fn look_along(d: &Vector3<f64>, roll: f64) -> Option<UnitQuaternion<f64>> {
    let yp = YawPitch::of(d)?;
    Some(UnitQuaternion::from_euler_angles(roll, yp.pitch, yp.yaw))
}

/// The rotation (in the view's own frame) turning its axis to `ray`: yaw about the
/// view's z, then pitch about the turned y, so the horizon of the view stays level
/// relative to it.
fn turn_to(ray: &Vector3<f64>) -> UnitQuaternion<f64> {
    let yaw = ray.y.atan2(ray.x);
    let pitch = (-ray.z).atan2(ray.x.hypot(ray.y));
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch)
}

/// The ray (view camera frame, not normalised) through the continuous pixel `(u, v)`
/// of a `w`×`h` view with horizontal FOV `hfov`: a pinhole for rectified views; for
/// panoramic ones yaw linear across the width and a pinhole vertically with the focal
/// length `w / hfov` (the same angular scale at the centre). `None` for a bad size/FOV.
pub fn view_ray(crop: CropMode, w: f64, h: f64, hfov: f64, u: f64, v: f64) -> Option<Vector3<f64>> {
    if !(w > 0.0 && h > 0.0 && hfov > 0.0 && hfov.is_finite()) {
        return None;
    }
    match crop {
        CropMode::Panoramic => {
            let yaw = (u / w - 0.5) * hfov;
            let f = w / hfov;
            Some(Vector3::new(yaw.cos(), yaw.sin(), (v - h / 2.0) / f))
        }
        CropMode::Default | CropMode::Rectified => {
            if hfov >= std::f64::consts::PI {
                return None;
            }
            let f = w / 2.0 / (hfov / 2.0).tan();
            Some(Vector3::new(1.0, (u - w / 2.0) / f, (v - h / 2.0) / f))
        }
    }
}

/// The pinhole model of a view `w`×`h` pixels with horizontal FOV `hfov`.
pub fn view_model(w: u32, h: u32, hfov: f64) -> Option<CameraModel> {
    if w == 0 || h == 0 {
        return None;
    }
    CameraModel::from_hfov(f64::from(w), f64::from(h), hfov).ok()
}

/// CAM_OFFSET for a virtual camera as published: the direction at offset (x, y) of
/// its last rendered view; `heading` the vehicle's heading (radians). Panoramic views
/// use their cylindrical mapping ([`view_ray`]).
pub fn cam_offset(cam: &VirtualCamState, heading: f64, x: f64, y: f64) -> Option<Direction> {
    let [_, _, w, h] = cam.view_rect;
    if w == 0 || h == 0 || !x.is_finite() || !y.is_finite() || !heading.is_finite() {
        return None;
    }
    let [qw, qx, qy, qz] = cam.ned_from_cam_q.map(f64::from);
    let q = Quaternion::new(qw, qx, qy, qz);
    let norm = q.norm();
    if !norm.is_finite() || (norm - 1.0).abs() > 0.01 {
        return None;
    }
    let pose = CameraPose::from_parts(UnitQuaternion::from_quaternion(q), heading);
    let hfov = f64::from(cam.effective_hfov_rad);
    let crop = CropMode::try_from(cam.crop_mode).unwrap_or(CropMode::Rectified);
    if crop == CropMode::Panoramic {
        let (w, h) = (f64::from(w), f64::from(h));
        let u = (1.0 + x) / 2.0 * w;
        let v = (1.0 - y) / 2.0 * h;
        let ray = view_ray(crop, w, h, hfov, u, v)?;
        return Direction::of_camera_ray(&pose, &ray);
    }
    let model = view_model(u32::from(w), u32::from(h), hfov)?;
    let pixel: Point2<f64> = model.offset_to_pixel(Offset { x, y });
    Direction::of_pixel(&model, &pose, &pixel)
}

#[cfg(test)]
mod tests;
