//! The `ShotStatus` sample: published when a discrete field changes (shot, phase,
//! app, authority, ROI validity, cruise speed, last exit) and at least every
//! [`STATUS_PERIOD_NS`] (5 Hz) for the continuous ones (progress, ROI position).

use skymesh_ipc_types::{FixedStr, ShotPhase, ShotStatus};

use super::{Engine, STATUS_PERIOD_NS};

/// The fields of a `ShotStatus` whose change publishes it at once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StatusKey {
    shot: i8,
    phase: u8,
    app_connected: u8,
    has_authority: u8,
    roi_valid: u8,
    cruise_speed: f32,
    last_exit: FixedStr<32>,
}

impl Engine {
    /// The current status sample.
    pub fn status(&self) -> ShotStatus {
        let mut s = ShotStatus {
            vehicle_id: self.settings.vehicle_id,
            shot: self.current_shot() as i8,
            app_connected: self.out.app_connected.into(),
            last_exit: FixedStr::new(self.last_exit),
            ..ShotStatus::default()
        };
        if let Some(a) = &self.active {
            s.phase = match &a.flight {
                None => ShotPhase::Setup,
                Some(_) if a.cruise == 0.0 => ShotPhase::Paused,
                Some(_) => ShotPhase::Running,
            }
            .to_wire();
            s.has_authority = a.flight.is_some().into();
            s.cruise_speed_mps = a.cruise;
            s.progress = a.progress();
            if let Some(roi) = a.roi() {
                s.roi_valid = 1;
                s.roi_lat_deg = roi.lat_deg;
                s.roi_lon_deg = roi.lon_deg;
                s.roi_alt_rel_m = roi.alt_rel_m;
            }
        }
        s
    }

    pub(crate) fn status_due(&mut self, now_ns: u64) -> Option<ShotStatus> {
        let s = self.status();
        let key = StatusKey {
            shot: s.shot,
            phase: s.phase,
            app_connected: s.app_connected,
            has_authority: s.has_authority,
            roi_valid: s.roi_valid,
            cruise_speed: s.cruise_speed_mps,
            last_exit: s.last_exit,
        };
        let due = match self.last_status {
            None => true,
            Some((last, at)) => last != key || now_ns.saturating_sub(at) >= STATUS_PERIOD_NS,
        };
        if !due {
            return None;
        }
        self.last_status = Some((key, now_ns));
        Some(s)
    }
}
