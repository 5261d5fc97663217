//! The pipeline's settings and every [`ViewControl`] / [`VisionControl`] → what to
//! do. Pure: no bus, no frames. Settings that live in other modules' objects
//! (virtual cameras, the single-target tracker, captures) come back as an [`Effect`]
//! the service applies; what is kept here (detector, output, tracker thresholds) is
//! changed here.
//!
//! | view control | here |
//! |---|---|
//! | `Ai` | enabled; model names must be in [`MODELS`] (else Ignored); an empty name keeps the current model |
//! | `Output` | width/height clamped to 1920/1080, below 640/480 → Ignored; layout > 6, overlay > 5 unchanged; views and boxes are computed, not set |
//! | `Capture` | → [`Effect::Capture`] |
//! | `Detection` | sorting > 2 keeps; thresholds outside 0..0.99 keep; scores of [`SCORE_KEEP`] keep |
//! | `Targeting`, `Optics` | range-checked (Invalid), → [`Effect::Targeting`] / [`Effect::Optics`] |
//! | `SingleTarget` | range-checked, → [`Effect::Stt`] |
//! | `DirectionAt` | offsets within −1..1, → [`Effect::DirectionAt`] |
//!
//! An unknown stream name or a camera outside 0..4 is Ignored ("the operation is
//! ignored"); a value out of range or not finite is Invalid with the field's name.

use std::f64::consts::{FRAC_PI_2, PI};

use skymesh_ipc_types::view::SCORE_KEEP;
use skymesh_ipc_types::{
    CropMode, FixedStr, ReferenceFrame, TargetingMode, TrackCommand, ViewControl, ViewControlKind,
    VisionControl, VisionControlKind, VisionResult, LOCK_PITCH, LOCK_ROLL, LOCK_YAW,
    VISION_MAX_CAMS,
};

use crate::detect::MODELS;
use crate::geometry::GeoPosition;
use crate::track::TrackerParams;
use crate::views::{Optics, Targeting, ZOOM_MAX, ZOOM_MIN};

/// MAVLink GIMBAL_MANAGER_FLAGS_YAW_LOCK.
pub const GIMBAL_YAW_LOCK: u32 = 16;
/// MAVLink GIMBAL_MANAGER_FLAGS_YAW_IN_EARTH_FRAME.
pub const GIMBAL_YAW_IN_EARTH_FRAME: u32 = 64;
/// `cam` meaning every camera of the stream.
pub const ALL_CAMS: u8 = 255;

/// One stream's output parameters (VIDEO_OUTPUT).
#[derive(Debug, Clone, PartialEq)]
pub struct StreamParams {
    pub name: String,
    pub out_width: u16,
    pub out_height: u16,
    pub layout_mode: u8,
    pub overlay_mode: u8,
}

/// Every DigiView parameter the pipeline keeps itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    pub ai_enabled: bool,
    pub scan_model: String,
    pub track_model: String,
    /// DETECTION `mode`: unused by DigiView, stored and reported.
    pub detection_mode: u8,
    pub tracker: TrackerParams,
    pub streams: Vec<StreamParams>,
}

/// Which virtual cameras of a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cams {
    One(u8),
    All,
}

impl Cams {
    /// The camera indices.
    pub fn indices(self) -> std::ops::Range<usize> {
        match self {
            Cams::One(c) => usize::from(c)..usize::from(c) + 1,
            Cams::All => 0..VISION_MAX_CAMS,
        }
    }
}

/// A single-target tracking command before the pipeline resolves it with the named
/// view's geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SttRequest {
    Disable,
    /// Command 1 with `rel_frame` 0: global yaw/pitch, radians.
    Global {
        yaw: f64,
        pitch: f64,
    },
    /// Command 1 otherwise: the direction at this offset of the named view.
    ViewOffset {
        x: f64,
        y: f64,
    },
    /// Command 2.
    Detection(u8),
    /// Command 3: move the target by this fraction of the named view.
    Nudge {
        x: f64,
        y: f64,
    },
    /// Command 4 (zoom level still applies).
    NoOp,
}

/// What the service must do after a control was accepted here.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// Only this state changed (VIDEO_OUTPUT, DETECTION: take it from [`Params`]).
    Changed,
    /// AI enabled or models changed: rebuild detectors / clear tracks.
    AiChanged,
    /// One image and/or start (true) or stop (false) recording.
    Capture {
        stream: usize,
        single_image: bool,
        record: Option<bool>,
    },
    Targeting {
        stream: usize,
        cam: u8,
        targeting: Targeting,
    },
    Optics {
        stream: usize,
        cam: u8,
        optics: Optics,
    },
    /// Answer with the direction at offset (x, y) of the camera's view.
    DirectionAt {
        stream: usize,
        cam: u8,
        x: f64,
        y: f64,
    },
    Stt {
        stream: usize,
        cam: u8,
        request: SttRequest,
        zoom_level: u16,
        rel_frame: u8,
    },
    Gimbal {
        stream: usize,
        cam: u8,
        yaw: Option<f64>,
        pitch: Option<f64>,
        yaw_rate: Option<f64>,
        pitch_rate: Option<f64>,
        yaw_global: bool,
    },
    Roi {
        stream: usize,
        cams: Cams,
        target: GeoPosition,
    },
    RoiNone {
        stream: usize,
        cams: Cams,
    },
    Zoom {
        stream: usize,
        cams: Cams,
        mode: u8,
        value: f32,
    },
}

/// Why a control was not applied: the reply's result and message.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub result: VisionResult,
    pub message: String,
}

impl Refusal {
    pub fn ignored(m: impl Into<String>) -> Refusal {
        Refusal {
            result: VisionResult::Ignored,
            message: m.into(),
        }
    }
    pub fn invalid(m: impl Into<String>) -> Refusal {
        Refusal {
            result: VisionResult::Invalid,
            message: m.into(),
        }
    }
    pub fn unsupported(m: impl Into<String>) -> Refusal {
        Refusal {
            result: VisionResult::Unsupported,
            message: m.into(),
        }
    }
    pub fn failed(m: impl Into<String>) -> Refusal {
        Refusal {
            result: VisionResult::Failed,
            message: m.into(),
        }
    }
}

/// NaN means "not given"; infinities are invalid.
fn optional(name: &str, v: f32) -> Result<Option<f64>, Refusal> {
    if v.is_nan() {
        Ok(None)
    } else if v.is_finite() {
        Ok(Some(f64::from(v)))
    } else {
        Err(Refusal::invalid(format!("{name} is not finite")))
    }
}

impl Params {
    /// The index of the stream called `name`.
    pub fn stream_index(&self, name: &str) -> Option<usize> {
        self.streams.iter().position(|s| s.name == name)
    }

    fn stream_named(&self, name: &str) -> Result<usize, Refusal> {
        self.stream_index(name)
            .ok_or_else(|| Refusal::ignored(format!("unknown stream `{name}`")))
    }

    fn stream_at(&self, index: u8) -> Result<usize, Refusal> {
        let i = usize::from(index);
        if i < self.streams.len() {
            Ok(i)
        } else {
            Err(Refusal::ignored(format!("no stream {index}")))
        }
    }

    fn cam(cam: u8) -> Result<u8, Refusal> {
        if usize::from(cam) < VISION_MAX_CAMS {
            Ok(cam)
        } else {
            Err(Refusal::ignored(format!("camera {cam} is not in 0..4")))
        }
    }

    fn cams(cam: u8) -> Result<Cams, Refusal> {
        if cam == ALL_CAMS {
            Ok(Cams::All)
        } else {
            Self::cam(cam).map(Cams::One)
        }
    }

    /// Applies one control: `Ok` = Applied (with what is left to do), `Err` = the reply.
    pub fn apply(&mut self, c: &VisionControl) -> Result<Effect, Refusal> {
        let kind = VisionControlKind::try_from(c.kind)
            .map_err(|_| Refusal::invalid(format!("unknown control kind {}", c.kind)))?;
        match kind {
            VisionControlKind::GimbalAttitude => {
                let stream = self.stream_at(c.stream)?;
                let cam = Self::cam(c.cam)?;
                let yaw = optional("yaw", c.yaw_rad)?;
                let pitch = optional("pitch", c.pitch_rad)?;
                let yaw_rate = optional("yaw rate", c.yaw_rate_rps)?;
                let pitch_rate = optional("pitch rate", c.pitch_rate_rps)?;
                if yaw.is_none() && pitch.is_none() && yaw_rate.is_none() && pitch_rate.is_none() {
                    return Err(Refusal::invalid("no angle and no rate given"));
                }
                Ok(Effect::Gimbal {
                    stream,
                    cam,
                    yaw,
                    pitch,
                    yaw_rate,
                    pitch_rate,
                    yaw_global: c.gimbal_flags & (GIMBAL_YAW_LOCK | GIMBAL_YAW_IN_EARTH_FRAME) != 0,
                })
            }
            VisionControlKind::RoiLocation => {
                let stream = self.stream_at(c.stream)?;
                let cams = Self::cams(c.cam)?;
                let target = GeoPosition {
                    lat_deg: c.lat_deg,
                    lon_deg: c.lon_deg,
                    alt_msl_m: f64::from(c.alt_msl_m),
                };
                let ok = target.lat_deg.is_finite()
                    && target.lon_deg.is_finite()
                    && target.alt_msl_m.is_finite()
                    && target.lat_deg.abs() <= 90.0
                    && target.lon_deg.abs() <= 180.0;
                if !ok {
                    return Err(Refusal::invalid(format!(
                        "bad position {}, {}, {} m",
                        target.lat_deg, target.lon_deg, target.alt_msl_m
                    )));
                }
                Ok(Effect::Roi {
                    stream,
                    cams,
                    target,
                })
            }
            VisionControlKind::RoiNone => Ok(Effect::RoiNone {
                stream: self.stream_at(c.stream)?,
                cams: Self::cams(c.cam)?,
            }),
            VisionControlKind::Zoom => {
                let stream = self.stream_at(c.stream)?;
                let cams = Self::cams(c.cam)?;
                if !c.value.is_finite() {
                    return Err(Refusal::invalid("zoom value is not finite"));
                }
                if c.zoom_mode > 3 {
                    return Err(Refusal::invalid(format!(
                        "unknown zoom type {}",
                        c.zoom_mode
                    )));
                }
                Ok(Effect::Zoom {
                    stream,
                    cams,
                    mode: c.zoom_mode,
                    value: c.value,
                })
            }
            VisionControlKind::ImageCapture => Ok(Effect::Capture {
                stream: self.stream_at(c.stream)?,
                single_image: true,
                record: None,
            }),
            VisionControlKind::RecordStart | VisionControlKind::RecordStop => Ok(Effect::Capture {
                stream: self.stream_at(c.stream)?,
                single_image: false,
                record: Some(kind == VisionControlKind::RecordStart),
            }),
        }
    }

    /// Applies one [`ViewControl`]: `Ok` = Applied (with what is left to do),
    /// `Err` = the reply.
    pub fn apply_view(&mut self, c: &ViewControl) -> Result<Effect, Refusal> {
        let kind = c
            .kind()
            .map_err(|_| Refusal::invalid(format!("unknown view control kind {}", c.kind)))?;
        match kind {
            ViewControlKind::Ai => {
                let pick = |name: &str, current: &str| -> Result<String, Refusal> {
                    if name.is_empty() {
                        Ok(current.to_string())
                    } else if MODELS.contains(&name) {
                        Ok(name.to_string())
                    } else {
                        Err(Refusal::ignored(format!(
                            "unknown model `{name}` (have: {})",
                            MODELS.join(", ")
                        )))
                    }
                };
                let scan = pick(text(&c.scan_model, "scan model")?, &self.scan_model)?;
                let track = pick(text(&c.track_model, "track model")?, &self.track_model)?;
                self.ai_enabled = c.ai_enabled != 0;
                self.scan_model = scan;
                self.track_model = track;
                Ok(Effect::AiChanged)
            }
            ViewControlKind::Output => {
                let i = self.stream_named(text(&c.stream, "stream")?)?;
                if c.width < 640 || c.height < 480 {
                    return Err(Refusal::ignored(format!(
                        "{}x{} is below 640x480",
                        c.width, c.height
                    )));
                }
                let s = &mut self.streams[i];
                s.out_width = c.width.min(1920);
                s.out_height = c.height.min(1080);
                if c.layout_mode <= 6 {
                    s.layout_mode = c.layout_mode;
                }
                if c.overlay_mode <= 5 {
                    s.overlay_mode = c.overlay_mode;
                }
                Ok(Effect::Changed)
            }
            ViewControlKind::Capture => Ok(Effect::Capture {
                stream: self.stream_named(text(&c.stream, "stream")?)?,
                single_image: c.capture_image != 0,
                record: Some(c.record != 0),
            }),
            ViewControlKind::Detection => {
                let t = &mut self.tracker;
                self.detection_mode = c.detection_mode;
                if c.sorting_mode <= 2 {
                    t.sorting_mode = c.sorting_mode;
                }
                let ratio = |v: f64, old: &mut f32| {
                    if (0.0..0.99).contains(&v) {
                        *old = v as f32;
                    }
                };
                ratio(c.track_confidence, &mut t.track_confidence);
                ratio(c.scan_confidence, &mut t.scan_confidence);
                ratio(c.track_overlap, &mut t.track_overlap);
                ratio(c.scan_overlap, &mut t.scan_overlap);
                let score = |v: u8, old: &mut u8| {
                    if v != SCORE_KEEP {
                        *old = v;
                    }
                };
                score(c.creation_score, &mut t.creation_score);
                score(c.bonus_detection, &mut t.bonus_detection);
                score(c.bonus_redetection, &mut t.bonus_redetection);
                score(c.missed_detection_penalty, &mut t.missed_detection_penalty);
                score(
                    c.missed_redetection_penalty,
                    &mut t.missed_redetection_penalty,
                );
                Ok(Effect::Changed)
            }
            ViewControlKind::Targeting => {
                let stream = self.stream_named(text(&c.stream, "stream")?)?;
                let cam = Self::cam(c.cam)?;
                if TargetingMode::try_from(c.targeting_mode).is_err() {
                    return Err(Refusal::invalid(format!(
                        "targeting mode {} is not one of 0-3",
                        c.targeting_mode
                    )));
                }
                range("yaw", c.yaw_rad, -PI, PI)?;
                range("pitch", c.pitch_rad, -FRAC_PI_2, FRAC_PI_2)?;
                range("roll", c.roll_rad, -FRAC_PI_2, FRAC_PI_2)?;
                if c.lock_flags > LOCK_YAW | LOCK_PITCH | LOCK_ROLL {
                    return Err(Refusal::invalid(format!(
                        "lock flags {:#b} name an unknown axis",
                        c.lock_flags
                    )));
                }
                offsets(c)?;
                range("latitude", c.lat_deg, -90.0, 90.0)?;
                range("longitude", c.lon_deg, -180.0, 180.0)?;
                if c.lon_deg == 180.0 {
                    return Err(Refusal::invalid("longitude 180 is -180"));
                }
                range("altitude", c.alt_rel_m, -1000.0, 10000.0)?;
                Ok(Effect::Targeting {
                    stream,
                    cam,
                    targeting: Targeting {
                        mode: c.targeting_mode,
                        euler_delta: c.euler_delta != 0,
                        yaw: c.yaw_rad,
                        pitch: c.pitch_rad,
                        roll: c.roll_rad,
                        lock_flags: c.lock_flags,
                        x_offset: c.x_offset,
                        y_offset: c.y_offset,
                        latitude: c.lat_deg,
                        longitude: c.lon_deg,
                        altitude: c.alt_rel_m,
                    },
                })
            }
            ViewControlKind::Optics => {
                let stream = self.stream_named(text(&c.stream, "stream")?)?;
                let cam = Self::cam(c.cam)?;
                range("zoom", f64::from(c.zoom), ZOOM_MIN, ZOOM_MAX)?;
                range("fov", c.fov_rad, 0.0, PI)?;
                if CropMode::try_from(c.crop_mode).is_err() {
                    return Err(Refusal::invalid(format!(
                        "crop mode {} is not one of 0-2",
                        c.crop_mode
                    )));
                }
                Ok(Effect::Optics {
                    stream,
                    cam,
                    optics: Optics {
                        zoom: c.zoom,
                        fov: c.fov_rad,
                        crop_mode: c.crop_mode,
                    },
                })
            }
            ViewControlKind::SingleTarget => {
                let stream = self.stream_named(text(&c.stream, "stream")?)?;
                let cam = Self::cam(c.cam)?;
                let command = TrackCommand::try_from(c.track_command).map_err(|_| {
                    Refusal::invalid(format!("unknown track command {}", c.track_command))
                })?;
                let reference = ReferenceFrame::try_from(c.reference).map_err(|_| {
                    Refusal::invalid(format!("unknown reference frame {}", c.reference))
                })?;
                offsets(c)?;
                range("zoom", f64::from(c.track_zoom), 0.0, 10.0)?;
                range("yaw", c.yaw_rad, -PI, PI)?;
                range("pitch", c.pitch_rad, -FRAC_PI_2, FRAC_PI_2)?;
                let request = match command {
                    TrackCommand::Disable => SttRequest::Disable,
                    TrackCommand::Direction if reference == ReferenceFrame::Global => {
                        SttRequest::Global {
                            yaw: c.yaw_rad,
                            pitch: c.pitch_rad,
                        }
                    }
                    TrackCommand::Direction => SttRequest::ViewOffset {
                        x: c.x_offset,
                        y: c.y_offset,
                    },
                    TrackCommand::Detection => SttRequest::Detection(c.detection_id),
                    TrackCommand::Nudge => SttRequest::Nudge {
                        x: c.x_offset,
                        y: c.y_offset,
                    },
                    TrackCommand::NoOp => SttRequest::NoOp,
                };
                Ok(Effect::Stt {
                    stream,
                    cam,
                    request,
                    zoom_level: c.track_zoom,
                    rel_frame: reference.to_wire(),
                })
            }
            ViewControlKind::DirectionAt => {
                let stream = self.stream_named(text(&c.stream, "stream")?)?;
                let cam = Self::cam(c.cam)?;
                offsets(c)?;
                Ok(Effect::DirectionAt {
                    stream,
                    cam,
                    x: c.x_offset,
                    y: c.y_offset,
                })
            }
        }
    }
}

/// A name from another process: refused if it is not UTF-8.
fn text<'a, const N: usize>(s: &'a FixedStr<N>, what: &str) -> Result<&'a str, Refusal> {
    s.try_as_str()
        .ok_or_else(|| Refusal::invalid(format!("{what} is not UTF-8")))
}

/// `v` finite and within `min..=max`.
fn range(name: &str, v: f64, min: f64, max: f64) -> Result<(), Refusal> {
    if !v.is_finite() {
        return Err(Refusal::invalid(format!("{name} is not finite")));
    }
    if v < min || v > max {
        return Err(Refusal::invalid(format!(
            "{name} {v} is outside [{min}, {max}]"
        )));
    }
    Ok(())
}

/// The view offsets of `c`, each within −1..1.
fn offsets(c: &ViewControl) -> Result<(), Refusal> {
    range("x offset", c.x_offset, -1.0, 1.0)?;
    range("y offset", c.y_offset, -1.0, 1.0)
}

#[cfg(test)]
mod tests;
