//! The ShotManager state machine: pure, no I/O, no clock. Every input is a method
//! call with the `CLOCK_MONOTONIC` time in ns; everything the engine wants done
//! comes back as [`Outputs`] (vehicle commands, app messages, a status sample), so
//! the whole behaviour is tested without processes (`engine/tests/`). The bus glue
//! is `service.rs`.
//!
//! # Inputs and outputs
//!
//! | input | method |
//! |---|---|
//! | app message (TCP or follow stream) | [`Engine::handle_app`] |
//! | app connected / disconnected | [`Engine::handle_app_session`] |
//! | controller button | [`Engine::handle_button`] |
//! | vehicle state, status, payload | [`Engine::handle_state`], [`Engine::handle_status`], [`Engine::handle_payload`] |
//! | arbiter: authority, events, acks | [`Engine::handle_authority`], [`Engine::handle_arbiter_event`], [`Engine::handle_ack`] |
//! | loop tick (`loop_hz`) | [`Engine::tick`]: steps the flying shot, then returns everything pending |
//! | between ticks | [`Engine::drain`]: returns what the handlers produced |
//! | after an app message or button | [`Engine::take_step_request`]: true when it changed a flying shot's guidance (tick now) |
//!
//! # Event steps
//!
//! An app message or button that changes what a *flying* shot does (ROI, locations,
//! cruise speed, cable / follow / zipline / pano / spline options, pause, entering a
//! shot that flies at once, Site Scan moves) asks for a step now
//! ([`Engine::take_step_request`]); the service then runs [`Engine::tick`] at once,
//! so the new guidance reaches the arbiter without waiting up to a loop period.
//! The loop keeps its phase: the periodic tick still comes when it was due. Every
//! step uses its measured `dt`, so the acceleration limit holds however the steps
//! are spaced, and the periodic tick after an event step continues the ramp the
//! event step began (restarting the period instead would shift the whole ramp by up
//! to a period: the first setpoint sooner, every later speed reached later). That
//! tick can carry a setpoint close to the event step's (a shot already at its
//! target): harmless, it is one extra setpoint per app message or button press
//! (human rate), the steady-state rate stays `loop_hz`, and the gap between
//! setpoints never exceeds the period, which is what the arbiter's freshness check
//! watches. Follow-stream positions do not ask for a step: they are a stream of
//! their own (the app's 25 Hz), and stepping on each would double the setpoint rate.

//! # Shots
//!
//! A shot is *entered* (SET_CURRENT_SHOT from the app, or A/B mapped to it) after the
//! entry gate (`flight.rs`), spends a *setup* phase collecting what it needs (selfie:
//! three locations; orbit: an ROI; cable cam: two recorded points; follow: the first
//! phone position), then *flies*: grab flight authority, GUIDED, set the ROI if it
//! has one, and a velocity setpoint every tick from `shots::*::step`. Camera commands
//! are sent only when they change meaningfully (`camera.rs`). Per-shot state is in
//! `shot.rs`, what the app and pilot do inside a shot in `controls.rs`; app dispatch,
//! buttons and not-implemented answers in `app.rs`; the arbiter's answers in
//! `arbiter.rs`; the GoPro model in `gopro.rs`; outputs in `out.rs` and `status.rs`.
//!
//! Site Scan (inspect, structure scan, survey: `sitescan.rs`) and the app's
//! geofence (validation, the arbiter's `GeofenceSet`, the predictive check and the
//! hold at the fence: `geofence.rs`) document theirs the same way.
//!
//! Multipoint cable cam (`multipoint.rs`), zipline (`zipline.rs`), pano (`pano.rs`)
//! and rewind with its breadcrumbs and the app's home location (`rewind.rs`) each
//! document their messages at the top of their file. Zipline, pano and rewind fly
//! from entry; multipoint from SPLINE_ATTACH. A photo pano and a rewind end by
//! themselves (exit `finished`, or `finished_rtl` for a rewind that returns home).
//!
//! # Where the spec is silent, what this engine does
//!
//! - Entering the shot that is already active only re-announces it
//!   (GET_CURRENT_SHOT n); it does not restart it (an app that reconnects and
//!   re-sends its shot must not reset an orbit in flight). Entering another shot
//!   ends the current one first (exit reason `replaced`). A refused entry leaves the
//!   current shot running, as the Solo does.
//! - Entering from a button needs a connected app (the spec: "this only works if
//!   an app is connected").
//! - On entry the engine sends the shot's options (SOLO_SHOT_OPTIONS for selfie and
//!   orbit, SOLO_FOLLOW_OPTIONS then _V2 for follow) so the app shows the speed the
//!   engine will use; cable cam sends its options after the second point, as the
//!   spec says.
//! - Exits that hand the vehicle back to the pilot — FLY, the app's SET_CURRENT_SHOT
//!   −1, app loss, another shot replacing this one, service shutdown — send `Brake`
//!   then `SetMode(Loiter)` when the vehicle is GUIDED, because GUIDED ignores the
//!   sticks: leaving the pilot in a braked GUIDED would leave them without control
//!   until they press FLY. A pilot or autopilot mode change is left alone (they
//!   chose the mode). Exits after losing authority or the link send nothing (it
//!   would be refused); the arbiter's freshness brake stops the vehicle.
//! - Orbit and cable cam already flying continue when the app disconnects: the pilot
//!   still has FLY (and the RC sticks through a mode change). Selfie and follow end
//!   (follow has no target without the phone; a selfie cannot be watched or
//!   stopped from the app). Any shot still in setup ends (it waits for app input).
//! - A link-down ends any shot, in setup too: nothing can be flown until it is back.
//! - Pause toggles the cruise speed between 0 and the previous speed; a new cruise
//!   speed from the app while paused ends the pause. Follow answers a pause with
//!   SOLO_FOLLOW_OPTIONS and _V2.
//! - A vehicle state older than one second while flying: the shot is not stepped
//!   and the setpoint is zero (hover) until fresh state returns.
//! - SET_CURRENT_SHOT of a shot this version does not fly is answered with
//!   SHOTMANAGER_ERROR and GET_CURRENT_SHOT of the *current* shot (−1 when idle, so
//!   the app leaves the shot screen; the running shot when one is active, which
//!   keeps flying).

mod app;
mod arbiter;
mod camera;
mod controls;
mod flight;
mod geofence;
mod gopro;
mod multipoint;
mod out;
mod pano;
mod rewind;
mod shot;
mod sitescan;
mod status;
#[cfg(test)]
mod tests;
mod zipline;

use skymesh_ipc_types::shot_api::ShotEvent;
use skymesh_ipc_types::{
    AppSession, ButtonEvent, FlightMode, PayloadState, ShotStatus, VehicleCommand, VehicleState,
    VehicleStatus,
};

use crate::config::Settings;
use crate::metrics::Metrics;
use crate::persist::{Loaded, Store};
use crate::shots::VehicleView;

pub use flight::{ExitReason, Refusal};
pub(crate) use out::Out;
use shot::Active;
use status::StatusKey;

/// A vehicle state older than this (since it was received) is not flown on.
pub const STATE_MAX_AGE_NS: u64 = 1_000_000_000;
/// While a shot is active `ShotStatus` is published at least this often (5 Hz, for
/// its continuous fields: progress, ROI position) and on every change.
pub const STATUS_PERIOD_NS: u64 = 200_000_000;
/// Without an active shot the status has no continuous field: it is published on
/// every change and otherwise once a second, on the machine-wide grid of whole
/// seconds (`skymesh_runtime::timer::grid_at_or_after`), where the services'
/// heartbeats fall too, so the idle engine wakes with them instead of five times a
/// second of its own.
pub const IDLE_STATUS_PERIOD_NS: u64 = 1_000_000_000;
/// SHOTMANAGER_ERROR text is cut to this many bytes (the bus carries 240).
pub const MAX_ERROR_TEXT: usize = 200;

/// What the engine wants done: publish these, in this order.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Outputs {
    /// For `skymesh/vehicle/{id}/command`, source `ShotEngine`.
    pub commands: Vec<VehicleCommand>,
    /// For the app (session 0 = whichever app is connected).
    pub to_app: Vec<ShotEvent>,
    /// A `ShotStatus` when it changed or is due (5 Hz).
    pub status: Option<ShotStatus>,
    /// For `skymesh/vehicle/{id}/geofence`: the app's fence changed (`geofence.rs`).
    pub geofence: Option<skymesh_ipc_types::GeofenceSet>,
}

/// The latest vehicle inputs, with the time each was received.
#[derive(Debug, Default)]
pub(crate) struct Inputs {
    state: Option<(VehicleState, u64)>,
    status: Option<VehicleStatus>,
    payload: Option<PayloadState>,
}

impl Inputs {
    fn mode(&self) -> FlightMode {
        self.status
            .as_ref()
            .map_or(FlightMode::Unknown, VehicleStatus::flight_mode)
    }

    /// The mode, if the last status describes a heartbeat that arrived at or after
    /// `since_ns`; `None` if it is older. Only such a status can tell whether a mode
    /// request sent at `since_ns` took effect: the last mode known when the request
    /// goes out may already be stale (the engine's own LOITER at the end of the shot
    /// before, not yet in a heartbeat). Even such a status may still show the mode
    /// from before the switch (a heartbeat the autopilot sent just before it switched
    /// arrives after the request), so a request is done when one shows the mode asked
    /// for, and only after that does another mode mean the pilot changed it.
    fn mode_since(&self, since_ns: u64) -> Option<FlightMode> {
        let status = self.status.as_ref()?;
        (status.heartbeat_ns()? >= since_ns).then(|| status.flight_mode())
    }

    /// The vehicle as the shots see it, if a valid position is fresh at `now_ns`.
    fn view(&self, now_ns: u64) -> Option<VehicleView> {
        let (s, rx_ns) = self.state.as_ref()?;
        if s.position_valid == 0 || now_ns.saturating_sub(*rx_ns) > STATE_MAX_AGE_NS {
            return None;
        }
        let position = crate::shots::GeoPoint {
            lat_deg: s.lat_deg,
            lon_deg: s.lon_deg,
            alt_rel_m: s.alt_rel_m,
        };
        Some(VehicleView::from_samples(
            position,
            s,
            self.payload.as_ref(),
        ))
    }
}

/// The shot engine of one vehicle.
#[derive(Debug)]
pub struct Engine {
    settings: Settings,
    store: Store,
    inputs: Inputs,
    out: Out,
    active: Option<Active>,
    gopro: gopro::GoPro,
    /// Current (or last) app session number; 0 = none seen.
    app_session: u32,
    /// When the gateway last said anything (session sample or app message).
    app_heard_ns: u64,
    /// Told to the app once one is connected: the shot a crash ended.
    restart_notice: Option<String>,
    /// Why the last shot ended; empty while in a shot.
    last_exit: &'static str,
    last_status: Option<(StatusKey, u64)>,
    /// We sent payload commands (gimbal, GoPro) and may hold payload authority.
    payload_used: bool,
    /// The app's geofence, the predictive check and the hold (`geofence.rs`).
    fence: geofence::FenceState,
    /// Breadcrumbs, rewind options, the home told to the app (`rewind.rs`).
    rewind: rewind::RewindState,
    /// An app message or button changed the flying shot's guidance since the last
    /// step: step now rather than on the next tick (see "Event steps").
    step_requested: bool,
}

impl Engine {
    /// An idle engine. `store` says what the last run left: a shot that was active
    /// then is reported (`last_exit = "restarted"`, and to the app once connected),
    /// never resumed, and no command is sent for it.
    pub fn new(settings: Settings, mut store: Store, metrics: Metrics) -> Engine {
        let mut restart_notice = None;
        let mut last_exit = "";
        if let Some(shot) = store.state().active_shot {
            let name = shot_title(shot);
            tracing::warn!(
                shot = name,
                "the shot engine restarted while a shot was active; it is not resumed (the arbiter's freshness brake stopped the vehicle when the setpoints stopped)"
            );
            restart_notice = Some(format!("shot engine restarted; {name} ended"));
            last_exit = "restarted";
            if let Err(e) = store.update(|s| s.active_shot = None) {
                metrics.state_file_errors.inc();
                tracing::error!(error = %e, "cannot write the state file");
            }
        }
        let gopro = gopro::GoPro::new(store.state().gopro_enabled);
        Engine {
            out: Out {
                vehicle_id: settings.vehicle_id,
                max_age_ms: settings.setpoint_max_age_ms,
                next_id: 1,
                metrics,
                app_connected: false,
                commands: Vec::new(),
                to_app: Vec::new(),
            },
            settings,
            store,
            inputs: Inputs::default(),
            active: None,
            gopro,
            app_session: 0,
            app_heard_ns: 0,
            restart_notice,
            last_exit,
            last_status: None,
            payload_used: false,
            fence: geofence::FenceState::default(),
            rewind: rewind::RewindState::default(),
            step_requested: false,
        }
    }

    /// Opens the state file and builds the engine, logging what was found.
    pub fn open(settings: Settings, metrics: Metrics) -> Engine {
        let (store, loaded) = Store::open(settings.state_file.clone());
        let path = store.path().display().to_string();
        match loaded {
            Loaded::Fresh => tracing::info!(state_file = %path, "no state file yet; defaults"),
            Loaded::Existing => tracing::info!(state_file = %path, "state loaded"),
            Loaded::Corrupt { error, kept } => {
                metrics.state_file_errors.inc();
                tracing::error!(state_file = %path, error, kept = ?kept, "state file is corrupt; starting from defaults (the bad file is kept)")
            }
            Loaded::Unreadable { error } => {
                metrics.state_file_errors.inc();
                tracing::error!(state_file = %path, error, "cannot read the state file; starting from defaults")
            }
        }
        Engine::new(settings, store, metrics)
    }

    /// The Solo shot index being set up or flown, −1 when idle.
    pub fn current_shot(&self) -> i32 {
        self.active
            .as_ref()
            .map_or(skymesh_ipc_types::shot_api::shots::NONE, |a| a.shot)
    }

    /// True while a shot flies (authority asked for, setpoints every tick).
    pub fn is_flying(&self) -> bool {
        self.active.as_ref().is_some_and(|a| a.flight.is_some())
    }

    /// Why the last shot ended (empty while in a shot).
    pub fn last_exit(&self) -> &'static str {
        self.last_exit
    }

    pub fn handle_state(&mut self, state: &VehicleState, now_ns: u64) {
        if state.vehicle_id == self.settings.vehicle_id {
            self.inputs.state = Some((*state, now_ns));
        }
    }

    pub fn handle_payload(&mut self, payload: &PayloadState, _now_ns: u64) {
        if payload.vehicle_id != self.settings.vehicle_id {
            return;
        }
        self.inputs.payload = Some(*payload);
        self.gopro_sync();
    }

    pub fn handle_app_session(&mut self, session: &AppSession, now_ns: u64) {
        self.app_heard_ns = now_ns;
        let connected = session.connected != 0;
        if connected && (!self.out.app_connected || session.session != self.app_session) {
            if self.out.app_connected {
                tracing::info!(
                    old = self.app_session,
                    new = session.session,
                    "the app reconnected"
                );
                self.app_lost(now_ns);
            }
            tracing::info!(
                session = session.session,
                peer = session.peer.as_str(),
                "app connected"
            );
            self.app_connected(session.session);
        } else if !connected && self.out.app_connected {
            tracing::info!(session = self.app_session, "app disconnected");
            self.out.app_connected = false;
            self.app_lost(now_ns);
        }
    }

    pub fn handle_button(&mut self, event: &ButtonEvent, now_ns: u64) {
        app::button(self, event, now_ns);
    }

    /// True (once) when an app message or button since the last step changed the
    /// guidance of a flying shot: the caller should [`Engine::tick`] now (keeping its
    /// loop's phase; see "Event steps").
    pub fn take_step_request(&mut self) -> bool {
        std::mem::take(&mut self.step_requested) && self.is_flying()
    }

    /// Until when the service loop may sleep instead of ticking at `loop_hz`
    /// (`CLOCK_MONOTONIC` ns): `None` while something needs every tick — a shot in
    /// setup or flying, an armed vehicle (rewind breadcrumbs, the geofence check), a
    /// fence hold, breadcrumbs a disarm must still clear. Otherwise a tick only has
    /// time-driven work: the once-a-second idle `ShotStatus` and the app-session
    /// timeout, so the earlier of the two is the next instant a tick does anything.
    /// Everything else an idle engine reacts to arrives as a sample the loop waits for.
    pub fn idle_until(&self) -> Option<u64> {
        let armed = self
            .inputs
            .status
            .as_ref()
            .is_some_and(VehicleStatus::is_armed);
        if self.active.is_some()
            || armed
            || self.geofence_needs_ticks()
            || !self.rewind.crumbs.is_empty()
        {
            return None;
        }
        let status_due = self.periodic_status_at();
        let session_timeout = self.out.app_connected.then(|| {
            let timeout =
                u64::try_from(self.settings.app_session_timeout.as_nanos()).unwrap_or(u64::MAX);
            // `tick` acts once the silence is strictly longer than the timeout.
            self.app_heard_ns.saturating_add(timeout).saturating_add(1)
        });
        Some(session_timeout.map_or(status_due, |t| t.min(status_due)))
    }

    /// Steps the flying shot and returns everything pending.
    pub fn tick(&mut self, now_ns: u64) -> Outputs {
        self.step_requested = false;
        if self.out.app_connected
            && now_ns.saturating_sub(self.app_heard_ns)
                > u64::try_from(self.settings.app_session_timeout.as_nanos()).unwrap_or(u64::MAX)
        {
            tracing::warn!(
                timeout = ?self.settings.app_session_timeout,
                "no app session from the gateway; treating the app as disconnected"
            );
            self.out.app_connected = false;
            self.app_lost(now_ns);
        }
        self.geofence_tick(now_ns);
        self.step(now_ns);
        self.pano_after_step();
        self.rewind_after_step(now_ns);
        self.drain(now_ns)
    }

    /// Returns what the handlers produced since the last call (no stepping), with a
    /// status sample if it changed or is due.
    pub fn drain(&mut self, now_ns: u64) -> Outputs {
        Outputs {
            commands: std::mem::take(&mut self.out.commands),
            to_app: std::mem::take(&mut self.out.to_app),
            status: self.status_due(now_ns),
            geofence: self.fence.take_pending(),
        }
    }

    /// Graceful stop: ends an active shot (handing the vehicle back to the pilot in
    /// LOITER) and returns the last outputs.
    pub fn shutdown(&mut self, now_ns: u64) -> Outputs {
        self.exit_shot(ExitReason::Shutdown);
        self.geofence_shutdown();
        let mut out = self.drain(now_ns);
        out.status = Some(self.status());
        out
    }

    fn app_connected(&mut self, session: u32) {
        self.out.app_connected = true;
        self.app_session = session;
        if let Some(notice) = self.restart_notice.take() {
            self.out.error(&notice);
        }
        self.out.current_shot(self.current_shot());
        self.gopro_send_state();
        self.geofence_app_connected();
        self.rewind_app_connected();
    }

    /// An app message arrived: the gateway is alive and an app is connected.
    fn app_heard(&mut self, session: u32, now_ns: u64) {
        self.app_heard_ns = now_ns;
        if session != 0 && (!self.out.app_connected || session != self.app_session) {
            tracing::info!(
                session,
                "message from an app the engine had not seen connect"
            );
            if self.out.app_connected {
                self.app_lost(now_ns);
            }
            self.app_connected(session);
        }
    }

    /// The persisted state changed; a failed write is logged and counted.
    fn persist(&mut self, change: impl FnOnce(&mut crate::persist::Persisted)) {
        if let Err(e) = self.store.update(change) {
            self.out.metrics.state_file_errors.inc();
            tracing::error!(error = %e, "cannot write the state file");
        }
    }
}

/// How a shot is named to the app's user.
pub fn shot_title(shot: i32) -> &'static str {
    match shot {
        skymesh_ipc_types::shot_api::shots::SELFIE => "selfie",
        skymesh_ipc_types::shot_api::shots::ORBIT => "orbit",
        skymesh_ipc_types::shot_api::shots::CABLECAM => "cable cam",
        skymesh_ipc_types::shot_api::shots::ZIPLINE => "zipline",
        skymesh_ipc_types::shot_api::shots::FOLLOW => "follow",
        skymesh_ipc_types::shot_api::shots::MULTIPOINT => "multipoint cable cam",
        skymesh_ipc_types::shot_api::shots::PANO => "pano",
        skymesh_ipc_types::shot_api::shots::REWIND => "rewind",
        skymesh_ipc_types::shot_api::shots::TRANSECT => "transect",
        skymesh_ipc_types::shot_api::shots::RTL => "return home shot",
        sitescan::INSPECT => "site scan inspect",
        sitescan::SCAN => "site scan scan",
        sitescan::SURVEY => "site scan survey",
        _ => "shot",
    }
}

/// The metric label of a shot index.
pub fn shot_label(shot: i32) -> &'static str {
    match shot {
        sitescan::INSPECT => "inspect",
        sitescan::SCAN => "scan",
        sitescan::SURVEY => "survey",
        _ => skymesh_ipc_types::shot_api::shots::name(shot).unwrap_or("unknown"),
    }
}
