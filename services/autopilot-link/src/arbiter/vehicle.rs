//! What the arbiter knows about the vehicle when it decides: armed, mode, a
//! recent position ([`Kinematics`]) and home, and whether that is "in the air".

use skymesh_ipc_types::{FlightMode, VehicleState};

use super::home::Home;
use super::ArbiterSettings;

/// Position and velocity of the vehicle, as far as the arbiter needs them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_rel_m: f32,
    pub vel_ned_mps: [f32; 3],
    /// How old the position fix is when the arbiter decides, s: the geofence adds it
    /// to the response time and refuses motion toward a boundary beyond
    /// [`super::geofence::MAX_FIX_AGE_S`].
    pub age_s: f32,
}

/// What the arbiter knows about the vehicle when it decides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleView {
    pub armed: bool,
    pub mode: FlightMode,
    /// `None` when no position has been received or it is older than
    /// [`VehicleView::POSITION_MAX_AGE_NS`].
    pub position: Option<Kinematics>,
    /// `None` until the autopilot reported its home.
    pub home: Option<Home>,
}

impl Default for VehicleView {
    /// Disarmed, mode unknown, no position, no home.
    fn default() -> Self {
        VehicleView {
            armed: false,
            mode: FlightMode::Unknown,
            position: None,
            home: None,
        }
    }
}

impl VehicleView {
    /// An older position is not used for the geofence or the in-air test.
    pub const POSITION_MAX_AGE_NS: u64 = 2_000_000_000;

    pub fn new(
        armed: bool,
        mode: FlightMode,
        state: Option<&VehicleState>,
        home: Option<Home>,
        now_ns: u64,
    ) -> Self {
        let position = state
            .filter(|s| {
                s.position_valid == 1
                    && now_ns.saturating_sub(s.position_stamp_ns) <= Self::POSITION_MAX_AGE_NS
            })
            .map(|s| Kinematics {
                lat_deg: s.lat_deg,
                lon_deg: s.lon_deg,
                alt_rel_m: s.alt_rel_m,
                vel_ned_mps: s.vel_ned_mps,
                age_s: now_ns.saturating_sub(s.position_stamp_ns) as f32 * 1e-9,
            });
        VehicleView {
            armed,
            mode,
            position,
            home,
        }
    }

    pub(super) fn in_air(&self, s: &ArbiterSettings) -> bool {
        self.armed
            && self.position.is_none_or(|k| {
                let [n, e, d] = k.vel_ned_mps;
                k.alt_rel_m > s.in_air_alt_m
                    || n.hypot(e) > s.in_air_speed_mps
                    || d.abs() > s.in_air_speed_mps
            })
    }
}
