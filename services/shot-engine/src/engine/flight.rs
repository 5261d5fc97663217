//! Entering, flying and leaving a shot; the arbiter's answers.
//!
//! Entry gate (SOLO_SHOT_ERROR codes of the spec): no vehicle state or status yet,
//! the link down, or no fresh position → 2 (RTL: "not now"; the log says which);
//! EKF not healthy → 0 (BAD_EKF); disarmed → 1 (UNARMED); RTL, SmartRTL or LAND, or
//! the battery at or below `battery_critical_pct` → 2 (RTL).
//!
//! Flying: `GrabFlightAuthority`, `SetMode(Guided)`, `SetRoi` (shots with an ROI),
//! then a velocity setpoint every tick; once the vehicle reports GUIDED the camera
//! commands are sent again (entering GUIDED resets ArduCopter's yaw mode). The shot ends when
//! - the vehicle leaves GUIDED after it was seen in GUIDED (`mode_change`), or does
//!   not reach GUIDED within [`GUIDED_TIMEOUT_NS`] or the mode change is refused
//!   (`guided_refused`);
//! - another source holds flight authority: the `AuthorityState` shows another
//!   holder after it showed us (`preempted`) or nobody (`authority_lost`), or a flight
//!   command of this flight is refused `no_authority` / `preempted`, or an
//!   `ArbiterEvent` says our flight authority was pre-empted;
//! - an emergency stop (`emergency`) or the link goes down (`link_down`).

use skymesh_ipc_types::{AuthorityDomain, Command, FlightMode, VehicleStatus};

use super::camera::Camera;
use super::{shot_label, Engine, Out};
use crate::shots::{GeoPoint, Guidance, VehicleView};

/// GUIDED must be reached this soon after it was asked for, ns.
pub const GUIDED_TIMEOUT_NS: u64 = 5_000_000_000;

/// Why a shot ended (`ShotStatus.last_exit`, metric label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitReason {
    /// SET_CURRENT_SHOT −1 from the app.
    App,
    FlyButton,
    /// The pilot or the autopilot changed the mode away from GUIDED.
    ModeChange,
    /// Another source took flight authority from us.
    Preempted,
    /// A flight command was refused for lack of authority before we held it.
    NoAuthority,
    /// Nobody holds authority any more (quiet timeout).
    AuthorityLost,
    Emergency,
    LinkDown,
    AppDisconnected,
    /// Another shot was entered.
    Replaced,
    /// GUIDED was refused or not reached in time.
    GuidedRefused,
    Shutdown,
    /// The shot completed (a photo pano, a rewind that hovers): brake, LOITER.
    Finished,
    /// A rewind completed and sent the vehicle home (RTL): authority released.
    FinishedRtl,
    /// The vehicle would cross the geofence: the engine holds it at the fence
    /// (`geofence.rs`); ROI cleared and authority released before the hold takes it.
    Geofence,
}

/// What an exit does with the vehicle (see the engine docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Handover {
    /// Brake and LOITER (if GUIDED), clear the ROI, release authority.
    Loiter,
    /// Clear the ROI, release authority.
    Release,
    /// Nothing: we no longer hold authority or the link is down.
    Nothing,
}

impl ExitReason {
    pub fn as_str(self) -> &'static str {
        match self {
            ExitReason::App => "app",
            ExitReason::FlyButton => "fly_button",
            ExitReason::ModeChange => "mode_change",
            ExitReason::Preempted => "preempted",
            ExitReason::NoAuthority => "no_authority",
            ExitReason::AuthorityLost => "authority_lost",
            ExitReason::Emergency => "emergency",
            ExitReason::LinkDown => "link_down",
            ExitReason::AppDisconnected => "app_disconnected",
            ExitReason::Replaced => "replaced",
            ExitReason::GuidedRefused => "guided_refused",
            ExitReason::Shutdown => "shutdown",
            ExitReason::Finished => "finished",
            ExitReason::FinishedRtl => "finished_rtl",
            ExitReason::Geofence => "geofence",
        }
    }

    fn handover(self) -> Handover {
        match self {
            ExitReason::App
            | ExitReason::FlyButton
            | ExitReason::AppDisconnected
            | ExitReason::Replaced
            | ExitReason::Shutdown
            | ExitReason::Finished => Handover::Loiter,
            ExitReason::ModeChange
            | ExitReason::GuidedRefused
            | ExitReason::FinishedRtl
            | ExitReason::Geofence => Handover::Release,
            ExitReason::Preempted
            | ExitReason::NoAuthority
            | ExitReason::AuthorityLost
            | ExitReason::Emergency
            | ExitReason::LinkDown => Handover::Nothing,
        }
    }
}

/// Why the entry gate said no.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    /// SOLO_SHOT_ERROR: 0 BAD_EKF, 1 UNARMED, 2 RTL.
    pub code: u32,
    /// Metric label.
    pub label: &'static str,
    pub why: String,
}

fn refusal(code: u32, label: &'static str, why: impl Into<String>) -> Refusal {
    Refusal {
        code,
        label,
        why: why.into(),
    }
}

/// The flying phase of a shot.
#[derive(Debug, Clone)]
pub(crate) struct Flight {
    /// Acks for commands before this id belong to an earlier flight.
    pub first_command_id: u32,
    /// The `AuthorityState` has shown us as the flight holder.
    pub confirmed: bool,
    pub guided_command_id: Option<u32>,
    pub guided_asked_ns: u64,
    /// A heartbeat that arrived after `guided_asked_ns` showed GUIDED: from then on,
    /// any other mode means the pilot took the vehicle back.
    pub guided_seen: bool,
    pub camera: Camera,
    pub last_step_ns: Option<u64>,
    /// A stale vehicle state has been logged (once per episode).
    pub stale_logged: bool,
    /// The velocity the shot asked for on its last step (NED, m/s): the geofence
    /// check predicts with the shot's intent, not only with what the arbiter let
    /// through (its envelope slows a vehicle near the fence, which would otherwise
    /// hide a shot that keeps pushing at it).
    pub commanded_vel: Option<[f32; 3]>,
}

/// Sends one step's guidance: the velocity setpoint (a non-finite one becomes a
/// hover) and the camera commands that changed; remembers the commanded velocity
/// for the geofence check. Every flying shot goes through here.
pub(crate) fn send_guidance(
    flight: &mut Flight,
    guidance: &Guidance,
    out: &mut Out,
    payload_used: &mut bool,
    now_ns: u64,
) {
    let mut vel = guidance.velocity_ned_mps;
    if vel.iter().any(|v| !v.is_finite()) {
        tracing::warn!(?vel, "shot asked for a non-finite velocity; holding");
        vel = [0.0; 3];
    }
    flight.commanded_vel = Some(vel);
    let camera = flight.camera.commands(guidance, now_ns);
    out.command(Command::VelocityNed {
        vel_ned_mps: vel,
        yaw_rate_dps: None,
    });
    for cmd in camera {
        if cmd.kind().authority() == Some(AuthorityDomain::Payload) {
            *payload_used = true;
        }
        out.command(cmd);
    }
}

impl Engine {
    /// The entry gate; the vehicle view to start from when it passes.
    pub(crate) fn gate(&self, now_ns: u64) -> Result<VehicleView, Refusal> {
        let (Some(_), Some(status)) = (&self.inputs.state, &self.inputs.status) else {
            return Err(refusal(2, "rtl", "no vehicle state received yet"));
        };
        if !status.is_link_up() {
            return Err(refusal(2, "rtl", "the autopilot link is down"));
        }
        if status.ekf_healthy == 0 {
            return Err(refusal(0, "bad_ekf", "the EKF is not healthy"));
        }
        if !status.is_armed() {
            return Err(refusal(1, "unarmed", "the vehicle is not armed"));
        }
        let mode = status.flight_mode();
        if matches!(
            mode,
            FlightMode::Rtl | FlightMode::SmartRtl | FlightMode::Land
        ) {
            return Err(refusal(2, "rtl", format!("the vehicle is in {mode}")));
        }
        let critical = self.settings.battery_critical_pct;
        if critical > 0
            && status.battery_remaining_pct >= 0
            && status.battery_remaining_pct as u8 <= critical
        {
            return Err(refusal(
                2,
                "rtl",
                format!("battery at {} %", status.battery_remaining_pct),
            ));
        }
        self.inputs
            .view(now_ns)
            .ok_or_else(|| refusal(0, "bad_ekf", "no valid vehicle position in the last second"))
    }

    /// Starts the flying phase of the active shot: authority, ROI, GUIDED.
    pub(crate) fn begin_flight(&mut self, roi: Option<GeoPoint>, now_ns: u64) {
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let mut flight = Flight {
            first_command_id: self.out.peek_id(),
            confirmed: false,
            guided_command_id: None,
            guided_asked_ns: now_ns,
            // Even when the last status says GUIDED: it may predate a LOITER of ours
            // (the shot before ended a moment ago) that no heartbeat has shown yet.
            guided_seen: false,
            camera: Camera::default(),
            last_step_ns: None,
            stale_logged: false,
            commanded_vel: None,
        };
        self.out.command(Command::GrabFlightAuthority);
        flight.guided_command_id = self.out.command(Command::SetMode(FlightMode::Guided));
        if let Some(roi) = roi {
            let cmd = flight.camera.roi_sent(roi, now_ns);
            self.out.command(cmd);
        }
        tracing::info!(
            shot = shot_label(active.shot),
            "shot flying: GUIDED, setpoints at loop rate"
        );
        active.flight = Some(flight);
    }

    /// Ends the active shot (if any) for `reason`.
    pub(crate) fn exit_shot(&mut self, reason: ExitReason) {
        let Some(active) = self.active.take() else {
            return;
        };
        let handover = reason.handover();
        if let Some(flight) = &active.flight {
            let guided = self.inputs.mode() == FlightMode::Guided;
            if handover == Handover::Loiter && guided {
                self.out.command(Command::Brake);
            }
            // Also when our GUIDED request may still be on its way: LOITER must win.
            if handover == Handover::Loiter && (guided || !flight.guided_seen) {
                self.out.command(Command::SetMode(FlightMode::Loiter));
            }
            if handover != Handover::Nothing {
                if flight.camera.roi.is_some() {
                    self.out.command(Command::ClearRoi);
                }
                self.out.command(Command::ReleaseFlightAuthority);
                self.release_payload_if_idle(false);
            }
        }
        tracing::info!(
            shot = shot_label(active.shot),
            reason = reason.as_str(),
            was_flying = active.flight.is_some(),
            "shot ended"
        );
        self.out
            .current_shot(skymesh_ipc_types::shot_api::shots::NONE);
        self.last_exit = reason.as_str();
        self.out.metrics.exited(reason.as_str());
        self.out.metrics.current_shot.set(-1.0);
        self.persist(|s| s.active_shot = None);
    }

    /// Gives payload authority back if nothing needs it (no GoPro request pending,
    /// and no flying shot unless `keep_for_flight` is false).
    pub(crate) fn release_payload_if_idle(&mut self, keep_for_flight: bool) {
        if !self.payload_used || self.gopro.pending() > 0 || (keep_for_flight && self.is_flying()) {
            return;
        }
        self.payload_used = false;
        self.out.command(Command::ReleasePayloadAuthority);
    }

    /// One control step of the flying shot.
    pub(crate) fn step(&mut self, now_ns: u64) {
        self.check_guided_timeout(now_ns);
        self.follow_prepare(now_ns);
        if self.sitescan_step(now_ns) {
            return;
        }
        let view = self.inputs.view(now_ns);
        let lim = self.settings.limits;
        let period = self.settings.loop_period.as_secs_f32();
        let follow_lost = self.settings.follow_lost;
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let Some(flight) = active.flight.as_mut() else {
            return;
        };
        let dt = flight
            .last_step_ns
            .map_or(period, |t| now_ns.saturating_sub(t) as f32 / 1e9)
            .clamp(0.001, 0.5);
        flight.last_step_ns = Some(now_ns);
        let guidance = match view {
            Some(v) => {
                if flight.stale_logged {
                    tracing::info!("vehicle state is fresh again; shot resumes");
                    flight.stale_logged = false;
                }
                active.guidance(&v, now_ns, dt, &lim, follow_lost, &mut self.out)
            }
            None => {
                if !flight.stale_logged {
                    tracing::warn!("no fresh vehicle state; holding (zero velocity)");
                    flight.stale_logged = true;
                }
                Guidance {
                    roi: flight.camera.roi,
                    ..Guidance::HOVER
                }
            }
        };
        let Some(flight) = active.flight.as_mut() else {
            return;
        };
        send_guidance(
            flight,
            &guidance,
            &mut self.out,
            &mut self.payload_used,
            now_ns,
        );
    }

    fn check_guided_timeout(&mut self, now_ns: u64) {
        let late = self
            .active
            .as_ref()
            .and_then(|a| a.flight.as_ref())
            .is_some_and(|f| {
                !f.guided_seen && now_ns.saturating_sub(f.guided_asked_ns) > GUIDED_TIMEOUT_NS
            });
        if late {
            tracing::warn!("the vehicle did not switch to GUIDED in time; ending the shot");
            self.out
                .error("could not switch the vehicle to GUIDED; shot ended");
            self.exit_shot(ExitReason::GuidedRefused);
        }
    }

    pub fn handle_status(&mut self, status: &VehicleStatus, _now_ns: u64) {
        if status.vehicle_id != self.settings.vehicle_id {
            return;
        }
        self.inputs.status = Some(*status);
        self.home_update();
        if self.active.is_none() {
            return;
        }
        if !status.is_link_up() {
            tracing::warn!("autopilot link down; ending the shot");
            self.exit_shot(ExitReason::LinkDown);
            return;
        }
        let Some(flight) = self.active.as_mut().and_then(|a| a.flight.as_mut()) else {
            return;
        };
        // A heartbeat from before the GUIDED request says nothing about it.
        let Some(mode) = self.inputs.mode_since(flight.guided_asked_ns) else {
            return;
        };
        if mode == FlightMode::Guided {
            if !flight.guided_seen {
                // Entering GUIDED resets the autopilot's yaw mode (ArduCopter forgets an
                // ROI set before): send the camera commands again on the next tick.
                flight.guided_seen = true;
                flight.camera.resend();
            }
        } else if flight.guided_seen {
            tracing::info!(%mode, "the vehicle left GUIDED; ending the shot");
            self.exit_shot(ExitReason::ModeChange);
        }
    }
}
