//! Rewind (shot 8), the breadcrumbs it flies back along, its options, and the home
//! location the app shows ([`crate::shots::rewind`]).
//!
//! | from | does |
//! |---|---|
//! | every tick, armed with a fresh position, not rewinding | a breadcrumb every [`BREADCRUMB_SPACING_M`] of path, the newest [`BREADCRUMB_CAPACITY`] kept; disarming forgets them (a new flight, a new path) |
//! | SET_CURRENT_SHOT 8 (or a mapped button) | entry gate (and refused while rewind is disabled); flies back along the breadcrumbs at `rewind_speed_mps`, at most `rewindDistance` of path |
//! | the end of the path | hover: brake and LOITER (exit `finished`); else RTL (exit `finished_rtl`); the breadcrumbs are forgotten |
//! | SOLO_REWIND_OPTIONS | enabled, hover, rewindDistance (clamped to 10..=60 m as the reference does); answered with the options in use |
//! | Pause | stops on the path ↔ goes on |
//! | app connects | SOLO_HOME_LOCATION (if home is known) and SOLO_REWIND_OPTIONS |
//! | `VehicleStatus` home changes | SOLO_HOME_LOCATION (altitude above MSL, as the reference sends the autopilot's home) |
//! | SOLO_HOME_LOCATION from the app ("return to me") | `Command::SetHome` at the app's lat/lon, keeping home's altitude (a phone's GPS altitude is too poor to move the reference of every relative altitude; the reference ShotManager does the same); refused while the vehicle has no home; once the vehicle reports the new home the row above tells the app. A location the command refuses (alt outside −1000..=10000 m), lat = lon = 0 (no position: the autopilot would read it as "here"), and a refused ack are answered with SHOTMANAGER_ERROR and the reason. The home already in effect is answered with SOLO_HOME_LOCATION at once, without a command |
//!
//! Setting home needs flight authority (it moves where RTL goes): outside a flying
//! shot or a geofence hold the engine takes it implicitly with the command and gives
//! it back right after (`ReleaseFlightAuthority`), as it does for a mapped mode
//! button; a higher-ranked holder refuses it (`no_authority`, told to the app). One
//! request is in flight at a time: a newer location that arrives meanwhile replaces
//! any other waiting one and is sent when the first is answered (autopilot-link would
//! otherwise cancel the older `DO_SET_HOME`), so an app streaming "return to me"
//! updates never floods the autopilot. The reference ShotManager only stored the
//! app's lat/lon (keeping home's altitude) for its own RTL, and only in flight; here
//! the autopilot's home moves, so its RTL and every relative altitude follow it.
//!
//! The reference's rewind flies its breadcrumb spline the same way but falls back to
//! RTL when there are none; here an empty path ends at once the same way as a full
//! one (hover or RTL), with a SHOTMANAGER_ERROR saying there was nothing to rewind.

use skymesh_ipc_types::shot_api::{Location, ShotEvent};
use skymesh_ipc_types::{AckResult, Command, CommandAck, VehicleStatus};

use super::shot::{Active, ShotKind};
use super::{Engine, ExitReason};
use crate::shots::rewind::{BREADCRUMB_CAPACITY, BREADCRUMB_SPACING_M};
use crate::shots::{Breadcrumbs, Guidance, Limits, Rewind, VehicleView};

/// Default rewind distance, metres (the Solo's).
pub const DEFAULT_REWIND_DISTANCE_M: f32 = 20.0;
/// rewindDistance is clamped to this range, metres (the reference's).
pub const REWIND_DISTANCE_RANGE_M: (f32, f32) = (10.0, 60.0);
/// A home request unanswered this long is taken as lost: the next one is sent
/// instead of waiting (autopilot-link answers every command well within this).
pub const HOME_ANSWER_WAIT_NS: u64 = 15_000_000_000;
/// The app's home counts as the one in effect within this, degrees (about 1 cm) …
const SAME_HOME_DEG: f64 = 1e-7;
/// … and this, metres (HOME_POSITION carries millimetres).
const SAME_HOME_ALT_M: f32 = 0.01;

/// SOLO_REWIND_OPTIONS.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RewindOptions {
    /// Rewind may be entered.
    pub enabled: bool,
    /// At the end: hover (LOITER) instead of RTL.
    pub hover: bool,
    /// How much of the flown path to fly back, metres.
    pub distance_m: f32,
}

impl Default for RewindOptions {
    fn default() -> Self {
        RewindOptions {
            enabled: true,
            hover: false,
            distance_m: DEFAULT_REWIND_DISTANCE_M,
        }
    }
}

impl RewindOptions {
    fn message(&self) -> ShotEvent {
        ShotEvent::RewindOptions {
            enabled: self.enabled.into(),
            hover: self.hover.into(),
            rewind_distance: self.distance_m,
        }
    }
}

/// What the engine keeps for rewind whether or not it is the shot.
#[derive(Debug)]
pub(crate) struct RewindState {
    pub crumbs: Breadcrumbs,
    pub options: RewindOptions,
    /// The home position last told to the app (or to be told on connect).
    home: Option<Location>,
    /// The app's home request in flight: its command id and when it was sent.
    home_request: Option<(u32, u64)>,
    /// The newest app home that arrived while one was in flight.
    home_next: Option<Location>,
}

impl Default for RewindState {
    fn default() -> Self {
        RewindState {
            crumbs: Breadcrumbs::new(BREADCRUMB_SPACING_M, BREADCRUMB_CAPACITY),
            options: RewindOptions::default(),
            home: None,
            home_request: None,
            home_next: None,
        }
    }
}

/// The rewind shot's own state.
#[derive(Debug, Default)]
pub(crate) struct RewindShot {
    /// The path back, laid when the shot starts flying.
    pub rewind: Option<Rewind>,
}

impl RewindShot {
    pub fn guidance(&mut self, v: &VehicleView, dt: f32, speed: f32, lim: &Limits) -> Guidance {
        match self.rewind.as_mut() {
            Some(r) => r.step(v, dt, speed, lim),
            None => Guidance::HOVER,
        }
    }

    pub fn progress(&self) -> f32 {
        self.rewind.as_ref().map_or(0.0, Rewind::progress)
    }
}

fn set_home(loc: &Location) -> Command {
    Command::SetHome {
        lat_deg: loc.lat_deg,
        lon_deg: loc.lon_deg,
        alt_msl_m: loc.alt_m,
    }
}

fn same_home(a: &Location, b: &Location) -> bool {
    (a.lat_deg - b.lat_deg).abs() < SAME_HOME_DEG
        && (a.lon_deg - b.lon_deg).abs() < SAME_HOME_DEG
        && (a.alt_m - b.alt_m).abs() < SAME_HOME_ALT_M
}

fn home_of(s: &VehicleStatus) -> Option<Location> {
    let home = Location {
        lat_deg: s.home_lat_deg,
        lon_deg: s.home_lon_deg,
        alt_m: s.home_alt_msl_m,
    };
    (s.home_valid != 0
        && home.lat_deg.is_finite()
        && home.lon_deg.is_finite()
        && home.alt_m.is_finite())
    .then_some(home)
}

impl Engine {
    /// Rewind may be entered (SOLO_REWIND_OPTIONS enabled).
    pub(crate) fn rewind_enabled(&self) -> bool {
        self.rewind.options.enabled
    }

    /// Just entered: lay the path back from here and fly it.
    pub(crate) fn rewind_start(&mut self, now_ns: u64) {
        let Some(v) = self.inputs.view(now_ns) else {
            return;
        };
        let distance = self.rewind.options.distance_m;
        let crumbs = self.rewind.crumbs.len();
        let Some(Active {
            kind: ShotKind::Rewind(r),
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        let path = Rewind::new(&self.rewind.crumbs, distance, &v);
        let length = path.length_m();
        r.rewind = Some(path);
        tracing::info!(
            length_m = length,
            crumbs,
            max_m = distance,
            "rewind: flying back along the path"
        );
        if length <= 0.0 {
            self.out
                .error("rewind: no flown path recorded; nothing to fly back along");
        }
        self.begin_flight(None, now_ns);
    }

    /// SOLO_REWIND_OPTIONS from the app: kept, answered with what is in use.
    pub(crate) fn rewind_options(&mut self, enabled: u8, hover: u8, distance_m: f32) {
        let (lo, hi) = REWIND_DISTANCE_RANGE_M;
        let distance_m = if distance_m.is_finite() {
            distance_m.clamp(lo, hi)
        } else {
            DEFAULT_REWIND_DISTANCE_M
        };
        self.rewind.options = RewindOptions {
            enabled: enabled != 0,
            hover: hover != 0,
            distance_m,
        };
        tracing::info!(enabled, hover, distance_m, "rewind: options");
        self.out.app(self.rewind.options.message());
    }

    /// SOLO_HOME_LOCATION from the app: move the vehicle's home there.
    pub(crate) fn home_location_from_app(&mut self, loc: &Location, now_ns: u64) {
        tracing::info!(
            lat = loc.lat_deg,
            lon = loc.lon_deg,
            alt_msl = loc.alt_m,
            "the app asks to set home"
        );
        if loc.lat_deg == 0.0 && loc.lon_deg == 0.0 {
            self.out
                .error("home location refused: (0, 0) is no position");
            return;
        }
        let current = self.inputs.status.as_ref().and_then(home_of);
        // Only the horizontal position moves, as the reference ShotManager does: home's
        // altitude is what every relative altitude (and RTL's climb) is measured from,
        // and a phone's GPS altitude is far too poor to move it.
        let Some(home_alt) = current.map(|h| h.alt_m) else {
            self.out
                .error("home location refused: the vehicle has no home yet");
            return;
        };
        let loc = &Location {
            alt_m: home_alt,
            ..*loc
        };
        if let Err(e) = set_home(loc).validate() {
            self.out.error(&format!("home location refused: {e}"));
            return;
        }
        if let Some(home) = current.filter(|h| same_home(h, loc)) {
            if self.rewind.home_request.is_none() {
                tracing::debug!("the app's home is already in effect");
                self.rewind.home = Some(home);
                self.out.app(ShotEvent::HomeLocation(home));
                return;
            }
        }
        match self.rewind.home_request {
            Some((id, sent_ns)) if now_ns.saturating_sub(sent_ns) < HOME_ANSWER_WAIT_NS => {
                tracing::debug!(
                    waiting_for = id,
                    "home request in flight; sending the newest when it is answered"
                );
                self.rewind.home_next = Some(*loc);
            }
            _ => self.send_home(loc, now_ns),
        }
    }

    /// Sends `SetHome`; outside a flying shot or a fence hold, flight authority is
    /// given back right after (the command grabbed it implicitly).
    fn send_home(&mut self, loc: &Location, now_ns: u64) {
        let keep_authority = self.is_flying() || self.fence.holding();
        self.rewind.home_request = self.out.command(set_home(loc)).map(|id| (id, now_ns));
        if self.rewind.home_request.is_some() && !keep_authority {
            self.out.command(Command::ReleaseFlightAuthority);
        }
    }

    /// An ack for the app's home request: true if it was one. A refusal is told to
    /// the app; an acceptance shows up as the vehicle's new home (`home_update`).
    pub(crate) fn home_ack(&mut self, ack: &CommandAck, accepted: bool, now_ns: u64) -> bool {
        if self.rewind.home_request.map(|(id, _)| id) != Some(ack.command_id) {
            return false;
        }
        if ack.result() == Some(AckResult::InProgress) {
            return true;
        }
        self.rewind.home_request = None;
        if accepted {
            tracing::info!("home set; the app hears it once the vehicle reports it");
        } else {
            let reason = ack.reason().map_or("refused", |r| r.as_str());
            self.out.error(&format!(
                "home location refused ({reason}: {})",
                ack.detail.as_str()
            ));
        }
        if let Some(next) = self.rewind.home_next.take() {
            self.send_home(&next, now_ns);
        }
        true
    }

    /// The app connected: tell it home and the rewind options.
    pub(crate) fn rewind_app_connected(&mut self) {
        if let Some(home) = self.inputs.status.as_ref().and_then(home_of) {
            self.rewind.home = Some(home);
            self.out.app(ShotEvent::HomeLocation(home));
        }
        self.out.app(self.rewind.options.message());
    }

    /// A new `VehicleStatus`: tell the app when home moved.
    pub(crate) fn home_update(&mut self) {
        let home = self.inputs.status.as_ref().and_then(home_of);
        if home.is_some() && home != self.rewind.home {
            self.rewind.home = home;
            if let Some(h) = home {
                tracing::info!(lat = h.lat_deg, lon = h.lon_deg, alt_msl = h.alt_m, "home");
                self.out.app(ShotEvent::HomeLocation(h));
            }
        }
    }

    /// After a tick: drop a breadcrumb while flying (not while rewinding), and end
    /// the rewind at the end of its path.
    pub(crate) fn rewind_after_step(&mut self, now_ns: u64) {
        let armed = self
            .inputs
            .status
            .as_ref()
            .is_some_and(VehicleStatus::is_armed);
        if !armed && !self.rewind.crumbs.is_empty() {
            tracing::debug!("disarmed: breadcrumbs forgotten");
            self.rewind.crumbs.clear();
        }
        let rewinding = matches!(
            self.active.as_ref().map(|a| &a.kind),
            Some(ShotKind::Rewind(_))
        );
        if armed && !rewinding {
            if let Some(v) = self.inputs.view(now_ns) {
                self.rewind.crumbs.record(&v.position);
            }
        }
        let done = matches!(
            self.active.as_ref(),
            Some(Active {
                kind: ShotKind::Rewind(r),
                flight: Some(_),
                ..
            }) if r.rewind.as_ref().is_some_and(Rewind::done)
        );
        if !done {
            return;
        }
        self.rewind.crumbs.clear();
        if self.rewind.options.hover {
            tracing::info!("rewind: at the end of the path; hovering");
            self.exit_shot(ExitReason::Finished);
        } else {
            tracing::info!("rewind: at the end of the path; RTL");
            self.out.command(Command::ReturnToLaunch);
            self.exit_shot(ExitReason::FinishedRtl);
        }
    }
}
