//! Cost of one vehicle-sim process in swarm mode: CPU and RSS of the real
//! `skymesh-vehicle-sim` binary serving N idle vehicles (on the ground,
//! disarmed) for a window, first with no clients (physics only), then with one
//! TCP client per vehicle reading the default telemetry streams (as one
//! autopilot-link per vehicle would, before it raises any rate). Prints numbers;
//! asserts nothing.
//!
//! ```sh
//! cargo build --release -p skymesh-vehicle-sim --bins --examples
//! ./target/release/examples/swarm-load                # 10, 100, 250 vehicles, 10 s each
//! ./target/release/examples/swarm-load 250 --secs 20  # one size, a longer window
//! ```
//!
//! The simulator runs in its own iceoryx2 domain (`simload<pid>`), is stopped
//! with SIGTERM, and the domain's leftover files are removed afterwards.

use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::io::AsyncReadExt;
use tokio::net::TcpStream;

fn main() -> anyhow::Result<()> {
    let mut sizes = Vec::new();
    let mut secs = 10.0;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--secs" => secs = args.next().unwrap_or_default().parse()?,
            "-h" | "--help" => {
                println!("usage: swarm-load [N ...] [--secs S]   (default 10 100 250, 10 s)");
                return Ok(());
            }
            n => sizes.push(n.parse::<u32>()?),
        }
    }
    if sizes.is_empty() {
        sizes = vec![10, 100, 250];
    }
    let window = Duration::from_secs_f64(secs);
    let bin = sim_binary()?;
    println!(
        "{} — idle vehicles, default stream rates, {secs} s windows",
        bin.display()
    );
    println!(
        "{:>8} {:>10} {:>12} {:>10} {:>14} {:>14}",
        "vehicles", "clients", "CPU %core", "RSS MiB", "frames/s in", "bytes/s in"
    );
    let domain = format!("simload{}", std::process::id());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    for n in sizes {
        let dir = tempfile_dir()?;
        let base = free_port_run(n)?;
        let cfg = dir.join("vehicle-sim.toml");
        std::fs::write(
            &cfg,
            format!("endpoint = \"tcp:127.0.0.1:{base}\"\n[swarm]\ncount = {n}\n"),
        )?;
        let mut child = Command::new(&bin)
            .arg("--config")
            .arg(&cfg)
            .env("SKYMESH_DOMAIN", &domain)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()?;
        let result = rt.block_on(measure(&child, base, n, window));
        stop(&mut child);
        let _ = std::fs::remove_dir_all(&dir);
        // iceoryx2 keeps a small management file per domain; leave nothing behind.
        if let Ok(d) = skymesh_runtime::Domain::load(&domain, None) {
            d.cleanup_dead_nodes();
            if d.live_nodes().is_empty() {
                d.remove_leftover_files();
            }
        }
        for (clients, m) in result? {
            println!(
                "{:>8} {:>10} {:>12.1} {:>10.1} {:>14.0} {:>14.0}",
                n, clients, m.cpu_pct, m.rss_mib, m.frames_per_s, m.bytes_per_s
            );
        }
    }
    Ok(())
}

struct Measured {
    cpu_pct: f64,
    rss_mib: f64,
    frames_per_s: f64,
    bytes_per_s: f64,
}

async fn measure(
    child: &Child,
    base: u16,
    n: u32,
    window: Duration,
) -> anyhow::Result<Vec<(u32, Measured)>> {
    let pid = child.id();
    let last = SocketAddr::from(([127, 0, 0, 1], base + n as u16 - 1));
    // Ready once the last vehicle's endpoint accepts (endpoints are bound before
    // the simulation starts); the probe connection is closed at once.
    let start = Instant::now();
    loop {
        if TcpStream::connect(last).await.is_ok() {
            break;
        }
        anyhow::ensure!(
            start.elapsed() < Duration::from_secs(20),
            "simulator did not come up"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    let mut out = Vec::new();

    // Physics only.
    let (t0, c0) = (Instant::now(), cpu_ticks(pid)?);
    tokio::time::sleep(window).await;
    out.push((
        0,
        Measured {
            cpu_pct: cpu_pct(pid, c0, t0)?,
            rss_mib: rss_mib(pid)?,
            frames_per_s: 0.0,
            bytes_per_s: 0.0,
        },
    ));

    // One reading client per vehicle.
    let bytes = Arc::new(AtomicU64::new(0));
    let frames = Arc::new(AtomicU64::new(0));
    let mut tasks = Vec::new();
    for i in 0..n {
        let addr = SocketAddr::from(([127, 0, 0, 1], base + i as u16));
        let mut s = TcpStream::connect(addr).await?;
        let (bytes, frames) = (bytes.clone(), frames.clone());
        tasks.push(tokio::spawn(async move {
            let mut buf = vec![0u8; 16 * 1024];
            while let Ok(k) = s.read(&mut buf).await {
                if k == 0 {
                    break;
                }
                bytes.fetch_add(k as u64, Ordering::Relaxed);
                // MAVLink 2 frames start with 0xFD; close enough for a rate.
                let starts = buf[..k].iter().filter(|b| **b == 0xFD).count();
                frames.fetch_add(starts as u64, Ordering::Relaxed);
            }
        }));
    }
    // Let the links settle (every stream is due at once when a link opens).
    tokio::time::sleep(Duration::from_secs(1)).await;
    let (b0, f0) = (
        bytes.load(Ordering::Relaxed),
        frames.load(Ordering::Relaxed),
    );
    let (t0, c0) = (Instant::now(), cpu_ticks(pid)?);
    tokio::time::sleep(window).await;
    let elapsed = t0.elapsed().as_secs_f64();
    out.push((
        n,
        Measured {
            cpu_pct: cpu_pct(pid, c0, t0)?,
            rss_mib: rss_mib(pid)?,
            frames_per_s: (frames.load(Ordering::Relaxed) - f0) as f64 / elapsed,
            bytes_per_s: (bytes.load(Ordering::Relaxed) - b0) as f64 / elapsed,
        },
    ));
    for t in tasks {
        t.abort();
    }
    Ok(out)
}

/// utime + stime of `pid`, clock ticks.
fn cpu_ticks(pid: u32) -> anyhow::Result<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    let rest = stat
        .rsplit_once(')')
        .map(|(_, r)| r)
        .ok_or_else(|| anyhow::anyhow!("bad /proc/{pid}/stat"))?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // After the comm: state is field 3, utime 14, stime 15 (1-based) → 11, 12 here.
    Ok(f[11].parse::<u64>()? + f[12].parse::<u64>()?)
}

fn cpu_pct(pid: u32, c0: u64, t0: Instant) -> anyhow::Result<f64> {
    // USER_HZ is 100 on every Linux this runs on.
    let ticks = cpu_ticks(pid)? - c0;
    Ok(ticks as f64 / 100.0 / t0.elapsed().as_secs_f64() * 100.0)
}

fn rss_mib(pid: u32) -> anyhow::Result<f64> {
    let statm = std::fs::read_to_string(format!("/proc/{pid}/statm"))?;
    let pages: u64 = statm
        .split_whitespace()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("bad statm"))?
        .parse()?;
    Ok(pages as f64 * 4096.0 / (1024.0 * 1024.0))
}

/// `n` consecutive TCP ports free on 127.0.0.1 right now.
fn free_port_run(n: u32) -> anyhow::Result<u16> {
    let mut base = 20_000 + (std::process::id() % 20_000) as u16;
    for _ in 0..50 {
        let all_free = (0..n as u16).all(|i| TcpListener::bind(("127.0.0.1", base + i)).is_ok());
        if all_free {
            return Ok(base);
        }
        base = base.wrapping_add(n as u16 + 7).max(20_000);
    }
    anyhow::bail!("no run of {n} free ports found")
}

fn tempfile_dir() -> anyhow::Result<PathBuf> {
    let d = std::env::temp_dir().join(format!("skymesh-swarm-load-{}", std::process::id()));
    std::fs::create_dir_all(&d)?;
    Ok(d)
}

/// `skymesh-vehicle-sim` next to this example's directory (`target/<profile>/`).
fn sim_binary() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .ok_or_else(|| anyhow::anyhow!("no target directory"))?;
    let bin = dir.join("skymesh-vehicle-sim");
    anyhow::ensure!(
        bin.exists(),
        "{} not built: cargo build --release -p skymesh-vehicle-sim --bins --examples",
        bin.display()
    );
    Ok(bin)
}

/// SIGTERM (a clean exit removes the simulator's iceoryx2 node), then wait.
fn stop(child: &mut Child) {
    let _ = Command::new("kill")
        .arg("-TERM")
        .arg(child.id().to_string())
        .status();
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
}
