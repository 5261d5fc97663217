//! Cable cam (legacy): fly a straight cable between two recorded points at the cruise
//! speed, stopping at the ends; the camera either interpolates between the two
//! recorded attitudes or is left to the pilot.

use super::geo::{distance_m, wrap_360, GeoPoint};
use super::line::Line;
use super::motion::{dt64, to_f32, Lim, Shaper};
use super::{Guidance, Limits, VehicleView};

/// Two recorded points closer than this are "on top of each other" (the second
/// overwrites the first), metres (ShotManager's WAYPOINT_NEARNESS_THRESHOLD, 3-D).
pub const CABLE_MIN_LENGTH_M: f64 = 2.5;

/// One end of the cable: where the vehicle was and where its camera looked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CablePoint {
    /// Recorded position.
    pub position: GeoPoint,
    /// Camera yaw, degrees 0..360, earth frame.
    pub yaw_deg: f32,
    /// Camera pitch, degrees (down negative).
    pub pitch_deg: f32,
}

/// A straight cable from `a` to `b`.
#[derive(Debug, Clone)]
pub struct CableCam {
    a: CablePoint,
    b: CablePoint,
    line: Line,
    interpolate: bool,
    yaw_clockwise: bool,
    parameter: f32,
    shaper: Shaper,
}

impl CableCam {
    /// A cable from `a` to `b`, camera interpolated the shorter way round. The engine
    /// refuses cables shorter than [`CABLE_MIN_LENGTH_M`]; a degenerate one given
    /// anyway is flown as a hold at `a`.
    pub fn new(a: CablePoint, b: CablePoint) -> CableCam {
        CableCam {
            a,
            b,
            line: Line::new(&a.position, &b.position),
            interpolate: true,
            yaw_clockwise: CableCam::default_yaw_clockwise(&a, &b),
            parameter: 0.0,
            shaper: Shaper::default(),
        }
    }

    /// Whether two recorded points are "on top of each other" (closer than
    /// [`CABLE_MIN_LENGTH_M`]): the second then overwrites the first.
    pub fn too_short(a: &CablePoint, b: &CablePoint) -> bool {
        let d = distance_m(&a.position, &b.position);
        d.is_nan() || d < CABLE_MIN_LENGTH_M
    }

    /// Shorter rotation from a's yaw to b's yaw: true = clockwise (what the Solo
    /// reports as yawDirection after the second point). Exactly opposite: clockwise.
    pub fn default_yaw_clockwise(a: &CablePoint, b: &CablePoint) -> bool {
        wrap_360(f64::from(b.yaw_deg) - f64::from(a.yaw_deg)) <= 180.0
    }

    /// Camera options (SOLO_CABLE_CAM_OPTIONS camInterpolation, yawDirection).
    pub fn set_camera(&mut self, interpolate: bool, yaw_clockwise: bool) {
        self.interpolate = interpolate;
        self.yaw_clockwise = yaw_clockwise;
    }

    /// Whether the camera is interpolated.
    pub fn interpolate(&self) -> bool {
        self.interpolate
    }

    /// The direction the interpolated yaw turns from a to b.
    pub fn yaw_clockwise(&self) -> bool {
        self.yaw_clockwise
    }

    /// The recorded ends.
    pub fn points(&self) -> (CablePoint, CablePoint) {
        (self.a, self.b)
    }

    /// Fly along the segment a→b at `cruise_speed` (positive toward b, negative
    /// toward a, 0 = hold), stop at the ends (decelerate within max_accel),
    /// cross-track error corrected; camera: interpolated yaw (in the chosen direction)
    /// and pitch between the two points by the position along the cable when
    /// `interpolate`, else `None` (pilot).
    pub fn step(
        &mut self,
        v: &VehicleView,
        dt_s: f32,
        cruise_speed: f32,
        lim: &Limits,
    ) -> Guidance {
        let lim = Lim::new(lim);
        let at = self.line.locate(&v.position);
        let s = self.line.parameter(&at);
        self.parameter = s as f32;
        let cruise = if cruise_speed.is_finite() {
            f64::from(cruise_speed)
        } else {
            0.0
        };
        let goal = if cruise > 0.0 {
            Some(self.line.len())
        } else if cruise < 0.0 {
            Some(0.0)
        } else {
            None
        };
        let commanded = self.shaper.current(v);
        let wish = self
            .line
            .wish(&at, goal, cruise, &commanded, &lim, dt64(dt_s));
        let vel = self.shaper.shape(wish, v, dt_s, &lim);
        let (yaw_deg, gimbal_pitch_deg) = if self.interpolate {
            let (yaw, pitch) = self.camera_at(s);
            (Some(yaw), Some(pitch))
        } else {
            (None, None)
        };
        Guidance {
            velocity_ned_mps: to_f32(&vel),
            roi: None,
            yaw_deg,
            gimbal_pitch_deg,
        }
    }

    /// Interpolated camera yaw (0..360) and pitch at parameter `s` (0 at a, 1 at b).
    pub fn camera_at(&self, s: f64) -> (f32, f32) {
        let s = s.clamp(0.0, 1.0);
        let from = f64::from(self.a.yaw_deg);
        let cw = wrap_360(f64::from(self.b.yaw_deg) - from);
        let turn = if self.yaw_clockwise {
            cw
        } else if cw == 0.0 {
            0.0
        } else {
            cw - 360.0
        };
        let yaw = wrap_360(from + s * turn) as f32;
        let pitch = f64::from(self.a.pitch_deg)
            + s * (f64::from(self.b.pitch_deg) - f64::from(self.a.pitch_deg));
        (yaw, pitch as f32)
    }

    /// 0 at a .. 1 at b, of the last step.
    pub fn parameter(&self) -> f32 {
        self.parameter
    }

    /// Cable length, metres (3-D).
    pub fn length_m(&self) -> f32 {
        self.line.len() as f32
    }
}
