//! Frame transport benchmark (issue 10, item 3): iceoryx2 shared memory (the skymesh
//! frame bus) vs a Unix domain socket carrying the same bytes, between two processes,
//! in the same run.
//!
//! ```text
//! cargo run --release -p skymesh-e2e --bin frames-bench [-- FRAMES_PER_PHASE]
//! ```
//!
//! For 640×480, 1280×720 and 1920×1080 RGB24 at 30 fps, four phases per size in this
//! order (fresh child process each), FRAMES_PER_PHASE frames each (default 200), the
//! first [`WARMUP`] not counted (page faults of fresh mappings, first wake-ups):
//!
//! - `full` (camera → pipeline, everything): latency from publish start, before the
//!   pixels are written (the camera's write is part of the transport's cost), to the
//!   moment the receiving process has read the last byte (it sums every byte and
//!   checks the sum). For iceoryx2 that is loan (zero-filled by iceoryx2) + pixel
//!   write + send + wake-up + read in place; for the socket, pixel write into the
//!   sender's buffer + `write_all` + `read_exact` + read.
//! - `xfer` (transfer only): the frame is already written when the clock starts and
//!   the receiver does not read the pixels. iceoryx2: the publisher loans and writes
//!   the frame (not timed); the bus stamps `header.stamp_ns` just before `send`; the
//!   receiver's time is taken in `recv_with`'s closure, when it holds the sample
//!   (header read, pixels untouched but the first and last byte checked after the
//!   clock stopped). Socket: header and pixels already in one buffer, stamped just
//!   before one `write_all`; receipt after `read_exact` of the whole frame (a socket
//!   has to move every byte: that is its transfer).
//!
//! The iceoryx2 receiver awaits `FrameSubscriber::recv_with` in a tokio
//! current-thread runtime, as the services receive frames.
//!
//! `FRAMES_BENCH_ONLY=1920` runs one size; `FRAMES_BENCH_RX_CPU=1 taskset -c 0 frames-bench` gives the receivers CPU 1 and
//! the sender CPU 0; `FRAMES_BENCH_RX_RT=10` runs the receivers under `SCHED_FIFO`.
//! `FRAMES_BENCH_MODES=xfer` runs those phases only.
//! `FRAMES_BENCH_TX_YIELD=1` makes the iceoryx2 sender yield its CPU
//! (`sched_yield`) right after each `publish_with`, so a receiver the kernel woke on
//! the sender's CPU runs before the sender goes to sleep (an experiment, counted in
//! the publisher's `send` column; docs/benchmarks.md, "Then: the publisher yields").
//!
//! Both sides use `CLOCK_MONOTONIC`, shared by the processes of one machine. CPU per
//! frame is `CLOCK_PROCESS_CPUTIME_ID` over the counted frames on each side. In the
//! iceoryx2 `xfer` phase the sender also measures the loan itself (the call to
//! `publish_with` until its closure runs: `loan_slice`, which zero-fills the slice)
//! and the pixel write, per frame, and the rest of `publish_with`:
//! header check, stamp, `send`, notify.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::time::Duration;

use anyhow::{ensure, Result};
use skymesh_e2e::transport_bench::{
    die_with_parent, expect_line, finish_child, percentiles, spawn_child, DomainGuard, Pacer, Rate,
    RxReport, SendCpu, Tally,
};
use skymesh_ipc_types::{topics, FrameHeader, PixelFormat, ServiceId};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, Domain, Stats};

const SIZES: [(u32, u32); 3] = [(640, 480), (1280, 720), (1920, 1080)];
const WARMUP: usize = 10;
const FPS: f64 = 30.0;
/// A receiver stops when no frame arrived for this long (a frame was lost).
const IDLE_END: Duration = Duration::from_secs(2);
/// Bytes in front of every frame on the socket: send stamp, index, length.
const HEAD: usize = 24;

/// What a phase measures.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// Pixel write + transfer + reading every byte.
    Full,
    /// Transfer only.
    Xfer,
}

impl Mode {
    fn arg(self) -> &'static str {
        match self {
            Mode::Full => "full",
            Mode::Xfer => "xfer",
        }
    }

    fn parse(s: &str) -> Result<Mode> {
        match s {
            "full" => Ok(Mode::Full),
            "xfer" => Ok(Mode::Xfer),
            _ => anyhow::bail!("unknown mode `{s}`"),
        }
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    match args.get(1).map(String::as_str) {
        Some("--iox-sub") => {
            die_with_parent()?;
            pin_receiver()?;
            iox_receiver(
                &args[2],
                args[3].parse()?,
                args[4].parse()?,
                Mode::parse(&args[5])?,
            )
        }
        Some("--uds-sub") => {
            die_with_parent()?;
            pin_receiver()?;
            uds_receiver(
                &args[2],
                args[3].parse()?,
                args[4].parse()?,
                Mode::parse(&args[5])?,
            )
        }
        other => {
            let frames: usize = other.map(str::parse).transpose()?.unwrap_or(200);
            driver(frames)
        }
    }
}

/// `FRAMES_BENCH_RX_CPU=N`: every receiving child (iceoryx2 and socket alike) pins
/// itself to CPU N, the consumer on a core of its own. Place the sender with
/// `taskset -c M frames-bench`. `FRAMES_BENCH_RX_RT=P`: the receiving children
/// run under `SCHED_FIFO` at P (the sender keeps the bench's scheduling).
fn pin_receiver() -> Result<()> {
    use skymesh_runtime::realtime;
    if let Ok(v) = std::env::var("FRAMES_BENCH_RX_CPU") {
        let cpus =
            realtime::parse_cpus(&v).map_err(|e| anyhow::anyhow!("FRAMES_BENCH_RX_CPU: {e}"))?;
        realtime::pin(&cpus)
            .map_err(|e| anyhow::anyhow!("FRAMES_BENCH_RX_CPU={v}: cannot pin: {e}"))?;
    }
    if let Ok(v) = std::env::var("FRAMES_BENCH_RX_RT") {
        let priority = realtime::parse(&v)
            .map_err(|e| anyhow::anyhow!("FRAMES_BENCH_RX_RT: {e}"))?
            .ok_or_else(|| anyhow::anyhow!("FRAMES_BENCH_RX_RT: 0 is not real time"))?;
        realtime::apply(priority)
            .map_err(|e| anyhow::anyhow!("FRAMES_BENCH_RX_RT={v}: refused: {e:?}"))?;
    }
    Ok(())
}

/// A `NAME=1` switch: unset or `0` is off, `1` on, anything else refused (as the
/// other knobs refuse what they cannot read).
fn env_flag(name: &str) -> Result<bool> {
    match std::env::var(name) {
        Err(_) => Ok(false),
        Ok(v) if v == "0" => Ok(false),
        Ok(v) if v == "1" => Ok(true),
        Ok(v) => Err(anyhow::anyhow!("{name}: `{v}` is neither 1 nor 0")),
    }
}

/// What the sender writes into every pixel of frame `k` (the receiver checks it).
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

fn check_sum(k: usize, len: usize, sum: u64) -> Result<()> {
    let want = len as u64 * u64::from(fill_value(k));
    ensure!(sum == want, "frame {k}: byte sum {sum}, expected {want}");
    Ok(())
}

fn check_ends(k: usize, pixels: (u8, u8)) -> Result<()> {
    let v = fill_value(k);
    ensure!(
        pixels == (v, v),
        "frame {k}: first/last byte {pixels:?}, expected {v}"
    );
    Ok(())
}

/// One phase's result.
struct Phase {
    rx: RxReport,
    tx_cpu: f64,
    /// iceoryx2 `xfer` only: per counted frame, the loan (ns) and the pixel write (ns).
    loan: Vec<u64>,
    write: Vec<u64>,
    /// From the end of the pixel write to `publish_with`'s return: header check,
    /// stamp, `send`, notify (ns).
    send: Vec<u64>,
}

impl Phase {
    fn p(&self) -> [f64; 3] {
        percentiles(&self.rx.latencies())
    }
}

fn driver(frames: usize) -> Result<()> {
    ensure!(frames > WARMUP, "need more than {WARMUP} frames per phase");
    println!(
        "frames-bench: RGB24 frames, this process → a child process, {frames} frames per phase \
         at {FPS} fps, first {WARMUP} not counted; full = publish start → receiver read the \
         last byte; xfer = stamp before send/write_all → receiver holds the frame; \
         latency µs, CPU µs per frame"
    );
    println!(
        "{:>9} {:>8} {:>4} {:>4} {:>7} | {:>9} {:>9} {:>9} | {:>8} {:>8}",
        "size", "bytes", "mode", "via", "got", "p50", "p99", "p999", "tx cpu", "rx cpu"
    );
    let mut iox_p = Vec::new();
    let mut loans = Vec::new();
    // FRAMES_BENCH_ONLY=1920 runs one size (for profiling).
    let only: Option<u32> = match std::env::var("FRAMES_BENCH_ONLY") {
        Ok(v) => Some(
            v.parse()
                .map_err(|_| anyhow::anyhow!("FRAMES_BENCH_ONLY: `{v}` is not a frame width"))?,
        ),
        Err(_) => None,
    };
    if let Some(o) = only {
        ensure!(
            SIZES.iter().any(|&(w, _)| w == o),
            "FRAMES_BENCH_ONLY: no frame size {o} pixels wide (640, 1280 or 1920)"
        );
    }
    // FRAMES_BENCH_MODES=xfer runs those phases only.
    let modes: Option<Vec<Mode>> = match std::env::var("FRAMES_BENCH_MODES") {
        Ok(v) => Some(
            v.split(',')
                .map(Mode::parse)
                .collect::<Result<_>>()
                .map_err(|e| anyhow::anyhow!("FRAMES_BENCH_MODES: {e}"))?,
        ),
        Err(_) => None,
    };
    for (w, h) in SIZES {
        if only.is_some_and(|o| o != w) {
            continue;
        }
        let len = (w * h * 3) as usize;
        for mode in [Mode::Full, Mode::Xfer] {
            if modes.as_ref().is_some_and(|m| !m.contains(&mode)) {
                continue;
            }
            let iox = iox_run(w, h, frames, mode)?;
            let uds = uds_run(len, frames, mode)?;
            let (pi, pu) = (iox.p(), uds.p());
            for (via, ph, p) in [("iox", &iox, pi), ("uds", &uds, pu)] {
                println!(
                    "{:>9} {:>8} {:>4} {:>4} {:>7} | {:>9.1} {:>9.1} {:>9.1} | {:>8.1} {:>8.1}",
                    format!("{w}x{h}"),
                    len,
                    mode.arg(),
                    via,
                    format!("{}/{frames}", ph.rx.got),
                    p[0] / 1e3,
                    p[1] / 1e3,
                    p[2] / 1e3,
                    ph.tx_cpu / 1e3,
                    ph.rx.cpu_per_msg() / 1e3,
                );
            }
            println!(
                "{:>9} {:>8} {:>4} {:>4} {:>7} | {:>9.1} {:>9.1} {:>9.1} | {:>8.1} {:>8.1}",
                format!("{w}x{h}"),
                len,
                mode.arg(),
                "u÷i",
                "",
                pu[0] / pi[0],
                pu[1] / pi[1],
                pu[2] / pi[2],
                uds.tx_cpu / iox.tx_cpu,
                uds.rx.cpu_per_msg() / iox.rx.cpu_per_msg(),
            );
            if mode != Mode::Full {
                loans.push((
                    w,
                    h,
                    mode,
                    percentiles(&iox.loan),
                    percentiles(&iox.write),
                    percentiles(&iox.send),
                ));
            }
            iox_p.push((w, mode, pi));
        }
    }
    println!("iceoryx2 publisher, per frame (xfer phases): µs");
    println!(
        "{:>9} {:>4} | {:>9} {:>9} {:>9} | {:>9} {:>9} {:>9} | {:>9} {:>9} {:>9}",
        "size",
        "mode",
        "loan p50",
        "loan p99",
        "loan p999",
        "write p50",
        "write p99",
        "write p999",
        "send p50",
        "send p99",
        "send p999"
    );
    // `send` = header check + stamp + send + notify.
    for (w, h, mode, l, wr, se) in loans {
        println!(
            "{:>9} {:>4} | {:>9.1} {:>9.1} {:>9.1} | {:>9.1} {:>9.1} {:>9.1} | {:>9.1} {:>9.1} {:>9.1}",
            format!("{w}x{h}"),
            mode.arg(),
            l[0] / 1e3,
            l[1] / 1e3,
            l[2] / 1e3,
            wr[0] / 1e3,
            wr[1] / 1e3,
            wr[2] / 1e3,
            se[0] / 1e3,
            se[1] / 1e3,
            se[2] / 1e3,
        );
    }
    for mode in [Mode::Full, Mode::Xfer] {
        let find = |w: u32| iox_p.iter().find(|e| e.0 == w && e.1 == mode).map(|e| e.2);
        if let (Some(small), Some(big)) = (find(640), find(1920)) {
            println!(
                "iox {} 1080p ÷ 480p: p50 {:.2}, p99 {:.2}, p999 {:.2}",
                mode.arg(),
                big[0] / small[0],
                big[1] / small[1],
                big[2] / small[2],
            );
        }
    }
    Ok(())
}

fn iox_run(w: u32, h: u32, frames: usize, mode: Mode) -> Result<Phase> {
    let name = format!("fb{}{w}{}", std::process::id(), mode.arg());
    let domain = DomainGuard(Domain::load(&name, None)?);
    let len = (w * h * 3) as usize;
    let bus = Bus::open(
        &domain.0,
        "bench-camera",
        ServiceId::Camera,
        0,
        Stats::new(),
    )?;
    let mut publ = bus.frame_publisher(&topics::camera_frames("bench"), len)?;
    let (child, mut out) = spawn_child(&[
        "--iox-sub".into(),
        name.clone(),
        len.to_string(),
        frames.to_string(),
        mode.arg().into(),
    ])?;
    expect_line(&mut out, "ready")?;
    std::thread::sleep(Duration::from_millis(100));
    let tx_yield = env_flag("FRAMES_BENCH_TX_YIELD")?;
    let mut pace = Pacer::new(Rate::Hz(FPS));
    let mut cpu = SendCpu::new(WARMUP);
    let mut loan = Vec::with_capacity(frames);
    let mut write = Vec::with_capacity(frames);
    let mut send = Vec::with_capacity(frames);
    for k in 0..frames {
        pace.wait();
        cpu.at(k);
        let t0 = monotonic_ns();
        let mut t_loaned = 0;
        let mut t_written = 0;
        publ.publish_with(len, |hd, pixels| {
            t_loaned = monotonic_ns();
            hd.set_geometry(PixelFormat::Rgb24, w, h, w * 3);
            hd.frame_seq = k as u64;
            hd.capture_mono_ns = t0;
            pixels.fill(fill_value(k));
            t_written = monotonic_ns();
        })?;
        if tx_yield {
            std::thread::yield_now();
        }
        let t_sent = monotonic_ns();
        if k >= WARMUP {
            loan.push(t_loaned.saturating_sub(t0));
            write.push(t_written.saturating_sub(t_loaned));
            send.push(t_sent.saturating_sub(t_written));
        }
    }
    let tx_cpu = cpu.per_msg();
    let rx = finish_child(child, out)?;
    drop(publ);
    drop(bus);
    let (loan, write, send) = match mode {
        Mode::Xfer => (loan, write, send),
        Mode::Full => (Vec::new(), Vec::new(), Vec::new()),
    };
    Ok(Phase {
        rx,
        tx_cpu,
        loan,
        write,
        send,
    })
}

fn iox_receiver(domain: &str, len: usize, frames: usize, mode: Mode) -> Result<()> {
    let domain = Domain::load(domain, None)?;
    let bus = Bus::open(&domain, "bench-reader", ServiceId::Tool, 0, Stats::new())?;
    let mut sub = bus.frame_subscriber(&topics::camera_frames("bench"))?;
    let mut tally = Tally::new(frames, WARMUP);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    println!("ready");
    // Waits in the kernel on the stream's event (an async `recv_with`, as the
    // services receive), as the socket receiver blocks in `read_exact`.
    let read = |hd: &FrameHeader, pixels: &[u8]| {
        let k = hd.frame_seq as usize;
        match mode {
            Mode::Full => {
                let sum = byte_sum(pixels);
                let t1 = monotonic_ns();
                (k, hd.capture_mono_ns, t1, pixels.len(), sum, (0, 0))
            }
            Mode::Xfer => {
                let t1 = monotonic_ns();
                let ends = (
                    pixels.first().copied().unwrap_or(0),
                    pixels.last().copied().unwrap_or(0),
                );
                (k, hd.header.stamp_ns, t1, pixels.len(), 0, ends)
            }
        }
    };
    while let Ok(got) =
        rt.block_on(async { tokio::time::timeout(IDLE_END, sub.recv_with(read)).await })
    {
        let (k, t0, t1, n, sum, ends) = got?;
        ensure!(n == len, "frame {k}: {n} bytes, expected {len}");
        match mode {
            Mode::Full => check_sum(k, n, sum)?,
            Mode::Xfer => check_ends(k, ends)?,
        }
        tally.add(k, t0, t1);
        if k + 1 >= frames {
            break;
        }
    }
    tally.report()
}

fn uds_run(len: usize, frames: usize, mode: Mode) -> Result<Phase> {
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
        mode.arg().into(),
    ])?;
    let (mut stream, _) = listener.accept()?;
    expect_line(&mut out, "ready")?;
    // The sender's buffer: header then the frame (what a camera fills before writing).
    let mut buf = vec![0u8; HEAD + len];
    let mut pace = Pacer::new(Rate::Hz(FPS));
    let mut cpu = SendCpu::new(WARMUP);
    for k in 0..frames {
        pace.wait();
        cpu.at(k);
        let t0 = match mode {
            Mode::Full => {
                let t0 = monotonic_ns();
                buf[HEAD..].fill(fill_value(k));
                t0
            }
            Mode::Xfer => {
                buf[HEAD..].fill(fill_value(k));
                monotonic_ns()
            }
        };
        buf[..8].copy_from_slice(&t0.to_le_bytes());
        buf[8..16].copy_from_slice(&(k as u64).to_le_bytes());
        buf[16..HEAD].copy_from_slice(&(len as u64).to_le_bytes());
        stream.write_all(&buf)?;
    }
    let tx_cpu = cpu.per_msg();
    let rx = finish_child(child, out)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(Phase {
        rx,
        tx_cpu,
        loan: Vec::new(),
        write: Vec::new(),
        send: Vec::new(),
    })
}

fn uds_receiver(path: &str, len: usize, frames: usize, mode: Mode) -> Result<()> {
    let mut stream = UnixStream::connect(path)?;
    stream.set_read_timeout(Some(IDLE_END))?;
    let mut tally = Tally::new(frames, WARMUP);
    println!("ready");
    let mut buf = vec![0u8; len];
    for _ in 0..frames {
        let mut head = [0u8; HEAD];
        stream.read_exact(&mut head)?;
        let field = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&head[i * 8..i * 8 + 8]);
            u64::from_le_bytes(b)
        };
        let (t0, k, n) = (field(0), field(1) as usize, field(2) as usize);
        ensure!(n == len, "frame {k}: {n} bytes, expected {len}");
        stream.read_exact(&mut buf)?;
        match mode {
            Mode::Full => {
                let sum = byte_sum(&buf);
                let t1 = monotonic_ns();
                check_sum(k, n, sum)?;
                tally.add(k, t0, t1);
            }
            Mode::Xfer => {
                let t1 = monotonic_ns();
                check_ends(k, (buf[0], buf[len - 1]))?;
                tally.add(k, t0, t1);
            }
        }
    }
    tally.report()
}
