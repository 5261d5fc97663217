//! The pipeline's processing state ([`Pipeline`]: parameters, per-stream detectors,
//! trackers, virtual cameras, renderer, capturer) and how it applies controls.

use std::time::Instant;

use nalgebra::UnitQuaternion;
use skymesh_ipc_types::{
    FixedStr, VehicleState, ViewControl, ViewControlKind, ViewReply, VisionControl,
    VisionControlKind, VisionDetection, VisionReply, VisionResult, VISION_MAX_CAMS,
};
use skymesh_runtime::WarnLimiter;

use crate::capture::Capturer;
use crate::config::Settings;
use crate::detect::Detector;
use crate::geometry::{CameraModel, CameraPose, Direction, Offset};
use crate::layout::{self, Layout};
use crate::metrics::Metrics;
use crate::params::{Effect, Params, Refusal, StreamParams, SttRequest};
use crate::render::Renderer;
use crate::stt::{SingleTargetTracker, SttCommand, SttError};
use crate::thermal::Thermometer;
use crate::track::Tracker;
use crate::views::{self, ViewError, VirtualCamera};

/// One stream's processing state.
#[derive(Debug)]
pub(super) struct StreamRt {
    pub(super) name: String,
    pub(super) scan: Option<Detector>,
    pub(super) track: Option<Detector>,
    pub(super) tracker: Tracker,
    pub(super) stt: SingleTargetTracker,
    pub(super) cams: Vec<VirtualCamera>,
    /// The orientation each camera was last rendered with.
    pub(super) aims: [Option<UnitQuaternion<f64>>; VISION_MAX_CAMS],
    pub(super) renderer: Renderer,
    pub(super) capturer: Option<Capturer>,
    pub(super) pending_image: bool,
    pub(super) detections: Vec<VisionDetection>,
    pub(super) layout: Layout,
    pub(super) last_frame: Option<Instant>,
    pub(super) last_good: Option<Instant>,
    pub(super) bad_since: Option<Instant>,
    pub(super) frames_processed: u64,
    pub(super) frames_dropped: u64,
    pub(super) last_seq: u64,
    pub(super) last_capture_ns: u64,
    pub(super) last_processed_ns: u64,
    pub(super) source: (u32, u32),
    pub(super) heading: f32,
    pub(super) pose: Option<CameraPose>,
}

/// Everything but the bus.
#[derive(Debug)]
pub(super) struct Pipeline {
    pub(super) settings: Settings,
    pub(super) params: Params,
    pub(super) streams: Vec<StreamRt>,
    pub(super) vehicle: Option<VehicleState>,
    pub(super) thermometer: Thermometer,
    pub(super) temperature: Option<f32>,
    pub(super) temperature_read: Option<Instant>,
    pub(super) last_state: Instant,
    pub(super) metrics: Metrics,
    pub(super) warn: WarnLimiter<&'static str>,
}

pub(super) fn detectors(p: &Params, s: &Settings) -> (Option<Detector>, Option<Detector>) {
    if !p.ai_enabled {
        return (None, None);
    }
    let make = |model: &str| match Detector::new(model, s.detector) {
        Ok(d) => Some(d),
        Err(e) => {
            tracing::error!(model, error = %e, "detector not available");
            None
        }
    };
    (make(&p.scan_model), make(&p.track_model))
}

impl Pipeline {
    pub(super) fn new(settings: Settings, metrics: Metrics) -> Pipeline {
        let params = Params {
            ai_enabled: settings.ai_enabled,
            scan_model: settings.scan_model.clone(),
            track_model: settings.track_model.clone(),
            detection_mode: 0,
            tracker: settings.tracker,
            streams: settings
                .streams
                .iter()
                .map(|s| StreamParams {
                    name: s.name.clone(),
                    out_width: s.width,
                    out_height: s.height,
                    layout_mode: s.layout,
                    overlay_mode: s.overlay,
                })
                .collect(),
        };
        let streams = settings
            .streams
            .iter()
            .map(|s| {
                let (scan, track) = detectors(&params, &settings);
                StreamRt {
                    name: s.name.clone(),
                    scan,
                    track,
                    tracker: Tracker::new(params.tracker),
                    stt: SingleTargetTracker::default(),
                    cams: (0..VISION_MAX_CAMS)
                        .map(|_| VirtualCamera::new(s.fov_rad))
                        .collect(),
                    aims: [None; VISION_MAX_CAMS],
                    renderer: Renderer::default(),
                    capturer: None,
                    pending_image: false,
                    detections: Vec::new(),
                    layout: layout::compute(s.layout, s.overlay, s.width, s.height),
                    last_frame: None,
                    last_good: None,
                    bad_since: None,
                    frames_processed: 0,
                    frames_dropped: 0,
                    last_seq: 0,
                    last_capture_ns: 0,
                    last_processed_ns: 0,
                    source: (0, 0),
                    heading: 0.0,
                    pose: None,
                }
            })
            .collect();
        Pipeline {
            thermometer: Thermometer::new(&settings.thermal),
            settings,
            params,
            streams,
            vehicle: None,
            temperature: None,
            temperature_read: None,
            last_state: Instant::now(),
            metrics,
            warn: WarnLimiter::default(),
        }
    }

    // ---------------------------------------------------------------- controls

    /// Applies one control; returns its reply (published once the state that
    /// contains the change is).
    pub(super) fn control(&mut self, c: &VisionControl) -> VisionReply {
        let outcome = self.params.apply(c).and_then(|effect| self.effect(effect));
        let (result, message) = self.answered(outcome, c.request_id, c.origin, || {
            VisionControlKind::try_from(c.kind).map_or("unknown", |k| k.as_str())
        });
        VisionReply {
            request_id: c.request_id,
            result: result.to_wire(),
            kind: c.kind,
            origin: c.origin,
            message: FixedStr::new(&message),
            ..VisionReply::default()
        }
    }

    /// Applies one view control; returns its reply (published once the state that
    /// contains the change is).
    pub(super) fn view_control(&mut self, c: &ViewControl) -> ViewReply {
        let mut reply = ViewReply {
            request_id: c.request_id,
            kind: c.kind,
            origin: c.origin,
            ..ViewReply::default()
        };
        let outcome = self.params.apply_view(c).and_then(|effect| match effect {
            Effect::DirectionAt { stream, cam, x, y } => {
                let d = self.direction_at(stream, cam, x, y)?;
                reply.yaw_global_rad = d.global.yaw;
                reply.pitch_global_rad = d.global.pitch;
                reply.yaw_camera_rad = d.camera.yaw;
                reply.pitch_camera_rad = d.camera.pitch;
                Ok(())
            }
            effect => self.effect(effect),
        });
        let (result, message) = self.answered(outcome, c.request_id, c.origin, || {
            c.kind().map_or("unknown", |k: ViewControlKind| k.as_str())
        });
        reply.result = result.to_wire();
        reply.message = FixedStr::new(&message);
        reply
    }

    /// After a control: the layout follows the output settings at once (the state
    /// published with the reply shows the views asked for); metrics and log.
    pub(super) fn answered(
        &mut self,
        outcome: Result<(), Refusal>,
        request_id: u64,
        origin: u8,
        kind: impl FnOnce() -> &'static str,
    ) -> (VisionResult, String) {
        for (s, p) in self.streams.iter_mut().zip(&self.params.streams) {
            s.layout = layout::compute(p.layout_mode, p.overlay_mode, p.out_width, p.out_height);
        }
        let (result, message) = match outcome {
            Ok(()) => (VisionResult::Applied, String::new()),
            Err(r) => (r.result, r.message),
        };
        let kind = kind();
        self.metrics.control(kind, result.as_str());
        if result != VisionResult::Applied {
            tracing::info!(request_id, kind, origin, %result, message, "control not applied");
        } else {
            tracing::debug!(request_id, kind, origin, "control applied");
        }
        (result, message)
    }

    /// The direction at offset (x, y) of camera `cam`'s view as the state publishes
    /// it (its last rendered orientation, field of view and rectangle).
    pub(super) fn direction_at(
        &self,
        stream: usize,
        cam: u8,
        x: f64,
        y: f64,
    ) -> Result<Direction, Refusal> {
        let s = &self.streams[stream];
        let c = usize::from(cam);
        let rect = s.layout.views.get(c).copied();
        let active = rect.is_some() && !s.layout.debug_source;
        let state = s.cams[c].state(active, rect.unwrap_or([0; 4]));
        views::cam_offset(&state, f64::from(s.heading), x, y).ok_or_else(|| {
            Refusal::ignored(format!(
                "camera {cam} of `{}` has no view direction yet",
                s.name
            ))
        })
    }

    /// A capture is running or asked for (it needs frames).
    pub(super) fn capturing(&self) -> bool {
        self.streams
            .iter()
            .any(|s| s.pending_image || s.capturer.as_ref().is_some_and(|c| c.recording()))
    }

    pub(super) fn effect(&mut self, effect: Effect) -> Result<(), Refusal> {
        let view_err = |e: ViewError| match e {
            ViewError::Ignored(m) => Refusal::ignored(m),
            ViewError::Invalid(m) => Refusal::invalid(m),
        };
        match effect {
            Effect::Changed => {
                for s in &mut self.streams {
                    s.tracker.set_params(self.params.tracker);
                }
                Ok(())
            }
            Effect::AiChanged => {
                for s in &mut self.streams {
                    let (scan, track) = detectors(&self.params, &self.settings);
                    s.scan = scan;
                    s.track = track;
                    if !self.params.ai_enabled {
                        s.tracker.clear();
                    }
                }
                Ok(())
            }
            Effect::Capture {
                stream,
                single_image,
                record,
            } => self.capture(stream, single_image, record),
            Effect::Targeting {
                stream,
                cam,
                targeting,
            } => self.streams[stream].cams[usize::from(cam)]
                .set_targeting(&targeting)
                .map_err(view_err),
            Effect::Optics {
                stream,
                cam,
                optics,
            } => self.streams[stream].cams[usize::from(cam)]
                .set_optics(&optics)
                .map_err(view_err),
            Effect::Gimbal {
                stream,
                cam,
                yaw,
                pitch,
                yaw_rate,
                pitch_rate,
                yaw_global,
            } => self.streams[stream].cams[usize::from(cam)]
                .gimbal(yaw, pitch, yaw_rate, pitch_rate, yaw_global)
                .map_err(view_err),
            Effect::Roi {
                stream,
                cams,
                target,
            } => {
                for c in cams.indices() {
                    self.streams[stream].cams[c].roi(target);
                }
                Ok(())
            }
            Effect::RoiNone { stream, cams } => {
                for c in cams.indices() {
                    self.streams[stream].cams[c].roi_none();
                }
                Ok(())
            }
            Effect::Zoom {
                stream,
                cams,
                mode,
                value,
            } => {
                for c in cams.indices() {
                    self.streams[stream].cams[c]
                        .zoom_mavlink(mode, value)
                        .map_err(view_err)?;
                }
                Ok(())
            }
            Effect::Stt {
                stream,
                cam,
                request,
                zoom_level,
                rel_frame,
            } => self.stt(stream, cam, request, zoom_level, rel_frame),
            // A question: answered by `view_control`, nothing changes.
            Effect::DirectionAt { .. } => Ok(()),
        }
    }

    pub(super) fn capture(
        &mut self,
        stream: usize,
        single_image: bool,
        record: Option<bool>,
    ) -> Result<(), Refusal> {
        let Some(dir) = self.settings.capture.dir.clone() else {
            return Err(Refusal::failed("capture dir not configured"));
        };
        let s = &mut self.streams[stream];
        if s.capturer.is_none() {
            let c = Capturer::new(
                &dir,
                &s.name,
                self.settings.capture.format,
                self.settings.capture.jpeg_quality,
            )
            .map_err(|e| Refusal::failed(format!("capture dir {}: {e}", dir.display())))?;
            s.capturer = Some(c);
        }
        let Some(c) = s.capturer.as_mut() else {
            return Err(Refusal::failed("capture dir not configured"));
        };
        match record {
            Some(true) if !c.recording() => {
                let path = c
                    .start_video()
                    .map_err(|e| Refusal::failed(format!("cannot start recording: {e}")))?;
                tracing::info!(stream = %s.name, path = %path.display(), "recording");
            }
            Some(false) if c.recording() => {
                c.stop_video()
                    .map_err(|e| Refusal::failed(format!("cannot finish recording: {e}")))?;
                tracing::info!(stream = %s.name, "recording stopped");
            }
            _ => {}
        }
        if single_image {
            s.pending_image = true;
        }
        Ok(())
    }

    /// The named view's pinhole model and last rendered pose.
    pub(super) fn view_geometry(
        &self,
        stream: usize,
        cam: u8,
    ) -> Result<(CameraModel, CameraPose), Refusal> {
        let s = &self.streams[stream];
        let c = usize::from(cam);
        let aim = s.aims[c].ok_or_else(|| {
            Refusal::ignored(format!(
                "camera {cam} of `{}` has not been rendered yet",
                s.name
            ))
        })?;
        let p = &self.params.streams[stream];
        let [_, _, w, h] =
            s.layout
                .views
                .get(c)
                .copied()
                .unwrap_or([0, 0, p.out_width, p.out_height]);
        let model = views::view_model(u32::from(w), u32::from(h), s.cams[c].effective_hfov())
            .ok_or_else(|| Refusal::ignored(format!("camera {cam} has no view geometry")))?;
        let heading = s.pose.map_or(0.0, |p| p.heading());
        Ok((model, CameraPose::from_parts(aim, heading)))
    }

    pub(super) fn stt(
        &mut self,
        stream: usize,
        cam: u8,
        request: SttRequest,
        zoom_level: u16,
        rel_frame: u8,
    ) -> Result<(), Refusal> {
        let command = match request {
            SttRequest::Disable => SttCommand::Disable,
            SttRequest::NoOp => SttCommand::NoOp,
            SttRequest::Detection(id) => SttCommand::Detection(id),
            SttRequest::Global { yaw, pitch } => {
                SttCommand::Direction(crate::geometry::YawPitch { yaw, pitch }.direction())
            }
            SttRequest::ViewOffset { x, y } => {
                let (model, pose) = self.view_geometry(stream, cam)?;
                let d = Direction::of_offset(&model, &pose, Offset { x, y })
                    .ok_or_else(|| Refusal::ignored("the offset is outside the view"))?;
                SttCommand::Direction(d.ned)
            }
            SttRequest::Nudge { x, y } => {
                let target = self.streams[stream]
                    .stt
                    .target()
                    .ok_or_else(|| Refusal::ignored("nothing is being tracked"))?;
                let (model, pose) = self.view_geometry(stream, cam)?;
                let pixel = model
                    .ray_to_pixel(&pose.ned_to_camera(&target))
                    .ok_or_else(|| Refusal::ignored("the target is not in that view"))?;
                let at = model.pixel_to_offset(&pixel);
                let d = Direction::of_offset(
                    &model,
                    &pose,
                    Offset {
                        x: at.x + x,
                        y: at.y + y,
                    },
                )
                .ok_or_else(|| Refusal::ignored("the nudge leaves the view"))?;
                SttCommand::Direction(d.ned)
            }
        };
        let s = &mut self.streams[stream];
        s.stt
            .command(command, cam, zoom_level, rel_frame, s.tracker.tracks())
            .map_err(|e| match e {
                SttError::UnknownDetection(_) => Refusal::ignored(e.to_string()),
                SttError::Zoom(_) => Refusal::invalid(e.to_string()),
            })
    }
}
