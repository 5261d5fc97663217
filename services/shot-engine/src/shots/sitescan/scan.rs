//! The structure scan: circles around a structure at descending levels (see the
//! contract in `sitescan.rs`).

use nalgebra::{Vector2, Vector3};
use skymesh_runtime::angle::wrap_pi;

use super::{check, photo_spacing_m, SiteScanError, SiteStep, ON_STATION_M};
use crate::shots::geo::{GeoPoint, LocalFrame};
use crate::shots::motion::{
    dt64, radial, sqrt_controller, to_f32, Hold1, Lim, Radial, Shaper, DIRECTION_MIN_M,
    VELOCITY_LAG_S,
};
use crate::shots::{Guidance, Limits, VehicleView};

/// The smallest structure-scan radius, metres.
pub const MIN_SCAN_RADIUS_M: f32 = 5.0;
/// Most scan levels.
pub const MAX_SCAN_LEVELS: usize = 200;
/// Structure scan settings (from config).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanConfig {
    /// Circle radius, metres (≥ [`MIN_SCAN_RADIUS_M`]); `None` = the vehicle's ground
    /// distance from the centre when the scan starts.
    pub radius_m: Option<f32>,
    /// Between levels, metres (> 0).
    pub altitude_step_m: f32,
    /// No level below this, metres above home.
    pub min_altitude_m: f32,
    /// Horizontal overlap of neighbouring photos, 0..0.95.
    pub overlap: f32,
    /// The camera's horizontal field of view, degrees (1..170).
    pub hfov_deg: f32,
}

/// Where a structure scan is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ScanPhase {
    /// Moving onto the circle of level `usize`.
    Approach(usize),
    /// Turning at level `usize`; `turned` radians done, next photo at `next_m` of arc.
    Circle {
        level: usize,
        turned: f64,
        next_m: f64,
    },
    Done,
}

/// Orbits around a structure at descending altitudes, photographing it.
#[derive(Debug, Clone)]
pub struct StructureScan {
    /// NED around the centre at home altitude.
    frame: LocalFrame,
    center: GeoPoint,
    radius: f64,
    levels: Vec<f32>,
    spacing: f64,
    phase: ScanPhase,
    /// Outward direction when too close to the centre to tell.
    fallback_out: Vector2<f64>,
    /// Angle around the centre, radians clockwise from north, unwrapped.
    angle: Option<f64>,
    /// The last non-zero direction: +1 counter-clockwise.
    direction: f64,
    shaper: Shaper,
    pause: Hold1,
}

impl StructureScan {
    /// A scan of the structure at `center` from where the vehicle is (module doc).
    pub fn new(
        center: GeoPoint,
        start: &VehicleView,
        cfg: &ScanConfig,
    ) -> Result<StructureScan, SiteScanError> {
        let step = check("altitude_step_m", cfg.altitude_step_m, |x| x > 0.0)?;
        let min_alt = check("min_altitude_m", cfg.min_altitude_m, |_| true)?;
        let overlap = check("overlap", cfg.overlap, |x| (0.0..=0.95).contains(&x))?;
        let hfov = check("hfov_deg", cfg.hfov_deg, |x| (1.0..=170.0).contains(&x))?;
        let radius = match cfg.radius_m {
            Some(r) => check("radius_m", r, |x| x >= MIN_SCAN_RADIUS_M)?,
            None => f64::NAN,
        };
        if !(center.lat_deg.is_finite() && center.lon_deg.is_finite()) {
            return Err(SiteScanError::BadCoordinate);
        }
        let start_alt = check("start altitude", start.position.alt_rel_m, |_| true)?;
        let frame = LocalFrame::new(GeoPoint {
            alt_rel_m: 0.0,
            ..center
        });
        let p = frame.to_ned(&start.position);
        let h = Vector2::new(p.x, p.y);
        let r = h.norm();
        let radius = if radius.is_nan() {
            r.max(f64::from(MIN_SCAN_RADIUS_M))
        } else {
            radius
        };
        let mut levels = vec![start_alt as f32];
        let mut alt = start_alt - step;
        while alt >= min_alt - 1e-6 {
            if levels.len() >= MAX_SCAN_LEVELS {
                return Err(SiteScanError::TooLarge {
                    what: "levels",
                    count: levels.len() + 1,
                    max: MAX_SCAN_LEVELS,
                });
            }
            levels.push(alt as f32);
            alt -= step;
        }
        let fallback_out = if r > DIRECTION_MIN_M {
            h / r
        } else {
            let hd = f64::from(start.heading_deg).to_radians();
            let hd = if hd.is_finite() { hd } else { 0.0 };
            -Vector2::new(hd.cos(), hd.sin())
        };
        Ok(StructureScan {
            frame,
            center,
            radius,
            levels,
            spacing: photo_spacing_m(radius, hfov, overlap),
            phase: ScanPhase::Approach(0),
            fallback_out,
            angle: None,
            direction: 1.0,
            shaper: Shaper::default(),
            pause: Hold1::default(),
        })
    }

    /// The circle's radius, metres.
    pub fn radius_m(&self) -> f32 {
        self.radius as f32
    }

    /// The levels' altitudes above home, first flown first.
    pub fn levels(&self) -> &[f32] {
        &self.levels
    }

    /// Arc between photos, metres.
    pub fn trigger_spacing_m(&self) -> f32 {
        self.spacing as f32
    }

    /// The level being flown (the last once done).
    pub fn level(&self) -> usize {
        match self.phase {
            ScanPhase::Approach(l) | ScanPhase::Circle { level: l, .. } => l,
            ScanPhase::Done => self.levels.len() - 1,
        }
    }

    /// 0..1: turns done of all turns.
    pub fn progress(&self) -> f32 {
        let n = self.levels.len() as f64;
        let p = match self.phase {
            ScanPhase::Approach(l) => l as f64 / n,
            ScanPhase::Circle { level, turned, .. } => {
                (level as f64 + (turned / std::f64::consts::TAU).min(1.0)) / n
            }
            ScanPhase::Done => 1.0,
        };
        p as f32
    }

    /// One tick (module doc).
    pub fn step(&mut self, v: &VehicleView, dt_s: f32, speed: f32, lim: &Limits) -> SiteStep {
        use std::f64::consts::TAU;
        let lim = Lim::new(lim);
        let dt = dt64(dt_s);
        let Radial {
            p,
            r,
            out,
            ccw,
            angle: angle_now,
        } = radial(&self.frame, v, self.fallback_out);
        let delta = match self.angle {
            Some(prev) => wrap_pi(angle_now - prev),
            None => 0.0,
        };
        let angle = self.angle.map_or(angle_now, |a| a + delta);
        self.angle = Some(angle);
        let cruise = if speed.is_finite() {
            f64::from(speed)
        } else {
            0.0
        };
        if cruise != 0.0 {
            self.direction = cruise.signum();
        }
        let level = self.level();
        let target_down = -f64::from(self.levels[level]);
        let on_station =
            (self.radius - r).abs() < ON_STATION_M && (target_down - p.z).abs() < ON_STATION_M;

        let mut trigger = false;
        self.phase = match self.phase {
            ScanPhase::Approach(l) if on_station && cruise != 0.0 => {
                trigger = true;
                ScanPhase::Circle {
                    level: l,
                    turned: 0.0,
                    next_m: self.spacing,
                }
            }
            ScanPhase::Circle {
                level,
                turned,
                next_m,
            } => {
                // Counter-clockwise is a falling angle.
                let turned = turned + (-delta * self.direction).max(0.0);
                let mut next_m = next_m;
                if cruise == 0.0 {
                    // Paused: the turn braking adds still counts; photos and the
                    // next level wait for the resume.
                    ScanPhase::Circle {
                        level,
                        turned,
                        next_m,
                    }
                } else if turned >= TAU {
                    if level + 1 < self.levels.len() {
                        ScanPhase::Approach(level + 1)
                    } else {
                        ScanPhase::Done
                    }
                } else {
                    if turned * self.radius >= next_m - 1e-9 {
                        trigger = true;
                        next_m += self.spacing;
                    }
                    ScanPhase::Circle {
                        level,
                        turned,
                        next_m,
                    }
                }
            }
            other => other,
        };

        let circling = matches!(self.phase, ScanPhase::Circle { .. });
        let max_tangential = lim.speed.min((lim.plan_accel() * self.radius).sqrt());
        let tangential = if circling && cruise != 0.0 {
            self.pause.release();
            cruise.clamp(-max_tangential, max_tangential)
        } else {
            // Approaching, paused or done: hold the point on the circle.
            let arc = -angle * self.radius;
            let commanded = self.shaper.current(v);
            let along = commanded.x * ccw.x + commanded.y * ccw.y;
            self.pause
                .speed(arc, along, (f64::NEG_INFINITY, f64::INFINITY), &lim, dt)
                .clamp(-max_tangential, max_tangential)
        };
        let radial = sqrt_controller(self.radius - r, lim.gain, lim.plan_accel(), dt);
        let inward = tangential * tangential / self.radius * VELOCITY_LAG_S;
        let xy = out * (radial - inward) + ccw * tangential;
        let down = sqrt_controller(target_down - p.z, lim.gain, lim.plan_accel(), dt);
        let vel = self
            .shaper
            .shape(Vector3::new(xy.x, xy.y, down), v, dt_s, &lim);
        let roi = GeoPoint {
            alt_rel_m: self.levels[self.level()],
            ..self.center
        };
        SiteStep {
            guidance: Guidance {
                velocity_ned_mps: to_f32(&vel),
                roi: Some(roi),
                yaw_deg: None,
                gimbal_pitch_deg: None,
            },
            trigger,
            progress: self.progress(),
            done: self.phase == ScanPhase::Done,
        }
    }
}
