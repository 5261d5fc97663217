//! GET answers built from the newest `VisionState` (pure).
//!
//! Choices where DigiView is silent or would ignore the request (skymesh always
//! answers, so the client learns why nothing came):
//! - an unknown stream or camera (not configured, or `cam_id` not shown by the
//!   stream's layout) → DATA_ERROR, where DigiView ignores the request;
//! - SYSTEM_STATUS carries temperature 0 while the pipeline could not read one;
//! - MODEL with no model listed, DETECTED_ROI matching no detection, CAM_OFFSET whose
//!   view has no direction yet (no frame rendered) → DATA_ERROR;
//! - CAM_OFFSET is the one GET the state cannot answer (the client chooses the
//!   point): once its stream, camera and offsets check out it becomes the pipeline's
//!   `DirectionAt` question ([`Answer::Ask`]), answered by the session;
//! - DETECTED_ROI: index 0–253 is the position in the pipeline's sorted detection
//!   list; 254 every detection shown in the overlay, 255 every known one; each reply
//!   carries its position among the replies sent (`index`) and how many were sent
//!   (`total`). Relative angles are in the configured `roi_rel_frame`; latitude,
//!   longitude, altitude and distance are real when the pipeline intersected the
//!   ground (`geo_valid`), else 0 as in DigiView;
//! - CAPTURE's `cap_single_image` reads false (a capture is an event, not a state);
//! - SINGLE_TARGET_TRACKING's `x/y_offset` read 0 (the tracker stores a direction,
//!   not the offset it was given) and its relative angles are in the frame of its
//!   last command's `rel_frame_of_reference`.

use digiview_proto::{
    Ai, BoundingBox, CamOffset, CamOpticsAndControl, CamTargeting, Capture, DetectedRoi, Detection,
    FixedName, Frame, GetRequest, Model, Param, ParamType, RoiSelector, SingleTargetTracking,
    StreamName, SystemStatus, VideoOutput, MAX_VIEWS,
};
use skymesh_ipc_types::{
    VirtualCamState, VisionDetection, VisionState, VisionStreamState, VISION_MAX_CAMS,
};

use crate::refusal::Refusal;

/// How a GET is answered.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// These CURRENT payloads, now.
    Now(Vec<Param>),
    /// CAM_OFFSET: ask the pipeline where this point of the view looks; its reply
    /// completes the payload.
    Ask(CamOffset),
}

/// Why a GET gets no CURRENT reply: the reason (its reply type is
/// [`Refusal::reply_type`]) and a detail for the log.
#[derive(Debug, Clone, PartialEq)]
pub struct NoAnswer {
    pub reason: Refusal,
    pub detail: String,
}

impl NoAnswer {
    fn new(reason: Refusal, detail: impl Into<String>) -> NoAnswer {
        NoAnswer {
            reason,
            detail: detail.into(),
        }
    }
}

/// The CURRENT payloads that answer a GET of `frame.param_type` (MODEL and
/// DETECTED_ROI may have several; every other type exactly one), or the question
/// that answers it.
pub fn answer_get(
    state: &VisionState,
    frame: &Frame,
    roi_rel_frame: u8,
) -> Result<Answer, NoAnswer> {
    let pt = frame.param_type;
    if pt == ParamType::CamOffset {
        return cam_offset(state, frame);
    }
    Ok(Answer::Now(match pt {
        ParamType::SystemStatus => vec![Param::SystemStatus(SystemStatus {
            status: state.status,
            error: 0,
            temperature: if state.temperature_valid != 0 {
                f64::from(state.temperature_c)
            } else {
                0.0
            },
        })],
        ParamType::Ai => vec![Param::Ai(Ai {
            enabled: state.ai_enabled != 0,
            track_model: name(state.track_model.as_str()),
            scan_model: name(state.scan_model.as_str()),
        })],
        ParamType::Model => {
            let models: Vec<Param> = state
                .models()
                .iter()
                .map(|m| {
                    Param::Model(Model {
                        name: name(m.as_str()),
                    })
                })
                .collect();
            if models.is_empty() {
                return Err(NoAnswer::new(
                    Refusal::NotFound,
                    "the pipeline lists no model",
                ));
            }
            models
        }
        ParamType::Detection => vec![Param::Detection(Detection {
            mode: state.detection_mode,
            sorting_mode: state.sorting_mode,
            track_confidence: f64::from(state.track_confidence),
            scan_confidence: f64::from(state.scan_confidence),
            track_overlap: f64::from(state.track_overlap),
            scan_overlap: f64::from(state.scan_overlap),
            creation_score: state.creation_score,
            bonus_detection: state.bonus_detection,
            bonus_redetection: state.bonus_redetection,
            missed_detection_penalty: state.missed_detection_penalty,
            missed_redetection_penalty: state.missed_redetection_penalty,
        })],
        ParamType::DetectedRoi => {
            detected_roi(state, RoiSelector::decode(&frame.data), roi_rel_frame)?
        }
        ParamType::VideoOutput => {
            let (stream_name, s) = stream(state, frame)?;
            let n = usize::from(s.num_views).min(MAX_VIEWS);
            vec![Param::VideoOutput(VideoOutput {
                stream: stream_name,
                width: s.out_width,
                height: s.out_height,
                fps: 0,
                layout_mode: s.layout_mode,
                layout_views: n as u8,
                overlay_mode: s.overlay_mode,
                views: s.cams[..n].iter().map(|c| bbox(c.view_rect)).collect(),
                overlay_box: bbox(s.overlay_box),
                single_detection_size: s.single_detection_size,
            })]
        }
        ParamType::Capture => {
            let (stream_name, s) = stream(state, frame)?;
            vec![Param::Capture(Capture {
                stream: stream_name,
                single_image: false,
                record_video: s.recording != 0,
                images_captured: s.images_captured,
                videos_captured: s.videos_captured,
            })]
        }
        ParamType::CamTargeting => {
            let (stream_name, _, cam_id, c) = cam(state, frame)?;
            vec![Param::CamTargeting(CamTargeting {
                stream: stream_name,
                cam: cam_id,
                mode: c.targeting_mode,
                euler_delta: c.euler_delta != 0,
                yaw: f64::from(c.yaw_rad),
                pitch: f64::from(c.pitch_rad),
                roll: f64::from(c.roll_rad),
                lock_flags: c.lock_flags,
                x_offset: f64::from(c.x_offset),
                y_offset: f64::from(c.y_offset),
                latitude: c.target_lat_deg,
                longitude: c.target_lon_deg,
                altitude: f64::from(c.target_alt_rel_m),
            })]
        }
        ParamType::CamOpticsAndControl => {
            let (stream_name, _, cam_id, c) = cam(state, frame)?;
            vec![Param::CamOpticsAndControl(CamOpticsAndControl {
                stream: stream_name,
                cam: cam_id,
                zoom: c.zoom,
                fov: f64::from(c.fov_rad),
                crop_mode: c.crop_mode,
            })]
        }
        // Answered above.
        ParamType::CamOffset => Vec::new(),
        ParamType::SingleTargetTracking => {
            let (stream_name, s) = stream(state, frame)?;
            let t = &s.stt;
            let (yaw_rel, pitch_rel) = match t.rel_frame {
                0 => (t.yaw_global_rad, t.pitch_global_rad),
                1 => (t.yaw_heading_rad, t.pitch_heading_rad),
                _ => (t.yaw_camera_rad, t.pitch_camera_rad),
            };
            vec![Param::SingleTargetTracking(SingleTargetTracking {
                command: t.mode,
                stream: stream_name,
                cam: t.cam,
                x_offset: 0.0,
                y_offset: 0.0,
                detection_id: t.detection_id,
                zoom: t.zoom_level,
                confidence: f64::from(t.confidence),
                yaw_global: f64::from(t.yaw_global_rad),
                pitch_global: f64::from(t.pitch_global_rad),
                rel_frame: t.rel_frame,
                yaw_rel: f64::from(yaw_rel),
                pitch_rel: f64::from(pitch_rel),
            })]
        }
        ParamType::Sensor | ParamType::CamDepthEstimation => {
            return Err(NoAnswer::new(
                Refusal::Disabled,
                format!("{} is disabled as in DigiView", pt.name()),
            ))
        }
    }))
}

/// A bus name as a wire name (bus names are at most as long; the empty name if not).
fn name<const N: usize>(s: &str) -> FixedName<N> {
    FixedName::new(s).unwrap_or_default()
}

fn bbox(r: [u16; 4]) -> BoundingBox {
    BoundingBox {
        x: r[0],
        y: r[1],
        w: r[2],
        h: r[3],
    }
}

/// The stream a GET names (`data[0..8]`).
fn stream<'a>(
    state: &'a VisionState,
    frame: &Frame,
) -> Result<(StreamName, &'a VisionStreamState), NoAnswer> {
    let req = GetRequest::decode(frame.param_type, &frame.data)
        .map_err(|e| NoAnswer::new(Refusal::BadPayload, e.to_string()))?;
    let s = state
        .stream_index(req.stream.as_str())
        .map(|i| &state.streams[i])
        .filter(|s| s.configured != 0)
        .ok_or_else(|| {
            NoAnswer::new(
                Refusal::NoSuchStream,
                format!("{}: no stream `{}`", frame.param_type.name(), req.stream),
            )
        })?;
    Ok((req.stream, s))
}

/// The stream and virtual camera a GET names (`data[0..8]`, `data[8]`).
fn cam<'a>(
    state: &'a VisionState,
    frame: &Frame,
) -> Result<(StreamName, &'a VisionStreamState, u8, &'a VirtualCamState), NoAnswer> {
    let (stream_name, s) = stream(state, frame)?;
    let id = frame.data[8];
    match s.cams.get(usize::from(id)) {
        Some(c) if usize::from(id) < VISION_MAX_CAMS && c.active != 0 => {
            Ok((stream_name, s, id, c))
        }
        _ => Err(NoAnswer::new(
            Refusal::NoSuchCam,
            format!(
                "{}: stream `{stream_name}` shows no camera {id} (layout has {} views)",
                frame.param_type.name(),
                s.num_views
            ),
        )),
    }
}

/// CAM_OFFSET: the GET carries the whole payload; x/y are read from it. The
/// direction is the pipeline's to compute: the answer is a question.
fn cam_offset(state: &VisionState, frame: &Frame) -> Result<Answer, NoAnswer> {
    let (stream_name, _, cam_id, _) = cam(state, frame)?;
    let Ok(Param::CamOffset(req)) = Param::decode(ParamType::CamOffset, &frame.data) else {
        return Err(NoAnswer::new(
            Refusal::BadPayload,
            "CAM_OFFSET: payload does not decode",
        ));
    };
    for (field, v) in [("x", req.x), ("y", req.y)] {
        if !(-1.0..=1.0).contains(&v) {
            return Err(NoAnswer::new(
                Refusal::BadPayload,
                format!("CAM_OFFSET.{field}: {v} is outside [-1, 1]"),
            ));
        }
    }
    let request = CamOffset {
        stream: stream_name,
        cam: cam_id,
        x: req.x,
        y: req.y,
        ..CamOffset::default()
    };
    Ok(Answer::Ask(request))
}

fn detected_roi(
    state: &VisionState,
    selector: RoiSelector,
    rel_frame: u8,
) -> Result<Vec<Param>, NoAnswer> {
    let all = state.detections();
    let chosen: Vec<&VisionDetection> = match selector {
        RoiSelector::One(i) => all.get(usize::from(i)).into_iter().collect(),
        RoiSelector::AllVisible => all.iter().filter(|d| d.overlay_slot != 255).collect(),
        RoiSelector::AllKnown => all.iter().collect(),
    };
    if chosen.is_empty() {
        return Err(NoAnswer::new(
            Refusal::NotFound,
            format!(
                "DETECTED_ROI index {}: no such detection ({} known)",
                selector.index(),
                all.len()
            ),
        ));
    }
    let total = chosen.len() as u8;
    Ok(chosen
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let (yaw_rel, pitch_rel) = match rel_frame {
                0 => (d.yaw_global_rad, d.pitch_global_rad),
                1 => (d.yaw_heading_rad, d.pitch_heading_rad),
                _ => (d.yaw_camera_rad, d.pitch_camera_rad),
            };
            let geo = d.geo_valid != 0;
            let or0 = |v: f64| if geo { v } else { 0.0 };
            Param::DetectedRoi(DetectedRoi {
                index: match selector {
                    RoiSelector::One(n) => n,
                    _ => i as u8,
                },
                score: d.score,
                total,
                object_type: d.object_type,
                yaw_global: f64::from(d.yaw_global_rad),
                pitch_global: f64::from(d.pitch_global_rad),
                rel_frame,
                yaw_rel: f64::from(yaw_rel),
                pitch_rel: f64::from(pitch_rel),
                latitude: or0(d.lat_deg),
                longitude: or0(d.lon_deg),
                altitude: or0(f64::from(d.alt_msl_m)),
                distance: or0(f64::from(d.distance_m)),
            })
        })
        .collect())
}
