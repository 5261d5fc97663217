//! The service loop: frames in, output frames and [`VisionState`] out, every
//! [`VisionControl`] answered by exactly one [`VisionReply`] and every
//! [`ViewControl`] by exactly one [`ViewReply`].
//!
//! One task does everything, one thing at a time: a control, a frame of stream 0 or
//! a frame of stream 1 (whichever is ready; two streams are processed one after the
//! other, not in parallel: the box has two cores and the renderer and detector are the
//! work), a demand word, or a timer (the 1 Hz state, a lapse of the demand).
//!
//! **Newest frame wins, nothing copied.** The frame topic queues up to two frames;
//! `FrameSubscriber::try_latest_with` takes every pending one, releases the older
//! ones unread (counted dropped) and hands the newest to the pipeline where it lies in
//! shared memory. The output frame is rendered in place into its shared-memory loan
//! and the state is written in place.
//!
//! **On demand.** Frames are read only while the output is used ([`Demand`]): a
//! consumer's `VisionDemand` word (the DigiView gateway while a client is connected),
//! a subscriber of an output frame topic, a capture or recording, a control within
//! `control_hold`, or `always_on`. Idle, the frame subscribers are closed and the
//! camera is told so (`CameraDemand`, `wanted = 0`), so it idles too; controls are
//! still answered and the state published every second (SYSTEM_STATUS 0, idle). A
//! demand word or a control reopens them at once and tells the camera, whose next
//! frame is made when its word arrives; while reading, the camera's word is renewed
//! every second.
//!
//! **No polling.** Idle, the pipeline wakes only for a control, a view control, a
//! demand word, the 1 s state (on the machine-wide grid, with the heartbeats) and
//! a one-shot timer at the next instant the demand lapses by itself (a word's lease,
//! the end of a control's hold). Output-frame subscribers send no word: they are
//! looked for at each of those wake-ups, so at least once a second.
//!
//! **Read your writes.** Every control's effect is in a published state before its
//! reply: the controls of one wake-up are applied, the state published, then the
//! replies, so a requester that got its reply reads the new values.
//!
//! Per frame: work image → (AI) scan, track, verify → geolocate every track → STT →
//! aim the active virtual cameras → layout → render the output → capture hooks →
//! state. Frames whose intrinsics or pose are unusable are counted (`reason`) and
//! make SYSTEM_STATUS 3 (error) when nothing usable came for more than a second.

use std::time::{Duration, Instant};

use anyhow::Context as _;
use nalgebra::{Point2, UnitQuaternion};
use skymesh_ipc_types::{
    CameraIntrinsics, FixedStr, FrameHeader, LensModel, PixelFormat, SttState, VehicleState,
    ViewControl, ViewControlKind, ViewReply, VisionControl, VisionControlKind, VisionDemand,
    VisionDetection, VisionReply, VisionResult, VisionState, VISION_DEMAND_LEASE_NS,
    VISION_MAX_CAMS, VISION_MAX_DETECTIONS, VISION_MAX_MODELS,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer;
use skymesh_runtime::{Context, FrameError, FramePublisher, WarnLimiter};

use crate::capture::{CaptureError, Capturer};
use crate::config::Settings;
use crate::detect::{Detector, PixelBox, WorkImage, MODELS};
use crate::geometry::{intersect_ground, CameraModel, CameraPose, Direction, GeoPosition, Offset};
use crate::ipc::{Ports, Sinks, StreamPorts};
use crate::layout::{self, Layout};
use crate::metrics::Metrics;
use crate::params::{Effect, Params, Refusal, StreamParams, SttRequest};
use crate::render::{Renderer, TileSpec, ViewSpec};
use crate::stt::{SingleTargetTracker, SttCommand, SttError};
use crate::thermal::Thermometer;
use crate::track::Tracker;
use crate::views::{self, AimContext, ViewError, VirtualCamera};

/// A stream counts as receiving (and the system as running) for this long after a frame.
const FRESH: Duration = Duration::from_secs(1);
/// The state is published at least this often.
const IDLE_PERIOD: Duration = Duration::from_secs(1);

/// Why the pipeline reads frames now.
#[derive(Debug, Default)]
struct Demand {
    /// Each publisher's (header service, instance) word that it wants the output,
    /// and when that lapses (monotonic ns).
    words: Vec<((u16, u16), u64)>,
    last_control: Option<Instant>,
}

impl Demand {
    /// A publisher's newest word, received at `now_ns`.
    fn word(&mut self, w: &VisionDemand, now_ns: u64) {
        let key = (w.header.service, w.header.instance);
        self.words.retain(|(k, _)| *k != key);
        if w.wanted != 0 {
            self.words
                .push((key, now_ns.saturating_add(VISION_DEMAND_LEASE_NS)));
        }
    }

    /// The next instant at which the demand may lapse by itself: a word's lease or
    /// the end of a control's hold (none if nothing would change without an event).
    fn next_deadline(&self, control_hold: Duration) -> Option<tokio::time::Instant> {
        let now = Instant::now();
        let now_ns = monotonic_ns();
        let lease = self
            .words
            .iter()
            .map(|&(_, until)| now + Duration::from_nanos(until.saturating_sub(now_ns)))
            .min();
        let hold = self
            .last_control
            .map(|t| t + control_hold)
            .filter(|&end| end > now);
        lease
            .into_iter()
            .chain(hold)
            .min()
            .map(tokio::time::Instant::from_std)
    }

    /// Whether any word wants the output at `now_ns` (lapsed words are forgotten).
    fn words(&mut self, now_ns: u64) -> bool {
        self.words.retain(|&(_, until)| until > now_ns);
        !self.words.is_empty()
    }

    /// What wants the output now, if anything (for the log).
    fn why(&mut self, p: &Pipeline, output_readers: usize) -> Option<&'static str> {
        let now = Instant::now();
        if p.settings.always_on {
            Some("always_on")
        } else if self.words(monotonic_ns()) {
            Some("demand")
        } else if output_readers > 0 {
            Some("output_reader")
        } else if p.capturing() {
            Some("capture")
        } else if self
            .last_control
            .is_some_and(|t| now.saturating_duration_since(t) < p.settings.control_hold)
        {
            Some("control")
        } else {
            None
        }
    }
}

/// Runs until `ctx.shutdown` is cancelled (then `Ok`) or the bus fails.
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let mut ports = Ports::open(&ctx.bus, &settings)?;
    let names: Vec<String> = settings.streams.iter().map(|s| s.name.clone()).collect();
    let metrics = Metrics::new(&ctx.stats, &names);
    let mut pipeline = Pipeline::new(settings, metrics);
    tracing::info!(
        streams = ?names,
        vehicle_id = pipeline.settings.vehicle_id,
        ai = pipeline.params.ai_enabled,
        scan_model = %pipeline.params.scan_model,
        track_model = %pipeline.params.track_model,
        captures = ?pipeline.settings.capture.dir,
        thermal = ?pipeline.thermometer.path(),
        always_on = pipeline.settings.always_on,
        "vision pipeline reading skymesh/camera/{{stream}}/frames while its output is used, publishing skymesh/vision/state and skymesh/vision/{{stream}}/output"
    );
    // The 1 s state publish on the machine-wide grid (with the heartbeats), and a
    // one-shot timer for the next lapse of the demand: idle, nothing else wakes the
    // pipeline but a control, a view control or a demand word.
    let mut state_tick = timer::Ticker::new(IDLE_PERIOD).context("creating the state timer")?;
    let mut deadline = timer::Timer::new().context("creating the demand timer")?;
    let mut demand = Demand::default();
    pipeline.metrics.active.set(0.0);
    pipeline.publish_state(&mut ports.sinks)?;
    ctx.ready();
    loop {
        let lapse = demand.next_deadline(pipeline.settings.control_hold);
        let event = tokio::select! {
            _ = ctx.shutdown.cancelled() => break,
            c = ports.control.recv_with(|c| *c) => Event::Control(c?),
            c = ports.view.recv_with(|c| *c) => Event::View(c?),
            d = ports.demand.recv() => Event::Demand(d?),
            (i, r) = next_frame(&mut ports.streams) => { r?; Event::Frame(i) }
            t = state_tick.tick() => { t.context("the state timer failed")?; Event::Tick }
            t = sleep_until(&mut deadline, lapse) => { t.context("the demand timer failed")?; Event::Lapse }
        };
        let mut replies = Vec::new();
        let mut view_replies = Vec::new();
        match event {
            Event::Control(c) => {
                demand.last_control = Some(Instant::now());
                replies.push(pipeline.control(&c));
            }
            Event::View(c) => {
                demand.last_control = Some(Instant::now());
                view_replies.push(pipeline.view_control(&c));
            }
            Event::Demand(d) => {
                demand.word(&d, monotonic_ns());
                while let Some(d) = ports.demand.try_recv()? {
                    demand.word(&d, monotonic_ns());
                }
            }
            Event::Frame(i) => {
                // Read for frames only (its topic keeps the newest samples).
                if let Some(v) = ports.vehicle.latest()? {
                    pipeline.vehicle = Some(v);
                }
                let StreamPorts { frames, output, .. } = &mut ports.streams[i];
                let sinks = &mut ports.sinks;
                let Some(frames) = frames.as_mut() else {
                    continue;
                };
                // Tens of milliseconds of CPU (seconds in a debug build on a loaded
                // machine): off the async worker, so the heartbeat task, which may sit
                // in this worker's LIFO slot where no other worker can steal it,
                // keeps beating and the supervisor does not take a busy pipeline for
                // a hung one.
                let done = tokio::task::block_in_place(|| {
                    frames.try_latest_with(|header, pixels| {
                        pipeline.frame(i, header, pixels, output, sinks)
                    })
                })?;
                if let Some((processed, skipped)) = done {
                    processed?;
                    pipeline.streams[i].frames_dropped += skipped;
                    pipeline.metrics.streams[i].dropped.add(skipped);
                }
            }
            Event::Tick => {
                // The 1 Hz state (unless a frame has just published it; reading, a
                // frame does at every frame). The camera's word is renewed.
                if pipeline.last_state.elapsed() >= IDLE_PERIOD / 10 {
                    pipeline.publish_state(&mut ports.sinks)?;
                }
                ports.renew_camera_demand()?;
            }
            // The demand below forgets what lapsed.
            Event::Lapse => {}
        }
        // Controls that arrived meanwhile are answered before the next frame.
        while let Some(c) = ports.control.try_recv()? {
            demand.last_control = Some(Instant::now());
            replies.push(pipeline.control(&c));
        }
        while let Some(c) = ports.view.try_recv()? {
            demand.last_control = Some(Instant::now());
            view_replies.push(pipeline.view_control(&c));
        }
        if !replies.is_empty() || !view_replies.is_empty() {
            // The state that contains the changes, then the replies.
            pipeline.publish_state(&mut ports.sinks)?;
            for r in replies {
                ports.sinks.reply(r)?;
            }
            for r in view_replies {
                ports.sinks.view_reply(r)?;
            }
        }
        let why = demand.why(&pipeline, ports.output_readers());
        if ports.set_reading(why.is_some())? {
            pipeline
                .metrics
                .active
                .set(if why.is_some() { 1.0 } else { 0.0 });
            match why {
                Some(why) => tracing::info!(why, "output used: reading frames"),
                None => {
                    tracing::info!("output not used: idle until it is");
                    pipeline.publish_state(&mut ports.sinks)?;
                }
            }
        }
    }
    // The camera need not wait for the word's lease to stop rendering.
    if let Err(e) = ports.set_reading(false) {
        tracing::warn!(error = %e, "could not withdraw the camera demand");
    }
    for s in &mut pipeline.streams {
        if let Some(c) = s.capturer.as_mut() {
            if c.recording() {
                if let Err(e) = c.stop_video() {
                    tracing::warn!(error = %e, "could not finish the recording");
                }
            }
        }
    }
    tracing::info!("vision pipeline stopped");
    Ok(())
}

enum Event {
    Control(VisionControl),
    View(ViewControl),
    Demand(VisionDemand),
    Frame(usize),
    Tick,
    Lapse,
}

/// Waits on `timer` until `at`; forever without a deadline.
async fn sleep_until(
    timer: &mut timer::Timer,
    at: Option<tokio::time::Instant>,
) -> std::io::Result<()> {
    match at {
        Some(at) => timer.sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// Waits until a frame of any stream that is read is pending (it is then read in
/// place); never while no stream is read.
async fn next_frame(streams: &mut [StreamPorts]) -> (usize, Result<(), FrameError>) {
    let mut open = streams
        .iter_mut()
        .enumerate()
        .filter_map(|(i, s)| s.frames.as_mut().map(|f| (i, f)));
    match (open.next(), open.next()) {
        (Some((i, a)), None) => (i, a.ready().await),
        (Some((i, a)), Some((j, b))) => tokio::select! {
            r = a.ready() => (i, r),
            r = b.ready() => (j, r),
        },
        _ => std::future::pending().await,
    }
}

/// One stream's processing state.
#[derive(Debug)]
struct StreamRt {
    name: String,
    scan: Option<Detector>,
    track: Option<Detector>,
    tracker: Tracker,
    stt: SingleTargetTracker,
    cams: Vec<VirtualCamera>,
    /// The orientation each camera was last rendered with.
    aims: [Option<UnitQuaternion<f64>>; VISION_MAX_CAMS],
    renderer: Renderer,
    capturer: Option<Capturer>,
    pending_image: bool,
    detections: Vec<VisionDetection>,
    layout: Layout,
    last_frame: Option<Instant>,
    last_good: Option<Instant>,
    bad_since: Option<Instant>,
    frames_processed: u64,
    frames_dropped: u64,
    last_seq: u64,
    last_capture_ns: u64,
    last_processed_ns: u64,
    source: (u32, u32),
    heading: f32,
    pose: Option<CameraPose>,
}

/// Everything but the bus.
#[derive(Debug)]
struct Pipeline {
    settings: Settings,
    params: Params,
    streams: Vec<StreamRt>,
    vehicle: Option<VehicleState>,
    thermometer: Thermometer,
    temperature: Option<f32>,
    temperature_read: Option<Instant>,
    last_state: Instant,
    metrics: Metrics,
    warn: WarnLimiter<&'static str>,
}

fn detectors(p: &Params, s: &Settings) -> (Option<Detector>, Option<Detector>) {
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
    fn new(settings: Settings, metrics: Metrics) -> Pipeline {
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
    fn control(&mut self, c: &VisionControl) -> VisionReply {
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
    fn view_control(&mut self, c: &ViewControl) -> ViewReply {
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
    fn answered(
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
    fn direction_at(&self, stream: usize, cam: u8, x: f64, y: f64) -> Result<Direction, Refusal> {
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
    fn capturing(&self) -> bool {
        self.streams
            .iter()
            .any(|s| s.pending_image || s.capturer.as_ref().is_some_and(|c| c.recording()))
    }

    fn effect(&mut self, effect: Effect) -> Result<(), Refusal> {
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

    fn capture(
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
    fn view_geometry(&self, stream: usize, cam: u8) -> Result<(CameraModel, CameraPose), Refusal> {
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

    fn stt(
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

    // ---------------------------------------------------------------- frames

    fn bad(&mut self, i: usize, reason: &'static str, error: &dyn std::fmt::Display) {
        let now = Instant::now();
        let s = &mut self.streams[i];
        s.last_frame = Some(now);
        s.bad_since.get_or_insert(now);
        self.metrics.streams[i].bad(reason);
        if let Some(hidden) = self.warn.allow(reason, now) {
            tracing::warn!(stream = %s.name, reason, error = %error, hidden, "frame not usable");
        }
    }

    fn frame(
        &mut self,
        i: usize,
        header: &FrameHeader,
        pixels: &[u8],
        output: &mut FramePublisher,
        sinks: &mut Sinks,
    ) -> anyhow::Result<()> {
        let began = Instant::now();
        // A frame the camera made before the pipeline (re)subscribed (the topic's
        // history) is not news: skipped, counted dropped.
        let age_ns = monotonic_ns().saturating_sub(header.capture_mono_ns);
        if header.capture_mono_ns > 0 && age_ns > FRESH.as_nanos() as u64 {
            self.streams[i].frames_dropped += 1;
            self.metrics.streams[i].dropped.inc();
            return Ok(());
        }
        let model = match CameraModel::from_header(header) {
            Ok(m) => m,
            Err(e) => {
                self.bad(i, "intrinsics", &e);
                return Ok(());
            }
        };
        let pose = match CameraPose::from_capture(header) {
            Ok(p) => p,
            Err(e) => {
                self.bad(i, "pose", &e);
                return Ok(());
            }
        };
        let work = match WorkImage::from_frame(header, pixels, self.settings.detector.work_width) {
            Ok(w) => w,
            Err(e) => {
                self.bad(i, "work_image", &e);
                return Ok(());
            }
        };
        let position = GeoPosition::from_capture(&header.pose).ok();
        // Height above the ground under the vehicle: its height above home.
        let height = self
            .vehicle
            .filter(|v| v.position_valid != 0 && v.alt_rel_m.is_finite())
            .map(|v| f64::from(v.alt_rel_m));
        let vehicle_attitude = self
            .vehicle
            .filter(|v| v.attitude_valid != 0)
            .and_then(|v| {
                let q = v.attitude_q.map(f64::from);
                let q = nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
                let n = q.norm();
                (n.is_finite() && (n - 1.0).abs() < 0.01)
                    .then(|| UnitQuaternion::from_quaternion(q))
            })
            .unwrap_or_else(|| UnitQuaternion::from_euler_angles(0.0, 0.0, pose.heading()));
        let dt_s = {
            let s = &self.streams[i];
            if s.last_capture_ns > 0 && header.capture_mono_ns > s.last_capture_ns {
                (header.capture_mono_ns - s.last_capture_ns) as f64 / 1e9
            } else {
                0.0
            }
        };

        let ai = self.params.ai_enabled;
        let p = self.params.streams[i].clone();
        let s = &mut self.streams[i];

        // Detection and tracking.
        if ai {
            if let Some(scan) = s.scan.as_mut() {
                let hits = scan.scan(&work);
                let track = &mut s.track;
                s.tracker.update(&hits, &mut |b: &PixelBox| {
                    track.as_mut().and_then(|d| d.verify(&work, b))
                });
            }
        }
        let lay = layout::compute(p.layout_mode, p.overlay_mode, p.out_width, p.out_height);
        s.tracker.assign_overlay(lay.tiles.len());

        // Geolocation.
        s.detections.clear();
        for t in s.tracker.tracks() {
            let (cx, cy) = t.bbox.center();
            let pixel = Point2::new(f64::from(cx), f64::from(cy));
            let mut d = VisionDetection {
                id: t.id,
                score: t.score,
                stream: i as u8,
                overlay_slot: t.overlay_slot.unwrap_or(255),
                model: t.model,
                age_frames: t.age_frames,
                confidence: t.confidence,
                bbox: t.bbox.to_wire(),
                ..VisionDetection::default()
            };
            if let Some(dir) = Direction::of_pixel(&model, &pose, &pixel) {
                d.yaw_global_rad = dir.global.yaw as f32;
                d.pitch_global_rad = dir.global.pitch as f32;
                d.yaw_heading_rad = dir.heading.yaw as f32;
                d.pitch_heading_rad = dir.heading.pitch as f32;
                d.yaw_camera_rad = dir.camera.yaw as f32;
                d.pitch_camera_rad = dir.camera.pitch as f32;
                let hit = position
                    .zip(height)
                    .and_then(|(pos, h)| intersect_ground(&pos, h, &dir.ned));
                if let Some(hit) = hit {
                    d.geo_valid = 1;
                    d.lat_deg = hit.position.lat_deg;
                    d.lon_deg = hit.position.lon_deg;
                    d.alt_msl_m = hit.position.alt_msl_m as f32;
                    d.distance_m = hit.distance_m as f32;
                }
            }
            s.detections.push(d);
        }

        // Single-target tracking.
        s.stt.update(&work, &model, &pose, s.tracker.tracks());

        // Aim the cameras the layout shows.
        let tracks = s.tracker.tracks();
        let detection = |id: u8| {
            let t = tracks.iter().find(|t| t.id == id)?;
            let (cx, cy) = t.bbox.center();
            Direction::of_pixel(&model, &pose, &Point2::new(f64::from(cx), f64::from(cy)))
                .map(|d| d.ned)
        };
        let ctx = AimContext {
            vehicle: vehicle_attitude,
            position,
            detection: &detection,
            single_target: s.stt.target(),
            dt_s,
        };
        let mut view_specs: Vec<ViewSpec> = Vec::with_capacity(lay.views.len());
        for (c, rect) in lay.views.iter().enumerate().take(VISION_MAX_CAMS) {
            let cam = &mut s.cams[c];
            // Offsets are fractions of this view: its aspect sets the vertical FOV.
            cam.set_view_size(rect[2], rect[3]);
            let aim = if lay.debug_source {
                Some(pose.ned_from_camera())
            } else {
                cam.aim(&ctx).or(s.aims[c])
            };
            if let Some(q) = aim {
                if !lay.debug_source {
                    s.aims[c] = Some(q);
                }
                view_specs.push(ViewSpec {
                    rect: *rect,
                    ned_from_view: q,
                    hfov: cam.effective_hfov(),
                    crop: cam.crop_mode(),
                });
            }
        }
        let tiles: Vec<TileSpec> = tracks
            .iter()
            .filter_map(|t| {
                let rect = *lay.tiles.get(usize::from(t.overlay_slot?))?;
                let side = (t.bbox.w.max(t.bbox.h) * 1.5).max(16.0);
                let (cx, cy) = t.bbox.center();
                Some(TileSpec {
                    rect,
                    source: PixelBox {
                        x: cx - side / 2.0,
                        y: cy - side / 2.0,
                        w: side,
                        h: side,
                    },
                })
            })
            .collect();

        // Render in place, then the capture hooks on the rendered pixels.
        let (w, h) = (u32::from(p.out_width), u32::from(p.out_height));
        let stride = w * 3;
        let len = (stride * h) as usize;
        let view0 = view_specs.first().copied().filter(|_| !lay.debug_source);
        let mut render_error = None;
        let mut capture_errors: Vec<CaptureError> = Vec::new();
        let renderer = &mut s.renderer;
        let capturer = &mut s.capturer;
        let pending_image = &mut s.pending_image;
        let debug_source = lay.debug_source;
        let sent = output.publish_with(len, |out_h, out| {
            out_h.set_geometry(PixelFormat::Rgb24, w, h, stride);
            out_h.frame_seq = header.frame_seq;
            out_h.capture_mono_ns = header.capture_mono_ns;
            out_h.capture_unix_ns = header.capture_unix_ns;
            out_h.vehicle_heading_deg = header.vehicle_heading_deg;
            out_h.pose = header.pose;
            if let Some(v) = view0 {
                out_h.pose.attitude_q = [
                    v.ned_from_view.w,
                    v.ned_from_view.i,
                    v.ned_from_view.j,
                    v.ned_from_view.k,
                ]
                .map(|x| x as f32);
                out_h.intrinsics = view_intrinsics(&v);
            }
            if let Err(e) = renderer.render(
                header,
                pixels,
                &model,
                &pose,
                &view_specs,
                debug_source,
                &tiles,
                out,
                w,
                h,
                stride,
            ) {
                render_error = Some(e);
            }
            if let Some(c) = capturer.as_mut() {
                if std::mem::take(pending_image) {
                    match c.image(out, w, h, stride) {
                        Ok(path) => tracing::info!(path = %path.display(), "image captured"),
                        Err(e) => capture_errors.push(e),
                    }
                }
                if c.recording() {
                    if let Err(e) = c.video_frame(out, w, h, stride) {
                        capture_errors.push(e);
                    }
                }
            }
        });
        s.layout = lay;
        s.pose = Some(pose);
        s.source = (header.width, header.height);
        s.heading = pose.heading() as f32;
        s.last_seq = header.frame_seq;
        s.last_capture_ns = header.capture_mono_ns;
        s.last_processed_ns = monotonic_ns();
        let now = Instant::now();
        s.last_frame = Some(now);
        s.last_good = Some(now);
        s.bad_since = None;
        s.frames_processed += 1;
        let name = s.name.clone();
        self.metrics.streams[i].processed.inc();
        for e in capture_errors {
            self.metrics.capture_errors.inc();
            if let Some(hidden) = self.warn.allow("capture", now) {
                tracing::warn!(stream = %name, error = %e, hidden, "capture failed");
            }
        }
        if let Some(e) = render_error {
            self.bad(i, "render", &e);
        }
        if let Err(e) = sent {
            self.bad(i, "publish", &e);
        }
        self.publish_state(sinks)?;
        let m = &self.metrics.streams[i];
        m.process_seconds.observe(began.elapsed().as_secs_f64());
        let latency_ns = monotonic_ns().saturating_sub(header.capture_mono_ns);
        if header.capture_mono_ns > 0 {
            m.latency_seconds.observe(latency_ns as f64 / 1e9);
        }
        Ok(())
    }

    // ---------------------------------------------------------------- state

    /// SYSTEM_STATUS: 3 if a stream's frames have been unusable for over a second,
    /// 1 if a usable frame came within the last second, else 0 (idle).
    fn status(&self, now: Instant) -> u8 {
        let error = self.streams.iter().any(|s| {
            s.bad_since
                .is_some_and(|t| now.saturating_duration_since(t) > FRESH)
        });
        let running = self.streams.iter().any(|s| {
            s.last_good
                .is_some_and(|t| now.saturating_duration_since(t) <= FRESH)
        });
        if error {
            3
        } else if running {
            1
        } else {
            0
        }
    }

    fn publish_state(&mut self, ports: &mut Sinks) -> anyhow::Result<()> {
        let now = Instant::now();
        if self
            .temperature_read
            .is_none_or(|t| now.saturating_duration_since(t) >= IDLE_PERIOD)
        {
            self.temperature = self.thermometer.read();
            self.temperature_read = Some(now);
        }
        let total: usize = self.streams.iter().map(|s| s.detections.len()).sum();
        self.metrics.detections.set(total as f64);
        let status = self.status(now);
        ports.state(|st| self.fill_state(st, status, now))?;
        self.last_state = now;
        Ok(())
    }

    fn fill_state(&self, st: &mut VisionState, status: u8, now: Instant) {
        let p = &self.params;
        st.status = status;
        st.ai_enabled = u8::from(p.ai_enabled);
        st.model_count = MODELS.len().min(VISION_MAX_MODELS) as u8;
        for (slot, m) in st.models.iter_mut().zip(MODELS) {
            *slot = skymesh_ipc_types::vision::ModelName::new(m);
        }
        st.stream_count = self.streams.len() as u8;
        st.temperature_valid = u8::from(self.temperature.is_some());
        st.temperature_c = self.temperature.unwrap_or(0.0);
        st.detection_mode = p.detection_mode;
        let t = &p.tracker;
        st.sorting_mode = t.sorting_mode;
        st.track_confidence = t.track_confidence;
        st.scan_confidence = t.scan_confidence;
        st.track_overlap = t.track_overlap;
        st.scan_overlap = t.scan_overlap;
        st.creation_score = t.creation_score;
        st.bonus_detection = t.bonus_detection;
        st.bonus_redetection = t.bonus_redetection;
        st.missed_detection_penalty = t.missed_detection_penalty;
        st.missed_redetection_penalty = t.missed_redetection_penalty;
        st.track_model = skymesh_ipc_types::vision::ModelName::new(&p.track_model);
        st.scan_model = skymesh_ipc_types::vision::ModelName::new(&p.scan_model);
        for ((out, s), sp) in st.streams.iter_mut().zip(&self.streams).zip(&p.streams) {
            out.name = FixedStr::new(&s.name);
            out.configured = 1;
            out.receiving = u8::from(
                s.last_frame
                    .is_some_and(|t| now.saturating_duration_since(t) <= FRESH),
            );
            out.layout_mode = sp.layout_mode;
            out.overlay_mode = sp.overlay_mode;
            out.num_views = s.layout.views.len().min(VISION_MAX_CAMS) as u8;
            out.out_width = sp.out_width;
            out.out_height = sp.out_height;
            out.overlay_box = s.layout.overlay_box;
            out.single_detection_size = s.layout.tile_size;
            if let Some(c) = s.capturer.as_ref() {
                out.recording = u8::from(c.recording());
                (out.images_captured, out.videos_captured) = c.counts();
            }
            (out.source_width, out.source_height) = s.source;
            out.vehicle_heading_rad = s.heading;
            out.frames_processed = s.frames_processed;
            out.frames_dropped = s.frames_dropped;
            out.last_frame_seq = s.last_seq;
            out.last_capture_mono_ns = s.last_capture_ns;
            out.last_processed_mono_ns = s.last_processed_ns;
            for (c, cam) in s.cams.iter().enumerate().take(VISION_MAX_CAMS) {
                let rect = s.layout.views.get(c).copied();
                let active = rect.is_some() && !s.layout.debug_source;
                out.cams[c] = cam.state(active, rect.unwrap_or([0; 4]));
            }
            out.stt = s
                .pose
                .map_or_else(SttState::default, |pose| s.stt.state(&pose));
        }
        let mut n = 0;
        for (slot, d) in st
            .detections
            .iter_mut()
            .zip(self.streams.iter().flat_map(|s| s.detections.iter()))
            .take(VISION_MAX_DETECTIONS)
        {
            *slot = *d;
            n += 1;
        }
        st.detection_count = n as u8;
    }
}

/// Pinhole intrinsics of a rectified view in output-frame pixels (the output header
/// describes view 0); unknown (`valid` 0) for a panoramic view.
fn view_intrinsics(v: &ViewSpec) -> CameraIntrinsics {
    let [x, y, w, h] = v.rect.map(f64::from);
    let half = (v.hfov / 2.0).tan();
    if v.crop == skymesh_ipc_types::CropMode::Panoramic || !(half.is_finite() && half > 0.0) {
        return CameraIntrinsics::default();
    }
    let f = (w / 2.0) / half;
    CameraIntrinsics {
        fx: f as f32,
        fy: f as f32,
        cx: (x + (w - 1.0) / 2.0) as f32,
        cy: (y + (h - 1.0) / 2.0) as f32,
        k: [0.0; 4],
        lens_model: LensModel::Pinhole.to_wire(),
        valid: 1,
        reserved: [0; 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::CropMode;

    #[test]
    fn view_intrinsics_describe_view_zero() {
        let v = ViewSpec {
            rect: [100, 50, 640, 480],
            ned_from_view: UnitQuaternion::identity(),
            hfov: std::f64::consts::FRAC_PI_2,
            crop: CropMode::Rectified,
        };
        let k = view_intrinsics(&v);
        assert_eq!(k.valid, 1);
        assert!((k.fx - 320.0).abs() < 1e-3 && k.fx == k.fy);
        assert_eq!((k.cx, k.cy), (419.5, 289.5));
        let pano = view_intrinsics(&ViewSpec {
            crop: CropMode::Panoramic,
            ..v
        });
        assert_eq!(pano.valid, 0);
    }
}
