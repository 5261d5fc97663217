//! Mesh spine benchmark: restart latency (SIGKILL of autopilot-link → VehicleState
//! flowing again at a subscriber, median and p99 over N kills) and the idle CPU and
//! resident memory of the whole default mesh. Prints numbers; asserts nothing.
//!
//!     cargo run --release -p skymesh-e2e --bin mesh-bench -- [--kills 20] [--idle-secs 10]
//!
//! Uses the end-to-end harness, so it runs the real binaries from the same target
//! directory (build them first: `cargo build --release --workspace`).

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use skymesh_e2e::bench::{arg, percentile};
use skymesh_e2e::{signal, Mesh, MeshOptions};
use skymesh_ipc_types::{topics, VehicleState};
use skymesh_runtime::clock::monotonic_ns;

/// utime + stime in clock ticks and resident pages of a process.
fn proc_usage(pid: u32) -> Option<(u64, u64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // After ")": state(0) ppid(1) ... utime(11) stime(12)
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    let statm = std::fs::read_to_string(format!("/proc/{pid}/statm")).ok()?;
    let rss_pages = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some((ticks, rss_pages))
}

fn main() -> anyhow::Result<()> {
    let kills = arg("--kills", 20) as usize;
    let idle_secs = arg("--idle-secs", 10);
    let opts = MeshOptions {
        // Each kill is a fresh crash: a budget big enough for the run, and the first
        // backoff step each time (the supervisor resets backoff after a stable period).
        supervisor_extra: format!(
            "[restart]\ninitial_backoff_ms = 100\nmax_backoff_ms = 30000\nbudget = {}\nbudget_window_s = 3600\nstable_after_s = 1\n",
            kills + 5
        ),
        ..MeshOptions::default()
    };
    let mut mesh = Mesh::start(opts)?;
    mesh.wait_running("vehicle-sim", Duration::from_secs(30))?;
    mesh.wait_running("autopilot-link", Duration::from_secs(30))?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;

    // Idle CPU and memory of the whole mesh (supervisor + services), vehicle on the ground.
    std::thread::sleep(Duration::from_secs(2));
    let tick_hz = nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)?.unwrap_or(100) as f64;
    let page = nix::unistd::sysconf(nix::unistd::SysconfVar::PAGE_SIZE)?.unwrap_or(4096) as f64;
    let pids = mesh.processes();
    let before: Vec<_> = pids.iter().filter_map(|p| proc_usage(*p)).collect();
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs(idle_secs));
    let after: Vec<_> = pids.iter().filter_map(|p| proc_usage(*p)).collect();
    let wall = t0.elapsed().as_secs_f64();
    for (pid, (a, b)) in pids.iter().zip(after.iter().zip(&before)) {
        let comm = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
        println!(
            "  {:<24} CPU {:5.2}%  RSS {:5.1} MiB",
            comm.trim(),
            100.0 * a.0.saturating_sub(b.0) as f64 / tick_hz / wall,
            a.1 as f64 * page / (1024.0 * 1024.0)
        );
    }
    let cpu_ticks: u64 = after
        .iter()
        .zip(&before)
        .map(|(a, b)| a.0.saturating_sub(b.0))
        .sum();
    let rss: f64 = after.iter().map(|a| a.1 as f64 * page).sum();
    println!(
        "idle mesh: {} processes, CPU {:.2}% of one core over {:.0} s, RSS {:.1} MiB total",
        pids.len(),
        100.0 * cpu_ticks as f64 / tick_hz / wall,
        wall,
        rss / (1024.0 * 1024.0)
    );

    // Restart latency.
    let mut latencies = Vec::with_capacity(kills);
    rt.block_on(async {
        let bus = mesh.bus("bench")?;
        let mut sub = bus.subscriber::<VehicleState>(&topics::vehicle_state(1))?;
        for i in 0..kills {
            let pid = mesh.wait_running("autopilot-link", Duration::from_secs(60))?;
            // Let it settle so each kill hits a steady-state service.
            tokio::time::sleep(Duration::from_millis(1500)).await;
            sub.latest()?;
            let killed_at = monotonic_ns();
            let t = Instant::now();
            signal(pid, Signal::SIGKILL)?;
            loop {
                let s = sub
                    .recv_timeout(Duration::from_secs(60))
                    .await?
                    .ok_or_else(|| anyhow::anyhow!("no VehicleState 60 s after kill {i}"))?;
                if s.header.stamp_ns > killed_at {
                    break;
                }
            }
            let ms = t.elapsed().as_secs_f64() * 1e3;
            latencies.push(ms);
            eprintln!(
                "kill {:2}: VehicleState flowing again after {ms:.0} ms",
                i + 1
            );
        }
        anyhow::Ok(())
    })?;
    latencies.sort_by(f64::total_cmp);
    println!(
        "restart latency (SIGKILL autopilot-link → VehicleState at a subscriber) over {} kills: p50 {:.0} ms, p99 {:.0} ms, min {:.0} ms, max {:.0} ms",
        latencies.len(),
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.99),
        latencies.first().copied().unwrap_or(f64::NAN),
        latencies.last().copied().unwrap_or(f64::NAN),
    );
    mesh.stop(Duration::from_secs(20))?;
    Ok(())
}
