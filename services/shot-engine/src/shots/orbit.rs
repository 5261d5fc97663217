//! Orbit: circle a fixed ROI at the radius and altitude the vehicle had when the
//! orbit began, at the cruise speed, camera on the ROI.

use nalgebra::{Vector2, Vector3};
use skymesh_runtime::angle::wrap_pi;

use super::geo::{GeoPoint, LocalFrame};
use super::motion::{
    dt64, radial, sqrt_controller, to_f32, Hold1, Lim, Radial, Shaper, DIRECTION_MIN_M,
    VELOCITY_LAG_S,
};
use super::{Guidance, Limits, VehicleView};

/// The smallest orbit: a vehicle closer to the ROI than this (or right above it)
/// first moves out to this radius, metres. Independent of [`Limits`].
pub const MIN_ORBIT_RADIUS_M: f32 = 2.0;

/// Circle a point of interest.
#[derive(Debug, Clone)]
pub struct Orbit {
    roi: GeoPoint,
    /// NED around the ROI.
    frame: LocalFrame,
    radius: f64,
    /// Outward direction when too close to the ROI to tell: where the vehicle was at
    /// the start, else behind its nose.
    fallback_out: Vector2<f64>,
    /// Altitude held, NED down in `frame`.
    hold_down: f64,
    /// Angle around the ROI, radians clockwise from north, unwrapped across steps.
    angle: Option<f64>,
    shaper: Shaper,
    pause: Hold1,
}

impl Orbit {
    /// Orbit `roi` at the vehicle's current ground distance (at least
    /// [`MIN_ORBIT_RADIUS_M`]) and current altitude.
    pub fn new(roi: GeoPoint, v: &VehicleView) -> Orbit {
        let frame = LocalFrame::new(roi);
        let p = frame.to_ned(&v.position);
        let h = Vector2::new(p.x, p.y);
        let r = h.norm();
        let fallback_out = if r > DIRECTION_MIN_M {
            h / r
        } else {
            let hd = f64::from(v.heading_deg).to_radians();
            let hd = if hd.is_finite() { hd } else { 0.0 };
            -Vector2::new(hd.cos(), hd.sin())
        };
        Orbit {
            roi,
            frame,
            radius: r.max(f64::from(MIN_ORBIT_RADIUS_M)),
            fallback_out,
            hold_down: p.z,
            angle: None,
            shaper: Shaper::default(),
            pause: Hold1::default(),
        }
    }

    /// The point circled.
    pub fn roi(&self) -> GeoPoint {
        self.roi
    }

    /// The orbit's radius, metres.
    pub fn radius_m(&self) -> f32 {
        self.radius as f32
    }

    /// A new ROI starts a new orbit (radius = current distance to the new ROI); the
    /// setpoint stays continuous.
    pub fn set_roi(&mut self, roi: GeoPoint, v: &VehicleView) {
        let shaper = self.shaper;
        *self = Orbit::new(roi, v);
        self.shaper = shaper;
    }

    /// Tangential speed = cruise_speed (m/s, sign = direction: positive
    /// counter-clockwise seen from above, as the Solo app's right arrow; limited so the
    /// turn needs at most the planning share of `max_accel`), radial error corrected
    /// with `position_gain`, altitude held; camera on the ROI. Cruise speed 0 brakes
    /// and holds the point on the circle where the vehicle stops.
    pub fn step(
        &mut self,
        v: &VehicleView,
        dt_s: f32,
        cruise_speed: f32,
        lim: &Limits,
    ) -> Guidance {
        let lim = Lim::new(lim);
        let dt = dt64(dt_s);
        let Radial {
            p,
            r,
            out,
            ccw,
            angle: angle_now,
        } = radial(&self.frame, v, self.fallback_out);
        let angle = match self.angle {
            Some(prev) => prev + wrap_pi(angle_now - prev),
            None => angle_now,
        };
        self.angle = Some(angle);

        // Turn within the planning acceleration: v²/R ≤ a.
        let max_tangential = lim.speed.min((lim.plan_accel() * self.radius).sqrt());
        let cruise = if cruise_speed.is_finite() {
            f64::from(cruise_speed)
        } else {
            0.0
        };
        let tangential = if cruise == 0.0 {
            // Arc length counter-clockwise (angle grows clockwise).
            let arc = -angle * self.radius;
            let commanded = self.shaper.current(v);
            let along = commanded.x * ccw.x + commanded.y * ccw.y;
            self.pause
                .speed(arc, along, (f64::NEG_INFINITY, f64::INFINITY), &lim, dt)
                .clamp(-max_tangential, max_tangential)
        } else {
            self.pause.release();
            cruise.clamp(-max_tangential, max_tangential)
        };
        let radial = sqrt_controller(self.radius - r, lim.gain, lim.plan_accel(), dt);
        // Centripetal feed-forward: aim the velocity where the curve will be once the
        // vehicle has followed it.
        let inward = tangential * tangential / self.radius * VELOCITY_LAG_S;
        let xy = out * (radial - inward) + ccw * tangential;
        let down = sqrt_controller(self.hold_down - p.z, lim.gain, lim.plan_accel(), dt);
        let wish = Vector3::new(xy.x, xy.y, down);
        let vel = self.shaper.shape(wish, v, dt_s, &lim);
        Guidance {
            velocity_ned_mps: to_f32(&vel),
            roi: Some(self.roi),
            yaw_deg: None,
            gimbal_pitch_deg: None,
        }
    }
}
