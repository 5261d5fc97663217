//! The survey: a lawnmower over a polygon (see the contract in `sitescan.rs`).

use nalgebra::{Vector2, Vector3};

use super::lanes::{lane_segments, longest_edge_heading, order};
use super::{check, photo_spacing_m, SiteScanError, SiteStep, ON_STATION_M};
use crate::shots::fence::{area, self_intersecting};
use crate::shots::geo::{distance_m, GeoPoint, LocalFrame};
use crate::shots::line::Line;
use crate::shots::motion::{dt64, to_f32, toward, Lim, Shaper};
use crate::shots::{Guidance, Limits, VehicleView};

/// Most survey lanes (split lanes count once per piece).
pub const MAX_SURVEY_LANES: usize = 2000;
/// A lane end is reached this close along it, metres.
const LANE_END_M: f64 = 0.5;

/// Survey settings (from config).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurveyConfig {
    /// Flown at this altitude above home, metres (≥ 2).
    pub altitude_m: f32,
    /// Along-lane overlap of neighbouring photos, 0..0.95.
    pub overlap: f32,
    /// Across-lane overlap (between lanes), 0..0.95.
    pub sidelap: f32,
    /// The camera's horizontal field of view (across the lanes), degrees (1..170).
    pub hfov_deg: f32,
    /// The camera's vertical field of view (along the lanes), degrees (1..170).
    pub vfov_deg: f32,
    /// Lane direction, degrees from north; `None` = along the polygon's longest edge.
    pub heading_deg: Option<f32>,
}

/// One lane, as flown (start → end), at the survey altitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurveyLane {
    pub start: GeoPoint,
    pub end: GeoPoint,
}

/// Where a survey is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum SurveyPhase {
    /// Flying to the start of lane `usize` (line built on the first step).
    Transit(usize),
    /// Flying lane `usize`; the next photo at `next_m` along it; `last_m` the last.
    Lane {
        lane: usize,
        next_m: f64,
        last_m: f64,
    },
    Done,
}

/// A lawnmower over a polygon.
#[derive(Debug, Clone)]
pub struct Survey {
    lanes: Vec<SurveyLane>,
    lane_len: Vec<f64>,
    total_len: f64,
    lane_spacing: f64,
    spacing: f64,
    phase: SurveyPhase,
    line: Option<Line>,
    /// Lane length flown before the current lane.
    flown: f64,
    progress: f64,
    shaper: Shaper,
}

impl Survey {
    /// Lanes covering `polygon` (module doc): every point of it within spacing/2 of
    /// a lane; lanes may reach up to spacing/2 outside it.
    pub fn new(polygon: &[GeoPoint], cfg: &SurveyConfig) -> Result<Survey, SiteScanError> {
        Survey::build(polygon, cfg, false)
    }

    /// Lanes kept inside `polygon` (for an area bounded by a keep-in fence): each
    /// lane is its own line clipped to the polygon, so no lane point lies outside
    /// it, and the cover is spacing/2 across the lanes only (short of it in corners
    /// an edge cuts at a slant; the camera footprint reaches past the lane ends).
    pub fn new_within(polygon: &[GeoPoint], cfg: &SurveyConfig) -> Result<Survey, SiteScanError> {
        Survey::build(polygon, cfg, true)
    }

    fn build(
        polygon: &[GeoPoint],
        cfg: &SurveyConfig,
        within: bool,
    ) -> Result<Survey, SiteScanError> {
        let alt = check("altitude_m", cfg.altitude_m, |x| x >= 2.0)?;
        let overlap = check("overlap", cfg.overlap, |x| (0.0..=0.95).contains(&x))?;
        let sidelap = check("sidelap", cfg.sidelap, |x| (0.0..=0.95).contains(&x))?;
        let hfov = check("hfov_deg", cfg.hfov_deg, |x| (1.0..=170.0).contains(&x))?;
        let vfov = check("vfov_deg", cfg.vfov_deg, |x| (1.0..=170.0).contains(&x))?;
        if polygon.len() < 3 {
            return Err(SiteScanError::TooFewVertices(polygon.len()));
        }
        if !polygon
            .iter()
            .all(|p| p.lat_deg.is_finite() && p.lon_deg.is_finite())
        {
            return Err(SiteScanError::BadCoordinate);
        }
        let frame = LocalFrame::new(GeoPoint {
            alt_rel_m: 0.0,
            ..polygon[0]
        });
        let ring: Vec<Vector2<f64>> = polygon
            .iter()
            .map(|p| {
                let v = frame.to_ned(p);
                Vector2::new(v.x, v.y)
            })
            .collect();
        if self_intersecting(&ring) || area(&ring).abs() < 1.0 {
            return Err(SiteScanError::BadPolygon);
        }
        let heading = match cfg.heading_deg {
            Some(h) => check("heading_deg", h, |_| true)?.to_radians(),
            None => longest_edge_heading(&ring),
        };
        let lane_spacing = photo_spacing_m(alt, hfov, sidelap);
        let spacing = photo_spacing_m(alt, vfov, overlap);
        let segments = lane_segments(&ring, heading, lane_spacing, within)?;
        let u = Vector2::new(heading.cos(), heading.sin());
        let w = Vector2::new(-heading.sin(), heading.cos());
        let at = |off: f64, along: f64| {
            let p = u * along + w * off;
            frame.to_geo(&Vector3::new(p.x, p.y, -alt))
        };
        let lanes: Vec<SurveyLane> = order(&segments)
            .into_iter()
            .map(|(off, a, b)| SurveyLane {
                start: at(off, a),
                end: at(off, b),
            })
            .collect();
        if lanes.is_empty() {
            return Err(SiteScanError::BadPolygon);
        }
        let lane_len: Vec<f64> = segments_len(&lanes, &frame);
        let total_len = lane_len.iter().sum();
        Ok(Survey {
            lanes,
            lane_len,
            total_len,
            lane_spacing,
            spacing,
            phase: SurveyPhase::Transit(0),
            line: None,
            flown: 0.0,
            progress: 0.0,
            shaper: Shaper::default(),
        })
    }

    /// The lanes in flying order.
    pub fn lanes(&self) -> &[SurveyLane] {
        &self.lanes
    }

    /// Between lanes, metres.
    pub fn lane_spacing_m(&self) -> f32 {
        self.lane_spacing as f32
    }

    /// Between photos along a lane, metres.
    pub fn trigger_spacing_m(&self) -> f32 {
        self.spacing as f32
    }

    /// 0..1 of the lane length flown.
    pub fn progress(&self) -> f32 {
        self.progress as f32
    }

    /// One tick (module doc).
    pub fn step(&mut self, v: &VehicleView, dt_s: f32, speed: f32, lim: &Limits) -> SiteStep {
        let lim_ = Lim::new(lim);
        let dt = dt64(dt_s);
        let speed = if speed.is_finite() {
            f64::from(speed).abs()
        } else {
            0.0
        };
        let commanded = self.shaper.current(v);
        let mut trigger = false;
        let goal = speed > 0.0;
        let wish = match self.phase {
            SurveyPhase::Transit(i) => {
                let lane = self.lanes[i];
                if distance_m(&v.position, &lane.start) < ON_STATION_M {
                    // On the lane: fly it from this tick (its first photo next tick).
                    self.phase = SurveyPhase::Lane {
                        lane: i,
                        next_m: 0.0,
                        last_m: f64::NEG_INFINITY,
                    };
                    self.line = Some(Line::new(&lane.start, &lane.end));
                }
                let line = self
                    .line
                    .get_or_insert_with(|| Line::new(&v.position, &lane.start));
                let at = line.locate(&v.position);
                let len = line.len();
                line.wish(&at, goal.then_some(len), speed, &commanded, &lim_, dt)
            }
            SurveyPhase::Lane {
                lane,
                next_m,
                last_m,
            } => {
                let l = self.lanes[lane];
                let line = self.line.get_or_insert_with(|| Line::new(&l.start, &l.end));
                let at = line.locate(&v.position);
                let len = line.len();
                let along = at.along.clamp(0.0, len);
                let (mut next_m, mut last_m) = (next_m, last_m);
                if along >= next_m {
                    trigger = true;
                    last_m = along;
                    next_m = along + self.spacing;
                }
                let wish = line.wish(&at, goal.then_some(len), speed, &commanded, &lim_, dt);
                let p = ((self.flown + along) / self.total_len.max(1e-9)).min(1.0);
                self.progress = self.progress.max(p);
                if len - along < LANE_END_M {
                    if !trigger && len - last_m > self.spacing / 2.0 {
                        trigger = true;
                    }
                    self.flown += self.lane_len[lane];
                    self.line = None;
                    self.phase = if lane + 1 < self.lanes.len() {
                        SurveyPhase::Transit(lane + 1)
                    } else {
                        self.progress = 1.0;
                        SurveyPhase::Done
                    };
                } else {
                    self.phase = SurveyPhase::Lane {
                        lane,
                        next_m,
                        last_m,
                    };
                }
                wish
            }
            SurveyPhase::Done => {
                let end = self.lanes[self.lanes.len() - 1].end;
                let frame = LocalFrame::new(end);
                toward(&frame.to_ned(&v.position), &Vector3::zeros(), &lim_, dt)
            }
        };
        let vel = self.shaper.shape(wish, v, dt_s, &lim_);
        SiteStep {
            guidance: Guidance {
                velocity_ned_mps: to_f32(&vel),
                roi: None,
                yaw_deg: None,
                gimbal_pitch_deg: Some(-90.0),
            },
            trigger,
            progress: self.progress(),
            done: self.phase == SurveyPhase::Done,
        }
    }
}

fn segments_len(lanes: &[SurveyLane], frame: &LocalFrame) -> Vec<f64> {
    lanes
        .iter()
        .map(|l| (frame.to_ned(&l.end) - frame.to_ned(&l.start)).norm())
        .collect()
}
