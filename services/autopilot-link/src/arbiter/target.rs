//! Position targets (`GoTo`, `Takeoff`) in flight: who flies one, and when it is
//! reached, so a source that loses flight authority on the way is braked.

use skymesh_ipc_types::{Command, CommandSource};

use super::{ends_stream, geofence, Arbiter, Kinematics, VehicleView};

/// A position target in flight: who flies it and where to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Target {
    pub(super) source: CommandSource,
    /// Latitude, longitude (`GoTo`); `None` for a take-off (altitude only).
    at: Option<(f64, f64)>,
    alt_rel_m: f32,
}

impl Target {
    const ARRIVED_M: f64 = 1.5;
    const ARRIVED_ALT_M: f32 = 1.0;
    const ARRIVED_MPS: f32 = 0.5;

    fn reached(&self, k: &Kinematics) -> bool {
        let [n, e, d] = k.vel_ned_mps;
        let slow = n.hypot(e).hypot(d) < Self::ARRIVED_MPS;
        let level = (k.alt_rel_m - self.alt_rel_m).abs() < Self::ARRIVED_ALT_M;
        let there = self.at.is_none_or(|(lat, lon)| {
            geofence::LocalFrame::new(lat, lon)
                .to_local(k.lat_deg, k.lon_deg)
                .norm()
                < Self::ARRIVED_M
        });
        slow && level && there
    }
}

impl Arbiter {
    /// An executed flight command of `source`: a `GoTo` or `Takeoff` is now the
    /// position target; anything else that moves the vehicle replaces it (a velocity
    /// setpoint, `Brake`, `Land`, RTL, a mode change...). Yaw, ROI and home leave it.
    pub(super) fn track_target(&mut self, command: &Command, source: CommandSource) {
        match *command {
            Command::GoTo {
                lat_deg,
                lon_deg,
                alt_rel_m,
                ..
            } => {
                self.position_target = Some(Target {
                    source,
                    at: Some((lat_deg, lon_deg)),
                    alt_rel_m,
                })
            }
            Command::Takeoff { alt_rel_m } => {
                self.position_target = Some(Target {
                    source,
                    at: None,
                    alt_rel_m,
                })
            }
            Command::VelocityNed { .. } => self.position_target = None,
            ref c if ends_stream(c.kind()) => self.position_target = None,
            _ => {}
        }
    }

    /// A new measurement of the vehicle: a position target it has reached (within
    /// [`Target::ARRIVED_M`] horizontally and [`Target::ARRIVED_ALT_M`] vertically,
    /// slower than [`Target::ARRIVED_MPS`]) is over, so its source going quiet
    /// afterwards is not braked (the autopilot holds the point by itself).
    pub fn observe(&mut self, vehicle: &VehicleView) {
        if let (Some(t), Some(k)) = (self.position_target, vehicle.position) {
            if t.reached(&k) {
                self.position_target = None;
            }
        }
    }
}
