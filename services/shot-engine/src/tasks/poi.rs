//! Orbiting a point of interest with the engine's [`Orbit`] (radius = the vehicle's
//! ground distance from the point when the orbit starts, altitude held, the
//! tangential speed the requester sets; positive counter-clockwise seen from above,
//! as the engine's cruise speed). This module holds the pure rules; `poi_task` runs
//! them at [`TICK`] through the arbiter.

use std::time::Duration;

use skymesh_ipc_types::{FlightMode, PoiReason, TaskResult};

use super::link::Snapshot;
use super::progress::{is_flying, position};
use crate::shots::{GeoPoint, Limits, Orbit, VehicleView};

/// The orbit's control period (25 Hz, as the shot engine).
pub const TICK: Duration = Duration::from_millis(40);
/// Max age of each velocity setpoint: the arbiter brakes if the runner stops.
pub const SETPOINT_MAX_AGE_MS: u32 = 500;
/// Orbit shaping: the shot engine's defaults.
pub const MAX_ACCEL_MPS2: f32 = 2.0;
pub const MAX_CLIMB_MPS: f32 = 1.5;
pub const POSITION_GAIN: f32 = 0.5;

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

/// Whether an orbit may start now: `Err((result, reason))` if not.
pub fn enter_check(s: &Snapshot, now_ns: u64) -> Result<VehicleView, (TaskResult, PoiReason)> {
    if !s.status.is_some_and(|st| st.is_link_up()) {
        return Err((TaskResult::VehicleUnavailable, PoiReason::LinkLost));
    }
    let Some(v) = view(s, now_ns) else {
        return Err((TaskResult::WrongState, PoiReason::PositioningFailure));
    };
    if !is_flying(s) {
        return Err((TaskResult::WrongState, PoiReason::NotTakenOff));
    }
    if s.status
        .is_some_and(|st| unavailable_mode(st.flight_mode()))
    {
        return Err((TaskResult::WrongState, PoiReason::UnavailableMode));
    }
    Ok(v)
}

/// The reason to report when a running orbit has to end, if it has.
pub fn running_check(s: &Snapshot, now_ns: u64) -> Option<PoiReason> {
    if !s.status.is_some_and(|st| st.is_link_up()) {
        return Some(PoiReason::LinkLost);
    }
    if view(s, now_ns).is_none() {
        return Some(PoiReason::PositioningFailure);
    }
    if !s.holds_flight() {
        return Some(PoiReason::FlightModeError);
    }
    match s.status.map(|st| st.flight_mode()) {
        Some(FlightMode::Guided) => {}
        Some(m) if unavailable_mode(m) => return Some(PoiReason::UnavailableMode),
        _ => return Some(PoiReason::FlightModeError),
    }
    if !is_flying(s) {
        return Some(PoiReason::NotTakenOff);
    }
    None
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

    pub fn max_speed(&self) -> f64 {
        self.max_speed
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shots::{bearing_deg, ground_distance_m, offset};
    use skymesh_ipc_types::{AuthorityState, CommandSource, VehicleState, VehicleStatus};

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
            source: CommandSource::DjiDrc,
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
            (TaskResult::WrongState, PoiReason::NotTakenOff)
        );
        let rtl = snap(at(0.0, 20.0, 15.0), FlightMode::Rtl, true);
        assert_eq!(
            enter_check(&rtl, 1).unwrap_err(),
            (TaskResult::WrongState, PoiReason::UnavailableMode)
        );
        assert_eq!(
            enter_check(&flying, 10_000_000_000).unwrap_err(),
            (TaskResult::WrongState, PoiReason::PositioningFailure),
            "stale position"
        );
        let mut down = flying;
        down.status.as_mut().unwrap().link_up = 0;
        assert_eq!(
            enter_check(&down, 1).unwrap_err(),
            (TaskResult::VehicleUnavailable, PoiReason::LinkLost)
        );
    }

    #[test]
    fn a_running_orbit_ends_on_mode_authority_or_landing() {
        let ok = snap(at(0.0, 20.0, 15.0), FlightMode::Guided, true);
        assert_eq!(running_check(&ok, 1), None);
        let loiter = snap(at(0.0, 20.0, 15.0), FlightMode::Loiter, true);
        assert_eq!(running_check(&loiter, 1), Some(PoiReason::FlightModeError));
        let land = snap(at(0.0, 20.0, 15.0), FlightMode::Land, true);
        assert_eq!(running_check(&land, 1), Some(PoiReason::UnavailableMode));
        let mut taken = ok;
        taken.authority.as_mut().unwrap().flight_holder = CommandSource::ManualRc.to_wire();
        assert_eq!(running_check(&taken, 1), Some(PoiReason::FlightModeError));
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
            let frame = crate::shots::LocalFrame::new(v.position);
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
    fn positive_speed_turns_counter_clockwise() {
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
}
