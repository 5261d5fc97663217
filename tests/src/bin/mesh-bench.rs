//! Mesh spine benchmark. Prints numbers; asserts nothing.
//!
//!     cargo run --release -p skymesh-e2e --bin mesh-bench -- [--kills 20] [--idle-secs 10]
//!
//! Default mode (the harness's minimal mesh: vehicle-sim + autopilot-link): restart
//! latency (SIGKILL of autopilot-link → VehicleState flowing again at a subscriber,
//! median and p99 over N kills) and the idle CPU and resident memory of that mesh.
//!
//!     cargo run --release -p skymesh-e2e --bin mesh-bench -- --default-mesh \
//!         [--settle-secs 5] [--window-secs 20] [--kills 10] [--restart solo-gateway,mqtt-broker,camera]
//!
//! `--default-mesh`: the real default mesh of deploy/skymesh.toml (every service, the
//! shipped service configs, its default ports, which must be free), in its own
//! iceoryx2 domain, vehicle on the ground. First the time from `skymesh up` to every
//! service `running` and to the first request on every protocol answered
//! (`skymesh_e2e::first_requests`, a ground station on the router's 14550); then, on
//! a fresh start with no clients, per process over the window:
//! CPU % of one core, RSS and wake-ups per second (voluntary + nonvoluntary context
//! switches of all its threads), again with a DigiView client attached (a GET
//! once a second: camera and vision pipeline at work) and once it left; then SIGKILL → `running` again in the supervisor's
//! /status for each `--restart` service; then the same idle window for the control
//! mesh (camera, vision-pipeline and digiview-gateway disabled). The generated config
//! differs from deploy/skymesh.toml only in absolute paths, `--metrics 127.0.0.1:0`
//! and a restart budget large enough for the kills (`stable_after_s = 1`).
//!
//! Uses the real binaries from the same target directory (build them first:
//! `cargo build --release --workspace`).

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
    if std::env::args().any(|a| a == "-h" || a == "--help") {
        println!(
            "usage: mesh-bench [--kills N] [--idle-secs S]\n\
             \x20      mesh-bench --default-mesh [--kills N] [--window-secs S] [--settle-secs S] [--restart a,b,...]\n\
             Without --default-mesh: the minimal mesh (supervisor, vehicle-sim, autopilot-link):\n\
             idle CPU/RSS and autopilot-link restart latency. With it: the whole deploy/skymesh.toml\n\
             mesh and the control mesh: per-process CPU, RSS, wake-ups/s, restart latency."
        );
        return Ok(());
    }
    if std::env::args().any(|a| a == "--default-mesh") {
        return default_mesh::run();
    }
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

/// `--default-mesh`: the real deploy/skymesh.toml mesh.
mod default_mesh {
    use std::collections::BTreeMap;
    use std::io::{Read as _, Write as _};
    use std::net::{SocketAddr, TcpStream};
    use std::path::Path;
    use std::process::{Child, Command, Stdio};
    use std::time::{Duration, Instant};

    use anyhow::{anyhow, bail, Context as _, Result};
    use nix::sys::signal::Signal;
    use skymesh_e2e::bench::{arg, percentile};
    use skymesh_e2e::first_requests::{report, send_all, GcsEndpoint, Targets};
    use skymesh_e2e::{bin_dir, processes_with_env, repo_root, signal};
    use skymesh_runtime::Domain;

    /// The services that make up the camera + vision pair (and its gateway).
    const VISION: [&str; 3] = ["camera", "vision-pipeline", "digiview-gateway"];

    /// Default ports of deploy/skymesh.toml's services (tcp listeners and udp binds).
    const TCP_PORTS: [(u16, &str); 5] = [
        (5760, "vehicle-sim MAVLink"),
        (5507, "solo-gateway"),
        (8000, "groundcontrol-gateway"),
        (1883, "mqtt-broker"),
        (8555, "digiview-gateway"),
    ];
    const UDP_PORTS: [(u16, &str); 2] = [(14558, "solo-gateway follow"), (6002, "imc-gateway")];

    /// `--name a,b,c` from the command line, else `default`.
    fn list_arg(name: &str, default: &str) -> Vec<String> {
        let args: Vec<String> = std::env::args().collect();
        let v = args
            .windows(2)
            .find(|w| w[0] == name)
            .map(|w| w[1].clone())
            .unwrap_or_else(|| default.to_string());
        v.split(',')
            .filter(|s| !s.is_empty())
            .map(str::to_string)
            .collect()
    }

    pub fn run() -> Result<()> {
        let settle = Duration::from_secs(arg("--settle-secs", 5));
        let window = Duration::from_secs(arg("--window-secs", 20));
        let kills = arg("--kills", 10) as usize;
        let restart = list_arg("--restart", "solo-gateway,mqtt-broker,camera");
        // `--control-only`: skip the whole mesh (A/B runs of the idle cost).
        let control_only = std::env::args().any(|a| a == "--control-only");
        if !control_only {
            first_requests(kills)?;
            println!(
                "\n# whole default mesh (deploy/skymesh.toml), settle {settle:?}, window {window:?}"
            );
            let mut mesh = DefaultMesh::start(&[], kills)?;
            mesh.wait_all_running(Duration::from_secs(90))?;
            std::thread::sleep(settle);
            println!("## nothing connected");
            let idle = mesh.measure(window)?;
            print_idle(&idle, window);
            println!("\n## a DigiView client attached (GET SYSTEM_STATUS once a second)");
            let client = DigiViewPoller::start(SocketAddr::from(([127, 0, 0, 1], 8555)))?;
            std::thread::sleep(Duration::from_secs(1));
            let busy = mesh.measure(window)?;
            let polls = client.stop()?;
            print_idle(&busy, window);
            println!("DigiView client: {polls} GETs answered");
            std::thread::sleep(settle);
            println!("\n## the client gone again");
            let idle = mesh.measure(window)?;
            print_idle(&idle, window);
            for name in &restart {
                restart_latency(&mut mesh, name, kills)?;
            }
            mesh.stop()?;
        }
        println!("\n# control mesh (camera, vision-pipeline, digiview-gateway disabled)");
        {
            let mut mesh = DefaultMesh::start(&VISION, kills)?;
            mesh.wait_all_running(Duration::from_secs(90))?;
            std::thread::sleep(settle);
            let idle = mesh.measure(window)?;
            print_idle(&idle, window);
            mesh.stop()?;
        }
        Ok(())
    }

    /// `skymesh up` of the shipped mesh, then the first request on every protocol
    /// the moment /status (polled every 10 ms) says every service runs: the time to
    /// "running" and to every first request answered (each within 1 s or reported
    /// failed), with a ground station listening on the router's default endpoint.
    fn first_requests(kills: usize) -> Result<()> {
        println!("# first requests on the shipped mesh (deploy/skymesh.toml, default ports)");
        let gcs = GcsEndpoint::bind(14550)?;
        let t_up = Instant::now();
        let mut mesh = DefaultMesh::start(&[], kills)?;
        mesh.wait_all_running_every(Duration::from_secs(90), Duration::from_millis(10))?;
        let running = t_up.elapsed();
        let local = |port| SocketAddr::from(([127, 0, 0, 1], port));
        let targets = Targets {
            solo: local(5507),
            mqtt: local(1883),
            dji_sn: "SKYMESH-DOCK-1".to_string(),
            digiview: local(8555),
            gc: local(8000),
            imc: local(6002),
        };
        let t0 = Instant::now();
        let answers = skymesh_e2e::ground::runtime().block_on(send_all(
            &targets,
            gcs,
            t0,
            Duration::from_secs(1),
        ));
        let served = answers.iter().map(|a| a.after).max().unwrap_or_default();
        print!("{}", report(&answers));
        let failed = answers.iter().filter(|a| a.outcome.is_err()).count();
        println!(
            "skymesh up → every service running {:.0} ms; → every first request answered {:.0} ms \
             ({} requests, {failed} failed; the slowest {:.0} ms after running)",
            running.as_secs_f64() * 1e3,
            (running + served).as_secs_f64() * 1e3,
            answers.len(),
            served.as_secs_f64() * 1e3
        );
        mesh.stop()
    }

    /// A DigiView client as a UI holds one: connected, a GET SYSTEM_STATUS each second.
    struct DigiViewPoller {
        stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
        thread: std::thread::JoinHandle<Result<u64>>,
    }

    impl DigiViewPoller {
        fn start(addr: SocketAddr) -> Result<DigiViewPoller> {
            use digiview_proto::{Frame, MessageType, ParamType, FRAME_LEN};
            let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2))?;
            s.set_read_timeout(Some(Duration::from_secs(2)))?;
            let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
            let flag = stop.clone();
            let thread = std::thread::spawn(move || -> Result<u64> {
                let mut n = 0;
                while !flag.load(std::sync::atomic::Ordering::Relaxed) {
                    s.write_all(&Frame::new(MessageType::Get, ParamType::SystemStatus).encode())?;
                    let mut b = [0u8; FRAME_LEN];
                    s.read_exact(&mut b)?;
                    n += 1;
                    std::thread::sleep(Duration::from_secs(1));
                }
                Ok(n)
            });
            Ok(DigiViewPoller { stop, thread })
        }

        fn stop(self) -> Result<u64> {
            self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
            self.thread
                .join()
                .map_err(|_| anyhow!("the DigiView client thread panicked"))?
        }
    }

    /// One process's counters at one instant.
    #[derive(Debug, Clone, Copy, Default)]
    struct Usage {
        /// utime + stime, clock ticks.
        ticks: u64,
        /// Resident set, bytes.
        rss: u64,
        /// voluntary + nonvoluntary context switches summed over its threads.
        switches: u64,
        threads: usize,
    }

    fn usage(pid: u32) -> Option<Usage> {
        let page = nix::unistd::sysconf(nix::unistd::SysconfVar::PAGE_SIZE)
            .ok()
            .flatten()
            .unwrap_or(4096) as u64;
        let (ticks, rss_pages) = super::proc_usage(pid)?;
        let mut switches = 0;
        let mut threads = 0;
        for t in std::fs::read_dir(format!("/proc/{pid}/task"))
            .ok()?
            .flatten()
        {
            let Ok(status) = std::fs::read_to_string(t.path().join("status")) else {
                continue;
            };
            threads += 1;
            for line in status.lines() {
                if let Some(v) = line
                    .strip_prefix("voluntary_ctxt_switches:")
                    .or_else(|| line.strip_prefix("nonvoluntary_ctxt_switches:"))
                {
                    switches += v.trim().parse::<u64>().unwrap_or(0);
                }
            }
        }
        Some(Usage {
            ticks,
            rss: rss_pages * page,
            switches,
            threads,
        })
    }

    /// Per process over the window: (CPU % of one core, RSS MiB, wake-ups/s, threads).
    type Idle = BTreeMap<String, (f64, f64, f64, usize)>;

    fn print_idle(idle: &Idle, window: Duration) {
        println!(
            "{:<24} {:>8} {:>9} {:>11} {:>7} {:>12}",
            "process", "CPU %", "RSS MiB", "wake-ups/s", "threads", "µs/wake-up"
        );
        for (name, (cpu, rss, wk, th)) in idle {
            // CPU per wake-up: % of one core × 10 000 µs/s ÷ wake-ups/s.
            let per_wake = if *wk > 0.0 { cpu * 1e4 / wk } else { 0.0 };
            println!("{name:<24} {cpu:>8.2} {rss:>9.1} {wk:>11.1} {th:>7} {per_wake:>12.0}");
        }
        let sum = |f: &dyn Fn(&str) -> bool| {
            idle.iter()
                .filter(|(n, _)| f(n))
                .fold((0.0, 0.0, 0.0, 0), |a, (_, v)| {
                    (a.0 + v.0, a.1 + v.1, a.2 + v.2, a.3 + 1)
                })
        };
        for (label, s) in [
            ("whole mesh (incl. supervisor)", sum(&|_| true)),
            (
                "camera + vision-pipeline",
                sum(&|n| n == "camera" || n == "vision-pipeline"),
            ),
            (
                "rest (w/o camera, vision, vehicle-sim)",
                sum(&|n| n != "camera" && n != "vision-pipeline" && n != "vehicle-sim"),
            ),
        ] {
            println!(
                "{label:<40} {} processes: CPU {:.2} % of one core, RSS {:.1} MiB, {:.1} wake-ups/s over {:.0} s",
                s.3,
                s.0,
                s.1,
                s.2,
                window.as_secs_f64()
            );
        }
    }

    fn restart_latency(mesh: &mut DefaultMesh, name: &str, kills: usize) -> Result<()> {
        let mut ms = Vec::with_capacity(kills);
        for i in 0..kills {
            let pid = mesh.wait_running(name, None, Duration::from_secs(60))?;
            // Let it settle so each kill hits a steady-state service.
            std::thread::sleep(Duration::from_millis(1500));
            let t = Instant::now();
            signal(pid, Signal::SIGKILL)?;
            mesh.wait_running(name, Some(pid), Duration::from_secs(60))?;
            let v = t.elapsed().as_secs_f64() * 1e3;
            eprintln!("{name} kill {:2}: running again after {v:.0} ms", i + 1);
            ms.push(v);
        }
        ms.sort_by(f64::total_cmp);
        println!(
            "restart latency {name} (SIGKILL → running with a new pid in /status, polled every 10 ms) over {} kills: p50 {:.0} ms, p99 {:.0} ms, min {:.0} ms, max {:.0} ms",
            ms.len(),
            percentile(&ms, 0.5),
            percentile(&ms, 0.99),
            ms.first().copied().unwrap_or(f64::NAN),
            ms.last().copied().unwrap_or(f64::NAN),
        );
        Ok(())
    }

    struct DefaultMesh {
        dir: tempfile::TempDir,
        domain: String,
        child: Option<Child>,
        addr: SocketAddr,
        disabled: Vec<String>,
    }

    /// deploy/skymesh.toml with absolute paths, `disabled` services off and a restart
    /// budget for `kills` kills per service.
    fn config_text(deploy: &Path, disabled: &[&str], kills: usize) -> Result<String> {
        let text = std::fs::read_to_string(deploy.join("skymesh.toml"))
            .context("reading deploy/skymesh.toml")?;
        let mut out = String::new();
        for line in text.lines() {
            let key = line.split('=').next().unwrap_or("").trim();
            let value = line
                .split_once('=')
                .map(|(_, v)| v.trim().trim_matches('"'))
                .unwrap_or("");
            match key {
                "config" | "ipc_config" => {
                    out += &format!("{key} = {:?}\n", deploy.join(value).display().to_string());
                }
                "budget" => out += &format!("budget = {}\n", kills + 5),
                "budget_window_s" => out += "budget_window_s = 3600\n",
                "stable_after_s" => out += "stable_after_s = 1\n",
                _ => {
                    out += line;
                    out.push('\n');
                }
            }
            if key == "name" && disabled.contains(&value) {
                out += "enabled = false\n";
            }
        }
        Ok(out)
    }

    impl DefaultMesh {
        fn start(disabled: &[&str], kills: usize) -> Result<DefaultMesh> {
            for (port, who) in TCP_PORTS {
                if disabled.iter().any(|d| who.starts_with(d)) {
                    continue;
                }
                if let Err(e) = std::net::TcpListener::bind(("127.0.0.1", port)) {
                    bail!("tcp port {port} ({who}, a default port of deploy/skymesh.toml) is taken: {e}; stop whatever uses it (another `skymesh up`?)");
                }
            }
            for (port, who) in UDP_PORTS {
                if let Err(e) = std::net::UdpSocket::bind(("127.0.0.1", port)) {
                    bail!("udp port {port} ({who}, a default port of deploy/skymesh.toml) is taken: {e}; stop whatever uses it (another `skymesh up`?)");
                }
            }
            let domain = format!("meshbench{}", std::process::id());
            let dir = tempfile::Builder::new()
                .prefix("skymesh-mesh-bench-")
                .tempdir()?;
            let deploy = repo_root().join("deploy");
            std::fs::write(
                dir.path().join("skymesh.toml"),
                config_text(&deploy, disabled, kills)?,
            )?;
            let skymesh = bin_dir().join("skymesh");
            if !skymesh.exists() {
                bail!(
                    "{} not built: cargo build --release --workspace",
                    skymesh.display()
                );
            }
            let status_file = dir.path().join("metrics.addr");
            let child = Command::new(&skymesh)
                .arg("up")
                .arg("--config")
                .arg(dir.path().join("skymesh.toml"))
                .arg("--metrics")
                .arg("127.0.0.1:0")
                .arg("--status-file")
                .arg(&status_file)
                .arg("--no-table")
                .env("SKYMESH_DOMAIN", &domain)
                .env_remove("NOTIFY_SOCKET")
                .stdin(Stdio::null())
                .stdout(std::fs::File::create(dir.path().join("supervisor.stdout"))?)
                .stderr(std::fs::File::create(dir.path().join("supervisor.stderr"))?)
                .spawn()
                .context("spawning skymesh up")?;
            let mut mesh = DefaultMesh {
                dir,
                domain,
                child: Some(child),
                addr: SocketAddr::from(([127, 0, 0, 1], 0)),
                disabled: disabled.iter().map(|s| s.to_string()).collect(),
            };
            let start = Instant::now();
            loop {
                if let Some(addr) = std::fs::read_to_string(&status_file)
                    .ok()
                    .and_then(|t| t.trim().parse().ok())
                {
                    mesh.addr = addr;
                    break;
                }
                mesh.check_alive()?;
                if start.elapsed() > Duration::from_secs(20) {
                    bail!("no supervisor status file after 20 s");
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            Ok(mesh)
        }

        fn check_alive(&mut self) -> Result<()> {
            if let Some(c) = self.child.as_mut() {
                if let Some(status) = c.try_wait()? {
                    let err = std::fs::read_to_string(self.dir.path().join("supervisor.stderr"))
                        .unwrap_or_default();
                    bail!("supervisor exited ({status}):\n{err}");
                }
            }
            Ok(())
        }

        fn status(&self) -> Result<Vec<serde_json::Value>> {
            let mut s = TcpStream::connect_timeout(&self.addr, Duration::from_secs(2))?;
            s.set_read_timeout(Some(Duration::from_secs(5)))?;
            write!(s, "GET /status HTTP/1.0\r\nHost: {}\r\n\r\n", self.addr)?;
            let mut resp = String::new();
            s.read_to_string(&mut resp)?;
            let body = resp
                .split_once("\r\n\r\n")
                .map(|(_, b)| b)
                .ok_or_else(|| anyhow!("no HTTP header end"))?;
            let v: serde_json::Value = serde_json::from_str(body)?;
            v.as_array()
                .cloned()
                .ok_or_else(|| anyhow!("/status is not an array"))
        }

        /// Waits until every enabled service is `running`.
        fn wait_all_running(&mut self, timeout: Duration) -> Result<()> {
            self.wait_all_running_every(timeout, Duration::from_millis(100))
        }

        /// Waits until every enabled service is `running`, asking every `poll`.
        fn wait_all_running_every(&mut self, timeout: Duration, poll: Duration) -> Result<()> {
            let start = Instant::now();
            loop {
                self.check_alive()?;
                if let Ok(st) = self.status() {
                    let pending: Vec<String> = st
                        .iter()
                        .filter(|s| {
                            let name = s["name"].as_str().unwrap_or("");
                            !self.disabled.iter().any(|d| d == name) && s["state"] != "running"
                        })
                        .map(|s| format!("{}={}", s["name"], s["state"]))
                        .collect();
                    if pending.is_empty() && !st.is_empty() {
                        return Ok(());
                    }
                    if start.elapsed() > timeout {
                        bail!("not running after {timeout:?}: {}", pending.join(", "));
                    }
                }
                std::thread::sleep(poll);
            }
        }

        /// Waits until `name` is `running` (with a pid other than `old`); its pid.
        fn wait_running(&mut self, name: &str, old: Option<u32>, timeout: Duration) -> Result<u32> {
            let start = Instant::now();
            loop {
                if let Ok(st) = self.status() {
                    if let Some(s) = st.iter().find(|s| s["name"] == name) {
                        let pid = s["pid"].as_u64().map(|p| p as u32);
                        if let Some(pid) = pid {
                            if s["state"] == "running" && Some(pid) != old {
                                return Ok(pid);
                            }
                        }
                    }
                }
                if start.elapsed() > timeout {
                    bail!("{name} not running after {timeout:?}");
                }
                self.check_alive()?;
                std::thread::sleep(Duration::from_millis(10));
            }
        }

        /// Idle CPU, RSS and wake-ups of every process over `window`.
        fn measure(&mut self, window: Duration) -> Result<Idle> {
            let mut names: BTreeMap<u32, String> = BTreeMap::new();
            for s in self.status()? {
                if let (Some(n), Some(p)) = (s["name"].as_str(), s["pid"].as_u64()) {
                    names.insert(p as u32, n.to_string());
                }
            }
            if let Some(c) = &self.child {
                names.insert(c.id(), "supervisor (skymesh)".to_string());
            }
            let pids = processes_with_env("SKYMESH_DOMAIN", &self.domain);
            let tick_hz =
                nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)?.unwrap_or(100) as f64;
            let before: Vec<(u32, Usage)> =
                pids.iter().filter_map(|p| Some((*p, usage(*p)?))).collect();
            let t0 = Instant::now();
            std::thread::sleep(window);
            let wall = t0.elapsed().as_secs_f64();
            let mut idle = Idle::new();
            for (pid, b) in before {
                let Some(a) = usage(pid) else { continue };
                let name = names.get(&pid).cloned().unwrap_or_else(|| {
                    let comm =
                        std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
                    format!("{} ({pid})", comm.trim())
                });
                idle.insert(
                    name,
                    (
                        100.0 * a.ticks.saturating_sub(b.ticks) as f64 / tick_hz / wall,
                        a.rss as f64 / (1024.0 * 1024.0),
                        a.switches.saturating_sub(b.switches) as f64 / wall,
                        a.threads,
                    ),
                );
            }
            Ok(idle)
        }

        fn stop(&mut self) -> Result<()> {
            if let Some(mut c) = self.child.take() {
                signal(c.id(), Signal::SIGTERM)?;
                let start = Instant::now();
                while c.try_wait()?.is_none() {
                    if start.elapsed() > Duration::from_secs(30) {
                        let _ = c.kill();
                        let _ = c.wait();
                        bail!("supervisor did not exit within 30 s of SIGTERM");
                    }
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
            Ok(())
        }
    }

    impl Drop for DefaultMesh {
        fn drop(&mut self) {
            if let Some(mut c) = self.child.take() {
                let _ = c.kill();
                let _ = c.wait();
            }
            for pid in processes_with_env("SKYMESH_DOMAIN", &self.domain) {
                let _ = signal(pid, Signal::SIGKILL);
            }
            if let Ok(d) = Domain::load(
                &self.domain,
                Some(&repo_root().join("deploy/iceoryx2.toml")),
            ) {
                std::thread::sleep(Duration::from_millis(100));
                d.cleanup_dead_nodes();
                if d.live_nodes().is_empty() {
                    d.remove_leftover_files();
                }
            }
            let _ = std::fs::remove_dir_all(format!("/tmp/skymesh-{}", self.domain));
        }
    }
}
