//! App messages and controller buttons: dispatch, entry, button mappings, and the
//! honest answers to what this version does not implement.
//!
//! Not implemented (each answered with SHOTMANAGER_ERROR "`<what>` is not
//! implemented in this skymesh version" and counted): SET_CURRENT_SHOT transect,
//! RTL (plus GET_CURRENT_SHOT of the current shot, so the app leaves the shot screen
//! when idle). HOME_LOCATION from the app sets the vehicle's home (`rewind.rs`).
//! GEOFENCE_* are `geofence.rs`'s; INSPECT_*, SCAN_START and SURVEY_START
//! `sitescan.rs`'s.
//!
//! Buttons (Press only, "we only use Press"): FLY ends the shot (and with no shot,
//! switches an armed vehicle to LOITER, the Solo's FLY mode); Pause toggles pause
//! (and tells the app with SOLO_PAUSE); A/B go to the shot when in one (orbit: A
//! locks the ROI; cable cam: A records a point; multipoint: A records, B records and
//! plays; zipline: A lays a new line, B toggles the spot lock; pano: A starts or
//! cancels, B changes the type; otherwise ignored), and when idle do
//! what they are mapped to: enter a shot (follow is refused: the spec says it is not
//! enterable from the controller), or set an ArduCopter mode.

use skymesh_ipc_types::shot_api::{
    shots, ButtonSetting, ShotEvent, ShotRequest, ShotRequestSample,
};
use skymesh_ipc_types::{Button, ButtonEvent, ButtonEventKind, Command, FlightMode};

use super::shot::{Active, ShotKind};
use super::{shot_label, shot_title, Engine, ExitReason};
use crate::persist::Mapping;

/// How a shot was asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Via {
    App,
    Button,
}

impl Engine {
    /// One request from a gateway (checked there against its protocol; its body
    /// is checked again here as it is decoded).
    pub fn handle_app(&mut self, msg: &ShotRequestSample, now_ns: u64) {
        let decoded = match msg.request() {
            Ok(m) => m,
            Err(e) => {
                self.out.metrics.decode_errors.inc();
                tracing::warn!(kind = msg.kind, error = %e, "shot request does not decode; ignored");
                return;
            }
        };
        self.out.metrics.app_in(decoded.name());
        if msg.is_follow_stream() {
            self.app_heard_ns = now_ns;
            match &decoded {
                ShotRequest::Location(loc) => self.follow_fix(loc, now_ns),
                other => {
                    tracing::debug!(msg = other.name(), "follow stream: not a location; ignored")
                }
            }
            return;
        }
        self.app_heard(msg.session, now_ns);
        let steers = steers_guidance(&decoded);
        self.dispatch(decoded, now_ns);
        if steers && self.is_flying() {
            self.step_requested = true;
        }
    }

    fn dispatch(&mut self, msg: ShotRequest, now_ns: u64) {
        use ShotRequest as M;
        match msg {
            M::StartShot(shot) => self.set_current_shot(shot, Via::App, now_ns),
            M::Location(loc) => self.shot_location(&loc, now_ns),
            M::RecordPosition => self.record_position(now_ns),
            M::CableOptions {
                cam_interpolation,
                yaw_direction_cw,
                cruise_speed,
            } => self.cable_options(cam_interpolation, yaw_direction_cw, cruise_speed),
            M::GetButtonSetting(b) => self.get_button_setting(b),
            M::SetButtonSetting(b) => self.set_button_setting(b),
            M::Pause => self.pause(false),
            M::FollowOptions {
                cruise_speed,
                look_at,
            } => self.follow_options(cruise_speed, look_at, None),
            M::FollowOptionsV2 {
                cruise_speed,
                look_at,
                follow_preference,
            } => self.follow_options(cruise_speed, look_at, Some(follow_preference)),
            M::ShotOptions { cruise_speed } => self.shot_options(cruise_speed),
            M::GoProSetEnabled(on) => self.gopro_set_enabled(on != 0),
            M::GoProSetRequest { command, value } => self.gopro_set_request(command, value),
            M::GoProSetExtendedRequest { command, value } => self.gopro_set(command, value),
            M::GoProRecord(what) => self.gopro_record(what),
            M::GoProRequestState => self.gopro_send_state(),
            M::SplinePoint(p) => self.spline_point(p),
            M::GeofenceUpdatePoly {
                action,
                polygon_index,
                vertex_index,
                lat_deg,
                lon_deg,
                sub_lat_deg,
                sub_lon_deg,
            } => self.geofence_update(
                action,
                polygon_index,
                vertex_index,
                lat_deg,
                lon_deg,
                sub_lat_deg,
                sub_lon_deg,
            ),
            M::GeofenceClear => self.geofence_clear_from_app(),
            M::SplineRecord => self.spline_record(),
            M::SplinePlay => self.spline_play(false),
            M::SplineSeek {
                u_position,
                cruise_state,
            } => self.spline_seek(u_position, cruise_state, now_ns),
            M::SplinePathSettings {
                camera_control,
                desired_time_s,
            } => self.spline_path_settings(camera_control, desired_time_s),
            M::SplineAttach(index) => self.spline_attach(index, now_ns),
            M::ZiplineOptions {
                cruise_speed,
                is_3d,
                cam_pointing,
            } => self.zipline_options(cruise_speed, is_3d, cam_pointing, now_ns),
            M::ZiplineLock => self.zipline_toggle_lock(now_ns),
            M::PanoOptions {
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov,
            } => self.pano_options(
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov,
                now_ns,
            ),
            M::RewindOptions {
                enabled,
                hover,
                rewind_distance,
            } => self.rewind_options(enabled, hover, rewind_distance),
            M::HomeLocation(loc) => self.home_location_from_app(&loc, now_ns),
            M::InspectStart { takeoff_alt_m } => self.inspect_start(takeoff_alt_m, now_ns),
            M::InspectSetWaypoint {
                lat_deg,
                lon_deg,
                alt_m,
            } => self.inspect_waypoint(lat_deg, lon_deg, alt_m, now_ns),
            M::InspectMoveGimbal {
                pitch_deg,
                roll_deg,
                yaw_deg,
            } => self.inspect_gimbal(pitch_deg, roll_deg, yaw_deg, now_ns),
            M::InspectMoveVehicle { vx, vy, vz } => self.inspect_move(vx, vy, vz, now_ns),
            M::ScanStart => self.scan_start(now_ns),
            M::SurveyStart => self.survey_start(now_ns),
        }
    }

    fn not_implemented(&mut self, what: &str) {
        self.out.metrics.unimplemented.inc();
        tracing::info!(
            what,
            "request for something this version does not implement"
        );
        self.out.error(&format!(
            "{what} is not implemented in this skymesh version"
        ));
    }

    /// SET_CURRENT_SHOT, or a button mapped to a shot.
    pub(crate) fn set_current_shot(&mut self, shot: i32, via: Via, now_ns: u64) {
        match shot {
            shots::NONE => {
                if self.active.is_some() {
                    self.exit_shot(ExitReason::App);
                } else {
                    self.out.current_shot(shots::NONE);
                }
            }
            shots::REWIND if !self.rewind_enabled() && self.current_shot() != shot => {
                self.out.metrics.refused_entry("rewind_disabled");
                tracing::info!(?via, "rewind is disabled in the rewind options");
                self.out
                    .error("rewind is disabled (SOLO_REWIND_OPTIONS enabled = 0)");
                self.out.current_shot(self.current_shot());
            }
            shots::SELFIE
            | shots::ORBIT
            | shots::CABLECAM
            | shots::FOLLOW
            | shots::ZIPLINE
            | shots::MULTIPOINT
            | shots::PANO
            | shots::REWIND => self.enter(shot, via, now_ns),
            shots::TRANSECT | shots::RTL => {
                self.not_implemented(shot_title(shot));
                self.out.current_shot(self.current_shot());
            }
            other => {
                tracing::warn!(shot = other, "unknown shot index");
                self.out.error(&format!("shot {other} does not exist"));
                self.out.current_shot(self.current_shot());
            }
        }
    }

    /// Gate, then enter `shot`, telling the app.
    fn enter(&mut self, shot: i32, via: Via, now_ns: u64) {
        let label = shot_label(shot);
        if via == Via::Button && shot == shots::FOLLOW {
            self.out.metrics.refused_entry("not_from_controller");
            tracing::info!("follow cannot be entered from the controller");
            self.out
                .error("follow cannot be started from the controller; start it in the app");
            return;
        }
        if self.current_shot() == shot {
            tracing::info!(shot = label, "already in this shot");
            self.out.current_shot(shot);
            return;
        }
        let view = match self.gate(now_ns) {
            Ok(v) => v,
            Err(r) => {
                self.out.metrics.refused_entry(r.label);
                tracing::info!(shot = label, code = r.code, why = %r.why, ?via, "shot refused");
                self.out.app(ShotEvent::Refused(r.code));
                return;
            }
        };
        self.exit_shot(ExitReason::Replaced);
        let Some(active) = Active::new(shot, &view, &self.settings) else {
            return;
        };
        tracing::info!(shot = label, ?via, "shot entered");
        self.active = Some(active);
        self.last_exit = "";
        self.out.metrics.entered(label);
        self.out.metrics.current_shot.set(f64::from(shot));
        self.persist(|s| s.active_shot = Some(shot));
        self.out.current_shot(shot);
        if !matches!(
            self.active.as_ref().map(|a| &a.kind),
            Some(ShotKind::Cable { .. })
        ) {
            self.send_options();
        }
        match shot {
            shots::ZIPLINE => self.zipline_start(now_ns),
            shots::PANO => self.pano_start(now_ns),
            shots::REWIND => self.rewind_start(now_ns),
            _ => {}
        }
    }

    fn mapping(&self, button: i32) -> Option<Mapping> {
        let b = &self.store.state().buttons;
        if button == i32::from(Button::A.to_wire()) {
            Some(b.a)
        } else if button == i32::from(Button::B.to_wire()) {
            Some(b.b)
        } else {
            None
        }
    }

    fn get_button_setting(&mut self, req: ButtonSetting) {
        let press = i32::from(ButtonEventKind::Press.to_wire());
        let m = self
            .mapping(req.button)
            .filter(|_| req.event == press)
            .unwrap_or(Mapping::NONE);
        self.out.app(ShotEvent::ButtonSetting(ButtonSetting {
            shot: m.shot,
            mode: m.mode,
            ..req
        }));
    }

    fn set_button_setting(&mut self, s: ButtonSetting) {
        if self.mapping(s.button).is_none() {
            self.out.error("only the A and B buttons can be mapped");
            return;
        }
        if s.event != i32::from(ButtonEventKind::Press.to_wire()) {
            self.out.error("only Press events can be mapped");
            return;
        }
        if !(shots::MIN..=shots::MAX).contains(&s.shot) || !(-1..=255).contains(&s.mode) {
            self.out.error(&format!(
                "button mapping shot {} / mode {} is out of range",
                s.shot, s.mode
            ));
            return;
        }
        let m = Mapping {
            shot: s.shot,
            mode: s.mode,
        };
        let is_a = s.button == i32::from(Button::A.to_wire());
        tracing::info!(
            button = if is_a { "A" } else { "B" },
            shot = m.shot,
            mode = m.mode,
            "button mapped"
        );
        self.persist(|p| {
            if is_a {
                p.buttons.a = m;
            } else {
                p.buttons.b = m;
            }
        });
    }

    /// The app went away: end the shots that need it.
    pub(crate) fn app_lost(&mut self, _now_ns: u64) {
        self.geofence_app_lost();
        let Some(a) = &self.active else {
            return;
        };
        let needs_app = matches!(a.kind, ShotKind::Selfie { .. } | ShotKind::Follow(_))
            || matches!(&a.kind, ShotKind::SiteScan(s) if s.needs_app())
            || a.flight.is_none();
        if needs_app {
            self.exit_shot(ExitReason::AppDisconnected);
        } else {
            tracing::info!(
                shot = shot_title(a.shot),
                "app gone; the shot keeps flying (the pilot ends it with FLY)"
            );
        }
    }
}

/// App messages that can change what a flying shot commands (or start its flight):
/// after one, the engine steps at once instead of on the next tick.
fn steers_guidance(msg: &ShotRequest) -> bool {
    use ShotRequest as M;
    matches!(
        msg,
        M::StartShot(_)
            | M::Location(_)
            | M::RecordPosition
            | M::CableOptions { .. }
            | M::Pause
            | M::FollowOptions { .. }
            | M::FollowOptionsV2 { .. }
            | M::ShotOptions { .. }
            | M::SplinePlay
            | M::SplineSeek { .. }
            | M::SplinePathSettings { .. }
            | M::SplineAttach(_)
            | M::ZiplineOptions { .. }
            | M::ZiplineLock
            | M::PanoOptions { .. }
            | M::RewindOptions { .. }
            | M::InspectStart { .. }
            | M::InspectSetWaypoint { .. }
            | M::InspectMoveGimbal { .. }
            | M::InspectMoveVehicle { .. }
            | M::ScanStart
            | M::SurveyStart
    )
}

/// GoPro status "connected" (GOPRO_HEARTBEAT_STATUS_CONNECTED, the app's STATUS_GOPRO_CONNECTED).
const GOPRO_CONNECTED: u8 = 2;

/// A controller button event.
pub(crate) fn button(engine: &mut Engine, ev: &ButtonEvent, now_ns: u64) {
    if ev.vehicle_id != engine.settings.vehicle_id {
        return;
    }
    let (Ok(button), Ok(kind)) = (ev.button(), ev.event()) else {
        tracing::warn!(
            button = ev.button,
            event = ev.event,
            "unknown button event; ignored"
        );
        return;
    };
    if kind != ButtonEventKind::Press {
        return;
    }
    if matches!(button, Button::Pause | Button::A | Button::B) {
        // Pause and the shot's A/B change a flying shot's guidance: step at once.
        engine.step_requested = true;
    }
    match button {
        Button::Fly if engine.active.is_some() => engine.exit_shot(ExitReason::FlyButton),
        Button::Fly => idle_fly(engine),
        Button::Pause => engine.pause(true),
        Button::A | Button::B if engine.active.is_some() => engine.shot_button(button, now_ns),
        Button::A | Button::B => idle_mapped(engine, button, now_ns),
        Button::CameraClick => camera_click(engine),
        other => tracing::debug!(button = %other, "button not handled by the shot engine"),
    }
}

/// The controller's camera button, in or out of a shot: with a GoPro connected (and
/// enabled) it is GOPRO_RECORD toggle (a photo in a photo mode, start/stop in
/// video), as on the Solo; without one, a photo through the MAVLink camera protocol.
fn camera_click(engine: &mut Engine) {
    let gopro = engine.gopro_state();
    if gopro.status == GOPRO_CONNECTED {
        engine.gopro_record(2);
    } else {
        tracing::info!("camera button: photo (no GoPro connected)");
        engine.payload_used = true;
        engine.out.command(Command::CameraCapture);
    }
}

/// FLY with no shot: the Solo's FLY button always means "LOITER, sticks to the
/// pilot". Needed when nothing else would give the sticks back, e.g. after the
/// engine restarted mid-shot and left the vehicle braked in GUIDED.
fn idle_fly(engine: &mut Engine) {
    let Some(status) = engine.inputs.status.as_ref() else {
        return;
    };
    let mode = status.flight_mode();
    if !status.is_armed() || mode == FlightMode::Loiter {
        return;
    }
    tracing::info!(from = %mode, "FLY: LOITER");
    engine.out.command(Command::SetMode(FlightMode::Loiter));
    engine.out.command(Command::ReleaseFlightAuthority);
}

/// A or B pressed with no shot active: do what it is mapped to.
fn idle_mapped(engine: &mut Engine, button: Button, now_ns: u64) {
    let Some(m) = engine.mapping(button.to_wire().into()) else {
        return;
    };
    if m.shot != shots::NONE {
        if !engine.out.app_connected {
            engine.out.metrics.refused_entry("no_app");
            tracing::warn!(%button, shot = shot_label(m.shot), "shots from the controller need a connected app");
            return;
        }
        engine.set_current_shot(m.shot, Via::Button, now_ns);
    } else if m.mode >= 0 {
        let mode = FlightMode::from_copter_custom_mode(m.mode as u32);
        if mode.to_copter_custom_mode().is_none() {
            tracing::warn!(%button, mode = m.mode, "button mapped to a mode skymesh does not know");
            engine.out.error(&format!(
                "button mapped to ArduCopter mode {}, which skymesh cannot command",
                m.mode
            ));
            return;
        }
        tracing::info!(%button, %mode, "button: mode change");
        engine.out.command(Command::SetMode(mode));
        engine.out.command(Command::ReleaseFlightAuthority);
    } else {
        tracing::info!(%button, "button is not mapped");
    }
}
