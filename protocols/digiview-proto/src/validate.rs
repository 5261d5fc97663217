//! Range checks against the document's ranges: what the gateway answers with
//! DATA_ERROR. Each failure names the parameter and the field.
//!
//! Where DigiView itself clamps or silently ignores (width above 1920, a layout above
//! 6, a sorting mode above 2), skymesh refuses instead: the client learns its value
//! was not applied. Angle limits are ±π and ±π/2 plus one milliradian, so the
//! rounded `i32 × 1000` of π itself passes. Choices where the document is unclear:
//! targeting modes 0–3 (the text's maximum, the table says 0–2), lock flags 0–7 (three
//! flag bits, the table says 0–4), crop modes 0–2 (table 0–1, text 1–2), STT zoom 0–10
//! (the text; the table says 0–65535), FOV 0–π radians.

use crate::fixed::NameError;
use crate::frame::ParamType;
use crate::params::{BoundingBox, Param, MAX_VIEWS};

/// What is wrong with one field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    #[error("{value} is outside [{min}, {max}]")]
    OutOfRange { value: f64, min: f64, max: f64 },
    #[error("{value} is outside [{min}, {max})")]
    OutOfHalfOpenRange { value: f64, min: f64, max: f64 },
    #[error("value is NaN or infinite")]
    NotFinite,
    #[error("bool byte {0} is neither 0 nor 1")]
    NotBool(u8),
    #[error("flags {0:#04x} set unknown bits")]
    UnknownBits(u8),
    #[error(transparent)]
    Name(#[from] NameError),
    #[error("box x {} y {} w {} h {} is outside the {width}x{height} frame", b.x, b.y, b.w, b.h)]
    OutsideFrame {
        b: BoundingBox,
        width: u16,
        height: u16,
    },
    #[error("minimum {min} is above maximum {max}")]
    MinAboveMax { min: f64, max: f64 },
}

/// A payload field the gateway refuses (DATA_ERROR).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}.{field}: {problem}", param.name())]
pub struct PayloadError {
    pub param: ParamType,
    pub field: &'static str,
    pub problem: Problem,
}

const MRAD: f64 = 0.001;
const PI: f64 = std::f64::consts::PI + MRAD;
const HALF_PI: f64 = std::f64::consts::FRAC_PI_2 + MRAD;

/// Collects the first failure of one parameter.
struct Check {
    param: ParamType,
}

impl Check {
    fn err(&self, field: &'static str, problem: Problem) -> PayloadError {
        PayloadError {
            param: self.param,
            field,
            problem,
        }
    }

    fn range(
        &self,
        field: &'static str,
        value: f64,
        min: f64,
        max: f64,
    ) -> Result<(), PayloadError> {
        if !value.is_finite() {
            return Err(self.err(field, Problem::NotFinite));
        }
        if value < min || value > max {
            return Err(self.err(field, Problem::OutOfRange { value, min, max }));
        }
        Ok(())
    }

    fn half_open(
        &self,
        field: &'static str,
        value: f64,
        min: f64,
        max: f64,
    ) -> Result<(), PayloadError> {
        if !value.is_finite() {
            return Err(self.err(field, Problem::NotFinite));
        }
        if value < min || value >= max {
            return Err(self.err(field, Problem::OutOfHalfOpenRange { value, min, max }));
        }
        Ok(())
    }

    fn int(
        &self,
        field: &'static str,
        value: impl Into<f64>,
        min: f64,
        max: f64,
    ) -> Result<(), PayloadError> {
        self.range(field, value.into(), min, max)
    }

    fn finite(&self, field: &'static str, value: f64) -> Result<(), PayloadError> {
        if value.is_finite() {
            Ok(())
        } else {
            Err(self.err(field, Problem::NotFinite))
        }
    }

    fn inside(
        &self,
        field: &'static str,
        b: &BoundingBox,
        width: u16,
        height: u16,
    ) -> Result<(), PayloadError> {
        let fits = u32::from(b.x) + u32::from(b.w) <= u32::from(width)
            && u32::from(b.y) + u32::from(b.h) <= u32::from(height);
        if fits {
            Ok(())
        } else {
            Err(self.err(
                field,
                Problem::OutsideFrame {
                    b: *b,
                    width,
                    height,
                },
            ))
        }
    }

    fn min_max(&self, field: &'static str, min: u32, max: u32) -> Result<(), PayloadError> {
        if min <= max {
            Ok(())
        } else {
            Err(self.err(
                field,
                Problem::MinAboveMax {
                    min: f64::from(min),
                    max: f64::from(max),
                },
            ))
        }
    }

    fn lat_lon_alt(&self, lat: f64, lon: f64, alt: f64) -> Result<(), PayloadError> {
        self.range("latitude", lat, -90.0, 90.0)?;
        self.half_open("longitude", lon, -180.0, 180.0)?;
        self.range("altitude", alt, -1000.0, 10000.0)
    }
}

impl Param {
    /// The document's ranges for every field; the first failure.
    pub fn validate(&self) -> Result<(), PayloadError> {
        let c = Check {
            param: self.param_type(),
        };
        match self {
            Param::SystemStatus(p) => {
                c.int("status", p.status, 0.0, 3.0)?;
                c.finite("temperature", p.temperature)
            }
            Param::Ai(_) | Param::Model(_) | Param::Capture(_) => Ok(()),
            Param::VideoOutput(p) => {
                c.int("width", p.width, 640.0, 1920.0)?;
                c.int("height", p.height, 480.0, 1080.0)?;
                c.int("layout_mode", p.layout_mode, 0.0, 6.0)?;
                c.int("layout_views", p.layout_views, 0.0, MAX_VIEWS as f64)?;
                c.int("overlay_mode", p.overlay_mode, 0.0, 5.0)?;
                c.range("num_views", p.views.len() as f64, 0.0, MAX_VIEWS as f64)?;
                for v in &p.views {
                    c.inside("views", v, p.width, p.height)?;
                }
                c.inside("overlay_box", &p.overlay_box, p.width, p.height)
            }
            Param::Detection(p) => {
                c.int("sorting_mode", p.sorting_mode, 0.0, 2.0)?;
                c.half_open("track_confidence", p.track_confidence, 0.0, 0.99)?;
                c.half_open("scan_confidence", p.scan_confidence, 0.0, 0.99)?;
                c.half_open("track_overlap", p.track_overlap, 0.0, 0.99)?;
                c.half_open("scan_overlap", p.scan_overlap, 0.0, 0.99)
            }
            Param::DetectedRoi(p) => {
                c.range("yaw_global", p.yaw_global, -PI, PI)?;
                c.range("pitch_global", p.pitch_global, -HALF_PI, HALF_PI)?;
                c.int("rel_frame", p.rel_frame, 0.0, 2.0)?;
                c.range("yaw_rel", p.yaw_rel, -PI, PI)?;
                c.range("pitch_rel", p.pitch_rel, -PI, PI)?;
                c.lat_lon_alt(p.latitude, p.longitude, p.altitude)?;
                c.range("distance", p.distance, 0.0, f64::MAX)
            }
            Param::CamTargeting(p) => {
                c.int("cam", p.cam, 0.0, 3.0)?;
                c.int("mode", p.mode, 0.0, 3.0)?;
                c.range("yaw", p.yaw, -PI, PI)?;
                c.range("pitch", p.pitch, -HALF_PI, HALF_PI)?;
                c.range("roll", p.roll, -HALF_PI, HALF_PI)?;
                c.int("lock_flags", p.lock_flags, 0.0, 7.0)?;
                c.range("x_offset", p.x_offset, -1.0, 1.0)?;
                c.range("y_offset", p.y_offset, -1.0, 1.0)?;
                c.lat_lon_alt(p.latitude, p.longitude, p.altitude)
            }
            Param::CamOpticsAndControl(p) => {
                c.int("cam", p.cam, 0.0, 3.0)?;
                c.int("zoom", p.zoom, -127.0, 127.0)?;
                c.range("fov", p.fov, 0.0, PI)?;
                c.int("crop_mode", p.crop_mode, 0.0, 2.0)
            }
            Param::CamOffset(p) => {
                c.int("cam", p.cam, 0.0, 3.0)?;
                c.range("x", p.x, -1.0, 1.0)?;
                c.range("y", p.y, -1.0, 1.0)?;
                c.range("yaw_global", p.yaw_global, -PI, PI)?;
                c.range("pitch_global", p.pitch_global, -PI, PI)?;
                c.range("yaw_rel", p.yaw_rel, -PI, PI)?;
                c.range("pitch_rel", p.pitch_rel, -PI, PI)
            }
            Param::Sensor(p) => {
                c.min_max("min_exposure", p.min_exposure, p.max_exposure)?;
                c.min_max("min_gain", p.min_gain, p.max_gain)
            }
            Param::CamDepthEstimation(p) => {
                c.int("cam", p.cam, 0.0, 3.0)?;
                c.range("depth", p.depth, 0.0, f64::MAX)
            }
            Param::SingleTargetTracking(p) => {
                c.int("command", p.command, 0.0, 4.0)?;
                c.int("cam", p.cam, 0.0, 3.0)?;
                c.range("x_offset", p.x_offset, -1.0, 1.0)?;
                c.range("y_offset", p.y_offset, -1.0, 1.0)?;
                c.int("zoom", p.zoom, 0.0, 10.0)?;
                c.finite("confidence", p.confidence)?;
                c.range("yaw_global", p.yaw_global, -PI, PI)?;
                c.range("pitch_global", p.pitch_global, -HALF_PI, HALF_PI)?;
                c.int("rel_frame", p.rel_frame, 0.0, 2.0)?;
                c.range("yaw_rel", p.yaw_rel, -PI, PI)?;
                c.range("pitch_rel", p.pitch_rel, -HALF_PI, HALF_PI)
            }
        }
    }
}
