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
use skymesh_ipc_types::{ViewControl, VisionControl, VisionDemand, VISION_DEMAND_LEASE_NS};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer;
use skymesh_runtime::{Context, FrameError};

use crate::config::Settings;
use crate::ipc::{Ports, StreamPorts};
use crate::metrics::Metrics;

mod frame;
mod pipeline;
mod state;

use pipeline::Pipeline;

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
        // Lapsed words are not deadlines any more (they are forgotten only where the
        // demand is asked for, which `always_on` skips).
        let lease = self
            .words
            .iter()
            .filter(|&&(_, until)| until > now_ns)
            .map(|&(_, until)| now + Duration::from_nanos(until - now_ns))
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
