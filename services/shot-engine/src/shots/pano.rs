//! Pano: hold position and turn the camera through a panorama — a cylinder of
//! photos, a sphere of photos, or a continuous video pan.
//!
//! Contract (for the engine):
//! - [`Pano::new`]`(kind, view, options)` starts in [`PanoPhase::Setup`]: the
//!   vehicle brakes and holds where it is, the camera is the pilot's (choosing the
//!   point of view). SOLO_PANO_OPTIONS with runState 1 → [`Pano::start`]`(view,
//!   now_s)`: the stations are laid out around the camera yaw (and, for the
//!   cylinder, the camera pitch) of that moment, and the phase becomes
//!   [`PanoPhase::Run`]. Options may change in setup ([`Pano::set_options`]); in
//!   run only the video pan's rate is taken (0 = paused, the app's pause/resume).
//! - [`Pano::step`]`(view, dt, now_s, limits)` → [`PanoStep`]: position held
//!   throughout (brake, then hold the point, zero velocity once there); per station
//!   the guidance asks for the station's yaw (`yaw_deg`, the engine's SetYaw) and
//!   gimbal pitch (`gimbal_pitch_deg`); once the camera is within
//!   [`ARRIVED_DEG`] of both (or [`TURN_TIMEOUT_S`] has passed: a camera that never
//!   reports must not hang the pano) and has held there [`SETTLE_S`], the step
//!   returns `trigger = true` exactly once for that station (the engine sends
//!   `Command::CameraCapture` and SOLO_PANO_STATE(station.0, station.1)); after
//!   [`SHUTTER_S`] the next station follows. After the last station's shutter time
//!   the phase is [`PanoPhase::Finished`] (the engine leaves the shot, as the Solo
//!   exits to Fly).
//! - `station = (photos taken, photos in total)`; (0, 0) for the video pan.
//! - Cylinder: `cylinder_fov_deg` clamped to 91..=360 (nonsense → 360); photo
//!   centres from −(fov − lens)/2 to +(fov − lens)/2 around the start yaw, spaced at
//!   most `lens_fov · (1 − `[`PANO_OVERLAP`]`)` apart (evenly, clockwise); a full
//!   360° has no duplicate end photo. `lens_fov_deg` clamped to 10..=170 (nonsense →
//!   [`DEFAULT_LENS_FOV_DEG`]).
//! - Sphere: the fixed set [`SPHERE_ROWS`] (pitch, photos evenly around from the
//!   start yaw), row by row from the horizon down, nadir last.
//! - Video pan: `yaw_rate_dps` clamped to ±[`VIDEO_PAN_MAX_RATE_DPS`] (positive =
//!   clockwise); each tick `yaw_deg` is a target moving at that rate, never more
//!   than [`VIDEO_PAN_MAX_LEAD_DEG`] ahead of the camera; it runs until the engine
//!   ends it; the gimbal pitch is the pilot's.

use nalgebra::Vector3;

use super::geo::{wrap_180, wrap_360, GeoPoint, LocalFrame};
use super::motion::{dt64, to_f32, toward, velocity, Lim, Shaper};
use super::{Guidance, Limits, VehicleView};

/// Share of the lens field of view neighbouring cylinder photos overlap.
pub const PANO_OVERLAP: f32 = 0.3;
/// Lens field of view when the app's is nonsense, degrees (GoPro HERO4 medium).
pub const DEFAULT_LENS_FOV_DEG: f32 = 69.5;
/// The fastest video pan, degrees per second either way.
pub const VIDEO_PAN_MAX_RATE_DPS: f32 = 60.0;
/// The video pan's yaw target is never further ahead of the camera than this, deg.
pub const VIDEO_PAN_MAX_LEAD_DEG: f32 = 30.0;
/// A station is reached when camera yaw and pitch are this close, degrees.
pub const ARRIVED_DEG: f32 = 3.0;
/// Held still this long at a station before the photo, seconds.
pub const SETTLE_S: f64 = 0.5;
/// After a photo, held this long before turning on (the camera's capture), seconds.
pub const SHUTTER_S: f64 = 1.0;
/// A station not reached within this long is photographed anyway, seconds.
pub const TURN_TIMEOUT_S: f64 = 8.0;
/// The sphere: rows of (gimbal pitch degrees, photos around). 17 photos.
pub const SPHERE_ROWS: [(f32, u8); 4] = [(0.0, 6), (-30.0, 6), (-60.0, 4), (-90.0, 1)];

/// The three panoramas (SOLO_PANO_OPTIONS panoType).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PanoKind {
    Cylinder,
    Sphere,
    VideoPan,
}

impl PanoKind {
    /// From the app's panoType (0 cylinder, 1 sphere, 2 video); else `None`.
    pub fn from_wire(v: u8) -> Option<PanoKind> {
        match v {
            0 => Some(PanoKind::Cylinder),
            1 => Some(PanoKind::Sphere),
            2 => Some(PanoKind::VideoPan),
            _ => None,
        }
    }

    /// The app's panoType.
    pub fn to_wire(self) -> u8 {
        match self {
            PanoKind::Cylinder => 0,
            PanoKind::Sphere => 1,
            PanoKind::VideoPan => 2,
        }
    }
}

/// The numbers of SOLO_PANO_OPTIONS (taken as given; the pano clamps them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PanoOptions {
    /// cylinderFov, degrees (91..=360).
    pub cylinder_fov_deg: f32,
    /// lensFov: the camera's horizontal field of view, degrees.
    pub lens_fov_deg: f32,
    /// degSecondYaw: the video pan's rate, degrees per second (positive clockwise).
    pub yaw_rate_dps: f32,
}

/// Setup → run → finished.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PanoPhase {
    /// Holding; the pilot chooses the view.
    Setup,
    /// Working through the stations (or panning).
    Run,
    /// Every photo taken; holding.
    Finished,
}

/// One photo: where the camera points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PanoStation {
    /// Earth-frame yaw, degrees 0..360.
    pub yaw_deg: f32,
    /// Gimbal pitch, degrees (down negative).
    pub pitch_deg: f32,
}

/// What one step of the pano asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PanoStep {
    pub guidance: Guidance,
    /// Take a photo now (once per station).
    pub trigger: bool,
    /// (photos taken, photos in total); (0, 0) for the video pan.
    pub station: (u8, u8),
    /// The phase after this step.
    pub phase: PanoPhase,
}

/// Where the current station is in its cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
enum StationState {
    /// Turning since `since_s`.
    Turning { since_s: f64 },
    /// On the station (within [`ARRIVED_DEG`]) since `since_s`.
    Settling { since_s: f64, turning_since_s: f64 },
    /// Photo taken at `at_s`.
    Shot { at_s: f64 },
}

/// A panorama in progress.
#[derive(Debug, Clone)]
pub struct Pano {
    kind: PanoKind,
    options: PanoOptions,
    phase: PanoPhase,
    stations: Vec<PanoStation>,
    /// Index of the station being worked on.
    current: usize,
    state: StationState,
    /// Photos taken.
    taken: usize,
    /// The video pan's yaw target, degrees (unwrapped).
    pan_yaw: f64,
    /// Where the position is held (NED in `frame`), once braked.
    frame: LocalFrame,
    hold: Option<Vector3<f64>>,
    shaper: Shaper,
}

impl Pano {
    /// A pano of `kind` in setup, holding around the vehicle's position.
    pub fn new(kind: PanoKind, v: &VehicleView, options: PanoOptions) -> Pano {
        Pano {
            kind,
            options,
            phase: PanoPhase::Setup,
            stations: Vec::new(),
            current: 0,
            state: StationState::Turning { since_s: 0.0 },
            taken: 0,
            pan_yaw: 0.0,
            frame: LocalFrame::new(v.position),
            hold: None,
            shaper: Shaper::default(),
        }
    }

    pub fn kind(&self) -> PanoKind {
        self.kind
    }

    pub fn options(&self) -> PanoOptions {
        self.options
    }

    pub fn phase(&self) -> PanoPhase {
        self.phase
    }

    /// The stations laid out by [`Pano::start`] (empty before, and for the video pan).
    pub fn stations(&self) -> &[PanoStation] {
        &self.stations
    }

    /// (photos taken, photos in total); (0, 0) for the video pan.
    pub fn station(&self) -> (u8, u8) {
        let c = |n: usize| u8::try_from(n).unwrap_or(u8::MAX);
        (c(self.taken), c(self.stations.len()))
    }

    /// The video pan's rate now, degrees per second (clamped; 0 for the others).
    pub fn yaw_rate_dps(&self) -> f32 {
        if self.kind != PanoKind::VideoPan || !self.options.yaw_rate_dps.is_finite() {
            return 0.0;
        }
        self.options
            .yaw_rate_dps
            .clamp(-VIDEO_PAN_MAX_RATE_DPS, VIDEO_PAN_MAX_RATE_DPS)
    }

    /// New options: all of them in setup; in run only the video pan's rate.
    pub fn set_options(&mut self, options: PanoOptions) {
        if self.phase == PanoPhase::Setup {
            self.options = options;
        } else {
            self.options.yaw_rate_dps = options.yaw_rate_dps;
        }
    }

    /// Setup → run: lay out the stations around the camera's yaw (and pitch, for the
    /// cylinder) now. Ignored unless in setup.
    pub fn start(&mut self, v: &VehicleView, now_s: f64) {
        if self.phase != PanoPhase::Setup {
            return;
        }
        let yaw = [v.camera_yaw_deg, v.heading_deg]
            .into_iter()
            .find(|y| y.is_finite())
            .unwrap_or(0.0);
        let pitch = if v.camera_pitch_deg.is_finite() {
            v.camera_pitch_deg.clamp(-90.0, 0.0)
        } else {
            0.0
        };
        self.stations = match self.kind {
            PanoKind::Cylinder => {
                cylinder_stations(yaw, pitch, self.options.cylinder_fov_deg, self.lens())
            }
            PanoKind::Sphere => sphere_stations(yaw),
            PanoKind::VideoPan => Vec::new(),
        };
        self.pan_yaw = f64::from(yaw);
        self.current = 0;
        self.taken = 0;
        self.state = StationState::Turning { since_s: now_s };
        self.phase = PanoPhase::Run;
    }

    fn lens(&self) -> f32 {
        let l = self.options.lens_fov_deg;
        if l.is_finite() && l > 0.0 {
            l.clamp(10.0, 170.0)
        } else {
            DEFAULT_LENS_FOV_DEG
        }
    }

    /// One tick (see the module doc).
    pub fn step(&mut self, v: &VehicleView, dt_s: f32, now_s: f64, lim: &Limits) -> PanoStep {
        let guidance = Guidance {
            velocity_ned_mps: self.hold_velocity(v, dt_s, lim),
            ..Guidance::HOVER
        };
        let mut trigger = false;
        let guidance = match (self.phase, self.kind) {
            (PanoPhase::Setup, _) => guidance,
            (PanoPhase::Run, PanoKind::VideoPan) => {
                let rate = f64::from(self.yaw_rate_dps());
                self.pan_yaw += rate * dt64(dt_s);
                // Never run away from a camera that turns slower than asked.
                if let Some(cam) = camera_yaw(v) {
                    let lead = wrap_180(self.pan_yaw - f64::from(cam));
                    let max = f64::from(VIDEO_PAN_MAX_LEAD_DEG);
                    if lead.abs() > max {
                        self.pan_yaw = f64::from(cam) + lead.clamp(-max, max);
                    }
                }
                Guidance {
                    yaw_deg: Some(wrap_360(self.pan_yaw) as f32),
                    ..guidance
                }
            }
            (PanoPhase::Run, _) => {
                trigger = self.advance(v, now_s);
                match self.stations.get(self.current) {
                    Some(s) => Guidance {
                        yaw_deg: Some(s.yaw_deg),
                        gimbal_pitch_deg: Some(s.pitch_deg),
                        ..guidance
                    },
                    None => guidance,
                }
            }
            (PanoPhase::Finished, _) => match self.stations.last() {
                // Keep looking where the last photo was taken.
                Some(s) => Guidance {
                    yaw_deg: Some(s.yaw_deg),
                    gimbal_pitch_deg: Some(s.pitch_deg),
                    ..guidance
                },
                None => guidance,
            },
        };
        PanoStep {
            guidance,
            trigger,
            station: self.station(),
            phase: self.phase,
        }
    }

    /// The station cycle: turn, settle, photo, shutter, next. True when a photo is
    /// due now.
    fn advance(&mut self, v: &VehicleView, now_s: f64) -> bool {
        let Some(target) = self.stations.get(self.current).copied() else {
            self.phase = PanoPhase::Finished;
            return false;
        };
        let on = on_station(v, &target);
        match self.state {
            StationState::Turning { since_s } => {
                if on || now_s - since_s >= TURN_TIMEOUT_S {
                    self.state = StationState::Settling {
                        since_s: now_s,
                        turning_since_s: since_s,
                    };
                }
                false
            }
            StationState::Settling {
                since_s,
                turning_since_s,
            } => {
                let timed_out = now_s - turning_since_s >= TURN_TIMEOUT_S;
                if !on && !timed_out {
                    // Knocked off the station: settle again once back.
                    self.state = StationState::Turning {
                        since_s: turning_since_s,
                    };
                    false
                } else if now_s - since_s >= SETTLE_S {
                    self.state = StationState::Shot { at_s: now_s };
                    self.taken += 1;
                    true
                } else {
                    false
                }
            }
            StationState::Shot { at_s } => {
                if now_s - at_s >= SHUTTER_S {
                    self.current += 1;
                    self.state = StationState::Turning { since_s: now_s };
                    if self.current >= self.stations.len() {
                        self.phase = PanoPhase::Finished;
                    }
                }
                false
            }
        }
    }

    /// Brake, then hold the point where the vehicle stopped (horizontally and
    /// vertically).
    fn hold_velocity(&mut self, v: &VehicleView, dt_s: f32, lim: &Limits) -> [f32; 3] {
        let lim = Lim::new(lim);
        let pos = self.frame.to_ned(&v.position);
        let commanded = self.shaper.current(v);
        if self.hold.is_none() && commanded.norm() <= 0.05 && velocity(v).norm() <= 0.5 {
            self.hold = Some(pos);
        }
        let wish = match self.hold {
            Some(p) => toward(&pos, &p, &lim, dt64(dt_s)),
            None => Vector3::zeros(),
        };
        to_f32(&self.shaper.shape(wish, v, dt_s, &lim))
    }

    /// Where the position is held, once the vehicle has braked.
    pub fn hold_point(&self) -> Option<GeoPoint> {
        self.hold.map(|p| self.frame.to_geo(&p))
    }
}

fn camera_yaw(v: &VehicleView) -> Option<f32> {
    [v.camera_yaw_deg, v.heading_deg]
        .into_iter()
        .find(|y| y.is_finite())
}

/// Whether the camera points at `s` within [`ARRIVED_DEG`] (yaw is not judged
/// straight down, where it means nothing).
fn on_station(v: &VehicleView, s: &PanoStation) -> bool {
    let pitch_ok =
        v.camera_pitch_deg.is_finite() && (v.camera_pitch_deg - s.pitch_deg).abs() <= ARRIVED_DEG;
    let yaw_ok = s.pitch_deg <= -89.0
        || camera_yaw(v).is_some_and(|y| {
            wrap_180(f64::from(y) - f64::from(s.yaw_deg)).abs() <= f64::from(ARRIVED_DEG)
        });
    pitch_ok && yaw_ok
}

/// The cylinder's stations (see the module doc).
pub fn cylinder_stations(
    center_yaw_deg: f32,
    pitch_deg: f32,
    fov_deg: f32,
    lens_fov_deg: f32,
) -> Vec<PanoStation> {
    let fov = if fov_deg.is_finite() {
        f64::from(fov_deg).clamp(91.0, 360.0)
    } else {
        360.0
    };
    let lens = if lens_fov_deg.is_finite() && lens_fov_deg > 0.0 {
        f64::from(lens_fov_deg).clamp(10.0, 170.0)
    } else {
        f64::from(DEFAULT_LENS_FOV_DEG)
    };
    let spacing = lens * f64::from(1.0 - PANO_OVERLAP);
    let (first, n, step) = if fov >= 360.0 {
        let n = (360.0 / spacing).ceil().max(1.0);
        (0.0, n as usize, 360.0 / n)
    } else {
        let span = (fov - lens).max(0.0);
        let gaps = (span / spacing).ceil();
        let step = if gaps > 0.0 { span / gaps } else { 0.0 };
        (-span / 2.0, gaps as usize + 1, step)
    };
    (0..n)
        .map(|i| PanoStation {
            yaw_deg: wrap_360(f64::from(center_yaw_deg) + first + step * i as f64) as f32,
            pitch_deg,
        })
        .collect()
}

/// The sphere's stations: [`SPHERE_ROWS`] from `start_yaw_deg`.
pub fn sphere_stations(start_yaw_deg: f32) -> Vec<PanoStation> {
    SPHERE_ROWS
        .iter()
        .flat_map(|&(pitch, n)| {
            (0..n).map(move |i| PanoStation {
                yaw_deg: wrap_360(f64::from(start_yaw_deg) + 360.0 * f64::from(i) / f64::from(n))
                    as f32,
                pitch_deg: pitch,
            })
        })
        .collect()
}
