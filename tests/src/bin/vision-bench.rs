//! Vision benchmark: 1080p frames at 30 fps through the real camera and the real vision
//! pipeline (separate processes, the mesh's shared memory), and the same frames over a
//! Unix domain socket in the same run.
//!
//! ```text
//! cargo build --release --workspace
//! target/release/vision-bench [--seconds 20] [--width 1920] [--height 1080] [--fps 30]
//! ```
//!
//! Prints:
//! 1. **Per-frame latency**, capture → detections published: from the frame's
//!    `capture_mono_ns` (stamped by the camera before it renders) to the pipeline's
//!    `last_processed_mono_ns` in `VisionState` (detections, tracks, virtual views
//!    rendered, state written), p50/p99; and to the moment this process received the
//!    state.
//! 2. **CPU per frame** of the camera (rendering) and the pipeline (everything above),
//!    from `/proc/<pid>/stat` over the run, divided by the frames each handled.
//! 3. **Transfer cost**: from the camera's publish (`stamp_ns`, after the pixels are
//!    written) to this process having read every byte of the frame in shared memory,
//!    vs a Unix socket carrying the same number of bytes at the same rate between two
//!    threads of this process (write start → last byte read), same run, same load.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use skymesh_e2e::bench::{arg, percentile, take_off};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{topics, VisionState};
use skymesh_runtime::clock::monotonic_ns;

fn main() -> Result<()> {
    let seconds = arg("--seconds", 20);
    let (w, h, fps) = (
        arg("--width", 1920),
        arg("--height", 1080),
        arg("--fps", 30),
    );
    let mut mesh = Mesh::start(MeshOptions {
        vision: true,
        attitude_hz: 25.0,
        camera_extra: format!(
            "stream = \"main\"\nwidth = {w}\nheight = {h}\nfps = {fps}\nformat = \"rgb24\"\n\
             [lens]\nmodel = \"pinhole\"\nhfov_deg = 90.0\n\
             [mount]\nuse_gimbal = false\npitch_deg = -90.0\n\
             [synthetic]\nrender_threads = 2\n\
             [[synthetic.targets]]\nid = 1\nsize_m = 3.0\nrgb = [220, 40, 40]\n\
             circle = {{ center_ne_m = [0.0, 0.0], radius_m = 12.0, speed_mps = 1.5 }}\n\
             [[synthetic.targets]]\nid = 2\nshape = \"square\"\nsize_m = 2.5\nrgb = [40, 70, 220]\n\
             line = {{ from_ne_m = [-15.0, -20.0], to_ne_m = [15.0, 20.0], speed_mps = 1.2 }}\n"
        ),
        vision_extra:
            "[[streams]]\nname = \"main\"\nwidth = 1280\nheight = 720\nlayout = 0\noverlay = 2\n"
                .into(),
        ..Default::default()
    })?;
    for name in ["vehicle-sim", "autopilot-link", "camera", "vision-pipeline"] {
        mesh.wait_running(name, Duration::from_secs(60))
            .with_context(|| format!("{name} did not start"))?;
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    rt.block_on(take_off(&mesh, 50.0))?;
    let bus = mesh.bus("vision-bench")?;
    let mut states = bus.subscriber::<VisionState>(&topics::vision_state())?;
    let frames = bus.frame_subscriber(&topics::camera_frames("main"))?;
    let pid = |name: &str| -> Result<u32> {
        mesh.service(name)?["pid"]
            .as_u64()
            .map(|p| p as u32)
            .context("no pid")
    };
    let (cam_pid, vis_pid) = (pid("camera")?, pid("vision-pipeline")?);
    // Warm up (page faults of fresh mappings, the tracker settling).
    std::thread::sleep(Duration::from_secs(3));

    let cpu0 = (cpu_s(cam_pid)?, cpu_s(vis_pid)?);
    let first = rt
        .block_on(states.recv_timeout(Duration::from_secs(5)))?
        .context("no vision state")?;
    let s0 = first.streams[0];
    let mut pipeline = Vec::new();
    let mut arrival = Vec::new();
    let mut transfer = Vec::new();
    let mut last_seq = s0.last_frame_seq;
    let mut last_frame_seq = 0;
    let t0 = Instant::now();
    let mut last = first;
    while t0.elapsed() < Duration::from_secs(seconds) {
        // Frames in shared memory: publish → every byte read here.
        while let Some((ns, seq)) = frames
            .try_recv_with(|hdr, px| {
                let sum = byte_sum(px);
                std::hint::black_box(sum);
                (
                    monotonic_ns().saturating_sub(hdr.header.stamp_ns),
                    hdr.frame_seq,
                )
            })
            .map_err(|e| anyhow::anyhow!("{e}"))?
        {
            if seq != last_frame_seq {
                transfer.push(ns as f64 / 1e6);
                last_frame_seq = seq;
            }
        }
        if let Some(s) = rt.block_on(states.recv_timeout(Duration::from_millis(5)))? {
            let st = s.streams[0];
            if st.last_frame_seq != last_seq && st.last_capture_mono_ns > 0 {
                last_seq = st.last_frame_seq;
                pipeline.push(
                    st.last_processed_mono_ns
                        .saturating_sub(st.last_capture_mono_ns) as f64
                        / 1e6,
                );
                arrival.push(monotonic_ns().saturating_sub(st.last_capture_mono_ns) as f64 / 1e6);
            }
            last = s;
        }
    }
    let elapsed = t0.elapsed().as_secs_f64();
    let cpu1 = (cpu_s(cam_pid)?, cpu_s(vis_pid)?);
    let s1 = last.streams[0];
    let processed = s1.frames_processed.saturating_sub(s0.frames_processed);
    let dropped = s1.frames_dropped.saturating_sub(s0.frames_dropped);
    let rendered = (processed + dropped).max(1);

    // The baseline: the same bytes at the same rate over a Unix socket, same run.
    let len = (w * h * 3) as usize;
    let uds = uds_baseline(len, fps, transfer.len().clamp(30, 300))?;

    for v in [&mut pipeline, &mut arrival, &mut transfer] {
        v.sort_by(f64::total_cmp);
    }
    let mut uds = uds;
    uds.sort_by(f64::total_cmp);
    let p = |v: &[f64], q: f64| percentile(v, q);
    println!("vision-bench: {w}x{h} RGB24 at {fps} fps, {elapsed:.1} s, camera → pipeline (output 1280x720, one view, detection overlay)");
    println!(
        "  frames: {processed} processed, {dropped} skipped by the pipeline (newest wins); detections now {}",
        last.detection_count
    );
    println!(
        "  capture → detections published (pipeline): p50 {:.2} ms  p99 {:.2} ms  (n={})",
        p(&pipeline, 50.0),
        p(&pipeline, 99.0),
        pipeline.len()
    );
    println!(
        "  capture → state received here:             p50 {:.2} ms  p99 {:.2} ms",
        p(&arrival, 50.0),
        p(&arrival, 99.0)
    );
    println!(
        "  CPU per frame: camera (render) {:.2} ms, pipeline {:.2} ms",
        (cpu1.0 - cpu0.0) * 1e3 / rendered as f64,
        (cpu1.1 - cpu0.1) * 1e3 / processed.max(1) as f64
    );
    println!(
        "  transfer, publish → all {len} bytes read: shared memory p50 {:.3} ms p99 {:.3} ms (n={}); Unix socket p50 {:.3} ms p99 {:.3} ms (n={}); ratio p50 {:.1}x",
        p(&transfer, 50.0),
        p(&transfer, 99.0),
        transfer.len(),
        p(&uds, 50.0),
        p(&uds, 99.0),
        uds.len(),
        p(&uds, 50.0) / p(&transfer, 50.0).max(1e-6)
    );
    mesh.stop(Duration::from_secs(10))?;
    Ok(())
}

/// utime + stime of `pid`, seconds.
fn cpu_s(pid: u32) -> Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the command name (which may contain spaces) in parentheses.
    let rest = stat.rsplit_once(')').context("stat")?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>()? + f[12].parse::<f64>()?;
    let hz = nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)?.unwrap_or(100) as f64;
    Ok(ticks / hz)
}

fn byte_sum(bytes: &[u8]) -> u64 {
    bytes
        .chunks(4096)
        .map(|c| c.iter().map(|&b| u64::from(b)).sum::<u64>())
        .sum()
}

/// `n` frames of `len` bytes at `fps` between two threads over a Unix socket: write
/// start (stamped in an 8-byte prefix) → last byte read and summed, ms.
fn uds_baseline(len: usize, fps: u64, n: usize) -> Result<Vec<f64>> {
    let (mut tx, mut rx) = UnixStream::pair()?;
    let reader = std::thread::spawn(move || -> Result<Vec<f64>> {
        let mut buf = vec![0u8; len];
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let mut stamp = [0u8; 8];
            rx.read_exact(&mut stamp)?;
            rx.read_exact(&mut buf)?;
            std::hint::black_box(byte_sum(&buf));
            out.push(monotonic_ns().saturating_sub(u64::from_le_bytes(stamp)) as f64 / 1e6);
        }
        Ok(out)
    });
    let frame: Vec<u8> = (0..len).map(|i| (i % 251) as u8).collect();
    let period = Duration::from_secs_f64(1.0 / fps as f64);
    let mut next = Instant::now();
    for _ in 0..n {
        tx.write_all(&monotonic_ns().to_le_bytes())?;
        tx.write_all(&frame)?;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    reader
        .join()
        .map_err(|_| anyhow::anyhow!("uds reader panicked"))?
}
