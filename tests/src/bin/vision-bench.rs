//! Vision benchmark: 1080p frames at 30 fps through the real camera and the real vision
//! pipeline (separate processes, the mesh's shared memory), and the same frames over a
//! Unix domain socket in the same run.
//!
//! ```text
//! cargo build --release --workspace
//! target/release/vision-bench [--seconds 20] [--width 1920] [--height 1080] [--fps 30] [--synthetic 1]
//! ```
//!
//! The camera plays a Y4M file this program writes first (a textured ground with
//! three coloured targets moving across it, 60 frames, looped), so the camera costs
//! a file read and a colour conversion per frame; `--synthetic 1` uses the camera's
//! ray-cast synthetic scene instead, which at 1080p needs more than one of this
//! machine's two cores on its own and so loads the pipeline's measurements.
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
    let synthetic = arg("--synthetic", 0) == 1;
    let dir = tempfile::tempdir()?;
    let source = if synthetic {
        "[synthetic]\nrender_threads = 2\n\
         [[synthetic.targets]]\nid = 1\nsize_m = 3.0\nrgb = [220, 40, 40]\n\
         circle = { center_ne_m = [0.0, 0.0], radius_m = 12.0, speed_mps = 1.5 }\n\
         [[synthetic.targets]]\nid = 2\nshape = \"square\"\nsize_m = 2.5\nrgb = [40, 70, 220]\n\
         line = { from_ne_m = [-15.0, -20.0], to_ne_m = [15.0, 20.0], speed_mps = 1.2 }\n"
            .to_string()
    } else {
        let path = dir.path().join("bench.y4m");
        write_y4m(&path, w as usize, h as usize, 60)?;
        format!(
            "source = \"y4m\"\n[y4m]\npath = {:?}\nloop = true\n",
            path.display().to_string()
        )
    };
    // `source` must precede the tables: split the top-level line off.
    let (top, tables) = match source.split_once('\n') {
        Some((first, rest)) if first.starts_with("source") => {
            (format!("{first}\n"), rest.to_string())
        }
        _ => (String::new(), source.clone()),
    };
    let mut mesh = Mesh::start(MeshOptions {
        vision: true,
        attitude_hz: 25.0,
        camera_extra: format!(
            "stream = \"main\"\nwidth = {w}\nheight = {h}\nfps = {fps}\nformat = \"rgb24\"\n{top}\
             [lens]\nmodel = \"pinhole\"\nhfov_deg = 90.0\n\
             [mount]\nuse_gimbal = false\npitch_deg = -90.0\n{tables}"
        ),
        // Every frame processed with no consumer attached: the pipeline's full rate.
        vision_extra:
            "always_on = true\n[[streams]]\nname = \"main\"\nwidth = 1280\nheight = 720\nlayout = 0\noverlay = 2\n"
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
    // Frames in shared memory, on their own thread blocked on the frame topic's
    // event (like a real consumer): publish → every byte read here.
    let frame_bus = bus.clone();
    let frames_for = Duration::from_secs(seconds + 3);
    let frame_thread = std::thread::spawn(move || -> Result<Vec<f64>> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let mut frames = frame_bus.frame_subscriber(&topics::camera_frames("main"))?;
        let mut out = Vec::new();
        let t0 = Instant::now();
        rt.block_on(async {
            while t0.elapsed() < frames_for {
                let got = tokio::time::timeout(
                    Duration::from_secs(1),
                    frames.recv_with(|hdr, px| {
                        std::hint::black_box(byte_sum(px));
                        monotonic_ns().saturating_sub(hdr.header.stamp_ns)
                    }),
                )
                .await;
                if let Ok(ns) = got {
                    // Skip the warm-up (fresh mappings fault in).
                    if t0.elapsed() > Duration::from_secs(3) {
                        out.push(ns.map_err(|e| anyhow::anyhow!("{e}"))? as f64 / 1e6);
                    }
                }
            }
            Ok::<_, anyhow::Error>(())
        })?;
        Ok(out)
    });
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
    let mut last_seq = s0.last_frame_seq;
    let t0 = Instant::now();
    let mut last = first;
    while t0.elapsed() < Duration::from_secs(seconds) {
        if let Some(s) = rt.block_on(states.recv_timeout(Duration::from_millis(100)))? {
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

    let mut transfer = frame_thread
        .join()
        .map_err(|_| anyhow::anyhow!("frame thread panicked"))??;
    // The baseline: the same bytes at the same rate over a Unix socket, same run.
    let len = (w * h * 3) as usize;
    let uds = uds_baseline(len, fps, transfer.len().clamp(30, 300))?;

    for v in [&mut pipeline, &mut arrival, &mut transfer] {
        v.sort_by(f64::total_cmp);
    }
    let mut uds = uds;
    uds.sort_by(f64::total_cmp);
    let p = |v: &[f64], q: f64| percentile(v, q / 100.0);
    println!(
        "vision-bench: {w}x{h} RGB24 at {fps} fps, {elapsed:.1} s, camera ({}) → pipeline (output 1280x720, one view, detection overlay)",
        if synthetic { "synthetic scene" } else { "Y4M file" }
    );
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

/// A 4:2:0 Y4M file of `n` frames: a textured ground (noise on a grid) with three
/// coloured discs moving across it.
fn write_y4m(path: &std::path::Path, w: usize, h: usize, n: usize) -> Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(f, "YUV4MPEG2 W{w} H{h} F30:1 Ip A1:1 C420jpeg")?;
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut y = vec![0u8; w * h];
    let mut u = vec![0u8; cw * ch];
    let mut v = vec![0u8; cw * ch];
    // (Y, Cb, Cr) of red, blue, yellow.
    let discs = [(81u8, 90u8, 240u8), (41, 240, 110), (210, 16, 146)];
    let mut seed = 0x2545_f491_u32;
    let mut noise = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        (seed % 24) as u8
    };
    let base: Vec<u8> = (0..w * h)
        .map(|i| {
            let (x, yy) = (i % w, i / w);
            let grid = if x % 160 < 3 || yy % 160 < 3 { 40 } else { 0 };
            100 + noise() + grid
        })
        .collect();
    for k in 0..n {
        y.copy_from_slice(&base);
        u.fill(118);
        v.fill(122);
        for (j, &(dy, du, dv)) in discs.iter().enumerate() {
            let t = k as f64 / n as f64 * std::f64::consts::TAU;
            let cx = w as f64 * (0.5 + 0.3 * (t + j as f64 * 2.1).cos());
            let cy = h as f64 * (0.5 + 0.3 * (t + j as f64 * 2.1).sin());
            let r = h as f64 / 40.0;
            for py in (cy - r) as usize..((cy + r) as usize).min(h) {
                for px in (cx - r) as usize..((cx + r) as usize).min(w) {
                    if (px as f64 - cx).hypot(py as f64 - cy) <= r {
                        y[py * w + px] = dy;
                        u[(py / 2) * cw + px / 2] = du;
                        v[(py / 2) * cw + px / 2] = dv;
                    }
                }
            }
        }
        f.write_all(b"FRAME\n")?;
        f.write_all(&y)?;
        f.write_all(&u)?;
        f.write_all(&v)?;
    }
    f.flush()?;
    Ok(())
}
