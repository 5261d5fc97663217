//! Selfie: fly to the near point, out to the far point and back, camera on the ROI.

use super::geo::GeoPoint;
use super::line::Line;
use super::motion::{dt64, to_f32, Lim, Shaper};
use super::{Guidance, Limits, VehicleView};

/// An end counts as reached this close along the track, metres.
const ARRIVED_M: f64 = 0.5;

/// Where a selfie is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SelfiePhase {
    /// Flying from wherever the shot started to the near point.
    ToNear,
    /// Near → far.
    Out,
    /// Far → near.
    Back,
    /// Holding at the near point.
    Done,
}

/// Near → far → near at the cruise speed, camera on the ROI.
#[derive(Debug, Clone)]
pub struct Selfie {
    roi: GeoPoint,
    /// The track, near (start) → far (end).
    track: Line,
    /// From the vehicle's position at the first step to near.
    approach: Option<Line>,
    phase: SelfiePhase,
    parameter: f32,
    shaper: Shaper,
}

impl Selfie {
    /// A selfie between `near` and `far`, looking at `roi`; starts in
    /// [`SelfiePhase::ToNear`].
    pub fn new(near: GeoPoint, far: GeoPoint, roi: GeoPoint) -> Selfie {
        Selfie {
            roi,
            track: Line::new(&near, &far),
            approach: None,
            phase: SelfiePhase::ToNear,
            parameter: 0.0,
            shaper: Shaper::default(),
        }
    }

    /// Fly to `near`, then near → far, then far → near, then hold at near (Done), at
    /// |cruise_speed| (0 = paused, hold position), camera on the ROI throughout.
    pub fn step(
        &mut self,
        v: &VehicleView,
        dt_s: f32,
        cruise_speed: f32,
        lim: &Limits,
    ) -> Guidance {
        let lim = Lim::new(lim);
        let dt = dt64(dt_s);
        let speed = if cruise_speed.is_finite() {
            f64::from(cruise_speed).abs()
        } else {
            0.0
        };
        let commanded = self.shaper.current(v);
        let at = self.track.locate(&v.position);
        let len = self.track.len();
        self.parameter = self.track.parameter(&at) as f32;

        if self.phase == SelfiePhase::ToNear && at.pos.norm() < ARRIVED_M {
            self.phase = SelfiePhase::Out;
        }
        if self.phase == SelfiePhase::Out && len - at.along < ARRIVED_M {
            self.phase = SelfiePhase::Back;
        }
        if self.phase == SelfiePhase::Back && at.along < ARRIVED_M {
            self.phase = SelfiePhase::Done;
        }

        let wish = match self.phase {
            SelfiePhase::ToNear => {
                let near = self.track.start();
                let approach = self
                    .approach
                    .get_or_insert_with(|| Line::new(&v.position, &near));
                let a = approach.locate(&v.position);
                let goal = (speed > 0.0).then_some(approach.len());
                approach.wish(&a, goal, speed, &commanded, &lim, dt)
            }
            SelfiePhase::Out | SelfiePhase::Back => {
                let goal = if self.phase == SelfiePhase::Out {
                    len
                } else {
                    0.0
                };
                self.track.wish(
                    &at,
                    (speed > 0.0).then_some(goal),
                    speed,
                    &commanded,
                    &lim,
                    dt,
                )
            }
            SelfiePhase::Done => {
                // Hold the near point itself, not wherever braking ended.
                self.track
                    .wish(&at, Some(0.0), lim.speed, &commanded, &lim, dt)
            }
        };
        let vel = self.shaper.shape(wish, v, dt_s, &lim);
        Guidance {
            velocity_ned_mps: to_f32(&vel),
            roi: Some(self.roi),
            yaw_deg: None,
            gimbal_pitch_deg: None,
        }
    }

    /// Where the selfie is.
    pub fn phase(&self) -> SelfiePhase {
        self.phase
    }

    /// 0 at near .. 1 at far, of the last step.
    pub fn parameter(&self) -> f32 {
        self.parameter
    }

    /// The point the camera looks at.
    pub fn roi(&self) -> GeoPoint {
        self.roi
    }
}
