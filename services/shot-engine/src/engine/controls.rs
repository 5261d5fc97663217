//! What the app and the pilot do inside a shot: locations, recorded points, the
//! orbit ROI, options, pause, A/B, and the follow stream (see [`super::shot`] for
//! the table of what each shot collects).

use skymesh_ipc_types::shot_api::{shots, Location, ShotEvent};
use skymesh_ipc_types::Button;

use super::shot::{geo, location, Active, ShotKind};
use super::{shot_title, Engine};
use crate::shots::{
    distance_m, projected_roi, CableCam, CablePoint, GeoPoint, Orbit, Selfie, VehicleView,
    CABLE_MIN_LENGTH_M,
};

impl Engine {
    /// Shot options to the app.
    pub(crate) fn send_options(&mut self) {
        if let Some(a) = &self.active {
            for m in a.options() {
                self.out.app(m);
            }
        }
    }

    /// SOLO_MESSAGE_LOCATION on the TCP connection.
    pub(crate) fn shot_location(&mut self, loc: &Location, now_ns: u64) {
        let p = geo(loc);
        let Some(active) = self.active.as_mut() else {
            tracing::debug!("LOCATION outside a shot ignored");
            return;
        };
        match &mut active.kind {
            ShotKind::Selfie {
                points,
                selfie: None,
            } => {
                points.push(p);
                tracing::info!(point = points.len(), "selfie location recorded");
                if let [near, far, roi] = points[..] {
                    active.kind = ShotKind::Selfie {
                        points: vec![near, far, roi],
                        selfie: Some(Selfie::new(near, far, roi)),
                    };
                    self.begin_flight(Some(roi), now_ns);
                }
            }
            ShotKind::Selfie { .. } => {
                tracing::info!(
                    "selfie: locations cannot change after the third; ignored (start a new selfie)"
                );
            }
            ShotKind::Orbit { .. } => {
                let view = self.inputs.view(now_ns);
                self.orbit_roi(p, view, now_ns);
            }
            ShotKind::Follow(_) => self.follow_fix(loc, now_ns),
            ShotKind::Cable { .. } => tracing::debug!("cable cam: LOCATION ignored"),
            ShotKind::Zipline(_) => self.zipline_location(loc),
            ShotKind::Multipoint(_)
            | ShotKind::Pano(_)
            | ShotKind::Rewind(_)
            | ShotKind::SiteScan(_) => {
                tracing::debug!(
                    shot = shot_title(active.shot),
                    "LOCATION does nothing in this shot"
                )
            }
        }
    }

    /// Orbit around `roi`: the first starts the shot, later ones a new orbit.
    fn orbit_roi(&mut self, roi: GeoPoint, view: Option<VehicleView>, now_ns: u64) {
        let Some(v) = view else {
            self.out
                .error("orbit: no vehicle position; the ROI was not set");
            return;
        };
        let Some(Active {
            kind: ShotKind::Orbit { orbit },
            flight,
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        match orbit {
            Some(o) => {
                o.set_roi(roi, &v);
                tracing::info!(radius_m = o.radius_m(), "orbit: new ROI, new orbit");
                if let Some(f) = flight.as_mut() {
                    let cmd = f.camera.roi_sent(roi, now_ns);
                    self.out.command(cmd);
                }
                self.out.app(ShotEvent::Location(location(&roi)));
            }
            None => {
                let o = Orbit::new(roi, &v);
                tracing::info!(radius_m = o.radius_m(), "orbit: ROI set");
                *orbit = Some(o);
                self.out.app(ShotEvent::Location(location(&roi)));
                self.begin_flight(Some(roi), now_ns);
            }
        }
    }

    /// RECORD_POSITION from the app, or A in a shot.
    pub(crate) fn record_position(&mut self, now_ns: u64) {
        let view = self.inputs.view(now_ns);
        let Some(active) = self.active.as_ref() else {
            tracing::debug!("RECORD_POSITION outside a shot ignored");
            return;
        };
        match active.kind {
            ShotKind::Orbit { .. } => match view {
                Some(v) => self.orbit_roi(projected_roi(&v), Some(v), now_ns),
                None => self
                    .out
                    .error("orbit: no vehicle position; the ROI was not set"),
            },
            ShotKind::Cable { .. } => self.cable_record(view, now_ns),
            ShotKind::Multipoint(_) => {
                self.multipoint_record(true, now_ns);
            }
            _ => tracing::info!(
                shot = shot_title(active.shot),
                "record position does nothing in this shot"
            ),
        }
    }

    fn cable_record(&mut self, view: Option<VehicleView>, now_ns: u64) {
        let Some(v) = view else {
            self.out
                .error("cable cam: no vehicle position; the point was not recorded");
            return;
        };
        let Some(Active {
            kind:
                ShotKind::Cable {
                    points,
                    cable,
                    interpolate,
                    yaw_clockwise,
                },
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        if cable.is_some() {
            tracing::info!("cable cam: both points are recorded; ignored");
            return;
        }
        let p = CablePoint {
            position: v.position,
            yaw_deg: v.heading_deg,
            pitch_deg: v.camera_pitch_deg,
        };
        let waypoint = ShotEvent::CableCamWaypoint {
            lat_deg: p.position.lat_deg,
            lon_deg: p.position.lon_deg,
            alt_m: p.position.alt_rel_m,
            yaw_deg: p.yaw_deg,
            pitch_deg: p.pitch_deg,
        };
        match points.first() {
            None => {
                points.push(p);
                tracing::info!("cable cam: first point recorded");
                self.out.app(waypoint);
            }
            Some(a) if distance_m(&a.position, &p.position) < CABLE_MIN_LENGTH_M => {
                points[0] = p;
                tracing::info!(
                    "cable cam: second point on top of the first; it replaces the first"
                );
                self.out.current_shot(shots::NONE);
                self.out.current_shot(shots::CABLECAM);
                self.out.app(waypoint);
            }
            Some(a) => {
                let a = *a;
                points.push(p);
                *interpolate = true;
                *yaw_clockwise = CableCam::default_yaw_clockwise(&a, &p);
                let mut c = CableCam::new(a, p);
                c.set_camera(*interpolate, *yaw_clockwise);
                tracing::info!(
                    length_m = c.length_m(),
                    "cable cam: second point recorded; flying the cable"
                );
                *cable = Some(c);
                self.out.app(waypoint);
                self.send_options();
                self.begin_flight(None, now_ns);
            }
        }
    }

    /// SOLO_CABLE_CAM_OPTIONS from the app.
    pub(crate) fn cable_options(&mut self, interp: u16, cw: u16, speed: f32) {
        let max = self.settings.limits.max_speed_mps;
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let ShotKind::Cable {
            cable,
            interpolate,
            yaw_clockwise,
            ..
        } = &mut active.kind
        else {
            tracing::debug!("CABLE_CAM_OPTIONS outside cable cam ignored");
            return;
        };
        *interpolate = interp != 0;
        *yaw_clockwise = cw != 0;
        if let Some(c) = cable.as_mut() {
            c.set_camera(*interpolate, *yaw_clockwise);
        }
        active.set_cruise(speed, max);
    }

    /// SOLO_FOLLOW_OPTIONS (v1: `preference` None keeps the current one) and _V2.
    pub(crate) fn follow_options(&mut self, speed: f32, look_at: i32, preference: Option<i32>) {
        let max = self.settings.limits.max_speed_mps;
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let ShotKind::Follow(f) = &mut active.kind else {
            tracing::debug!("follow options outside follow ignored");
            return;
        };
        f.look_at = look_at != 0;
        if let Some(p) = preference {
            if (0..=2).contains(&p) {
                f.preference = p;
            } else {
                tracing::warn!(
                    preference = p,
                    "unknown follow preference; kept the current one"
                );
            }
        }
        active.set_cruise(speed, max);
        self.send_options();
    }

    /// SOLO_SHOT_OPTIONS from the app.
    pub(crate) fn shot_options(&mut self, speed: f32) {
        let max = self.settings.limits.max_speed_mps;
        match self.active.as_mut() {
            Some(a) => a.set_cruise(speed, max),
            None => tracing::debug!("SHOT_OPTIONS outside a shot ignored"),
        }
    }

    /// Pause from the app or the controller's pause button.
    pub(crate) fn pause(&mut self, from_controller: bool) {
        let Some(active) = self.active.as_mut() else {
            tracing::debug!("pause outside a shot ignored");
            return;
        };
        let paused = active.toggle_pause();
        tracing::info!(
            shot = shot_title(active.shot),
            paused,
            cruise = active.cruise,
            "pause"
        );
        if from_controller {
            self.out.app(ShotEvent::Pause);
        }
        self.send_options();
    }

    /// A or B pressed during a shot.
    pub(crate) fn shot_button(&mut self, button: Button, now_ns: u64) {
        let Some(active) = self.active.as_ref() else {
            return;
        };
        match (&active.kind, button) {
            (ShotKind::Orbit { .. } | ShotKind::Cable { .. }, Button::A) => {
                self.record_position(now_ns)
            }
            (ShotKind::Multipoint(_), Button::A | Button::B) => {
                self.multipoint_button(button, now_ns)
            }
            (ShotKind::Zipline(_), Button::A | Button::B) => self.zipline_button(button, now_ns),
            (ShotKind::Pano(_), Button::A | Button::B) => self.pano_button(button, now_ns),
            _ => tracing::info!(
                shot = shot_title(active.shot),
                %button,
                "button does nothing in this shot"
            ),
        }
    }

    /// A follow-stream position: kept until the next tick (only the newest counts).
    pub(crate) fn follow_fix(&mut self, loc: &Location, now_ns: u64) {
        if let Some(Active {
            kind: ShotKind::Follow(f),
            ..
        }) = self.active.as_mut()
        {
            f.newest = Some((geo(loc), now_ns));
        }
    }

    /// Before a step: feed follow its newest position, and start flying on the first.
    pub(crate) fn follow_prepare(&mut self, _now_ns: u64) {
        let Some(Active {
            kind: ShotKind::Follow(f),
            flight,
            ..
        }) = self.active.as_mut()
        else {
            return;
        };
        let Some((p, at_ns)) = f.newest.take() else {
            return;
        };
        f.follow.update_target(p, at_ns as f64 / 1e9);
        f.last_fix_ns = Some(at_ns);
        if f.lost_reported {
            tracing::info!("follow: phone positions are back");
            f.lost_reported = false;
        }
        if flight.is_none() {
            tracing::info!("follow: first phone position; flying");
            self.begin_flight(None, at_ns.max(_now_ns));
        }
    }
}
