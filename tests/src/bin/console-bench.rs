//! What the web console costs the supervisor. Prints numbers; asserts nothing.
//!
//!     cargo run --release -p skymesh-e2e --bin console-bench -- [--window-secs 30] [--settle-secs 5]
//!
//! The harness's minimal mesh (vehicle-sim + autopilot-link at 50 Hz ATTITUDE,
//! vehicle on the ground): the supervisor's CPU (percent of one core) and wake-ups
//! per second over a window with nobody looking, then over the same window with the
//! console open: once a second the two GETs its page makes (`/api/mesh` and
//! `/api/vehicles`, what docs/console.md describes), from this process. Uses the
//! real binaries of the same target directory (build them first).

use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use skymesh_e2e::bench::arg;
use skymesh_e2e::{Mesh, MeshOptions};

/// utime + stime (clock ticks) and voluntary + nonvoluntary context switches of
/// every thread of `pid`.
fn usage(pid: u32) -> Option<(u64, u64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let f: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    let mut switches = 0;
    for t in std::fs::read_dir(format!("/proc/{pid}/task")).ok()? {
        let status = std::fs::read_to_string(t.ok()?.path().join("status")).ok()?;
        for line in status.lines() {
            if let Some(v) = line
                .strip_prefix("voluntary_ctxt_switches:")
                .or_else(|| line.strip_prefix("nonvoluntary_ctxt_switches:"))
            {
                switches += v.trim().parse::<u64>().unwrap_or(0);
            }
        }
    }
    Some((ticks, switches))
}

fn ticks_per_second() -> f64 {
    nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
        .ok()
        .flatten()
        .map_or(100.0, |t| t as f64)
}

/// One GET; returns the body length.
fn get(addr: SocketAddr, path: &str) -> anyhow::Result<usize> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2))?;
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n")?;
    let mut resp = Vec::new();
    s.read_to_end(&mut resp)?;
    anyhow::ensure!(
        resp.starts_with(b"HTTP/1.1 200") || resp.starts_with(b"HTTP/1.0 200"),
        "GET {path}: not 200"
    );
    Ok(resp.len())
}

/// CPU % of one core and wake-ups/s of `pid` over `window`, calling `each_second`
/// once a second meanwhile.
fn measure(
    pid: u32,
    window: Duration,
    mut each_second: impl FnMut() -> anyhow::Result<()>,
) -> anyhow::Result<(f64, f64)> {
    let (t0, s0) = usage(pid).ok_or_else(|| anyhow::anyhow!("supervisor gone"))?;
    let start = Instant::now();
    let mut next = start;
    while start.elapsed() < window {
        each_second()?;
        next += Duration::from_secs(1);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let elapsed = start.elapsed().as_secs_f64();
    let (t1, s1) = usage(pid).ok_or_else(|| anyhow::anyhow!("supervisor gone"))?;
    let cpu = (t1 - t0) as f64 / ticks_per_second() / elapsed * 100.0;
    Ok((cpu, (s1 - s0) as f64 / elapsed))
}

fn main() -> anyhow::Result<()> {
    if std::env::args().any(|a| a == "-h" || a == "--help") {
        println!("usage: console-bench [--window-secs S] [--settle-secs S]");
        return Ok(());
    }
    let window = Duration::from_secs(arg("--window-secs", 30));
    let settle = Duration::from_secs(arg("--settle-secs", 5));
    let mut mesh = Mesh::start(MeshOptions {
        // The shipped heartbeat period, not the tests' faster one.
        heartbeat_ms: 500,
        ..MeshOptions::default()
    })?;
    mesh.wait_all_running(Duration::from_secs(60))?;
    let pid = mesh
        .supervisor_pid()
        .ok_or_else(|| anyhow::anyhow!("no supervisor"))?;
    let addr = mesh.metrics_addr();
    // The vehicle's link up and reporting, so /api/vehicles carries real data.
    mesh.wait_for(Duration::from_secs(60), "vehicle link up", |m| {
        m.http_get("/api/vehicles")
            .ok()
            .filter(|b| b.contains("\"link_up\":true"))
    })?;
    std::thread::sleep(settle);

    let (closed_cpu, closed_wakeups) = measure(pid, window, || Ok(()))?;
    let mut bytes = 0;
    let (open_cpu, open_wakeups) = measure(pid, window, || {
        bytes += get(addr, "/api/mesh")? + get(addr, "/api/vehicles")?;
        Ok(())
    })?;
    let polls = window.as_secs().max(1);
    println!("supervisor, minimal mesh (vehicle-sim + autopilot-link, 50 Hz ATTITUDE), {window:?} windows:");
    println!("  console closed: {closed_cpu:.2} % of a core, {closed_wakeups:.1} wake-ups/s");
    println!(
        "  console open (2 GETs/s as the page polls, {} bytes per poll): {open_cpu:.2} % of a core, {open_wakeups:.1} wake-ups/s",
        bytes as u64 / polls
    );
    println!(
        "  the open console costs {:.2} points of a core",
        open_cpu - closed_cpu
    );
    Ok(())
}
