//! `skymesh-camera`: publishes camera frames into shared memory, written in place
//! (`skymesh/camera/{stream}/frames`: a `FrameHeader` with capture time, intrinsics
//! and pose, then the pixels), paced at the configured frame rate.
//!
//! Sources (`source` in the config):
//! - `synthetic` ([`synthetic`]): a textured ground plane with moving targets rendered
//!   for the vehicle's current pose, whose true positions are published on
//!   `skymesh/camera/{stream}/truth` with every frame. Frames are rendered one at a
//!   time from the service's task (bands of rows on `synthetic.render_threads` scoped
//!   threads) straight into the loaned frame.
//! - `y4m` ([`file`]): a YUV4MPEG2 file read frame by frame ([`y4m`]) and converted
//!   ([`yuv`]) straight into the loaned frame; no truth topic (a file has none).
//! - V4L2 devices are not implemented yet (refused by the config).
//!
//! When a frame takes longer than a frame period the missed ticks are skipped and
//! counted (`skymesh_camera_frames_skipped_total{reason="late"}`).
//!
//! **On demand.** Frames are made only while a reader wants them ([`demand`]): its
//! `CameraDemand` word on `skymesh/camera/{stream}/demand` (the vision pipeline's
//! while its own output is used), a subscriber of the frame topic (tools and tests,
//! which send no word), or always with `always_on`. Idle, the camera sleeps until a
//! word arrives (its first frame is made at once) and looks for word-less
//! subscribers once a second; no frame clock runs.
//!
//! The frame header's `pose.attitude_q` is the **camera mount → NED** quaternion
//! (x along the optical axis, y image right, z image down), not the vehicle's
//! attitude (as `ipc-types/src/frame.rs` defines it); the vehicle heading is in
//! `vehicle_heading_deg`. See [`pose`].
#![deny(unsafe_code)]

pub mod config;
mod demand;
pub mod file;
mod ipc;
pub mod metrics;
pub mod pose;
pub mod render;
pub mod scene;
pub mod synthetic;
pub mod y4m;
pub mod yuv;

use std::time::{SystemTime, UNIX_EPOCH};

use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Context, WarnLimiter};
use tokio::time::Instant;

pub use config::{RawConfig, Settings, Source};

use crate::demand::Pace;
use crate::ipc::Ports;
use crate::metrics::{Metrics, Skip};
use crate::synthetic::{FrameStamp, Synthetic};

/// Publishes frames until `ctx.shutdown` is cancelled (then `Ok`) or the bus fails
/// (or, for a file source, the file cannot be opened or no longer fits the config).
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let ports = Ports::open(&ctx.bus, &settings)?;
    let metrics = Metrics::new(&ctx.stats);
    match settings.source.clone() {
        Source::Synthetic => run_synthetic(settings, ctx, ports, metrics).await,
        Source::Y4m(y4m) => file::run(settings, y4m, ctx, ports, metrics).await,
    }
}

/// The capture times of a frame taken now.
pub(crate) fn stamp_now(seq: u64) -> FrameStamp {
    FrameStamp {
        seq,
        mono_ns: monotonic_ns(),
        unix_ns: SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64),
    }
}

async fn run_synthetic(
    settings: Settings,
    ctx: Context,
    mut ports: Ports,
    metrics: Metrics,
) -> anyhow::Result<()> {
    tracing::info!(
        stream = %settings.stream,
        vehicle_id = settings.vehicle_id,
        width = settings.width,
        height = settings.height,
        fps = settings.fps,
        format = %settings.format,
        fx = settings.intrinsics.fx,
        lens = ?settings.intrinsics.lens,
        targets = settings.synthetic.targets.len(),
        "camera publishing synthetic frames on skymesh/camera/{}/frames",
        settings.stream,
    );
    let len = settings.frame_len();
    let mut pace = Pace::new(settings.fps, settings.always_on)?;
    let mut source = Synthetic::new(settings);
    let start = Instant::now();
    let mut frame_seq = 0u64;
    let mut warn = WarnLimiter::default();
    ctx.ready();
    // Idle, the pose is not even read: the topics keep their newest samples, which
    // the first tick with a reader takes.
    while let Some(tick) = pace.next(&ctx, &mut ports, &metrics).await? {
        let (vehicle, payload) = ports.inputs()?;
        if let Some(v) = vehicle {
            source.update_vehicle(&v);
        }
        if let Some(p) = payload {
            source.update_payload(&p);
        }
        if source.pose().is_err() {
            metrics.skipped(Skip::NoPose, 1);
            if let Some(hidden) = warn.allow("no_pose", std::time::Instant::now()) {
                tracing::info!(
                    hidden,
                    "no vehicle pose yet and no configured origin: waiting"
                );
            }
            continue;
        }
        let began = std::time::Instant::now();
        let stamp = stamp_now(frame_seq + 1);
        let t_s = tick.duration_since(start).as_secs_f64();
        let mut truth = None;
        // Rendering is CPU work: off the async worker (see vision-pipeline's frame
        // step), so the heartbeat keeps beating while a frame is drawn.
        let sent = tokio::task::block_in_place(|| {
            ports.frame(len, |header, pixels| {
                truth = source.render(t_s, stamp, header, pixels).ok();
            })
        });
        metrics
            .render_seconds
            .observe(began.elapsed().as_secs_f64());
        match sent {
            Ok(_) => {
                frame_seq = stamp.seq;
                metrics.published.inc();
                if let Some(truth) = truth {
                    ports.truth(truth)?;
                }
            }
            Err(e) => {
                metrics.skipped(Skip::PublishError, 1);
                if let Some(hidden) = warn.allow("publish", std::time::Instant::now()) {
                    tracing::warn!(error = %e, hidden, "frame not published");
                }
            }
        }
    }
    tracing::info!(frames = frame_seq, "camera stopped");
    Ok(())
}
