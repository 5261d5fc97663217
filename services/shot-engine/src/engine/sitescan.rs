//! Site Scan: inspect, structure scan and survey, entered through their START
//! messages (they have no Solo shot index: the engine numbers them [`INSPECT`],
//! [`SCAN`], [`SURVEY`] for its status and metrics, and never tells the app an index
//! for them; an exit still sends GET_CURRENT_SHOT −1).
//!
//! | message | the engine |
//! |---|---|
//! | SOLO_INSPECT_START (takeoffAlt, 1..=`site_scan_max_alt_m`) | entry gate as any shot; then flight authority and GUIDED, and once GUIDED: `Takeoff` to takeoffAlt when the vehicle is on the ground (at most `IN_AIR_ALT_M` up), else a `GoTo` straight up (or down) to it |
//! | SOLO_INSPECT_SET_WAYPOINT | `GoTo` lat/lon/alt (alt 1..=`site_scan_max_alt_m`) at the cruise speed |
//! | SOLO_INSPECT_MOVE_GIMBAL | `Gimbal` pitch (clamped to −90..=0; roll is not commanded) and `SetYaw` to the earth-frame yaw |
//! | SOLO_INSPECT_MOVE_VEHICLE | one `VelocityNed` per message: the body-frame velocity turned by the heading, within the speed limits, with the setpoint max age — the engine sends nothing between messages, so when the app stops, the arbiter brakes |
//! | SOLO_SCAN_START | a structure scan (`shots::sitescan::StructureScan`) around the active shot's ROI (an orbit's), else `scan_center`, else the camera's projected ROI; in the air only |
//! | SOLO_SURVEY_START | a survey (`shots::sitescan::Survey`) over the first keep-in geofence polygon, else `survey_area`; in the air only. Over the fence it flies the polygon's hold line (its sub-polygon, which the app draws inside the fence): lanes end on the area's edge, and lanes ending on the fence itself would trip the predictive check and the arbiter's margin there — the hold line should lie a few metres (more than the arbiter's `fence_margin_m`) inside. The camera footprint reaches past the lane ends. |
//!
//! A START while the same Site Scan shot runs is ignored (the spec: once per shot);
//! inspect commands outside an inspect shot are refused with SHOTMANAGER_ERROR
//! (MOVE_VEHICLE, a stream, is dropped silently). Commands that need GUIDED wait for
//! it. Inspect re-sends `GrabFlightAuthority` every [`KEEPALIVE_NS`] while the app
//! sends nothing, so the arbiter's quiet timeout does not take the authority.
//!
//! Scan and survey fly like the other shots (a velocity setpoint every tick,
//! camera commands on change), take a photo (`CameraCapture`) at each trigger,
//! report progress in `ShotStatus.progress` (0..1) and the log (every 10 %; the
//! protocol has no progress message), and end in LOITER (exit reason
//! `finished`). Pause holds them; in inspect, which the app flies, it only shows
//! in the status. Inspect ends when the app disconnects (the app flies it); a scan
//! or survey flies on (the pilot has FLY).

use skymesh_ipc_types::{AuthorityDomain, Command, FenceKind};

use super::geofence::in_air;
use super::shot::{Active, ShotKind};
use super::{shot_label, Engine, ExitReason};
use crate::shots::{
    body_to_ned, projected_roi, GeoPoint, Guidance, StructureScan, Survey, VehicleView,
};

/// Engine-internal shot numbers (outside the Solo range −1..=10).
pub const INSPECT: i32 = 100;
pub const SCAN: i32 = 101;
pub const SURVEY: i32 = 102;

/// Inspect re-grabs flight authority this often while idle (the arbiter's quiet
/// timeout is 5 s by default), ns.
pub const KEEPALIVE_NS: u64 = 1_000_000_000;

/// A Site Scan shot's own state.
#[derive(Debug)]
pub(crate) enum SiteScan {
    Inspect {
        /// Flight commands waiting for GUIDED, oldest first.
        pending: Vec<Command>,
        /// When the last flight command went out.
        last_flight_ns: u64,
    },
    Scan {
        scan: Box<StructureScan>,
        center: GeoPoint,
        photos: u32,
        progress: f32,
    },
    Survey {
        survey: Box<Survey>,
        photos: u32,
        progress: f32,
    },
}

impl SiteScan {
    /// The structure a scan looks at.
    pub fn roi(&self) -> Option<GeoPoint> {
        match self {
            SiteScan::Scan { center, .. } => Some(*center),
            _ => None,
        }
    }

    /// 0..1 for scan and survey; 0 for inspect.
    pub fn progress(&self) -> f32 {
        match self {
            SiteScan::Scan { progress, .. } | SiteScan::Survey { progress, .. } => *progress,
            SiteScan::Inspect { .. } => 0.0,
        }
    }

    /// Inspect is flown by the app: it ends with the app.
    pub fn needs_app(&self) -> bool {
        matches!(self, SiteScan::Inspect { .. })
    }
}

impl Engine {
    fn site_scan(&self) -> Option<&SiteScan> {
        match &self.active.as_ref()?.kind {
            ShotKind::SiteScan(s) => Some(s),
            _ => None,
        }
    }

    /// The entry gate, plus "in the air" for scan and survey. Refusals are told.
    fn site_gate(&mut self, shot: i32, need_air: bool, now_ns: u64) -> Option<VehicleView> {
        let label = shot_label(shot);
        let view = match self.gate(now_ns) {
            Ok(v) => v,
            Err(r) => {
                self.out.metrics.refused_entry(r.label);
                tracing::info!(shot = label, code = r.code, why = %r.why, "site scan refused");
                self.out.app(skymesh_ipc_types::ShotEvent::Refused(r.code));
                return None;
            }
        };
        if need_air && !in_air(&view) {
            self.out.metrics.refused_entry("on_ground");
            tracing::info!(shot = label, "site scan refused: on the ground");
            self.out.error(&format!(
                "{label}: take off first (the vehicle is on the ground)"
            ));
            return None;
        }
        Some(view)
    }

    /// Ends the current shot and enters Site Scan `shot`.
    fn site_enter(&mut self, shot: i32, kind: SiteScan, cruise: f32, now_ns: u64) {
        // A flying shot is handed over in LOITER first: GUIDED counts only once the
        // vehicle reports it again (else the LOITER on its way would end this shot).
        let handed_over = self.is_flying();
        self.exit_shot(ExitReason::Replaced);
        let label = shot_label(shot);
        tracing::info!(shot = label, "site scan shot entered");
        self.active = Some(Active {
            shot,
            kind: ShotKind::SiteScan(Box::new(kind)),
            cruise,
            paused: None,
            flight: None,
        });
        self.last_exit = "";
        self.out.metrics.entered(label);
        self.out.metrics.current_shot.set(f64::from(shot));
        self.persist(|s| s.active_shot = Some(shot));
        self.begin_flight(None, now_ns);
        if handed_over {
            if let Some(f) = self.active.as_mut().and_then(|a| a.flight.as_mut()) {
                f.guided_seen = false;
            }
        }
    }

    /// SOLO_INSPECT_START.
    pub(crate) fn inspect_start(&mut self, takeoff_alt_m: f32, now_ns: u64) {
        if matches!(self.site_scan(), Some(SiteScan::Inspect { .. })) {
            tracing::info!("inspect: already started; INSPECT_START ignored");
            return;
        }
        let max = self.settings.site_scan.max_alt_m;
        if !(1.0..=max).contains(&takeoff_alt_m) {
            self.out.error(&format!(
                "inspect: takeoff altitude {takeoff_alt_m} m is outside 1..={max} m"
            ));
            return;
        }
        let Some(view) = self.site_gate(INSPECT, false, now_ns) else {
            return;
        };
        let on_ground = !in_air(&view);
        let climb = if on_ground {
            Command::Takeoff {
                alt_rel_m: takeoff_alt_m,
            }
        } else {
            self.goto(&GeoPoint {
                alt_rel_m: takeoff_alt_m,
                ..view.position
            })
        };
        tracing::info!(takeoff_alt_m, on_ground, "inspect: climbing once GUIDED");
        let kind = SiteScan::Inspect {
            pending: vec![climb],
            last_flight_ns: now_ns,
        };
        let cruise = self.settings.limits.max_speed_mps;
        self.site_enter(INSPECT, kind, cruise, now_ns);
    }

    fn goto(&self, p: &GeoPoint) -> Command {
        let cruise = self.active.as_ref().map_or(0.0, |a| a.cruise);
        let speed = if cruise > 0.0 {
            cruise
        } else {
            self.settings.limits.max_speed_mps
        };
        Command::GoTo {
            lat_deg: p.lat_deg,
            lon_deg: p.lon_deg,
            alt_rel_m: p.alt_rel_m,
            yaw_deg: None,
            speed_mps: Some(speed),
        }
    }

    /// Sends `cmds` now if GUIDED was seen, else queues them (inspect only).
    fn inspect_send(&mut self, cmds: Vec<Command>, now_ns: u64) {
        let guided = self
            .active
            .as_ref()
            .and_then(|a| a.flight.as_ref())
            .is_some_and(|f| f.guided_seen);
        let Some(Active {
            kind: ShotKind::SiteScan(s),
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        let SiteScan::Inspect {
            pending,
            last_flight_ns,
        } = s.as_mut()
        else {
            return;
        };
        if !guided {
            pending.extend(cmds);
            return;
        }
        *last_flight_ns = now_ns;
        for c in cmds {
            if c.kind().authority() == Some(AuthorityDomain::Payload) {
                self.payload_used = true;
            }
            self.out.command(c);
        }
    }

    /// True (after telling the app) if no inspect shot is active.
    fn not_inspecting(&mut self, what: &str) -> bool {
        if matches!(self.site_scan(), Some(SiteScan::Inspect { .. })) {
            return false;
        }
        tracing::info!(what, "inspect command outside an inspect shot; refused");
        self.out.error(&format!(
            "inspect: {what} needs an inspect shot (send SOLO_INSPECT_START first)"
        ));
        true
    }

    /// SOLO_INSPECT_SET_WAYPOINT.
    pub(crate) fn inspect_waypoint(&mut self, lat: f32, lon: f32, alt: f32, now_ns: u64) {
        if self.not_inspecting("set waypoint") {
            return;
        }
        let max = self.settings.site_scan.max_alt_m;
        if !(1.0..=max).contains(&alt) {
            self.out.error(&format!(
                "inspect: waypoint altitude {alt} m is outside 1..={max} m"
            ));
            return;
        }
        let p = GeoPoint {
            lat_deg: f64::from(lat),
            lon_deg: f64::from(lon),
            alt_rel_m: alt,
        };
        tracing::info!(lat, lon, alt, "inspect: waypoint");
        let cmd = self.goto(&p);
        self.inspect_send(vec![cmd], now_ns);
    }

    /// SOLO_INSPECT_MOVE_GIMBAL.
    pub(crate) fn inspect_gimbal(&mut self, pitch: f32, roll: f32, yaw: f32, now_ns: u64) {
        if self.not_inspecting("move gimbal") {
            return;
        }
        tracing::debug!(pitch, roll, yaw, "inspect: gimbal (roll is not commanded)");
        let cmds = vec![
            Command::Gimbal {
                pitch_deg: pitch.clamp(-90.0, 0.0),
                yaw_deg: 0.0,
            },
            Command::SetYaw {
                yaw_deg: yaw.rem_euclid(360.0),
                rate_dps: 0.0,
                relative: false,
            },
        ];
        self.inspect_send(cmds, now_ns);
    }

    /// SOLO_INSPECT_MOVE_VEHICLE: one setpoint, forwarded only in GUIDED.
    pub(crate) fn inspect_move(&mut self, vx: f32, vy: f32, vz: f32, now_ns: u64) {
        let guided = self
            .active
            .as_ref()
            .and_then(|a| a.flight.as_ref())
            .is_some_and(|f| f.guided_seen);
        if !matches!(self.site_scan(), Some(SiteScan::Inspect { .. })) || !guided {
            tracing::debug!("MOVE_VEHICLE outside a flying inspect shot dropped");
            return;
        }
        let Some(view) = self.inputs.view(now_ns) else {
            tracing::debug!("MOVE_VEHICLE without a fresh heading dropped");
            return;
        };
        let lim = self.settings.limits;
        let [n, e, d] = body_to_ned(vx, vy, vz, view.heading_deg);
        let h = n.hypot(e);
        let k = if h > lim.max_speed_mps {
            lim.max_speed_mps / h
        } else {
            1.0
        };
        let vel = [n * k, e * k, d.clamp(-lim.max_climb_mps, lim.max_climb_mps)];
        self.inspect_send(
            vec![Command::VelocityNed {
                vel_ned_mps: vel,
                yaw_rate_dps: None,
            }],
            now_ns,
        );
    }

    /// SOLO_SCAN_START.
    pub(crate) fn scan_start(&mut self, now_ns: u64) {
        if matches!(self.site_scan(), Some(SiteScan::Scan { .. })) {
            tracing::info!("scan: already scanning; SCAN_START ignored");
            return;
        }
        let shot_roi = self.active.as_ref().and_then(Active::roi);
        let Some(view) = self.site_gate(SCAN, true, now_ns) else {
            return;
        };
        let ss = &self.settings.site_scan;
        let center = shot_roi
            .or(ss.scan_center)
            .unwrap_or_else(|| projected_roi(&view));
        let scan = match StructureScan::new(center, &view, &ss.scan) {
            Ok(s) => s,
            Err(e) => {
                self.out.error(&format!("scan: cannot fly it: {e}"));
                return;
            }
        };
        tracing::info!(
            lat = center.lat_deg,
            lon = center.lon_deg,
            radius_m = scan.radius_m(),
            levels = scan.levels().len(),
            photo_every_m = scan.trigger_spacing_m(),
            "scan: structure scan"
        );
        let kind = SiteScan::Scan {
            scan: Box::new(scan),
            center,
            photos: 0,
            progress: 0.0,
        };
        let cruise = ss.scan_speed_mps;
        self.site_enter(SCAN, kind, cruise, now_ns);
    }

    /// SOLO_SURVEY_START.
    pub(crate) fn survey_start(&mut self, now_ns: u64) {
        if matches!(self.site_scan(), Some(SiteScan::Survey { .. })) {
            tracing::info!("survey: already surveying; SURVEY_START ignored");
            return;
        }
        let fence_area = self
            .fence
            .fence()
            .zones()
            .iter()
            .find(|z| z.kind == FenceKind::KeepIn)
            .map(|z| {
                z.sub_polygon
                    .iter()
                    .map(|p| GeoPoint {
                        lat_deg: p[0],
                        lon_deg: p[1],
                        alt_rel_m: 0.0,
                    })
                    .collect::<Vec<_>>()
            });
        let (area, source) = match fence_area {
            Some(a) => (a, "the keep-in geofence's hold line"),
            None if !self.settings.site_scan.survey_area.is_empty() => {
                (self.settings.site_scan.survey_area.clone(), "survey_area")
            }
            None => {
                self.out.error(
                    "survey: no area to survey (set a keep-in geofence, or survey_area in the config)",
                );
                return;
            }
        };
        if self.site_gate(SURVEY, true, now_ns).is_none() {
            return;
        }
        let ss = &self.settings.site_scan;
        // Lanes cut to the area, so no lane leaves it (the area is the keep-in's hold
        // line, and a lane past it would trip the fence check).
        let survey = match Survey::new_within(&area, &ss.survey) {
            Ok(s) => s,
            Err(e) => {
                self.out.error(&format!("survey: cannot fly {source}: {e}"));
                return;
            }
        };
        tracing::info!(
            area = source,
            lanes = survey.lanes().len(),
            lane_spacing_m = survey.lane_spacing_m(),
            photo_every_m = survey.trigger_spacing_m(),
            "survey: lawnmower"
        );
        let kind = SiteScan::Survey {
            survey: Box::new(survey),
            photos: 0,
            progress: 0.0,
        };
        let cruise = ss.survey_speed_mps;
        self.site_enter(SURVEY, kind, cruise, now_ns);
    }

    /// Steps a flying Site Scan shot; false if the active shot is not one (the
    /// other shots step in `flight.rs`).
    pub(crate) fn sitescan_step(&mut self, now_ns: u64) -> bool {
        let view = self.inputs.view(now_ns);
        let lim = self.settings.limits;
        let period = self.settings.loop_period.as_secs_f32();
        let Some(Active {
            kind: ShotKind::SiteScan(site),
            flight: Some(flight),
            cruise,
            ..
        }) = self.active.as_mut()
        else {
            return matches!(
                self.active.as_ref().map(|a| &a.kind),
                Some(ShotKind::SiteScan(_))
            );
        };
        let cruise = *cruise;
        let dt = flight
            .last_step_ns
            .map_or(period, |t| now_ns.saturating_sub(t) as f32 / 1e9)
            .clamp(0.001, 0.5);
        flight.last_step_ns = Some(now_ns);
        let (guidance, trigger, done) = match (site.as_mut(), view) {
            (
                SiteScan::Inspect {
                    pending,
                    last_flight_ns,
                },
                _,
            ) => {
                if flight.guided_seen && !pending.is_empty() {
                    *last_flight_ns = now_ns;
                    for c in std::mem::take(pending) {
                        if c.kind().authority() == Some(AuthorityDomain::Payload) {
                            self.payload_used = true;
                        }
                        self.out.command(c);
                    }
                } else if now_ns.saturating_sub(*last_flight_ns) >= KEEPALIVE_NS {
                    *last_flight_ns = now_ns;
                    self.out.command(Command::GrabFlightAuthority);
                }
                return true;
            }
            (_, None) => {
                if !flight.stale_logged {
                    tracing::warn!("site scan: no fresh vehicle state; holding (zero velocity)");
                    flight.stale_logged = true;
                }
                (
                    Guidance {
                        roi: flight.camera.roi,
                        ..Guidance::HOVER
                    },
                    false,
                    false,
                )
            }
            (
                SiteScan::Scan {
                    scan,
                    progress,
                    photos,
                    ..
                },
                Some(v),
            ) => {
                flight.stale_logged = false;
                let s = scan.step(&v, dt, cruise, &lim);
                *photos += u32::from(s.trigger);
                log_progress(SCAN, progress, s.progress, *photos);
                (s.guidance, s.trigger, s.done)
            }
            (
                SiteScan::Survey {
                    survey,
                    progress,
                    photos,
                },
                Some(v),
            ) => {
                flight.stale_logged = false;
                let s = survey.step(&v, dt, cruise, &lim);
                *photos += u32::from(s.trigger);
                log_progress(SURVEY, progress, s.progress, *photos);
                (s.guidance, s.trigger, s.done)
            }
        };
        super::flight::send_guidance(
            flight,
            &guidance,
            &mut self.out,
            &mut self.payload_used,
            now_ns,
        );
        if trigger {
            self.payload_used = true;
            self.out.command(Command::CameraCapture);
        }
        if done {
            let shot = self.current_shot();
            tracing::info!(shot = shot_label(shot), "site scan complete; LOITER");
            self.exit_shot(ExitReason::Finished);
        }
        true
    }
}

/// Stores `now` and logs each 10 % step.
fn log_progress(shot: i32, last: &mut f32, now: f32, photos: u32) {
    if (now * 10.0).floor() > (*last * 10.0).floor() {
        tracing::info!(
            shot = shot_label(shot),
            progress_pct = (now * 100.0).round(),
            photos,
            "site scan progress"
        );
    }
    *last = now;
}
