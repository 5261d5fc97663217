//! The `ShotStatus` sample: published when a discrete field changes (shot, phase,
//! app, authority, ROI validity, cruise speed, last exit), at least every
//! [`STATUS_PERIOD_NS`] (5 Hz) while a shot is active for the continuous ones
//! (progress, ROI position), and once a second on the whole-second grid without one
//! ([`IDLE_STATUS_PERIOD_NS`]: nothing in it can change but through a discrete field).

use std::time::Duration;

use skymesh_ipc_types::{FixedStr, ShotPhase, ShotStatus};
use skymesh_runtime::timer::grid_at_or_after;

use super::{Engine, IDLE_STATUS_PERIOD_NS, STATUS_PERIOD_NS};

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
            Some((last, _)) => last != key || now_ns >= self.periodic_status_at(),
        };
        if !due {
            return None;
        }
        self.last_status = Some((key, now_ns));
        Some(s)
    }

    /// When the status is next due without a change (`CLOCK_MONOTONIC` ns; 0 before
    /// the first): [`STATUS_PERIOD_NS`] after the last one while a shot is active, else
    /// the first whole second at least [`IDLE_STATUS_PERIOD_NS`] after it.
    pub(crate) fn periodic_status_at(&self) -> u64 {
        let Some((_, at)) = self.last_status else {
            return 0;
        };
        if self.active.is_some() {
            return at.saturating_add(STATUS_PERIOD_NS);
        }
        let second = Duration::from_nanos(IDLE_STATUS_PERIOD_NS);
        grid_at_or_after(
            at.saturating_add(IDLE_STATUS_PERIOD_NS),
            second,
            Duration::ZERO,
        )
    }
}
