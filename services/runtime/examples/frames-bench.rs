//! Frame transport benchmark: iceoryx2 shared memory (the skymesh frame bus) vs a Unix
//! domain socket carrying the same bytes, between two processes, in the same run.
//!
//! ```text
//! cargo run --release -p skymesh-runtime --example frames-bench [-- FRAMES_PER_SIZE]
//! ```
//!
//! For 640×480, 1280×720 and 1920×1080 RGB24 at 30 fps: latency from publish start
//! (before the pixels are written: the camera's write is part of the transport's
//! cost) to the moment the receiving process has read the last byte (it sums every
//! byte and checks the sum). Both sides use `CLOCK_MONOTONIC`, shared by the
//! processes of one machine. The first frames (page faults of fresh mappings) are
//! not counted.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use skymesh_ipc_types::{topics, PixelFormat, ServiceId};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, Domain, Stats};

const SIZES: [(u32, u32); 3] = [(640, 480), (1280, 720), (1920, 1080)];
const WARMUP: usize = 10;
const FPS: f64 = 30.0;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("--iox-sub") => iox_receiver(&args[2], args[3].parse()?, args[4].parse()?),
        Some("--uds-sub") => uds_receiver(&args[2], args[3].parse()?, args[4].parse()?),
        other => {
            let frames: usize = other.map(str::parse).transpose()?.unwrap_or(150);
            driver(frames)
        }
    }
}

/// What the sender writes into every pixel of frame `k` (the receiver checks the sum).
fn fill_value(k: usize) -> u8 {
    (k % 251) as u8 + 1
}

/// Reads every byte; returns their sum.
fn byte_sum(bytes: &[u8]) -> u64 {
    bytes
        .chunks(4096)
        .map(|c| c.iter().map(|&b| u64::from(b)).sum::<u64>())
        .sum()
}

fn check(k: usize, len: usize, sum: u64) -> anyhow::Result<()> {
    let want = len as u64 * u64::from(fill_value(k));
    anyhow::ensure!(sum == want, "frame {k}: byte sum {sum}, expected {want}");
    Ok(())
}

fn driver(frames: usize) -> anyhow::Result<()> {
    anyhow::ensure!(frames > WARMUP, "need more than {WARMUP} frames per size");
    println!(
        "frames-bench: {frames} frames per size at {FPS} fps, first {WARMUP} not counted; \
         latency = publish start → receiver read the last byte"
    );
    println!(
        "{:>10} {:>10} | {:>12} {:>12} | {:>12} {:>12} | {:>9} {:>9}",
        "size", "bytes", "shm p50 µs", "shm p99 µs", "uds p50 µs", "uds p99 µs", "p50 ×", "p99 ×"
    );
    for (w, h) in SIZES {
        let len = (w * h * 3) as usize;
        let shm = percentiles(iox_run(w, h, frames)?);
        let uds = percentiles(uds_run(len, frames)?);
        println!(
            "{:>10} {:>10} | {:>12.1} {:>12.1} | {:>12.1} {:>12.1} | {:>9.1} {:>9.1}",
            format!("{w}x{h}"),
            len,
            shm.0 / 1e3,
            shm.1 / 1e3,
            uds.0 / 1e3,
            uds.1 / 1e3,
            uds.0 / shm.0,
            uds.1 / shm.1,
        );
    }
    Ok(())
}

fn percentiles(mut v: Vec<u64>) -> (f64, f64) {
    v.sort_unstable();
    let at = |q: f64| v[((v.len() as f64 * q) as usize).min(v.len() - 1)] as f64;
    (at(0.50), at(0.99))
}

fn spawn_child(args: &[String]) -> anyhow::Result<(Child, BufReader<std::process::ChildStdout>)> {
    let mut child = Command::new(std::env::current_exe()?)
        .args(args)
        .stdout(Stdio::piped())
        .spawn()?;
    let out = BufReader::new(child.stdout.take().expect("piped"));
    Ok((child, out))
}

fn expect_line(out: &mut BufReader<std::process::ChildStdout>, want: &str) -> anyhow::Result<()> {
    let mut line = String::new();
    out.read_line(&mut line)?;
    anyhow::ensure!(line.trim() == want, "receiver said `{}`", line.trim());
    Ok(())
}

/// Collects the receiver's latencies (one `ns` per line) and its exit status.
fn finish(mut child: Child, out: BufReader<std::process::ChildStdout>) -> anyhow::Result<Vec<u64>> {
    let mut lat = Vec::new();
    for line in out.lines() {
        lat.push(line?.trim().parse()?);
    }
    let status = child.wait()?;
    anyhow::ensure!(status.success(), "receiver failed: {status}");
    Ok(lat.split_off(WARMUP.min(lat.len())))
}

/// Paces a loop at [`FPS`].
struct Pacer {
    start: Instant,
    n: u32,
}

impl Pacer {
    fn wait(&mut self) {
        let due = self.start + Duration::from_secs_f64(f64::from(self.n) / FPS);
        self.n += 1;
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
}

fn iox_run(w: u32, h: u32, frames: usize) -> anyhow::Result<Vec<u64>> {
    let name = format!("fb{}{w}", std::process::id());
    let domain = Domain::load(&name, None)?;
    let len = (w * h * 3) as usize;
    {
        let bus = Bus::open(&domain, "bench-camera", ServiceId::Camera, 0, Stats::new())?;
        let mut publ = bus.frame_publisher(&topics::camera_frames("bench"), len)?;
        let (child, mut out) = spawn_child(&[
            "--iox-sub".into(),
            name.clone(),
            len.to_string(),
            frames.to_string(),
        ])?;
        expect_line(&mut out, "ready")?;
        std::thread::sleep(Duration::from_millis(100));
        let mut pace = Pacer {
            start: Instant::now(),
            n: 0,
        };
        for k in 0..frames {
            pace.wait();
            let t0 = monotonic_ns();
            publ.publish_with(len, |hd, pixels| {
                hd.set_geometry(PixelFormat::Rgb24, w, h, w * 3);
                hd.frame_seq = k as u64;
                hd.capture_mono_ns = t0;
                pixels.fill(fill_value(k));
            })?;
        }
        let lat = finish(child, out)?;
        drop(publ);
        drop(bus);
        domain.remove_leftover_files();
        Ok(lat)
    }
}

fn iox_receiver(domain: &str, len: usize, frames: usize) -> anyhow::Result<()> {
    let domain = Domain::load(domain, None)?;
    let bus = Bus::open(&domain, "bench-reader", ServiceId::Tool, 0, Stats::new())?;
    let mut sub = bus.frame_subscriber(&topics::camera_frames("bench"))?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    println!("ready");
    let mut lat = Vec::with_capacity(frames);
    rt.block_on(async {
        for _ in 0..frames {
            let (k, t0, n, sum) = sub
                .recv_with(|hd, pixels| {
                    let sum = byte_sum(pixels);
                    (hd.frame_seq as usize, hd.capture_mono_ns, pixels.len(), sum)
                })
                .await?;
            let t1 = monotonic_ns();
            anyhow::ensure!(n == len, "frame {k}: {n} bytes, expected {len}");
            check(k, n, sum)?;
            lat.push(t1.saturating_sub(t0));
        }
        anyhow::Ok(())
    })?;
    let mut out = std::io::stdout().lock();
    for l in lat {
        writeln!(out, "{l}")?;
    }
    Ok(())
}

fn uds_run(len: usize, frames: usize) -> anyhow::Result<Vec<u64>> {
    let dir = std::env::temp_dir().join(format!("frames-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("sock");
    let _ = std::fs::remove_file(&path);
    let listener = UnixListener::bind(&path)?;
    let (child, mut out) = spawn_child(&[
        "--uds-sub".into(),
        path.display().to_string(),
        len.to_string(),
        frames.to_string(),
    ])?;
    let (mut stream, _) = listener.accept()?;
    expect_line(&mut out, "ready")?;
    // The sender's frame buffer (what a camera fills before writing to a socket).
    let mut frame = vec![0u8; len];
    let mut pace = Pacer {
        start: Instant::now(),
        n: 0,
    };
    for k in 0..frames {
        pace.wait();
        let t0 = monotonic_ns();
        frame.fill(fill_value(k));
        let mut head = [0u8; 24];
        head[..8].copy_from_slice(&t0.to_le_bytes());
        head[8..16].copy_from_slice(&(k as u64).to_le_bytes());
        head[16..].copy_from_slice(&(len as u64).to_le_bytes());
        stream.write_all(&head)?;
        stream.write_all(&frame)?;
    }
    let lat = finish(child, out)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(lat)
}

fn uds_receiver(path: &str, len: usize, frames: usize) -> anyhow::Result<()> {
    let mut stream = UnixStream::connect(path)?;
    println!("ready");
    let mut buf = vec![0u8; len];
    let mut lat = Vec::with_capacity(frames);
    for _ in 0..frames {
        let mut head = [0u8; 24];
        stream.read_exact(&mut head)?;
        let field = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&head[i * 8..i * 8 + 8]);
            u64::from_le_bytes(b)
        };
        let (t0, k, n) = (field(0), field(1) as usize, field(2) as usize);
        anyhow::ensure!(n == len, "frame {k}: {n} bytes, expected {len}");
        stream.read_exact(&mut buf)?;
        let sum = byte_sum(&buf);
        let t1 = monotonic_ns();
        check(k, n, sum)?;
        lat.push(t1.saturating_sub(t0));
    }
    let mut out = std::io::stdout().lock();
    for l in lat {
        writeln!(out, "{l}")?;
    }
    Ok(())
}
