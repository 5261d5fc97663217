//! `skymesh-camera`: publishes camera frames into shared memory, written in place
//! (`skymesh/camera/{stream}/frames`: a `FrameHeader` with capture time, intrinsics
//! and pose, then the pixels), paced at the configured frame rate.
//!
//! Sources: the synthetic scene ([`synthetic`]) — a textured ground plane with moving
//! targets rendered for the vehicle's current pose, whose true positions are
//! published on `skymesh/camera/{stream}/truth` with every frame. Y4M files and V4L2
//! devices are not implemented yet (refused by the config).
//!
//! Frames are rendered one at a time from the service's task (bands of rows on
//! `synthetic.render_threads` scoped threads) straight into the loaned frame; when
//! rendering takes longer than a frame period the missed ticks are skipped and
//! counted (`skymesh_camera_frames_skipped_total{reason="late"}`).
//!
//! The frame header's `pose.attitude_q` is the **camera mount → NED** quaternion
//! (x along the optical axis, y image right, z image down), not the vehicle's
//! attitude (as `ipc-types/src/frame.rs` defines it); the vehicle heading is in
//! `vehicle_heading_deg`. See [`synthetic`].
#![deny(unsafe_code)]

pub mod config;
mod ipc;
pub mod metrics;
pub mod render;
pub mod scene;
pub mod synthetic;

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Context, WarnLimiter};
use tokio::time::{Instant, MissedTickBehavior};

pub use config::{RawConfig, Settings};

use crate::ipc::Ports;
use crate::metrics::{Metrics, Skip};
use crate::synthetic::{FrameStamp, Synthetic};

/// Publishes frames until `ctx.shutdown` is cancelled (then `Ok`) or the bus fails.
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let mut ports = Ports::open(&ctx.bus, &settings)?;
    let metrics = Metrics::new(&ctx.stats);
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
    let period = Duration::from_secs_f64(1.0 / f64::from(settings.fps));
    let len = settings.frame_len();
    let mut source = Synthetic::new(settings);
    let mut interval = tokio::time::interval(period);
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let start = Instant::now();
    let mut prev_tick: Option<Instant> = None;
    let mut frame_seq = 0u64;
    let mut warn = WarnLimiter::default();
    ctx.ready();
    loop {
        let tick = tokio::select! {
            _ = ctx.shutdown.cancelled() => break,
            t = interval.tick() => t,
        };
        if let Some(prev) = prev_tick {
            let periods = (tick - prev).as_secs_f64() / period.as_secs_f64();
            let missed = periods.round() as u64;
            if missed > 1 {
                metrics.skipped(Skip::Late, missed - 1);
            }
        }
        prev_tick = Some(tick);

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
        let stamp = FrameStamp {
            seq: frame_seq + 1,
            mono_ns: monotonic_ns(),
            unix_ns: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64),
        };
        let t_s = tick.duration_since(start).as_secs_f64();
        let mut truth = None;
        let sent = ports.frame(len, |header, pixels| {
            truth = source.render(t_s, stamp, header, pixels).ok();
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
