//! Multipoint cable cam playback: attach to a keypoint, then fly along the spline to
//! the positions the app seeks, camera interpolated between the keypoints.
//!
//! Contract (what the engine uses):
//!
//! - [`Multipoint::new`]`(path)` with a [`SplinePath`] (built with the shot limits);
//!   nothing flies until [`Multipoint::attach`]; [`Multipoint::step`] before that
//!   brakes and holds where the vehicle is, camera left alone.
//! - [`Multipoint::attach`]`(i)` flies straight to keypoint `i` (camera to its
//!   attitude); once within [`ATTACH_RADIUS_M`] and slower than
//!   [`ATTACH_SPEED_MPS`] it is attached ([`PlaybackEvent::Attached`]) and holds
//!   there. Attaching again (another keypoint) flies there the same way.
//! - [`Multipoint::seek`]`(u, cruise_state)` (only when attached, else
//!   [`MultipointError::NotAttached`]) flies along the spline to `u` and stops there.
//!   `cruise_state` is what the app shows: 0 with `u` at the vehicle is a pause; +1
//!   (−1) with `u` not ahead (behind) means "cruise to the end (start)", as the
//!   reference ShotManager does; otherwise the vehicle flies to `u`.
//! - Speed: the cruise speed ([`Multipoint::set_cruise_speed`], or
//!   [`Multipoint::set_desired_time`] → the speed that flies the whole path in that
//!   time), never above [`SplinePath::speed_limit`] (curvature, acceleration, speed
//!   and climb limits); braking at the path's planning deceleration.
//! - [`Multipoint::pause`] brakes and holds where braking ends (the pause button).
//! - Events for SOLO_SPLINE_PLAYBACK_STATUS, drained with
//!   [`Multipoint::take_events`] after each step (or call): attached, started and
//!   stopped moving, passed a keypoint (including the first and last). The 10 Hz
//!   status while [`Multipoint::moving`] is the engine's; [`Multipoint::u`] and
//!   [`Multipoint::cruise_state`] are what it reports.
//! - Camera: yaw and gimbal pitch from [`SplinePath::camera_at`] at the vehicle's
//!   `u` in every [`Guidance`], unless [`Multipoint::set_camera_free`]`(true)`.
//!
//! Tracking: the vehicle's `s` is its projection onto the spline, searched near the
//! previous one; the along-path speed comes from the square-root controller toward
//! the goal, capped by the cruise speed and the profile at `s` and a lag ahead; the
//! velocity points along the tangent a lag ahead (centripetal feed-forward, as orbit
//! does), plus a correction back to the foot point (cross-track, as the cable does).

use nalgebra::Vector3;

use super::motion::{
    dt64, sqrt_controller, to_f32, toward, velocity, Hold1, HoldPoint, Lim, Shaper, VELOCITY_LAG_S,
};
use super::spline::SplinePath;
use super::{Guidance, Limits, VehicleView};

/// Attached once this close to the keypoint, metres (3-D).
pub const ATTACH_RADIUS_M: f64 = 1.0;

/// … and slower than this, m/s.
pub const ATTACH_SPEED_MPS: f64 = 0.5;

/// The minimum cruise speed SOLO_SPLINE_DURATIONS' maxTime is flown at unless the
/// engine sets another, m/s.
pub const DEFAULT_MIN_CRUISE_MPS: f64 = 0.5;

/// Arrived at a seek target when this close along the path, metres, …
const ARRIVE_M: f64 = 0.3;

/// … and slower than this, m/s (also the end of a pause's braking).
const STOPPED_MPS: f64 = 0.2;

/// A keypoint is passed when the vehicle comes this close to it along the path,
/// metres; it is left again at twice this.
const KEYPOINT_ZONE_M: f64 = 0.5;

/// The projection is searched this far either side of the previous `s`, metres (plus
/// the distance flown in a tick).
const TRACK_WINDOW_M: f64 = 3.0;

/// The speed cap looks this far ahead (in seconds of flight) so a lagging vehicle
/// has slowed by the time it reaches a turn.
const LOOKAHEAD_S: f64 = 2.0 * VELOCITY_LAG_S;

/// What the engine reports to the app (SOLO_SPLINE_ATTACH, _PLAYBACK_STATUS).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlaybackEvent {
    /// Reached keypoint `index` after [`Multipoint::attach`].
    Attached { index: usize },
    /// Started moving along the path.
    Started,
    /// Stopped: at the seek target, or a pause finished braking.
    Stopped,
    /// Came to keypoint `index` (including the first and the last).
    PassedKeypoint { index: usize },
}

/// Requests the controller refuses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MultipointError {
    #[error("keypoint {index} is not on the path (it has {count})")]
    NoSuchKeypoint { index: usize, count: usize },
    #[error("not attached to the path yet")]
    NotAttached,
    #[error("seek position {u} is not a number in 0..=1")]
    BadPosition { u: f32 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// Not asked to fly yet: hold.
    Idle,
    /// Flying to keypoint `index`.
    Attaching { index: usize },
    /// On the path: `goal` (metres along) or paused (`None`).
    OnPath { goal: Option<f64> },
}

/// The multipoint cable cam's playback controller.
#[derive(Debug, Clone)]
pub struct Multipoint {
    path: SplinePath,
    mode: Mode,
    /// Vehicle's position along the path, metres (valid on the path; the attach
    /// keypoint's while attaching).
    s: f64,
    cruise_mps: f64,
    min_cruise_mps: f64,
    camera_free: bool,
    moving: bool,
    /// Keypoint the vehicle is at (within the zone), for PassedKeypoint.
    zone: Option<usize>,
    events: Vec<PlaybackEvent>,
    shaper: Shaper,
    pause: Hold1,
    hold: HoldPoint,
}

impl Multipoint {
    /// Playback of `path`, idle until attached; cruise at the fastest the path
    /// allows until told otherwise.
    pub fn new(path: SplinePath) -> Multipoint {
        let cruise_mps = path.max_speed_mps();
        Multipoint {
            path,
            mode: Mode::Idle,
            s: 0.0,
            cruise_mps,
            min_cruise_mps: DEFAULT_MIN_CRUISE_MPS,
            camera_free: false,
            moving: false,
            zone: None,
            events: Vec::new(),
            shaper: Shaper::default(),
            pause: Hold1::default(),
            hold: HoldPoint::default(),
        }
    }

    /// The path flown.
    pub fn path(&self) -> &SplinePath {
        &self.path
    }

    /// The minimum cruise speed (config), m/s: the slowest `set_desired_time` picks
    /// and what `durations` reports maxTime at.
    pub fn set_min_cruise_speed(&mut self, mps: f64) {
        if mps.is_finite() && mps > 0.0 {
            self.min_cruise_mps = mps;
        }
    }

    /// SOLO_SPLINE_DURATIONS for this path.
    pub fn durations(&self) -> super::spline::Durations {
        self.path.durations(self.min_cruise_mps)
    }

    /// Cruise speed, m/s (clamped to the minimum cruise speed .. the path's fastest).
    pub fn set_cruise_speed(&mut self, mps: f64) {
        if mps.is_finite() {
            self.cruise_mps = mps.abs().clamp(
                self.min_cruise_mps.min(self.path.max_speed_mps()),
                self.path.max_speed_mps(),
            );
        }
    }

    /// SOLO_SPLINE_PATH_SETTINGS desiredTime: cruise at the speed that flies the
    /// whole path in `secs` (0 or nonsense: the fastest).
    pub fn set_desired_time(&mut self, secs: f64) {
        self.cruise_mps = if secs.is_finite() && secs > 0.0 {
            self.path.cruise_for_time(secs, self.min_cruise_mps)
        } else {
            self.path.max_speed_mps()
        };
    }

    /// The cruise speed, m/s.
    pub fn cruise_speed_mps(&self) -> f64 {
        self.cruise_mps
    }

    /// SOLO_SPLINE_PATH_SETTINGS cameraControl: `true` leaves the camera to the
    /// pilot.
    pub fn set_camera_free(&mut self, free: bool) {
        self.camera_free = free;
    }

    pub fn camera_free(&self) -> bool {
        self.camera_free
    }

    /// Fly to keypoint `index` and attach there.
    pub fn attach(&mut self, index: usize) -> Result<(), MultipointError> {
        let count = self.path.keypoints().len();
        if index >= count {
            return Err(MultipointError::NoSuchKeypoint { index, count });
        }
        self.mode = Mode::Attaching { index };
        self.s = self.path.spline().keypoint_s(index);
        self.zone = None;
        self.set_moving(false);
        self.pause.release();
        self.hold.release();
        Ok(())
    }

    /// Keypoint being attached to, while flying there.
    pub fn attaching(&self) -> Option<usize> {
        match self.mode {
            Mode::Attaching { index } => Some(index),
            _ => None,
        }
    }

    /// On the path (attached).
    pub fn attached(&self) -> bool {
        matches!(self.mode, Mode::OnPath { .. })
    }

    /// Fly along the path to `u` (see the module doc for `cruise_state`).
    pub fn seek(&mut self, u: f32, cruise_state: i32) -> Result<(), MultipointError> {
        if !self.attached() {
            return Err(MultipointError::NotAttached);
        }
        if !u.is_finite() || !(0.0..=1.0).contains(&u) {
            return Err(MultipointError::BadPosition { u });
        }
        let target = self.path.s_of_u(f64::from(u));
        let here = self.s;
        let goal = match cruise_state.signum() {
            1 if target <= here + ARRIVE_M => Some(self.path.length_m()),
            -1 if target >= here - ARRIVE_M => Some(0.0),
            0 if (target - here).abs() <= ARRIVE_M => None,
            _ => Some(target),
        };
        match goal {
            Some(g) => {
                self.pause.release();
                self.mode = Mode::OnPath { goal: Some(g) };
                if (g - here).abs() > ARRIVE_M {
                    self.set_moving(true);
                }
            }
            None => self.pause(),
        }
        Ok(())
    }

    /// Brake and hold where braking ends (on the path; before attaching: where the
    /// vehicle is).
    pub fn pause(&mut self) {
        match self.mode {
            Mode::OnPath { .. } => self.mode = Mode::OnPath { goal: None },
            Mode::Attaching { .. } | Mode::Idle => {
                self.mode = Mode::Idle;
                self.hold.release();
            }
        }
    }

    /// Whether the vehicle is moving along the path (from a seek until it stops).
    pub fn moving(&self) -> bool {
        self.moving
    }

    /// The vehicle's parametric position on the path, 0..=1 (the attach keypoint's
    /// while attaching).
    pub fn u(&self) -> f32 {
        self.path.u_of_s(self.s) as f32
    }

    /// The app's cruiseState: +1 flying toward the end, −1 toward the start, 0 not
    /// moving or braking for a pause.
    pub fn cruise_state(&self) -> i32 {
        match self.mode {
            Mode::OnPath { goal: Some(g) } if self.moving => {
                if g > self.s {
                    1
                } else if g < self.s {
                    -1
                } else {
                    0
                }
            }
            _ => 0,
        }
    }

    /// The events since the last call, oldest first.
    pub fn take_events(&mut self) -> Vec<PlaybackEvent> {
        std::mem::take(&mut self.events)
    }

    /// This tick's velocity setpoint and camera.
    pub fn step(&mut self, v: &VehicleView, dt_s: f32, limits: &Limits) -> Guidance {
        let lim = Lim::new(limits);
        let dt = dt64(dt_s);
        let pos = self.path.frame().to_ned(&v.position);
        let vel = velocity(v);
        let commanded = self.shaper.current(v);
        if let Mode::Attaching { index } = self.mode {
            let target = self
                .path
                .spline()
                .position(self.path.spline().keypoint_s(index));
            if (target - pos).norm() < ATTACH_RADIUS_M && vel.norm() < ATTACH_SPEED_MPS {
                self.mode = Mode::OnPath { goal: Some(self.s) };
                self.zone = Some(index);
                self.events.push(PlaybackEvent::Attached { index });
            }
        }
        let (wish, camera) = match self.mode {
            Mode::Idle => (self.hold.wish(&pos, &commanded, &lim, dt), false),
            Mode::Attaching { index } => {
                let target = self
                    .path
                    .spline()
                    .position(self.path.spline().keypoint_s(index));
                (toward(&pos, &target, &lim, dt), true)
            }
            Mode::OnPath { goal } => (
                self.along_path(goal, &pos, &vel, &commanded, &lim, dt),
                true,
            ),
        };
        let out = self.shaper.shape(wish, v, dt_s, &lim);
        let (yaw_deg, gimbal_pitch_deg) = if camera && !self.camera_free {
            let (pitch, yaw) = self.path.camera_at(self.path.u_of_s(self.s));
            (Some(yaw), Some(pitch))
        } else {
            (None, None)
        };
        Guidance {
            velocity_ned_mps: to_f32(&out),
            roi: None,
            yaw_deg,
            gimbal_pitch_deg,
        }
    }

    /// The velocity wish on the path toward `goal` (or paused).
    fn along_path(
        &mut self,
        goal: Option<f64>,
        pos: &Vector3<f64>,
        vel: &Vector3<f64>,
        commanded: &Vector3<f64>,
        lim: &Lim,
        dt: f64,
    ) -> Vector3<f64> {
        let len = self.path.length_m();
        let w = TRACK_WINDOW_M + vel.norm() * dt * 2.0;
        let prev = self.s;
        let s = self
            .path
            .spline()
            .closest_s(pos, Some((prev - w, prev + w)));
        self.s = s;
        self.note_keypoints(prev, s);
        let tangent = self.path.spline().tangent(s);
        let accel = self.path.profile_limits().accel_mps2;
        let commanded_along = commanded.dot(&tangent);
        let slow = vel.norm() < STOPPED_MPS;
        let (along, stopped) = match goal {
            Some(g) => {
                let dir = if g >= s { 1.0 } else { -1.0 };
                let reach = vel.dot(&tangent).abs().max(commanded_along.abs()) * LOOKAHEAD_S;
                let cap = [0.0, 0.5, 1.0]
                    .iter()
                    .map(|f| self.path.speed_limit(s + dir * reach * f))
                    .fold(self.cruise_mps, f64::min);
                let along = sqrt_controller(g - s, lim.gain, accel, dt).clamp(-cap, cap);
                (along, (g - s).abs() < ARRIVE_M && slow)
            }
            None => {
                let max = self.path.speed_limit(s);
                let along = self
                    .pause
                    .speed(s, commanded_along, (0.0, len), lim, dt)
                    .clamp(-max, max);
                (along, slow && commanded_along.abs() < STOPPED_MPS)
            }
        };
        if self.moving && stopped {
            self.set_moving(false);
        }
        // Aim along the curve a lag ahead, and back onto the path.
        let spline = self.path.spline();
        let lead = spline.tangent(s + along * VELOCITY_LAG_S);
        let err = spline.position(s) - pos;
        let d = err.norm();
        let cross = if d > 1e-9 {
            err * (sqrt_controller(d, lim.gain, lim.plan_accel(), dt) / d)
        } else {
            Vector3::zeros()
        };
        lead * along + cross
    }

    fn set_moving(&mut self, moving: bool) {
        if moving != self.moving {
            self.moving = moving;
            self.events.push(if moving {
                PlaybackEvent::Started
            } else {
                PlaybackEvent::Stopped
            });
        }
    }

    /// PassedKeypoint when the vehicle comes within the zone of a keypoint or crosses
    /// it between two ticks.
    fn note_keypoints(&mut self, prev: f64, s: f64) {
        let spline = self.path.spline();
        if let Some(z) = self.zone {
            if (s - spline.keypoint_s(z)).abs() <= 2.0 * KEYPOINT_ZONE_M {
                return;
            }
        }
        let hit = (0..spline.keypoint_count()).find(|&i| {
            let k = spline.keypoint_s(i);
            (s - k).abs() <= KEYPOINT_ZONE_M || (prev - k) * (s - k) < 0.0
        });
        if hit != self.zone {
            if let Some(index) = hit {
                self.events.push(PlaybackEvent::PassedKeypoint { index });
            }
            self.zone = hit;
        }
    }
}
