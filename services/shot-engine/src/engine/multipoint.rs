//! Multipoint cable cam (shot 6): record a path of keypoints, then play it with the
//! spline controller of [`crate::shots::multipoint`].
//!
//! | from | record mode | play mode |
//! |---|---|---|
//! | SPLINE_RECORD | clears the path (and the path settings) | stops flying (brake, LOITER, authority back), clears the path: record mode |
//! | RECORD_POSITION, A | keypoint at the vehicle → SPLINE_POINT | SPLINE_POINT status −1 (A: ignored) |
//! | SPLINE_POINT (app) | validated, stored → SPLINE_POINT with its status | SPLINE_POINT status −1 |
//! | B | records a keypoint, then plays (the Solo's "Finish Point") | ignored |
//! | SPLINE_PLAY | valid path → play (below); else SHOTMANAGER_ERROR | sends the path again |
//! | SPLINE_ATTACH i | SHOTMANAGER_ERROR | grab authority, GUIDED, fly to keypoint i; SPLINE_ATTACH i once there |
//! | SPLINE_SEEK u, state | ignored | once attached: fly along the path (see [`crate::shots::multipoint`]) |
//! | SPLINE_PATH_SETTINGS | kept for play | camera free (1) / interpolated (0); desiredTime → cruise speed |
//! | Pause | — | brake on the path; again: resume the last attach or seek |
//!
//! Replies, one SPLINE_POINT per app SPLINE_POINT and RECORD_POSITION (the spec's
//! ACK rule), statuses as the spec numbers them: 0 stored (the keypoint as stored,
//! uPosition 0); −1 play mode; −2 closer than `keypoint_min_spacing_m` (3-D) to the
//! keypoint before or after it (app keypoints); −3 an app keypoint whose index is
//! already on the path; −4 anything else (version ≠ 0, index outside
//! 0..[`MAX_KEYPOINTS`], not in this shot, no vehicle position, path full).
//!
//! Where the spec is silent, what this engine does:
//! - A *recorded* keypoint closer than the spacing to the last one replaces it
//!   (same index, status 0), as the Solo does: the spec allows coalescing, and the
//!   pilot can re-aim the camera at a point without deleting it. Keypoints loaded by
//!   the app are not coalesced: −2.
//! - A keypoint records the vehicle's position, its heading as yaw and the camera
//!   pitch; absAltRef is the home altitude above MSL (from `VehicleStatus`, else the
//!   vehicle's MSL minus relative altitude), set by the path's first keypoint (the
//!   app's, when it loads one).
//! - Play mode: SPLINE_PLAY to the app first when entered with B, then every
//!   keypoint with its uPosition (status 0), then SPLINE_DURATIONS (maxTime at
//!   [`crate::shots::multipoint::DEFAULT_MIN_CRUISE_MPS`]; they depend only on the
//!   path and the configured limits, so they change only with a new path, when they
//!   are sent again with it). The vehicle does not move
//!   until SPLINE_ATTACH (the only point from which the shot flies: authority and
//!   GUIDED). The cruise speed is `multipoint_cruise_speed` until
//!   SPLINE_PATH_SETTINGS gives a desired time.
//! - SPLINE_SEEK: `cruiseState` 0 flies to `u` and stops (a scrub; `u` where the
//!   vehicle is: a pause); ±1 with `u` not ahead (behind) cruises to the end (start),
//!   as the reference does with any `u`; otherwise to `u`. It also ends a pause
//!   from the controller. `u` is clamped to 0..=1.
//! - SPLINE_PLAYBACK_STATUS (u, cruiseState): every 100 ms while moving, and on
//!   attach, at each keypoint passed, when the vehicle starts or stops, and on each
//!   seek.
//! - SPLINE_ATTACH is valid once per play (no detach, as the spec says): a second
//!   one once attached is ignored.

mod record;

use skymesh_ipc_types::shot_api::{ShotEvent, SplinePoint};
use skymesh_ipc_types::{Command, FlightMode};

use super::shot::{Active, ShotKind};
use super::{Engine, Out};
use crate::shots::multipoint::DEFAULT_MIN_CRUISE_MPS;
use crate::shots::{
    Guidance, Keypoint, Limits, Multipoint, PlaybackEvent, SplinePath, VehicleView,
};
use record::{status, POINT_VERSION};

/// SOLO_SPLINE_PLAYBACK_STATUS while moving: every 100 ms (10 Hz), ns.
pub const PLAYBACK_STATUS_PERIOD_NS: u64 = 100_000_000;

/// What resumes after a pause from the controller.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Resume {
    Attach(usize),
    Seek { u: f32, cruise_state: i32 },
}

/// Play mode: the controller and what the app has been told.
#[derive(Debug)]
pub(crate) struct Play {
    pub ctrl: Multipoint,
    /// The last attach or seek (resumed after a pause).
    resume: Option<Resume>,
    /// The pause the controller was last given (cruise 0).
    paused: bool,
    /// When the next periodic SPLINE_PLAYBACK_STATUS is due (advanced by the period,
    /// so a 25 Hz loop still reports at 10 Hz on average).
    next_status_ns: u64,
}

/// The multipoint cable cam's own state.
#[derive(Debug, Default)]
pub(crate) struct MultipointShot {
    /// Keypoints by index; record mode may have gaps while the app loads a path.
    keypoints: std::collections::BTreeMap<i32, Keypoint>,
    /// Home altitude above MSL when the path was recorded, metres.
    abs_alt_ref_m: Option<f32>,
    /// SPLINE_PATH_SETTINGS cameraControl 1: the pilot points the camera.
    camera_free: bool,
    /// SPLINE_PATH_SETTINGS desiredTime, seconds (None: not given).
    desired_time_s: Option<f32>,
    pub play: Option<Play>,
}

impl MultipointShot {
    /// Parametric position on the path (0 before play).
    pub fn progress(&self) -> f32 {
        self.play.as_ref().map_or(0.0, |p| p.ctrl.u())
    }

    fn point(&self, index: i32, k: &Keypoint, u: f32, status: i16) -> SplinePoint {
        SplinePoint {
            version: POINT_VERSION,
            abs_alt_ref_m: self.abs_alt_ref_m.unwrap_or(0.0),
            index,
            lat_deg: k.position.lat_deg,
            lon_deg: k.position.lon_deg,
            alt_m: k.position.alt_rel_m,
            pitch_deg: k.pitch_deg,
            yaw_deg: k.yaw_deg,
            u_position: u,
            status,
        }
    }

    /// The next index a recorded keypoint gets.
    fn next_index(&self) -> i32 {
        self.keypoints.keys().next_back().map_or(0, |i| i + 1)
    }

    /// The keypoints in order when they form a valid path (≥ 2, indices 0..n−1).
    fn path(&self) -> Result<Vec<Keypoint>, String> {
        let n = self.keypoints.len();
        if n < 2 {
            return Err(format!(
                "multipoint: a path needs at least 2 keypoints (have {n})"
            ));
        }
        if let Some(missing) = (0..n as i32).find(|i| !self.keypoints.contains_key(i)) {
            return Err(format!(
                "multipoint: keypoint {missing} is missing (a path has indices 0..{})",
                n - 1
            ));
        }
        Ok(self.keypoints.values().copied().collect())
    }

    /// This tick's guidance while flying (attached or attaching), with the
    /// SOLO_SPLINE_ATTACH and _PLAYBACK_STATUS messages it calls for.
    pub fn guidance(
        &mut self,
        v: &VehicleView,
        now_ns: u64,
        dt: f32,
        cruise: f32,
        lim: &Limits,
        out: &mut Out,
    ) -> Guidance {
        let Some(play) = self.play.as_mut() else {
            return Guidance::HOVER;
        };
        let paused = cruise == 0.0 || !cruise.is_finite();
        if paused != play.paused {
            play.paused = paused;
            if paused {
                play.ctrl.pause();
            } else {
                play.resume_last();
            }
        }
        if !paused {
            play.ctrl.set_cruise_speed(f64::from(cruise));
        }
        let g = play.ctrl.step(v, dt, lim);
        let mut report = false;
        for ev in play.ctrl.take_events() {
            match ev {
                PlaybackEvent::Attached { index } => {
                    tracing::info!(index, "multipoint: attached to the path");
                    play.resume = None;
                    out.app(ShotEvent::SplineAttach(index as u32));
                    report = true;
                }
                PlaybackEvent::Started | PlaybackEvent::Stopped => report = true,
                PlaybackEvent::PassedKeypoint { index } => {
                    tracing::debug!(index, "multipoint: at a keypoint");
                    report = true;
                }
            }
        }
        if report {
            play.status(now_ns, out);
        } else if play.ctrl.moving() && now_ns >= play.next_status_ns {
            let deadline = play.next_status_ns;
            play.status(now_ns, out);
            // Keep the 10 Hz cadence across ticks that do not divide 100 ms.
            play.next_status_ns = deadline
                .saturating_add(PLAYBACK_STATUS_PERIOD_NS)
                .max(now_ns + 1);
        }
        g
    }
}

impl Play {
    fn status(&mut self, now_ns: u64, out: &mut Out) {
        self.next_status_ns = now_ns.saturating_add(PLAYBACK_STATUS_PERIOD_NS);
        out.app(ShotEvent::SplinePlaybackStatus {
            u_position: self.ctrl.u(),
            cruise_state: self.ctrl.cruise_state(),
        });
    }

    fn resume_last(&mut self) {
        let r = match self.resume {
            Some(Resume::Attach(i)) => self.ctrl.attach(i),
            Some(Resume::Seek { u, cruise_state }) => self.ctrl.seek(u, cruise_state),
            None => Ok(()),
        };
        if let Err(e) = r {
            tracing::warn!(error = %e, "multipoint: could not resume after the pause");
        }
    }
}

/// The multipoint shot, if it is the active one.
fn multipoint_of(active: &mut Option<Active>) -> Option<&mut MultipointShot> {
    match active.as_mut() {
        Some(Active {
            kind: ShotKind::Multipoint(m),
            ..
        }) => Some(m),
        _ => None,
    }
}

impl Engine {
    /// SOLO_SPLINE_RECORD: record mode with an empty path.
    pub(crate) fn spline_record(&mut self) {
        if multipoint_of(&mut self.active).is_none() {
            tracing::info!("SPLINE_RECORD outside the multipoint cable cam ignored");
            return;
        }
        self.multipoint_stop_flying();
        if let Some(m) = multipoint_of(&mut self.active) {
            *m = MultipointShot::default();
        }
        if let Some(a) = self.active.as_mut() {
            a.cruise = self.settings.multipoint_cruise_speed;
            a.paused = None;
        }
        tracing::info!("multipoint: record mode, path cleared");
    }

    /// Play mode is left: hand the vehicle back like an exit to FLY (brake, LOITER,
    /// authority released), staying in the shot.
    fn multipoint_stop_flying(&mut self) {
        let guided = self.inputs.mode() == FlightMode::Guided;
        let Some(flight) = self.active.as_mut().and_then(|a| a.flight.take()) else {
            return;
        };
        if guided {
            self.out.command(Command::Brake);
        }
        if guided || !flight.guided_seen {
            self.out.command(Command::SetMode(FlightMode::Loiter));
        }
        if flight.camera.roi.is_some() {
            self.out.command(Command::ClearRoi);
        }
        self.out.command(Command::ReleaseFlightAuthority);
        self.release_payload_if_idle(false);
        tracing::info!("multipoint: stopped flying the path; LOITER");
    }

    /// SOLO_SPLINE_PLAY from the app, or B: play mode with a valid path.
    pub(crate) fn spline_play(&mut self, by_button: bool) {
        let lim = self.settings.limits;
        let cruise = self.settings.multipoint_cruise_speed;
        let Some(m) = multipoint_of(&mut self.active) else {
            self.out
                .error("multipoint: SPLINE_PLAY outside the multipoint cable cam shot");
            return;
        };
        if m.play.is_none() {
            let path = m
                .path()
                .and_then(|k| SplinePath::new(&k, &lim).map_err(|e| format!("multipoint: {e}")));
            let path = match path {
                Ok(p) => p,
                Err(text) => {
                    tracing::info!(why = %text, "multipoint: cannot play");
                    self.out.error(&text);
                    return;
                }
            };
            let mut ctrl = Multipoint::new(path);
            ctrl.set_min_cruise_speed(DEFAULT_MIN_CRUISE_MPS);
            ctrl.set_camera_free(m.camera_free);
            match m.desired_time_s {
                Some(t) => ctrl.set_desired_time(f64::from(t)),
                None => ctrl.set_cruise_speed(f64::from(cruise)),
            }
            tracing::info!(
                keypoints = ctrl.path().keypoints().len(),
                length_m = ctrl.path().length_m(),
                cruise_mps = ctrl.cruise_speed_mps(),
                "multipoint: play mode"
            );
            let speed = ctrl.cruise_speed_mps() as f32;
            m.play = Some(Play {
                ctrl,
                resume: None,
                paused: false,
                next_status_ns: 0,
            });
            if let Some(a) = self.active.as_mut() {
                a.cruise = speed;
                a.paused = None;
            }
        }
        if by_button {
            self.out.app(ShotEvent::SplinePlay);
        }
        self.multipoint_send_path();
    }

    /// Every keypoint with its uPosition, then the durations.
    fn multipoint_send_path(&mut self) {
        let Some(m) = self.active.as_ref().and_then(|a| match &a.kind {
            ShotKind::Multipoint(m) => Some(m),
            _ => None,
        }) else {
            return;
        };
        let Some(play) = m.play.as_ref() else {
            return;
        };
        let path = play.ctrl.path();
        let mut msgs: Vec<ShotEvent> = path
            .keypoints()
            .iter()
            .enumerate()
            .map(|(i, k)| {
                let u = path.keypoint_u(i).unwrap_or(1.0) as f32;
                ShotEvent::SplinePoint(m.point(i as i32, k, u, status::OK))
            })
            .collect();
        let d = play.ctrl.durations();
        msgs.push(ShotEvent::SplineDurations {
            min_time_s: d.min_time_s,
            max_time_s: d.max_time_s,
        });
        for msg in msgs {
            self.out.app(msg);
        }
    }

    /// SOLO_SPLINE_ATTACH from the app.
    pub(crate) fn spline_attach(&mut self, index: u32, now_ns: u64) {
        let Some(m) = multipoint_of(&mut self.active) else {
            tracing::info!("SPLINE_ATTACH outside the multipoint cable cam ignored");
            return;
        };
        let Some(play) = m.play.as_mut() else {
            self.out
                .error("multipoint: SPLINE_ATTACH needs play mode (SPLINE_PLAY first)");
            return;
        };
        if play.ctrl.attached() {
            tracing::info!(index, "multipoint: already attached; SPLINE_ATTACH ignored");
            return;
        }
        let i = usize::try_from(index).unwrap_or(usize::MAX);
        if let Err(e) = play.ctrl.attach(i) {
            self.out.error(&format!("multipoint: cannot attach: {e}"));
            return;
        }
        play.resume = Some(Resume::Attach(i));
        play.paused = false;
        tracing::info!(index, "multipoint: attaching");
        let flying = self.is_flying();
        if let Some(a) = self.active.as_mut() {
            if let Some(previous) = a.paused.take() {
                a.cruise = previous;
            }
        }
        if !flying {
            self.begin_flight(None, now_ns);
        }
    }

    /// SOLO_SPLINE_SEEK from the app (only once attached).
    pub(crate) fn spline_seek(&mut self, u: f32, cruise_state: i32, now_ns: u64) {
        let Some(a) = self.active.as_mut() else {
            return;
        };
        let ShotKind::Multipoint(m) = &mut a.kind else {
            tracing::debug!("SPLINE_SEEK outside the multipoint cable cam ignored");
            return;
        };
        let Some(play) = m.play.as_mut().filter(|p| p.ctrl.attached()) else {
            tracing::debug!("SPLINE_SEEK before the vehicle is attached ignored");
            return;
        };
        // The app's seek ends a pause from the controller.
        if let Some(previous) = a.paused.take() {
            a.cruise = previous;
        }
        if a.cruise > 0.0 {
            play.paused = false;
            play.ctrl.set_cruise_speed(f64::from(a.cruise));
        }
        let u = u.clamp(0.0, 1.0);
        match play.ctrl.seek(u, cruise_state) {
            Ok(()) => {
                play.resume = Some(Resume::Seek { u, cruise_state });
                tracing::debug!(u, cruise_state, "multipoint: seek");
            }
            Err(e) => tracing::warn!(error = %e, "multipoint: seek refused"),
        }
        play.status(now_ns, &mut self.out);
    }

    /// SOLO_SPLINE_PATH_SETTINGS from the app.
    pub(crate) fn spline_path_settings(&mut self, camera_control: u32, desired_time_s: f32) {
        let Some(a) = self.active.as_mut() else {
            return;
        };
        let ShotKind::Multipoint(m) = &mut a.kind else {
            tracing::debug!("SPLINE_PATH_SETTINGS outside the multipoint cable cam ignored");
            return;
        };
        m.camera_free = camera_control == 1;
        if desired_time_s > 0.0 {
            m.desired_time_s = Some(desired_time_s);
        }
        let Some(play) = m.play.as_mut() else {
            return;
        };
        play.ctrl.set_camera_free(m.camera_free);
        if let Some(t) = m.desired_time_s {
            play.ctrl.set_desired_time(f64::from(t));
            let speed = play.ctrl.cruise_speed_mps() as f32;
            match a.paused.as_mut() {
                Some(previous) => *previous = speed,
                None => a.cruise = speed,
            }
            tracing::info!(
                desired_time_s = t,
                cruise_mps = speed,
                camera_free = m.camera_free,
                "multipoint: path settings"
            );
        }
    }
}
