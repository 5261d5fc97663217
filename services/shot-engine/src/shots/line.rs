//! A straight segment between two geodetic points, flown along at a commanded speed
//! with the cross-track error corrected: the cable of the cable cam and the track of
//! the selfie.

use nalgebra::Vector3;

use super::geo::{GeoPoint, LocalFrame};
use super::motion::{sqrt_controller, Hold1, Lim};

/// Shorter than this, a segment has no direction and is flown as a point, metres.
const DEGENERATE_M: f64 = 1e-3;

/// A segment from `start` to `end` in a NED frame centred on `start`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line {
    frame: LocalFrame,
    len: f64,
    /// Unit vector start → end (zero for a degenerate segment).
    dir: Vector3<f64>,
    pause: Hold1,
}

/// Where the vehicle is relative to a line.
#[derive(Debug, Clone, Copy)]
pub(crate) struct OnLine {
    /// Vehicle position, NED from the start.
    pub pos: Vector3<f64>,
    /// Distance along the line from the start (may be < 0 or > len).
    pub along: f64,
}

impl Line {
    pub fn new(start: &GeoPoint, end: &GeoPoint) -> Line {
        let frame = LocalFrame::new(*start);
        let e = frame.to_ned(end);
        let len = e.norm();
        let dir = if len > DEGENERATE_M {
            e / len
        } else {
            Vector3::zeros()
        };
        Line {
            frame,
            len,
            dir,
            pause: Hold1::default(),
        }
    }

    /// The start point.
    pub fn start(&self) -> GeoPoint {
        self.frame.origin()
    }

    pub fn len(&self) -> f64 {
        self.len
    }

    pub fn locate(&self, p: &GeoPoint) -> OnLine {
        let pos = self.frame.to_ned(p);
        OnLine {
            pos,
            along: pos.dot(&self.dir),
        }
    }

    /// 0 at the start .. 1 at the end, of a located position.
    pub fn parameter(&self, at: &OnLine) -> f64 {
        if self.len > DEGENERATE_M {
            (at.along / self.len).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The velocity wish that flies along the line towards `goal` (metres from the
    /// start, within the segment) at up to `speed`, stopping there, while pulling the
    /// vehicle back onto the line. `commanded` is the previous setpoint. `goal = None`
    /// is a pause: stop where braking ends and hold that point.
    pub fn wish(
        &mut self,
        at: &OnLine,
        goal: Option<f64>,
        speed: f64,
        commanded: &Vector3<f64>,
        lim: &Lim,
        dt: f64,
    ) -> Vector3<f64> {
        let cap = speed.abs().min(lim.speed_along(&self.dir));
        let along = match goal {
            Some(g) => {
                self.pause.release();
                sqrt_controller(g - at.along, lim.gain, lim.plan_accel(), dt).clamp(-cap, cap)
            }
            None => {
                let max = lim.speed_along(&self.dir);
                let c = commanded.dot(&self.dir);
                self.pause
                    .speed(at.along, c, (0.0, self.len), lim, dt)
                    .clamp(-max, max)
            }
        };
        // Back onto the line: the perpendicular error (the whole error for a point).
        let foot = self.dir * at.along;
        let err = foot - at.pos;
        let d = err.norm();
        let cross = if d > 1e-9 {
            err * (sqrt_controller(d, lim.gain, lim.plan_accel(), dt) / d)
        } else {
            Vector3::zeros()
        };
        self.dir * along + cross
    }
}
