//! joystick_invalid_notify while in DRC mode, pure: each condition is a level read
//! from the vehicle samples (or a burst of arbiter events), and only its onset is
//! reported, once. At drc_mode_enter every condition starts false, so one that
//! already holds is reported once right away.
//!
//! | condition | reason |
//! |---|---|
//! | no `VehicleStatus` for [`STATUS_MAX_AGE`], `link_up` 0, or the arbiter's `link_lost` (until `link_restored`) | 0 remote controller lost |
//! | armed, mode RTL/SmartRTL, and the battery is low: `battery_remaining_pct` ≤ `low_battery_pct`, or the last STATUSTEXT says "battery" with "low", "critical" or "failsafe" (ArduCopter's battery failsafe texts) | 1 low battery return |
//! | the same in LAND | 2 low battery landing |
//! | the arbiter limited (`geofence_limited`) or refused (`geofence_refused`) one of our commands; a new onset after [`GEOFENCE_QUIET`] without such events | 3 near a restricted zone |
//! | flight authority held by `manual_rc`, `operator` or `safety` (not the safety hold of our own drone_emergency_stop: while `AuthorityState::emergency_by(dji_drc)`, or just after we sent it) | 4 RC takeover |
//! | armed in RTL/SmartRTL/LAND without a low battery (a return or landing someone else triggered: the document's "triggered return") | 4 RC takeover |
//!
//! MAVLink has no "why did the mode change" field, hence the battery evidence above.

use std::time::{Duration, Instant};

use dji_proto::JoystickInvalidReason;
use skymesh_ipc_types::{ArbiterEvent, ArbiterEventKind, CommandSource, FlightMode, VehicleStatus};

use super::session::STATUS_MAX_AGE;
use crate::link::{Snapshot, SOURCE};

/// Geofence events closer together than this are one condition.
pub const GEOFENCE_QUIET: Duration = Duration::from_secs(5);
/// After our own emergency stop, safety holding flight authority is not a takeover
/// until safety has let go (and at least this long has passed).
const OWN_ESTOP_GRACE: Duration = Duration::from_secs(5);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Condition {
    LinkLost = 0,
    BatteryReturn = 1,
    BatteryLanding = 2,
    AuthorityTaken = 3,
    ReturnTriggered = 4,
}

const CONDITIONS: [Condition; 5] = [
    Condition::LinkLost,
    Condition::BatteryReturn,
    Condition::BatteryLanding,
    Condition::AuthorityTaken,
    Condition::ReturnTriggered,
];

impl Condition {
    fn reason(self) -> JoystickInvalidReason {
        match self {
            Condition::LinkLost => JoystickInvalidReason::RcLost,
            Condition::BatteryReturn => JoystickInvalidReason::LowBatteryReturn,
            Condition::BatteryLanding => JoystickInvalidReason::LowBatteryLanding,
            Condition::AuthorityTaken | Condition::ReturnTriggered => {
                JoystickInvalidReason::RcTakeover
            }
        }
    }
}

/// The metrics label of a reason.
pub fn reason_name(r: JoystickInvalidReason) -> &'static str {
    match r {
        JoystickInvalidReason::RcLost => "rc_lost",
        JoystickInvalidReason::LowBatteryReturn => "low_battery_return",
        JoystickInvalidReason::LowBatteryLanding => "low_battery_landing",
        JoystickInvalidReason::NearRestrictedZone => "near_restricted_zone",
        JoystickInvalidReason::RcTakeover => "rc_takeover",
    }
}

/// The onset detector of one DRC session.
#[derive(Debug)]
pub struct InvalidWatch {
    low_battery_pct: u8,
    active: [bool; CONDITIONS.len()],
    /// Between the arbiter's `link_lost` and `link_restored`.
    arbiter_link_down: bool,
    last_geofence: Option<Instant>,
    own_estop: Option<Instant>,
}

impl InvalidWatch {
    pub fn new(low_battery_pct: u8) -> Self {
        InvalidWatch {
            low_battery_pct,
            active: [false; CONDITIONS.len()],
            arbiter_link_down: false,
            last_geofence: None,
            own_estop: None,
        }
    }

    /// We sent drone_emergency_stop at `now` (safety will hold flight authority).
    pub fn emergency_stop_sent(&mut self, now: Instant) {
        self.own_estop = Some(now);
    }

    /// The conditions that began with these samples (`now_ns`: `CLOCK_MONOTONIC`).
    pub fn on_vehicle(
        &mut self,
        now: Instant,
        snap: &Snapshot,
        now_ns: u64,
    ) -> Vec<JoystickInvalidReason> {
        let levels = self.levels(now, snap, now_ns);
        let mut onsets = Vec::new();
        for c in CONDITIONS {
            let i = c as usize;
            if levels[i] && !self.active[i] {
                onsets.push(c.reason());
            }
            self.active[i] = levels[i];
        }
        onsets
    }

    /// An arbiter event: a geofence onset, or the link going down/up (the link
    /// condition is then re-read with the next [`InvalidWatch::on_vehicle`]; a
    /// `link_lost` reports at once).
    pub fn on_arbiter_event(
        &mut self,
        now: Instant,
        event: &ArbiterEvent,
    ) -> Option<JoystickInvalidReason> {
        match event.event_kind()? {
            ArbiterEventKind::GeofenceLimited | ArbiterEventKind::GeofenceRefused
                if event.source == SOURCE.to_wire() =>
            {
                let onset = self
                    .last_geofence
                    .is_none_or(|t| now.saturating_duration_since(t) >= GEOFENCE_QUIET);
                self.last_geofence = Some(now);
                onset.then_some(JoystickInvalidReason::NearRestrictedZone)
            }
            ArbiterEventKind::LinkLost => {
                self.arbiter_link_down = true;
                let i = Condition::LinkLost as usize;
                let onset = !self.active[i];
                self.active[i] = true;
                onset.then_some(JoystickInvalidReason::RcLost)
            }
            ArbiterEventKind::LinkRestored => {
                self.arbiter_link_down = false;
                None
            }
            _ => None,
        }
    }

    fn levels(&mut self, now: Instant, snap: &Snapshot, now_ns: u64) -> [bool; CONDITIONS.len()] {
        let mut levels = [false; CONDITIONS.len()];
        let max_age_ns = u64::try_from(STATUS_MAX_AGE.as_nanos()).unwrap_or(u64::MAX);
        let fresh = snap
            .status
            .filter(|s| s.header.age_ns(now_ns) <= max_age_ns);
        levels[Condition::LinkLost as usize] =
            self.arbiter_link_down || !fresh.is_some_and(|s| s.is_link_up());
        if let Some(status) = fresh.filter(|s| s.is_armed()) {
            let low = battery_low(&status, self.low_battery_pct);
            match status.flight_mode() {
                FlightMode::Rtl | FlightMode::SmartRtl if low => {
                    levels[Condition::BatteryReturn as usize] = true
                }
                FlightMode::Land if low => levels[Condition::BatteryLanding as usize] = true,
                FlightMode::Rtl | FlightMode::SmartRtl | FlightMode::Land => {
                    levels[Condition::ReturnTriggered as usize] = true
                }
                _ => {}
            }
        }
        let holder = snap.authority.and_then(|a| a.flight());
        if holder != Some(CommandSource::Safety) {
            self.own_estop = self
                .own_estop
                .filter(|t| now.saturating_duration_since(*t) < OWN_ESTOP_GRACE);
        }
        // Our own stop in force (whoever else stopped the vehicle too): the safety
        // hold is the one the pilot asked for.
        let own_stop_held = snap.authority.is_some_and(|a| a.emergency_by(SOURCE));
        levels[Condition::AuthorityTaken as usize] = match holder {
            Some(CommandSource::ManualRc | CommandSource::Operator) => true,
            Some(CommandSource::Safety) => self.own_estop.is_none() && !own_stop_held,
            _ => false,
        };
        levels
    }
}

/// The battery is low by the percentage, or the autopilot's last text says so.
fn battery_low(status: &VehicleStatus, low_battery_pct: u8) -> bool {
    let pct = status.battery_remaining_pct;
    (pct >= 0 && pct.unsigned_abs() <= low_battery_pct)
        || text_says_battery_low(status.status_text.as_str())
}

/// "Battery 1 is low 10.50V used 1234 mAh", "Battery failsafe", "Battery 1 is
/// critical": whole words, so "below" (PreArm texts) is no "low".
fn text_says_battery_low(text: &str) -> bool {
    let lower = text.to_ascii_lowercase();
    let words: Vec<&str> = lower
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect();
    words.contains(&"battery")
        && words
            .iter()
            .any(|w| matches!(*w, "low" | "critical" | "failsafe"))
}
