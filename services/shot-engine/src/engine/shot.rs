//! The active shot: what each shot collects during setup, its options, pause, and
//! its per-tick guidance.
//!
//! | shot | setup | starts flying | options (to the app) |
//! |---|---|---|---|
//! | selfie | LOCATIONs 1–3: near, far, ROI (altitude above home); more are ignored | after the third | SOLO_SHOT_OPTIONS |
//! | orbit | ROI: LOCATION, RECORD_POSITION or A (projected ROI of the camera) | first ROI (echoed as LOCATION); a new one starts a new orbit (echoed) | SOLO_SHOT_OPTIONS |
//! | cable cam | RECORD_POSITION or A records position, heading, camera pitch → CABLE_CAM_WAYPOINT; a second point closer than `CABLE_MIN_LENGTH_M` replaces the first (GET_CURRENT_SHOT −1, 2, WAYPOINT) | after the second point (CABLE_CAM_OPTIONS first) | SOLO_CABLE_CAM_OPTIONS |
//! | follow | the phone's positions (follow stream, newest per tick) | first position | SOLO_FOLLOW_OPTIONS then _V2 |
//! | multipoint | keypoints (`engine/multipoint.rs`), then SPLINE_PLAY | SPLINE_ATTACH | SPLINE_* (no options message) |
//! | zipline | — (a line from the camera pose) | at entry (cruise 0) | SOLO_ZIPLINE_OPTIONS |
//! | pano | — (holds; options and A start the run) | at entry | SOLO_PANO_OPTIONS (cruise = the video pan rate, °/s) |
//! | rewind | — (the breadcrumbs) | at entry | — (SOLO_REWIND_OPTIONS are the engine's) |

use skymesh_ipc_types::shot_api::{shots, Location, ShotEvent};

use super::flight::Flight;
use super::Out;
use crate::shots::{
    CableCam, CablePoint, Follow, FollowMode, GeoPoint, Guidance, Limits, Orbit, Selfie,
    VehicleView,
};

/// Follow's own state.
#[derive(Debug)]
pub(crate) struct FollowShot {
    pub follow: Follow,
    pub look_at: bool,
    /// 0 hold angle, 1 free look, 2 leash.
    pub preference: i32,
    /// The newest phone position since the last tick, with its arrival time.
    pub newest: Option<(GeoPoint, u64)>,
    /// Arrival time of the last position fed to the shot.
    pub last_fix_ns: Option<u64>,
    /// The app has been told the target is lost (once per loss).
    pub lost_reported: bool,
}

impl FollowShot {
    pub fn mode(&self) -> FollowMode {
        if self.look_at {
            return FollowMode::LookAt;
        }
        match self.preference {
            1 => FollowMode::FreeLook,
            2 => FollowMode::Leash,
            _ => FollowMode::Orbit,
        }
    }
}

#[derive(Debug)]
pub(crate) enum ShotKind {
    Selfie {
        points: Vec<GeoPoint>,
        selfie: Option<Selfie>,
    },
    Orbit {
        orbit: Option<Orbit>,
    },
    Cable {
        points: Vec<CablePoint>,
        cable: Option<CableCam>,
        interpolate: bool,
        yaw_clockwise: bool,
    },
    Follow(Box<FollowShot>),
    /// Multipoint cable cam (`engine/multipoint.rs`).
    Multipoint(Box<super::multipoint::MultipointShot>),
    /// Zipline (`engine/zipline.rs`).
    Zipline(Box<super::zipline::ZiplineShot>),
    /// Pano (`engine/pano.rs`).
    Pano(Box<super::pano::PanoShot>),
    /// Rewind (`engine/rewind.rs`).
    Rewind(Box<super::rewind::RewindShot>),
    /// Site Scan inspect, structure scan or survey (`engine/sitescan.rs`).
    SiteScan(Box<super::sitescan::SiteScan>),
}

/// The shot being set up or flown.
#[derive(Debug)]
pub(crate) struct Active {
    pub shot: i32,
    pub kind: ShotKind,
    /// m/s; signed for orbit (direction) and cable cam (towards a or b).
    pub cruise: f32,
    /// While paused: the speed to go back to.
    pub paused: Option<f32>,
    pub flight: Option<Flight>,
}

pub(crate) fn location(p: &GeoPoint) -> Location {
    Location {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_m: p.alt_rel_m,
    }
}

pub(crate) fn geo(l: &Location) -> GeoPoint {
    GeoPoint {
        lat_deg: l.lat_deg,
        lon_deg: l.lon_deg,
        alt_rel_m: l.alt_m,
    }
}

impl Active {
    pub fn new(shot: i32, view: &VehicleView, s: &crate::config::Settings) -> Option<Active> {
        let (kind, cruise) = match shot {
            shots::SELFIE => (
                ShotKind::Selfie {
                    points: Vec::new(),
                    selfie: None,
                },
                s.selfie_cruise_speed,
            ),
            shots::ORBIT => (ShotKind::Orbit { orbit: None }, s.orbit_initial_speed),
            shots::CABLECAM => (
                ShotKind::Cable {
                    points: Vec::new(),
                    cable: None,
                    interpolate: true,
                    yaw_clockwise: false,
                },
                s.cable_initial_speed,
            ),
            shots::FOLLOW => (
                ShotKind::Follow(Box::new(FollowShot {
                    follow: Follow::new(view),
                    look_at: false,
                    preference: 0,
                    newest: None,
                    last_fix_ns: None,
                    lost_reported: false,
                })),
                s.follow_cruise_speed,
            ),
            shots::MULTIPOINT => (
                ShotKind::Multipoint(Box::default()),
                s.multipoint_cruise_speed,
            ),
            shots::ZIPLINE => (
                ShotKind::Zipline(Box::new(super::zipline::ZiplineShot::new(view))),
                0.0,
            ),
            shots::PANO => (
                ShotKind::Pano(Box::new(super::pano::PanoShot::new(view))),
                super::pano::DEFAULT_VIDEO_RATE_DPS,
            ),
            shots::REWIND => (ShotKind::Rewind(Box::default()), s.rewind_speed_mps),
            _ => return None,
        };
        Some(Active {
            shot,
            kind,
            cruise,
            paused: None,
            flight: None,
        })
    }

    /// The options message(s) that tell the app the current settings.
    pub fn options(&self) -> Vec<ShotEvent> {
        match &self.kind {
            ShotKind::Selfie { .. } | ShotKind::Orbit { .. } => {
                vec![ShotEvent::ShotOptions {
                    cruise_speed: self.cruise,
                }]
            }
            ShotKind::Cable {
                interpolate,
                yaw_clockwise,
                ..
            } => vec![ShotEvent::CableOptions {
                cam_interpolation: (*interpolate).into(),
                yaw_direction_cw: (*yaw_clockwise).into(),
                cruise_speed: self.cruise,
            }],
            ShotKind::Follow(f) => vec![
                ShotEvent::FollowOptions {
                    cruise_speed: self.cruise,
                    look_at: f.look_at.into(),
                },
                ShotEvent::FollowOptionsV2 {
                    cruise_speed: self.cruise,
                    look_at: f.look_at.into(),
                    follow_preference: f.preference,
                },
            ],
            // The Site Scan messages have no options message.
            ShotKind::SiteScan(_) => Vec::new(),
            ShotKind::Zipline(z) => vec![z.options(self.cruise)],
            ShotKind::Pano(p) => vec![p.options(self.cruise)],
            // Multipoint reports through SPLINE_PLAYBACK_STATUS; rewind's options
            // are the engine's, not the shot's.
            ShotKind::Multipoint(_) | ShotKind::Rewind(_) => Vec::new(),
        }
    }

    /// Sets the cruise speed (ends a pause).
    pub fn set_cruise(&mut self, speed: f32, max: f32) {
        let speed = if speed.is_finite() { speed } else { 0.0 };
        let speed = match self.kind {
            // The selfie flies out and back: only the magnitude matters.
            ShotKind::Selfie { .. } => speed.abs().min(max),
            _ => speed.clamp(-max, max),
        };
        self.cruise = speed;
        self.paused = None;
    }

    /// Pause ↔ resume; true when now paused.
    pub fn toggle_pause(&mut self) -> bool {
        match self.paused.take() {
            Some(previous) => {
                self.cruise = previous;
                false
            }
            None => {
                self.paused = Some(self.cruise);
                self.cruise = 0.0;
                true
            }
        }
    }

    /// Where the camera looks (for the status sample).
    pub fn roi(&self) -> Option<GeoPoint> {
        if let Some(roi) = self.flight.as_ref().and_then(|f| f.camera.roi) {
            return Some(roi);
        }
        match &self.kind {
            ShotKind::Selfie { points, .. } => points.get(2).copied(),
            ShotKind::Orbit { orbit } => orbit.as_ref().map(Orbit::roi),
            ShotKind::Follow(f) => f.follow.target(),
            ShotKind::Cable { .. } => None,
            ShotKind::SiteScan(s) => s.roi(),
            ShotKind::Zipline(z) => z.line.spot_lock(),
            ShotKind::Multipoint(_) | ShotKind::Pano(_) | ShotKind::Rewind(_) => None,
        }
    }

    /// Orbit radius, or the selfie / cable parameter 0..1; multipoint: u on the
    /// path; zipline: metres along the line; pano: share of the photos taken;
    /// rewind: share of the path flown back.
    pub fn progress(&self) -> f32 {
        match &self.kind {
            ShotKind::Selfie {
                selfie: Some(s), ..
            } => s.parameter(),
            ShotKind::Orbit { orbit: Some(o) } => o.radius_m(),
            ShotKind::Cable { cable: Some(c), .. } => c.parameter(),
            ShotKind::SiteScan(s) => s.progress(),
            ShotKind::Multipoint(m) => m.progress(),
            ShotKind::Zipline(z) => z.line.along_m(),
            ShotKind::Pano(p) => p.progress(),
            ShotKind::Rewind(r) => r.progress(),
            _ => 0.0,
        }
    }

    /// This tick's guidance (the shot is flying and `v` is fresh).
    pub fn guidance(
        &mut self,
        v: &VehicleView,
        now_ns: u64,
        dt: f32,
        lim: &Limits,
        follow_lost: std::time::Duration,
        out: &mut Out,
    ) -> Guidance {
        let cruise = self.cruise;
        let held_roi = self.flight.as_ref().and_then(|f| f.camera.roi);
        match &mut self.kind {
            ShotKind::Selfie {
                selfie: Some(s), ..
            } => s.step(v, dt, cruise.abs(), lim),
            ShotKind::Orbit { orbit: Some(o) } => o.step(v, dt, cruise, lim),
            ShotKind::Cable { cable: Some(c), .. } => c.step(v, dt, cruise, lim),
            ShotKind::Follow(f) => {
                let now_s = now_ns as f64 / 1e9;
                let age = f.last_fix_ns.map(|t| now_ns.saturating_sub(t));
                let lost = age.is_none_or(|a| a as u128 > follow_lost.as_nanos());
                if lost {
                    if !f.lost_reported {
                        f.lost_reported = true;
                        let secs = follow_lost.as_secs_f64();
                        let text = if secs.fract() == 0.0 {
                            format!("follow: no phone position for {secs:.0} s, holding")
                        } else {
                            format!("follow: no phone position for {secs:.1} s, holding")
                        };
                        tracing::warn!("{text}");
                        out.error(&text);
                    }
                    // Hold, camera where it was.
                    return Guidance {
                        roi: held_roi,
                        ..Guidance::HOVER
                    };
                }
                if f.follow.mode() != f.mode() {
                    let mode = f.mode();
                    f.follow.set_mode(mode, v);
                }
                f.follow.step(v, now_s, dt, cruise, lim)
            }
            ShotKind::Multipoint(m) => m.guidance(v, now_ns, dt, cruise, lim, out),
            ShotKind::Zipline(z) => z.line.step(v, dt, cruise, lim),
            ShotKind::Pano(p) => p.guidance(v, now_ns, dt, cruise, lim),
            ShotKind::Rewind(r) => r.guidance(v, dt, cruise, lim),
            // Flying without its geometry cannot happen (flight starts with it): hold.
            _ => Guidance::HOVER,
        }
    }
}
