//! Zipline: an unbounded straight line from where the vehicle is, along where the
//! camera looks, flown at the cruise speed.
//!
//! Contract (for the engine):
//! - [`Zipline::new`]`(view, is_3d)` lays the line through the vehicle's position
//!   along the camera yaw; with `is_3d` it also tilts with the camera pitch (a
//!   camera looking 30° down gives a line descending at 30° when flown forward),
//!   else it is horizontal. A camera pitched steeper than [`MAX_3D_PITCH_DEG`] is
//!   read as that pitch (straight down has no forward direction). The A button makes
//!   a new line: [`Zipline::relay`] (keeps the setpoint continuous and the spot lock).
//! - [`Zipline::step`]`(view, dt, cruise_speed, limits)`: along the line at
//!   `cruise_speed` (m/s, positive = the way the camera looked, negative = back;
//!   limited by the horizontal/vertical limits along the line's direction), the
//!   cross-track error (3-D distance from the line) pulled back with the position
//!   gain. Cruise speed 0 = pause: brake, then hold the point where it stopped.
//!   The line has no ends: the engine (or the geofence) stops it.
//! - Camera: free look (`roi`, `yaw_deg`, `gimbal_pitch_deg` all `None`: the pilot
//!   aims) unless a spot lock is set with [`Zipline::set_spot_lock`], then `roi` =
//!   the spot. [`Zipline::projected_spot`] is where a spot lock would look now (the
//!   projected ROI of `shots::projected_roi`): the engine locks it on B or
//!   SOLO_ZIPLINE_LOCK and sends it to the app as a SOLO_MESSAGE_LOCATION.

use nalgebra::Vector3;

use super::geo::{GeoPoint, LocalFrame};
use super::motion::{dt64, sqrt_controller, to_f32, Hold1, Lim, Shaper};
use super::{projected_roi, Guidance, Limits, VehicleView};

/// The steepest a 3-D zipline tilts, degrees either way (a camera looking further
/// up or down is read as this).
pub const MAX_3D_PITCH_DEG: f32 = 80.0;

/// An unbounded line through the vehicle's starting position.
#[derive(Debug, Clone)]
pub struct Zipline {
    /// NED around the line's origin (where the vehicle was when it was laid).
    frame: LocalFrame,
    /// Unit direction the camera looked (NED).
    dir: Vector3<f64>,
    is_3d: bool,
    yaw_deg: f32,
    pitch_deg: f32,
    spot: Option<GeoPoint>,
    /// Signed distance along the line of the last step, metres.
    along: f64,
    /// Distance from the line of the last step, metres.
    cross: f64,
    shaper: Shaper,
    pause: Hold1,
}

impl Zipline {
    /// A line from the vehicle's position along its camera yaw (and camera pitch,
    /// clamped to ±[`MAX_3D_PITCH_DEG`], when `is_3d`; else horizontal). A camera
    /// without numbers uses the heading and pitch 0.
    pub fn new(v: &VehicleView, is_3d: bool) -> Zipline {
        let yaw = [v.camera_yaw_deg, v.heading_deg]
            .into_iter()
            .find(|y| y.is_finite())
            .unwrap_or(0.0);
        let yaw = f64::from(yaw).rem_euclid(360.0) as f32;
        let pitch = if is_3d && v.camera_pitch_deg.is_finite() {
            v.camera_pitch_deg
                .clamp(-MAX_3D_PITCH_DEG, MAX_3D_PITCH_DEG)
        } else {
            0.0
        };
        let (sy, cy) = f64::from(yaw).to_radians().sin_cos();
        let (sp, cp) = f64::from(pitch).to_radians().sin_cos();
        Zipline {
            frame: LocalFrame::new(v.position),
            dir: Vector3::new(cp * cy, cp * sy, -sp),
            is_3d,
            yaw_deg: yaw,
            pitch_deg: pitch,
            spot: None,
            along: 0.0,
            cross: 0.0,
            shaper: Shaper::default(),
            pause: Hold1::default(),
        }
    }

    /// A new line from the vehicle's position and camera now (the A button), same
    /// 2-D/3-D choice; the spot lock and the setpoint continuity are kept.
    pub fn relay(&mut self, v: &VehicleView) {
        let (shaper, spot) = (self.shaper, self.spot);
        *self = Zipline::new(v, self.is_3d);
        self.shaper = shaper;
        self.spot = spot;
    }

    /// Whether the line follows the camera pitch.
    pub fn is_3d(&self) -> bool {
        self.is_3d
    }

    /// Where the line was laid.
    pub fn origin(&self) -> GeoPoint {
        self.frame.origin()
    }

    /// The line's direction: yaw (degrees 0..360) and pitch (degrees, down negative).
    pub fn direction_deg(&self) -> (f32, f32) {
        (self.yaw_deg, self.pitch_deg)
    }

    /// Lock the camera on a spot (`Some`), or give it back to the pilot (`None`).
    pub fn set_spot_lock(&mut self, spot: Option<GeoPoint>) {
        self.spot = spot;
    }

    /// The locked spot, if any.
    pub fn spot_lock(&self) -> Option<GeoPoint> {
        self.spot
    }

    /// Where a spot lock would look now: the projected ROI of the camera
    /// ([`projected_roi`]).
    pub fn projected_spot(v: &VehicleView) -> GeoPoint {
        projected_roi(v)
    }

    /// Signed distance along the line from its origin at the last step, metres.
    pub fn along_m(&self) -> f32 {
        self.along as f32
    }

    /// Distance from the line at the last step, metres.
    pub fn cross_track_m(&self) -> f32 {
        self.cross as f32
    }

    /// Fly along the line at `cruise_speed` (see the module doc), holding it.
    pub fn step(
        &mut self,
        v: &VehicleView,
        dt_s: f32,
        cruise_speed: f32,
        lim: &Limits,
    ) -> Guidance {
        let lim = Lim::new(lim);
        let dt = dt64(dt_s);
        let pos = self.frame.to_ned(&v.position);
        let along = pos.dot(&self.dir);
        let foot = self.dir * along;
        let err = foot - pos;
        let d = err.norm();
        self.along = along;
        self.cross = d;
        let cruise = if cruise_speed.is_finite() {
            f64::from(cruise_speed)
        } else {
            0.0
        };
        let max = lim.speed_along(&self.dir);
        let speed = if cruise == 0.0 {
            let commanded = self.shaper.current(v).dot(&self.dir);
            self.pause
                .speed(
                    along,
                    commanded,
                    (f64::NEG_INFINITY, f64::INFINITY),
                    &lim,
                    dt,
                )
                .clamp(-max, max)
        } else {
            self.pause.release();
            cruise.clamp(-max, max)
        };
        let back = if d > 1e-9 {
            err * (sqrt_controller(d, lim.gain, lim.plan_accel(), dt) / d)
        } else {
            Vector3::zeros()
        };
        let vel = self.shaper.shape(self.dir * speed + back, v, dt_s, &lim);
        Guidance {
            velocity_ned_mps: to_f32(&vel),
            roi: self.spot,
            yaw_deg: None,
            gimbal_pitch_deg: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HOME: GeoPoint = GeoPoint {
        lat_deg: -35.363_261,
        lon_deg: 149.165_230,
        alt_rel_m: 20.0,
    };

    fn view(yaw: f32, pitch: f32) -> VehicleView {
        VehicleView {
            position: HOME,
            vel_ned_mps: [0.0; 3],
            heading_deg: 10.0,
            camera_pitch_deg: pitch,
            camera_yaw_deg: yaw,
        }
    }

    #[test]
    fn the_line_follows_the_camera_yaw_and_pitch_only_in_3d() {
        let flat = Zipline::new(&view(90.0, -30.0), false);
        assert_eq!(flat.direction_deg(), (90.0, 0.0));
        assert!((flat.dir - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-9);
        let tilted = Zipline::new(&view(90.0, -30.0), true);
        assert_eq!(tilted.direction_deg(), (90.0, -30.0));
        let want = Vector3::new(0.0, 30f64.to_radians().cos(), 0.5);
        assert!((tilted.dir - want).norm() < 1e-9, "{:?}", tilted.dir);
        // Straight down is clamped; no camera numbers: heading, level.
        let down = Zipline::new(&view(0.0, -90.0), true);
        assert_eq!(down.direction_deg().1, -MAX_3D_PITCH_DEG);
        let blind = Zipline::new(&view(f32::NAN, f32::NAN), true);
        assert_eq!(blind.direction_deg(), (10.0, 0.0));
        assert_eq!(blind.origin(), HOME);
    }

    #[test]
    fn spot_lock_points_the_camera_and_free_look_leaves_it() {
        let v = view(0.0, -70.0);
        let mut z = Zipline::new(&v, false);
        let lim = Limits {
            max_speed_mps: 5.0,
            max_accel_mps2: 2.5,
            max_climb_mps: 2.0,
            position_gain: 1.0,
        };
        let g = z.step(&v, 0.04, 3.0, &lim);
        assert_eq!((g.roi, g.yaw_deg, g.gimbal_pitch_deg), (None, None, None));
        let spot = Zipline::projected_spot(&v);
        assert_eq!(spot, projected_roi(&v));
        z.set_spot_lock(Some(spot));
        assert_eq!(z.step(&v, 0.04, 3.0, &lim).roi, Some(spot));
        // A new line keeps the lock.
        z.relay(&view(180.0, 0.0));
        assert_eq!(z.spot_lock(), Some(spot));
        assert_eq!(z.direction_deg().0, 180.0);
        z.set_spot_lock(None);
        assert_eq!(z.step(&v, 0.04, 3.0, &lim).roi, None);
    }
}
