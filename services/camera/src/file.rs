//! The Y4M file source: reads a YUV4MPEG2 file frame by frame and publishes its
//! frames at the configured `fps` (the file's own `F` rate is only logged), each
//! converted into the configured format straight into the loaned frame.
//!
//! - The file is checked when the configuration is (`--check-config`, exit 64): it
//!   must open, have a valid header with 4:2:0 or mono chroma, and frames of exactly
//!   the configured `width` × `height`. It is opened again at start and checked again
//!   (a file replaced in between fails the start, exit 1).
//! - Intrinsics come from `[lens]` (a file has none). The header's pose is the
//!   vehicle's (as for the synthetic source: position, heading, gimbal or mount),
//!   `pose.valid = 0` until a vehicle state has arrived — file frames are published
//!   without one. There is no truth topic.
//! - At the end of the file: with `loop = true` start again from the first frame;
//!   else stop publishing, log once, and stay up and healthy until shut down. A
//!   truncated or corrupt frame, or a read error, is logged (rate-limited, with its
//!   byte offset), counted (`skymesh_camera_file_errors_total`) and handled as the
//!   end of the file.
//! - Memory: one buffer of one raw file frame, reused; the conversion writes
//!   directly into the shared-memory frame.

use std::fs::File;
use std::io::BufReader;

use anyhow::Context as _;
use skymesh_ipc_types::{CapturePose, PixelFormat};
use skymesh_runtime::{Context, WarnLimiter};

use crate::config::{check_y4m_size, Settings, Y4mSettings};
use crate::demand::Pace;
use crate::ipc::Ports;
use crate::metrics::{Metrics, Skip};
use crate::pose::PoseTracker;
use crate::stamp_now;
use crate::y4m::{Chroma, Y4mReader};
use crate::yuv::Converter;

/// What the next tick gets from the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Next {
    Frame,
    /// No more frames (end without loop, an empty file, or a failed rewind).
    Finished,
}

/// Reads the next frame into `raw`, starting again at the end when `looping`.
fn next_frame(
    reader: &mut Y4mReader<BufReader<File>>,
    raw: &mut [u8],
    looping: bool,
    metrics: &Metrics,
    warn: &mut WarnLimiter<&'static str>,
    path: &std::path::Path,
) -> Next {
    for attempt in 0..2 {
        match reader.read_frame(raw) {
            Ok(true) => return Next::Frame,
            Ok(false) => {}
            Err(e) => {
                metrics.file_errors.inc();
                if let Some(hidden) = warn.allow("file", std::time::Instant::now()) {
                    tracing::warn!(
                        file = %path.display(),
                        offset = e.offset(),
                        error = %e,
                        hidden,
                        "bad Y4M frame: handled as the end of the file"
                    );
                }
            }
        }
        // The end of the file (or what is left of it).
        let frames = reader.frames_read();
        if !looping || frames == 0 || attempt == 1 {
            tracing::info!(
                file = %path.display(),
                frames_this_pass = frames,
                looping,
                "end of the Y4M file: no more frames are published (the service stays up)"
            );
            return Next::Finished;
        }
        if let Err(e) = reader.rewind() {
            metrics.file_errors.inc();
            tracing::warn!(file = %path.display(), error = %e, "cannot rewind the Y4M file: no more frames are published");
            return Next::Finished;
        }
        metrics.file_rewinds.inc();
        tracing::debug!(file = %path.display(), frames, "Y4M file: starting again");
    }
    Next::Finished
}

/// Publishes the file's frames until `ctx.shutdown` is cancelled (then `Ok`).
pub(crate) async fn run(
    settings: Settings,
    y4m: Y4mSettings,
    ctx: Context,
    mut ports: Ports,
    metrics: Metrics,
) -> anyhow::Result<()> {
    let path = y4m.path.as_path();
    let file = File::open(path).with_context(|| format!("opening Y4M file {}", path.display()))?;
    let mut reader = Y4mReader::new(BufReader::new(file))
        .map_err(|e| anyhow::anyhow!("Y4M file {}: {e}", path.display()))?;
    let header = *reader.header();
    check_y4m_size(path, &header, settings.width, settings.height).map_err(anyhow::Error::msg)?;
    if settings.format == PixelFormat::Nv12 && (header.width % 2 != 0 || header.height % 2 != 0) {
        anyhow::bail!(
            "Y4M file {}: nv12 needs an even width and height, the file is {}×{}",
            path.display(),
            header.width,
            header.height
        );
    }
    tracing::info!(
        stream = %settings.stream,
        vehicle_id = settings.vehicle_id,
        file = %path.display(),
        width = header.width,
        height = header.height,
        file_fps = header.fps().map_or_else(|| "unknown".to_string(), |f| format!("{f:.3}")),
        chroma = ?header.chroma,
        range = ?y4m.range,
        fps = settings.fps,
        format = %settings.format,
        looping = y4m.looping,
        "camera publishing Y4M file frames on skymesh/camera/{}/frames at the configured fps",
        settings.stream,
    );
    if header.chroma == Chroma::Mono {
        tracing::info!("the Y4M file is monochrome: frames are grey");
    }
    let len = settings.frame_len();
    let stride = settings.stride() as usize;
    let converter = Converter::new(y4m.range);
    let intrinsics = settings.intrinsics.to_wire();
    let mut raw = vec![0u8; header.frame_len()];
    let mut tracker = PoseTracker::new(settings.mount);
    let mut pace = Pace::new(settings.fps, settings.always_on)?;
    let mut warn = WarnLimiter::default();
    let mut finished = false;
    let mut frame_seq = 0u64;
    ctx.ready();
    // Idle, neither the pose nor the file is read: playback pauses while nobody
    // watches.
    while pace.next(&ctx, &mut ports, &metrics).await?.is_some() {
        if finished {
            // Nothing more to publish: up and healthy until shut down.
            ctx.shutdown.cancelled().await;
            break;
        }
        let (vehicle, payload) = ports.inputs()?;
        if let Some(v) = vehicle {
            tracker.update_vehicle(&v);
        }
        if let Some(p) = payload {
            tracker.update_payload(&p);
        }
        let began = std::time::Instant::now();
        if next_frame(
            &mut reader,
            &mut raw,
            y4m.looping,
            &metrics,
            &mut warn,
            path,
        ) == Next::Finished
        {
            finished = true;
            continue;
        }
        let stamp = stamp_now(frame_seq + 1);
        let (pose, heading) = match tracker.vehicle() {
            Some(v) => {
                let (_, capture, heading) = tracker.capture(&v);
                (capture, heading)
            }
            None => (CapturePose::default(), 0.0),
        };
        let mut converted = false;
        let sent = ports.frame(len, |h, pixels| {
            converted = match settings.format {
                PixelFormat::Rgb24 => converter.to_rgb24(&header, &raw, stride, pixels),
                PixelFormat::Nv12 => converter.to_nv12(&header, &raw, stride, pixels),
            };
            h.set_geometry(
                settings.format,
                settings.width,
                settings.height,
                stride as u32,
            );
            h.frame_seq = stamp.seq;
            h.capture_mono_ns = stamp.mono_ns;
            h.capture_unix_ns = stamp.unix_ns;
            h.intrinsics = intrinsics;
            h.pose = pose;
            h.vehicle_heading_deg = heading;
        });
        metrics
            .render_seconds
            .observe(began.elapsed().as_secs_f64());
        match sent {
            Ok(_) => {
                frame_seq = stamp.seq;
                metrics.published.inc();
            }
            Err(e) => {
                metrics.skipped(Skip::PublishError, 1);
                if let Some(hidden) = warn.allow("publish", std::time::Instant::now()) {
                    tracing::warn!(error = %e, hidden, "frame not published");
                }
            }
        }
        if !converted {
            // Sizes were checked at start; this is a bug, not bad input.
            anyhow::bail!(
                "frame {} of {} could not be converted to {} ({} bytes)",
                stamp.seq,
                path.display(),
                settings.format,
                len
            );
        }
    }
    tracing::info!(frames = frame_seq, "camera stopped");
    Ok(())
}
