//! The autopilot's home and the bounds on moving it (`SetHome`).

use skymesh_ipc_types::RefusalReason;

use super::geofence;
use super::{Arbiter, VehicleView};

/// The autopilot's home (HOME_POSITION), where RTL returns to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Home {
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Above mean sea level, m.
    pub alt_msl_m: f32,
}

impl Arbiter {
    /// `SetHome` bounds: home is where a failsafe RTL flies, so it stays inside the
    /// fences, within `max_home_move_m` of the current home and at its altitude
    /// (± `max_home_alt_change_m`).
    pub(super) fn home_check(
        &self,
        lat_deg: f64,
        lon_deg: f64,
        alt_msl_m: f32,
        vehicle: &VehicleView,
    ) -> Result<(), (RefusalReason, String)> {
        let Some(home) = vehicle.home else {
            return Err((
                RefusalReason::WrongState,
                "home not known yet: cannot bound a new home".to_string(),
            ));
        };
        let frame = geofence::LocalFrame::new(home.lat_deg, home.lon_deg);
        let moved = frame.to_local(lat_deg, lon_deg).norm();
        let max = f64::from(self.settings.max_home_move_m);
        if !moved.is_finite() || moved > max {
            return Err((
                RefusalReason::Denied,
                format!("new home {moved:.0} m from the current one, max {max:.0} m"),
            ));
        }
        let dz = alt_msl_m - home.alt_msl_m;
        if !dz.is_finite() || dz.abs() > self.settings.max_home_alt_change_m {
            return Err((
                RefusalReason::Denied,
                format!(
                    "home altitude change {:.1} m, max {:.1} m",
                    dz.abs(),
                    self.settings.max_home_alt_change_m
                ),
            ));
        }
        if !self.fence.contains(lat_deg, lon_deg) {
            return Err((
                RefusalReason::Geofence,
                "new home outside the geofence".to_string(),
            ));
        }
        Ok(())
    }
}
