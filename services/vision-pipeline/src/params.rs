//! The DigiView parameter state and every [`VisionControl`] → what to do, per the
//! document's SET behaviour (`digiview-vision.md`, FACTS.md). Pure: no bus, no
//! frames. Parameters that live in other modules' objects (virtual cameras, the
//! single-target tracker, captures) come back as an [`Effect`] the service applies;
//! what is kept here (AI, VIDEO_OUTPUT, DETECTION) is changed here.
//!
//! | parameter | SET here |
//! |---|---|
//! | AI | enabled; model names must be in [`MODELS`] (else Ignored); an empty name keeps the current model |
//! | VIDEO_OUTPUT | width/height clamped to 1920/1080, below 640/480 → Ignored; layout > 6, overlay > 5 unchanged; views, boxes and fps are computed, not set |
//! | CAPTURE | → [`Effect::Capture`] |
//! | DETECTION | sorting > 2 keeps; thresholds outside 0..0.99 keep; score bytes 255 keep |
//! | CAM_TARGETING, CAM_OPTICS_AND_CONTROL | range-checked, → [`Effect::Targeting`] / [`Effect::Optics`] |
//! | SINGLE_TARGET_TRACKING | range-checked, → [`Effect::Stt`] |
//! | SENSOR, CAM_DEPTH_ESTIMATION | Unsupported (disabled, as in DigiView) |
//! | SYSTEM_STATUS, MODEL, DETECTED_ROI, CAM_OFFSET | Invalid (not settable) |
//!
//! An unknown stream name or a camera outside 0..4 is Ignored (the document:
//! "the operation is ignored"); an undecodable payload is Invalid with the error.

use digiview_proto::{CamOpticsAndControl, CamTargeting, Param, ParamType, DATA_LEN, SCORE_KEEP};
use skymesh_ipc_types::{VisionControl, VisionControlKind, VisionResult, VISION_MAX_CAMS};

use crate::detect::MODELS;
use crate::geometry::GeoPosition;
use crate::track::TrackerParams;

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
        targeting: CamTargeting,
    },
    Optics {
        stream: usize,
        cam: u8,
        optics: CamOpticsAndControl,
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
            VisionControlKind::DigiViewSet => self.digiview_set(c.param, &c.data),
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

    /// A DigiView SET of parameter type `param` with payload `data`.
    pub fn digiview_set(&mut self, param: u8, data: &[u8; DATA_LEN]) -> Result<Effect, Refusal> {
        let ptype = ParamType::from_u8(param)
            .ok_or_else(|| Refusal::invalid(format!("unknown parameter type {param}")))?;
        match ptype {
            ParamType::SystemStatus
            | ParamType::Model
            | ParamType::DetectedRoi
            | ParamType::CamOffset => {
                return Err(Refusal::invalid(format!(
                    "{} is not settable",
                    ptype.name()
                )))
            }
            ParamType::Sensor | ParamType::CamDepthEstimation => {
                return Err(Refusal::unsupported(format!(
                    "{} is disabled, as in DigiView",
                    ptype.name()
                )))
            }
            _ => {}
        }
        let p = Param::decode(ptype, data).map_err(|e| Refusal::invalid(e.to_string()))?;
        match p {
            Param::Ai(a) => {
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
                let scan = pick(a.scan_model.as_str(), &self.scan_model)?;
                let track = pick(a.track_model.as_str(), &self.track_model)?;
                self.ai_enabled = a.enabled;
                self.scan_model = scan;
                self.track_model = track;
                Ok(Effect::AiChanged)
            }
            Param::VideoOutput(v) => {
                let i = self.stream_named(v.stream.as_str())?;
                if v.width < 640 || v.height < 480 {
                    return Err(Refusal::ignored(format!(
                        "{}x{} is below 640x480",
                        v.width, v.height
                    )));
                }
                let s = &mut self.streams[i];
                s.out_width = v.width.min(1920);
                s.out_height = v.height.min(1080);
                if v.layout_mode <= 6 {
                    s.layout_mode = v.layout_mode;
                }
                if v.overlay_mode <= 5 {
                    s.overlay_mode = v.overlay_mode;
                }
                Ok(Effect::Changed)
            }
            Param::Capture(c) => Ok(Effect::Capture {
                stream: self.stream_named(c.stream.as_str())?,
                single_image: c.single_image,
                record: Some(c.record_video),
            }),
            Param::Detection(d) => {
                let t = &mut self.tracker;
                self.detection_mode = d.mode;
                if d.sorting_mode <= 2 {
                    t.sorting_mode = d.sorting_mode;
                }
                let ratio = |v: f64, old: &mut f32| {
                    if (0.0..0.99).contains(&v) {
                        *old = v as f32;
                    }
                };
                ratio(d.track_confidence, &mut t.track_confidence);
                ratio(d.scan_confidence, &mut t.scan_confidence);
                ratio(d.track_overlap, &mut t.track_overlap);
                ratio(d.scan_overlap, &mut t.scan_overlap);
                let score = |v: u8, old: &mut u8| {
                    if v != SCORE_KEEP {
                        *old = v;
                    }
                };
                score(d.creation_score, &mut t.creation_score);
                score(d.bonus_detection, &mut t.bonus_detection);
                score(d.bonus_redetection, &mut t.bonus_redetection);
                score(d.missed_detection_penalty, &mut t.missed_detection_penalty);
                score(
                    d.missed_redetection_penalty,
                    &mut t.missed_redetection_penalty,
                );
                Ok(Effect::Changed)
            }
            Param::CamTargeting(t) => {
                let stream = self.stream_named(t.stream.as_str())?;
                let cam = Self::cam(t.cam)?;
                p.validate().map_err(|e| Refusal::invalid(e.to_string()))?;
                Ok(Effect::Targeting {
                    stream,
                    cam,
                    targeting: t,
                })
            }
            Param::CamOpticsAndControl(o) => {
                let stream = self.stream_named(o.stream.as_str())?;
                let cam = Self::cam(o.cam)?;
                p.validate().map_err(|e| Refusal::invalid(e.to_string()))?;
                Ok(Effect::Optics {
                    stream,
                    cam,
                    optics: o,
                })
            }
            Param::SingleTargetTracking(s) => {
                let stream = self.stream_named(s.stream.as_str())?;
                let cam = Self::cam(s.cam)?;
                p.validate().map_err(|e| Refusal::invalid(e.to_string()))?;
                let request = match s.command {
                    0 => SttRequest::Disable,
                    1 if s.rel_frame == 0 => SttRequest::Global {
                        yaw: s.yaw_global,
                        pitch: s.pitch_global,
                    },
                    1 => SttRequest::ViewOffset {
                        x: s.x_offset,
                        y: s.y_offset,
                    },
                    2 => SttRequest::Detection(s.detection_id),
                    3 => SttRequest::Nudge {
                        x: s.x_offset,
                        y: s.y_offset,
                    },
                    _ => SttRequest::NoOp,
                };
                Ok(Effect::Stt {
                    stream,
                    cam,
                    request,
                    zoom_level: s.zoom,
                    rel_frame: s.rel_frame,
                })
            }
            // Refused above.
            Param::SystemStatus(_)
            | Param::Model(_)
            | Param::DetectedRoi(_)
            | Param::CamOffset(_)
            | Param::Sensor(_)
            | Param::CamDepthEstimation(_) => Err(Refusal::invalid(format!(
                "{} is not settable",
                ptype.name()
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use digiview_proto::{
        Ai, BoundingBox, Capture, Detection, ModelName, SingleTargetTracking, StreamName,
        VideoOutput,
    };
    use skymesh_ipc_types::VisionOrigin;

    fn params() -> Params {
        Params {
            ai_enabled: true,
            scan_model: MODELS[0].into(),
            track_model: MODELS[0].into(),
            detection_mode: 0,
            tracker: TrackerParams::default(),
            streams: vec![
                StreamParams {
                    name: "main".into(),
                    out_width: 1280,
                    out_height: 720,
                    layout_mode: 0,
                    overlay_mode: 2,
                },
                StreamParams {
                    name: "aux".into(),
                    out_width: 640,
                    out_height: 480,
                    layout_mode: 4,
                    overlay_mode: 0,
                },
            ],
        }
    }

    fn set(p: &mut Params, param: &Param) -> Result<Effect, Refusal> {
        let (t, data) = param.encode();
        let c = VisionControl {
            request_id: 7,
            kind: VisionControlKind::DigiViewSet.to_wire(),
            origin: VisionOrigin::DigiView.to_wire(),
            param: t as u8,
            data,
            ..VisionControl::default()
        };
        p.apply(&c)
    }

    fn stream(name: &str) -> StreamName {
        StreamName::new(name).unwrap()
    }

    fn video(name: &str, w: u16, h: u16, layout: u8, overlay: u8) -> Param {
        Param::VideoOutput(VideoOutput {
            stream: stream(name),
            width: w,
            height: h,
            layout_mode: layout,
            overlay_mode: overlay,
            views: vec![BoundingBox::default()],
            ..VideoOutput::default()
        })
    }

    #[test]
    fn video_output_clamps_ignores_and_keeps_per_the_document() {
        let mut p = params();
        assert_eq!(
            set(&mut p, &video("main", 1920, 1080, 4, 3)),
            Ok(Effect::Changed)
        );
        let s = &p.streams[0];
        assert_eq!(
            (s.out_width, s.out_height, s.layout_mode, s.overlay_mode),
            (1920, 1080, 4, 3)
        );
        // Above the maximum: clamped; out-of-range modes leave the setting unchanged.
        assert_eq!(
            set(&mut p, &video("main", 4000, 2000, 9, 9)),
            Ok(Effect::Changed)
        );
        let s = &p.streams[0];
        assert_eq!(
            (s.out_width, s.out_height, s.layout_mode, s.overlay_mode),
            (1920, 1080, 4, 3)
        );
        // Below the minimum: the whole operation is ignored.
        let before = p.clone();
        let e = set(&mut p, &video("main", 320, 720, 1, 1)).unwrap_err();
        assert_eq!(e.result, VisionResult::Ignored);
        assert_eq!(p, before);
        // Unknown stream: ignored; the other stream is addressed by name.
        let e = set(&mut p, &video("nope", 800, 600, 1, 1)).unwrap_err();
        assert_eq!(e.result, VisionResult::Ignored);
        assert!(e.message.contains("nope"), "{}", e.message);
        set(&mut p, &video("aux", 800, 600, 6, 5)).unwrap();
        assert_eq!((p.streams[1].out_width, p.streams[1].layout_mode), (800, 6));
        assert_eq!(p.streams[0].out_width, 1920);
    }

    #[test]
    fn ai_models_must_exist_and_empty_names_keep() {
        let mut p = params();
        let ai = |enabled, scan: &str, track: &str| {
            Param::Ai(Ai {
                enabled,
                scan_model: ModelName::new(scan).unwrap(),
                track_model: ModelName::new(track).unwrap(),
            })
        };
        assert_eq!(
            set(&mut p, &ai(false, "motion-bg", "")),
            Ok(Effect::AiChanged)
        );
        assert!(!p.ai_enabled);
        assert_eq!(
            (p.scan_model.as_str(), p.track_model.as_str()),
            ("motion-bg", MODELS[0])
        );
        let before = p.clone();
        let e = set(&mut p, &ai(true, "yolo-v9", "motion-bg")).unwrap_err();
        assert_eq!(e.result, VisionResult::Ignored);
        assert!(e.message.contains("yolo-v9"));
        assert_eq!(p, before, "nothing changes on an unknown model");
    }

    #[test]
    fn detection_keeps_out_of_range_values_and_score_255() {
        let mut p = params();
        let d = Detection {
            mode: 3,
            sorting_mode: 2,
            track_confidence: 0.6,
            scan_confidence: 0.995,
            track_overlap: 0.2,
            scan_overlap: 0.4,
            creation_score: 100,
            bonus_detection: SCORE_KEEP,
            bonus_redetection: 5,
            missed_detection_penalty: SCORE_KEEP,
            missed_redetection_penalty: 0,
        };
        assert_eq!(set(&mut p, &Param::Detection(d)), Ok(Effect::Changed));
        let t = p.tracker;
        let def = TrackerParams::default();
        assert_eq!(p.detection_mode, 3);
        assert_eq!(t.sorting_mode, 2);
        assert!((t.track_confidence - 0.6).abs() < 0.005);
        assert_eq!(
            t.scan_confidence, def.scan_confidence,
            "0.995 is out of range"
        );
        assert!((t.track_overlap - 0.2).abs() < 0.005);
        assert_eq!(t.creation_score, 100);
        assert_eq!(t.bonus_detection, def.bonus_detection);
        assert_eq!(t.bonus_redetection, 5);
        assert_eq!(t.missed_detection_penalty, def.missed_detection_penalty);
        assert_eq!(t.missed_redetection_penalty, 0);
        set(
            &mut p,
            &Param::Detection(Detection {
                sorting_mode: 3,
                ..d
            }),
        )
        .unwrap();
        assert_eq!(
            p.tracker.sorting_mode, 2,
            "sorting mode 3 leaves it unchanged"
        );
    }

    #[test]
    fn capture_names_the_stream() {
        let mut p = params();
        let c = |name: &str, single_image, record_video| {
            Param::Capture(Capture {
                stream: stream(name),
                single_image,
                record_video,
                ..Capture::default()
            })
        };
        assert_eq!(
            set(&mut p, &c("aux", true, false)),
            Ok(Effect::Capture {
                stream: 1,
                single_image: true,
                record: Some(false)
            })
        );
        assert_eq!(
            set(&mut p, &c("main", false, true)),
            Ok(Effect::Capture {
                stream: 0,
                single_image: false,
                record: Some(true)
            })
        );
        assert_eq!(
            set(&mut p, &c("x", true, true)).unwrap_err().result,
            VisionResult::Ignored
        );
    }

    #[test]
    fn cameras_are_checked_and_ranges_validated() {
        let mut p = params();
        let t = CamTargeting {
            stream: stream("main"),
            cam: 2,
            mode: 1,
            latitude: 47.0,
            longitude: 8.0,
            altitude: -50.0,
            ..CamTargeting::default()
        };
        match set(&mut p, &Param::CamTargeting(t)) {
            Ok(Effect::Targeting {
                stream: 0,
                cam: 2,
                targeting,
            }) => assert_eq!(targeting.mode, 1),
            other => panic!("{other:?}"),
        }
        let e = set(&mut p, &Param::CamTargeting(CamTargeting { cam: 4, ..t })).unwrap_err();
        assert_eq!(e.result, VisionResult::Ignored);
        let e = set(
            &mut p,
            &Param::CamTargeting(CamTargeting {
                stream: stream("zz"),
                ..t
            }),
        )
        .unwrap_err();
        assert_eq!(e.result, VisionResult::Ignored);
        let e = set(
            &mut p,
            &Param::CamTargeting(CamTargeting { pitch: 2.0, ..t }),
        )
        .unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid);
        assert!(e.message.contains("pitch"), "{}", e.message);
        let o = CamOpticsAndControl {
            stream: stream("aux"),
            cam: 1,
            zoom: 20,
            fov: 1.0,
            crop_mode: 2,
        };
        assert_eq!(
            set(&mut p, &Param::CamOpticsAndControl(o)),
            Ok(Effect::Optics {
                stream: 1,
                cam: 1,
                optics: o
            })
        );
        let e = set(
            &mut p,
            &Param::CamOpticsAndControl(CamOpticsAndControl { fov: 4.0, ..o }),
        )
        .unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid);
    }

    #[test]
    fn single_target_commands_resolve() {
        let mut p = params();
        let s = SingleTargetTracking {
            command: 1,
            stream: stream("main"),
            cam: 0,
            // Exact in the wire's fixed point (× 32767).
            x_offset: 1.0,
            y_offset: -1.0,
            detection_id: 9,
            zoom: 3,
            yaw_global: 1.0,
            pitch_global: -0.5,
            rel_frame: 2,
            ..SingleTargetTracking::default()
        };
        let req =
            |p: &mut Params, s: SingleTargetTracking| match set(p, &Param::SingleTargetTracking(s))
            {
                Ok(Effect::Stt {
                    request,
                    zoom_level,
                    ..
                }) => {
                    assert_eq!(zoom_level, s.zoom);
                    request
                }
                other => panic!("{other:?}"),
            };
        assert_eq!(req(&mut p, s), SttRequest::ViewOffset { x: 1.0, y: -1.0 });
        assert_eq!(
            req(&mut p, SingleTargetTracking { rel_frame: 0, ..s }),
            SttRequest::Global {
                yaw: 1.0,
                pitch: -0.5
            }
        );
        assert_eq!(
            req(&mut p, SingleTargetTracking { command: 2, ..s }),
            SttRequest::Detection(9)
        );
        assert_eq!(
            req(&mut p, SingleTargetTracking { command: 3, ..s }),
            SttRequest::Nudge { x: 1.0, y: -1.0 }
        );
        assert_eq!(
            req(&mut p, SingleTargetTracking { command: 0, ..s }),
            SttRequest::Disable
        );
        assert_eq!(
            req(&mut p, SingleTargetTracking { command: 4, ..s }),
            SttRequest::NoOp
        );
        let e = set(
            &mut p,
            &Param::SingleTargetTracking(SingleTargetTracking { zoom: 11, ..s }),
        )
        .unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid);
    }

    #[test]
    fn unsettable_unsupported_and_garbage() {
        let mut p = params();
        let raw = |p: &mut Params, param: u8, data: [u8; DATA_LEN]| {
            p.apply(&VisionControl {
                kind: VisionControlKind::DigiViewSet.to_wire(),
                param,
                data,
                ..VisionControl::default()
            })
        };
        for t in [
            ParamType::SystemStatus,
            ParamType::Model,
            ParamType::DetectedRoi,
            ParamType::CamOffset,
        ] {
            let e = raw(&mut p, t as u8, [0; DATA_LEN]).unwrap_err();
            assert_eq!(e.result, VisionResult::Invalid, "{t:?}");
            assert!(e.message.contains("not settable"));
        }
        for t in [ParamType::Sensor, ParamType::CamDepthEstimation] {
            let e = raw(&mut p, t as u8, [0; DATA_LEN]).unwrap_err();
            assert_eq!(e.result, VisionResult::Unsupported, "{t:?}");
        }
        assert_eq!(
            raw(&mut p, 99, [0; DATA_LEN]).unwrap_err().result,
            VisionResult::Invalid
        );
        // A bool byte of 7 in AI cannot be decoded.
        let mut data = [0u8; DATA_LEN];
        data[0] = 7;
        let e = raw(&mut p, ParamType::Ai as u8, data).unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid);
        // Garbage everywhere: never a panic, always an answer.
        for t in 0..=255u8 {
            let _ = raw(&mut p, t, [0xff; DATA_LEN]);
        }
        let e = p
            .apply(&VisionControl {
                kind: 200,
                ..VisionControl::default()
            })
            .unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid);
    }

    #[test]
    fn gimbal_roi_zoom_and_capture_controls() {
        let mut p = params();
        let c = |kind: VisionControlKind| VisionControl {
            kind: kind.to_wire(),
            origin: VisionOrigin::GimbalV2.to_wire(),
            stream: 0,
            cam: 1,
            ..VisionControl::default()
        };
        let g = VisionControl {
            yaw_rad: 0.5,
            gimbal_flags: GIMBAL_YAW_IN_EARTH_FRAME,
            ..c(VisionControlKind::GimbalAttitude)
        };
        assert_eq!(
            p.apply(&g),
            Ok(Effect::Gimbal {
                stream: 0,
                cam: 1,
                yaw: Some(0.5),
                pitch: None,
                yaw_rate: None,
                pitch_rate: None,
                yaw_global: true
            })
        );
        // Nothing given, an infinite angle, a camera out of range, an unknown stream.
        assert_eq!(
            p.apply(&c(VisionControlKind::GimbalAttitude))
                .unwrap_err()
                .result,
            VisionResult::Invalid
        );
        let inf = VisionControl {
            pitch_rad: f32::INFINITY,
            ..g
        };
        assert_eq!(p.apply(&inf).unwrap_err().result, VisionResult::Invalid);
        assert_eq!(
            p.apply(&VisionControl { cam: 255, ..g })
                .unwrap_err()
                .result,
            VisionResult::Ignored
        );
        assert_eq!(
            p.apply(&VisionControl { stream: 2, ..g })
                .unwrap_err()
                .result,
            VisionResult::Ignored
        );

        let roi = VisionControl {
            cam: ALL_CAMS,
            lat_deg: 47.0,
            lon_deg: 8.0,
            alt_msl_m: 500.0,
            ..c(VisionControlKind::RoiLocation)
        };
        assert!(matches!(
            p.apply(&roi),
            Ok(Effect::Roi {
                cams: Cams::All,
                ..
            })
        ));
        let nan = VisionControl {
            lat_deg: f64::NAN,
            ..roi
        };
        assert_eq!(p.apply(&nan).unwrap_err().result, VisionResult::Invalid);
        assert_eq!(
            p.apply(&c(VisionControlKind::RoiNone)),
            Ok(Effect::RoiNone {
                stream: 0,
                cams: Cams::One(1)
            })
        );
        let z = VisionControl {
            zoom_mode: 2,
            value: 50.0,
            ..c(VisionControlKind::Zoom)
        };
        assert!(matches!(p.apply(&z), Ok(Effect::Zoom { mode: 2, .. })));
        let znan = VisionControl {
            value: f32::NAN,
            ..z
        };
        assert_eq!(p.apply(&znan).unwrap_err().result, VisionResult::Invalid);
        assert_eq!(
            p.apply(&c(VisionControlKind::RecordStop)),
            Ok(Effect::Capture {
                stream: 0,
                single_image: false,
                record: Some(false)
            })
        );
        assert_eq!(
            p.apply(&c(VisionControlKind::ImageCapture)),
            Ok(Effect::Capture {
                stream: 0,
                single_image: true,
                record: None
            })
        );
        assert_eq!(Cams::All.indices(), 0..4);
        assert_eq!(Cams::One(2).indices(), 2..3);
    }
}
