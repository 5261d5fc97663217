//! POI mode: orbit a point with the shot engine's [`Orbit`] (pure geometry: radius =
//! the vehicle's ground distance from the point when POI starts, altitude held, the
//! tangential speed the cloud sets). This module holds the pure rules; `poi_task`
//! runs them at [`TICK`] through the arbiter.
//!
//! Sign: DJI's `circle_speed` is negative clockwise, positive counter-clockwise, as
//! the shot engine's cruise speed (positive = counter-clockwise seen from above):
//! passed through unchanged.

use std::time::Duration;

use dji_proto::{codes, PoiStatus, PoiStatusNotify};
use skymesh_ipc_types::FlightMode;
use skymesh_shot_engine::shots::{GeoPoint, Limits, Orbit, VehicleView};

use crate::link::Snapshot;
use crate::progress::{is_flying, position};

/// The orbit's control period (25 Hz, as the shot engine).
pub const TICK: Duration = Duration::from_millis(40);
/// Max age of each velocity setpoint: the arbiter brakes if the gateway stops.
pub const SETPOINT_MAX_AGE_MS: u32 = 500;
/// Orbit shaping: the shot engine's defaults.
pub const MAX_ACCEL_MPS2: f32 = 2.0;
pub const MAX_CLIMB_MPS: f32 = 1.5;
pub const POSITION_GAIN: f32 = 0.5;

/// poi_status_notify reasons (the document's table).
pub mod reason {
    pub const NORMAL: u8 = 0;
    pub const POSITIONING_FAILURE: u8 = 4;
    pub const NOT_TAKEN_OFF: u8 = 5;
    pub const FLIGHT_MODE_ERROR: u8 = 6;
    /// Returning, landing, attitude mode.
    pub const UNAVAILABLE_MODE: u8 = 7;
    pub const LINK_LOST: u8 = 8;
}

/// What the shots see of the vehicle, if its position is fresh at `now_ns`.
pub fn view(s: &Snapshot, now_ns: u64) -> Option<VehicleView> {
    let position = position(s, now_ns)?;
    let st = s.state?;
    Some(VehicleView::from_samples(position, &st, s.payload.as_ref()))
}

/// Modes in which POI cannot run (the vehicle returns, lands or flies manually).
fn unavailable_mode(m: FlightMode) -> bool {
    matches!(
        m,
        FlightMode::Rtl
            | FlightMode::SmartRtl
            | FlightMode::Land
            | FlightMode::Stabilize
            | FlightMode::Acro
            | FlightMode::AltHold
    )
}

/// Whether POI may start now: `Err((result, poi reason))` if not.
pub fn enter_check(s: &Snapshot, now_ns: u64) -> Result<VehicleView, (u32, u8)> {
    if !s.status.is_some_and(|st| st.is_link_up()) {
        return Err((codes::VEHICLE_UNAVAILABLE, reason::LINK_LOST));
    }
    let Some(v) = view(s, now_ns) else {
        return Err((codes::WRONG_STATE, reason::POSITIONING_FAILURE));
    };
    if !is_flying(s) {
        return Err((codes::WRONG_STATE, reason::NOT_TAKEN_OFF));
    }
    if s.status
        .is_some_and(|st| unavailable_mode(st.flight_mode()))
    {
        return Err((codes::WRONG_STATE, reason::UNAVAILABLE_MODE));
    }
    Ok(v)
}

/// The reason to report when a running orbit has to end, if it has.
pub fn running_check(s: &Snapshot, now_ns: u64) -> Option<u8> {
    if !s.status.is_some_and(|st| st.is_link_up()) {
        return Some(reason::LINK_LOST);
    }
    if view(s, now_ns).is_none() {
        return Some(reason::POSITIONING_FAILURE);
    }
    if !s.holds_flight() {
        return Some(reason::FLIGHT_MODE_ERROR);
    }
    match s.status.map(|st| st.flight_mode()) {
        Some(FlightMode::Guided) => {}
        Some(m) if unavailable_mode(m) => return Some(reason::UNAVAILABLE_MODE),
        _ => return Some(reason::FLIGHT_MODE_ERROR),
    }
    if !is_flying(s) {
        return Some(reason::NOT_TAKEN_OFF);
    }
    None
}

/// `|speed| ≤ max`, finite.
pub fn check_speed(speed: f64, max: f64) -> Result<f64, u32> {
    if speed.is_finite() && speed.abs() <= max {
        Ok(speed)
    } else {
        Err(codes::OUT_OF_RANGE)
    }
}

/// One orbit around the point.
#[derive(Debug, Clone)]
pub struct PoiController {
    orbit: Orbit,
    speed: f64,
    max_speed: f64,
    limits: Limits,
}

impl PoiController {
    /// Orbit `point` (altitude above home) starting from `v` at `speed` m/s.
    pub fn new(point: GeoPoint, v: &VehicleView, speed: f64, max_speed: f64) -> Self {
        PoiController {
            orbit: Orbit::new(point, v),
            speed,
            max_speed,
            limits: Limits {
                max_speed_mps: max_speed as f32,
                max_accel_mps2: MAX_ACCEL_MPS2,
                max_climb_mps: MAX_CLIMB_MPS,
                position_gain: POSITION_GAIN,
            },
        }
    }

    pub fn point(&self) -> GeoPoint {
        self.orbit.roi()
    }

    pub fn radius_m(&self) -> f64 {
        f64::from(self.orbit.radius_m())
    }

    pub fn speed(&self) -> f64 {
        self.speed
    }

    pub fn set_speed(&mut self, speed: f64) {
        self.speed = speed;
    }

    /// The velocity setpoint (NED m/s) for this tick.
    pub fn step(&mut self, v: &VehicleView, dt_s: f32) -> [f32; 3] {
        self.orbit
            .step(v, dt_s, self.speed as f32, &self.limits)
            .velocity_ned_mps
    }

    /// poi_status_notify data.
    pub fn status(&self, status: PoiStatus, reason: u8) -> PoiStatusNotify {
        PoiStatusNotify {
            status,
            reason,
            circle_radius: crate::progress::round1(self.radius_m()),
            circle_speed: self.speed,
            max_circle_speed: self.max_speed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{AuthorityState, CommandSource, VehicleState, VehicleStatus};
    use skymesh_shot_engine::shots::{bearing_deg, ground_distance_m, offset};

    const POINT: GeoPoint = GeoPoint {
        lat_deg: -35.363_261,
        lon_deg: 149.165_230,
        alt_rel_m: 0.0,
    };

    fn snap(at: GeoPoint, mode: FlightMode, armed: bool) -> Snapshot {
        Snapshot {
            state: Some(VehicleState {
                position_valid: 1,
                lat_deg: at.lat_deg,
                lon_deg: at.lon_deg,
                alt_rel_m: at.alt_rel_m,
                position_stamp_ns: 1,
                ..Default::default()
            }),
            status: Some(VehicleStatus {
                armed: u8::from(armed),
                link_up: 1,
                mode: mode.to_wire(),
                ..Default::default()
            }),
            payload: None,
            authority: Some(AuthorityState {
                flight_holder: CommandSource::DjiDrc.to_wire(),
                ..Default::default()
            }),
        }
    }

    fn at(bearing: f64, dist: f64, alt: f32) -> GeoPoint {
        GeoPoint {
            alt_rel_m: alt,
            ..offset(&POINT, bearing, dist)
        }
    }

    #[test]
    fn entering_needs_a_flying_vehicle_with_a_position() {
        let flying = snap(at(0.0, 20.0, 15.0), FlightMode::Loiter, true);
        assert!(enter_check(&flying, 1).is_ok());
        let ground = snap(at(0.0, 20.0, 0.0), FlightMode::Loiter, true);
        assert_eq!(
            enter_check(&ground, 1).unwrap_err(),
            (codes::WRONG_STATE, reason::NOT_TAKEN_OFF)
        );
        let rtl = snap(at(0.0, 20.0, 15.0), FlightMode::Rtl, true);
        assert_eq!(
            enter_check(&rtl, 1).unwrap_err(),
            (codes::WRONG_STATE, reason::UNAVAILABLE_MODE)
        );
        assert_eq!(
            enter_check(&flying, 10_000_000_000).unwrap_err(),
            (codes::WRONG_STATE, reason::POSITIONING_FAILURE),
            "stale position"
        );
        let mut down = flying;
        down.status.as_mut().unwrap().link_up = 0;
        assert_eq!(
            enter_check(&down, 1).unwrap_err(),
            (codes::VEHICLE_UNAVAILABLE, reason::LINK_LOST)
        );
    }

    #[test]
    fn a_running_orbit_ends_on_mode_authority_or_landing() {
        let ok = snap(at(0.0, 20.0, 15.0), FlightMode::Guided, true);
        assert_eq!(running_check(&ok, 1), None);
        let loiter = snap(at(0.0, 20.0, 15.0), FlightMode::Loiter, true);
        assert_eq!(running_check(&loiter, 1), Some(reason::FLIGHT_MODE_ERROR));
        let land = snap(at(0.0, 20.0, 15.0), FlightMode::Land, true);
        assert_eq!(running_check(&land, 1), Some(reason::UNAVAILABLE_MODE));
        let mut taken = ok;
        taken.authority.as_mut().unwrap().flight_holder = CommandSource::ManualRc.to_wire();
        assert_eq!(running_check(&taken, 1), Some(reason::FLIGHT_MODE_ERROR));
    }

    #[test]
    fn speed_sign_and_limit() {
        assert_eq!(check_speed(-5.0, 5.0), Ok(-5.0));
        assert_eq!(check_speed(5.01, 5.0), Err(codes::OUT_OF_RANGE));
        assert_eq!(check_speed(-5.01, 5.0), Err(codes::OUT_OF_RANGE));
        assert_eq!(check_speed(f64::NAN, 5.0), Err(codes::OUT_OF_RANGE));
    }

    /// Flies the controller on an ideal point mass: positive speed goes
    /// counter-clockwise (bearing decreases), negative clockwise, at the radius the
    /// vehicle started at.
    fn fly(speed: f64) -> (f64, f64) {
        let start = at(0.0, 20.0, 15.0);
        let s = snap(start, FlightMode::Guided, true);
        let mut v = view(&s, 1).unwrap();
        let mut c = PoiController::new(POINT, &v, speed, 5.0);
        assert!((c.radius_m() - 20.0).abs() < 0.01);
        let dt = TICK.as_secs_f32();
        let mut turned = 0.0;
        let mut prev = bearing_deg(&POINT, &v.position);
        for _ in 0..250 {
            let vel = c.step(&v, dt);
            let frame = skymesh_shot_engine::shots::LocalFrame::new(v.position);
            v.position = frame.to_geo(&nalgebra::Vector3::new(
                f64::from(vel[0]) * f64::from(dt),
                f64::from(vel[1]) * f64::from(dt),
                f64::from(vel[2]) * f64::from(dt),
            ));
            v.vel_ned_mps = vel;
            let b = bearing_deg(&POINT, &v.position);
            turned += ((b - prev + 540.0) % 360.0) - 180.0;
            prev = b;
        }
        (turned, ground_distance_m(&POINT, &v.position))
    }

    #[test]
    fn the_orbit_turns_the_way_dji_says() {
        let (ccw, r) = fly(3.0);
        assert!(
            ccw < -30.0,
            "positive speed: counter-clockwise, turned {ccw}°"
        );
        assert!((r - 20.0).abs() < 1.0, "radius kept: {r}");
        let (cw, _) = fly(-3.0);
        assert!(cw > 30.0, "negative speed: clockwise, turned {cw}°");
        let (still, _) = fly(0.0);
        assert!(still.abs() < 1.0, "zero holds: {still}");
    }

    #[test]
    fn status_reports_radius_and_speeds() {
        let s = snap(at(90.0, 12.34, 15.0), FlightMode::Guided, true);
        let v = view(&s, 1).unwrap();
        let mut c = PoiController::new(POINT, &v, 2.0, 5.0);
        c.set_speed(-1.5);
        let st = c.status(PoiStatus::InProgress, reason::NORMAL);
        assert_eq!(st.circle_radius, 12.3);
        assert_eq!((st.circle_speed, st.max_circle_speed), (-1.5, 5.0));
    }
}
