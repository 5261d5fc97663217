//! Zipline (shot 3): an unbounded line from the vehicle along the camera, flown at
//! the cruise speed ([`crate::shots::zipline`]).
//!
//! | from | does |
//! |---|---|
//! | SET_CURRENT_SHOT 3 (or a mapped button) | entry gate, then a line from the camera pose now; flies at once (authority, GUIDED), cruise speed 0; SOLO_ZIPLINE_OPTIONS to the app |
//! | SOLO_ZIPLINE_OPTIONS | cruise speed (signed: + the way the camera looked), is3D (for the next line), camPointing (1 locks a spot, 0 frees the camera) |
//! | A | a new line from the camera pose now (speed and spot lock kept); options to the app |
//! | B, SOLO_ZIPLINE_LOCK | spot lock on ↔ off; on: the projected ROI, sent as SOLO_MESSAGE_LOCATION; options to the app |
//! | SOLO_MESSAGE_LOCATION | while spot-locked: the new spot (its altitude kept, as the Solo does: the app cannot set one); echoed |
//! | Pause | cruise speed 0 ↔ the previous one; options to the app |
//!
//! Where the reference differs: its app-sent SOLO_ZIPLINE_LOCK lays a new line (and
//! it sends ZIPLINE_LOCK to the app when a line starts); the issue asks for the lock
//! toggle, which is what this engine does, and the gateway's catalog lists the
//! message as app → vehicle only, so the engine never sends it. Free look leaves
//! yaw and gimbal to the pilot (no camera command); spot lock points nose and gimbal
//! at the spot with an ROI.

use skymesh_ipc_types::shot_api::{Location, ShotEvent};
use skymesh_ipc_types::Button;

use super::shot::{geo, location, Active, ShotKind};
use super::Engine;
use crate::shots::{VehicleView, Zipline};

/// The zipline's own state.
#[derive(Debug)]
pub(crate) struct ZiplineShot {
    pub line: Zipline,
    /// SOLO_ZIPLINE_OPTIONS is3D: the next line follows the camera pitch.
    pub is_3d: bool,
}

impl ZiplineShot {
    /// A horizontal line from the camera pose of `v`.
    pub fn new(v: &VehicleView) -> ZiplineShot {
        ZiplineShot {
            line: Zipline::new(v, false),
            is_3d: false,
        }
    }

    /// SOLO_ZIPLINE_OPTIONS as the engine uses them.
    pub fn options(&self, cruise: f32) -> ShotEvent {
        ShotEvent::ZiplineOptions {
            cruise_speed: cruise,
            is_3d: self.is_3d.into(),
            cam_pointing: self.line.spot_lock().is_some().into(),
        }
    }

    /// A new line from the camera pose of `v` (spot lock kept).
    fn relay(&mut self, v: &VehicleView) {
        if self.line.is_3d() == self.is_3d {
            self.line.relay(v);
        } else {
            let spot = self.line.spot_lock();
            self.line = Zipline::new(v, self.is_3d);
            self.line.set_spot_lock(spot);
        }
    }
}

fn zipline_of(active: &mut Option<Active>) -> Option<(&mut ZiplineShot, f32)> {
    match active.as_mut() {
        Some(Active {
            kind: ShotKind::Zipline(z),
            cruise,
            ..
        }) => Some((z, *cruise)),
        _ => None,
    }
}

impl Engine {
    /// Just entered: fly the line.
    pub(crate) fn zipline_start(&mut self, now_ns: u64) {
        if let Some((z, _)) = zipline_of(&mut self.active) {
            let (yaw, pitch) = z.line.direction_deg();
            tracing::info!(yaw, pitch, "zipline: line laid along the camera");
            self.begin_flight(None, now_ns);
        }
    }

    /// SOLO_ZIPLINE_OPTIONS from the app.
    pub(crate) fn zipline_options(
        &mut self,
        cruise_speed: f32,
        is_3d: u8,
        cam_pointing: u8,
        now_ns: u64,
    ) {
        let max = self.settings.limits.max_speed_mps;
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let ShotKind::Zipline(z) = &mut active.kind else {
            tracing::debug!("ZIPLINE_OPTIONS outside zipline ignored");
            return;
        };
        z.is_3d = is_3d != 0;
        let lock_changes = (cam_pointing != 0) != z.line.spot_lock().is_some();
        active.set_cruise(cruise_speed, max);
        tracing::info!(
            cruise = active.cruise,
            is_3d,
            cam_pointing,
            "zipline: options"
        );
        if lock_changes {
            self.zipline_toggle_lock(now_ns);
        }
    }

    /// B or SOLO_ZIPLINE_LOCK: spot lock on ↔ off.
    pub(crate) fn zipline_toggle_lock(&mut self, now_ns: u64) {
        let view = self.inputs.view(now_ns);
        let Some((z, cruise)) = zipline_of(&mut self.active) else {
            tracing::debug!("ZIPLINE_LOCK outside zipline ignored");
            return;
        };
        if z.line.spot_lock().is_some() {
            z.line.set_spot_lock(None);
            tracing::info!("zipline: free look");
        } else {
            let Some(v) = view else {
                self.out
                    .error("zipline: no vehicle position; the spot was not locked");
                return;
            };
            let spot = Zipline::projected_spot(&v);
            z.line.set_spot_lock(Some(spot));
            tracing::info!(
                lat = spot.lat_deg,
                lon = spot.lon_deg,
                alt = spot.alt_rel_m,
                "zipline: spot lock"
            );
            self.out.app(ShotEvent::Location(location(&spot)));
        }
        let options = z.options(cruise);
        self.out.app(options);
    }

    /// SOLO_MESSAGE_LOCATION in zipline: moves a locked spot.
    pub(crate) fn zipline_location(&mut self, loc: &Location) {
        let Some((z, _)) = zipline_of(&mut self.active) else {
            return;
        };
        let Some(old) = z.line.spot_lock() else {
            tracing::debug!("zipline: LOCATION without a spot lock ignored");
            return;
        };
        let spot = crate::shots::GeoPoint {
            alt_rel_m: old.alt_rel_m,
            ..geo(loc)
        };
        z.line.set_spot_lock(Some(spot));
        tracing::info!(lat = spot.lat_deg, lon = spot.lon_deg, "zipline: new spot");
        self.out.app(ShotEvent::Location(location(&spot)));
    }

    /// A or B in zipline.
    pub(crate) fn zipline_button(&mut self, button: Button, now_ns: u64) {
        match button {
            Button::A => {
                let Some(v) = self.inputs.view(now_ns) else {
                    self.out.error("zipline: no vehicle position; no new line");
                    return;
                };
                let Some((z, cruise)) = zipline_of(&mut self.active) else {
                    return;
                };
                z.relay(&v);
                let (yaw, pitch) = z.line.direction_deg();
                tracing::info!(yaw, pitch, "zipline: new line");
                let options = z.options(cruise);
                self.out.app(options);
            }
            Button::B => self.zipline_toggle_lock(now_ns),
            _ => {}
        }
    }
}
