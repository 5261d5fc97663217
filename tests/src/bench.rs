//! What the benchmark binaries (`src/bin/*-bench.rs`) share: command-line numbers,
//! percentiles, and the MAVLink tap that sits between autopilot-link and vehicle-sim.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use anyhow::{bail, Context as _, Result};
use skymesh_ipc_types::{
    topics, AckResult, Command, CommandAck, CommandSource, FlightMode, VehicleCommand,
    VehicleState, VehicleStatus,
};

use mavlink_frame::FrameParser;
use skymesh_runtime::realtime::{self, RealtimePriority};

use crate::{Mesh, MeshOptions};

/// The priority and CPUs [`bench_thread_realtime`] gives the bench's own threads.
static BENCH_REALTIME: OnceLock<(RealtimePriority, Vec<usize>)> = OnceLock::new();

/// From now on, the bench's own threads (the MAVLink tap, bus watchers, MQTT
/// clients) run `SCHED_FIFO` at `priority`, on `cpus` if any: they stand in for the
/// world outside the companion computer (the cloud, the flight controller), which
/// does not queue behind its vision work. Set it before the mesh starts; the
/// bench's main thread, which starts the supervisor, keeps normal scheduling
/// (children inherit a policy and an affinity).
pub fn set_bench_realtime(priority: RealtimePriority, cpus: Vec<usize>) {
    let _ = BENCH_REALTIME.set((priority, cpus));
}

/// Puts the calling bench thread under [`set_bench_realtime`]'s priority and CPUs,
/// if set (a refusal is printed: the bench still runs, its stamps possibly late).
pub fn bench_thread_realtime() {
    let Some((p, cpus)) = BENCH_REALTIME.get() else {
        return;
    };
    if !cpus.is_empty() {
        if let Err(e) = realtime::pin(cpus) {
            eprintln!("bench thread: CPU affinity {cpus:?} refused: {e}");
        }
    }
    if let Err(e) = realtime::apply(*p) {
        eprintln!("bench thread: real-time priority {} refused: {e}", p.get());
    }
}

/// How an end-to-end bench runs the mesh's control path and load, from its command
/// line: `--realtime P` gives the named services `SCHED_FIFO` as deploy/skymesh.toml
/// does (priority P, or P + 10 for the ones marked high) on CPU 1 (`--pin N`,
/// `--pin none`), and the bench's own threads P + 10 on the same CPUs
/// ([`set_bench_realtime`]); `--vision` adds the camera (the embedded default,
/// 1280x720 at 30 fps) and the vision pipeline, with normal scheduling on any CPU.
#[derive(Debug, Default)]
pub struct ControlPath {
    pub realtime: Vec<(String, u8)>,
    pub cpu_affinity: Vec<(String, Vec<usize>)>,
    pub vision: bool,
    /// One line for the bench's header.
    pub describe: String,
}

impl ControlPath {
    /// Reads `--realtime`, `--pin` and `--vision`; `services` are the control path's
    /// (name, high).
    pub fn from_args(services: &[(&str, bool)]) -> Result<ControlPath> {
        let args: Vec<String> = std::env::args().collect();
        let value = |name: &str| args.windows(2).find(|w| w[0] == name).map(|w| w[1].clone());
        let low = match value("--realtime") {
            Some(v) => v
                .parse::<u8>()
                .ok()
                .filter(|p| *p <= 89)
                .context("--realtime must be 0 (off) to 89")?,
            None => 0,
        };
        let pin = match value("--pin") {
            Some(v) if v == "none" => Vec::new(),
            Some(v) => realtime::parse_cpus(&v).map_err(anyhow::Error::msg)?,
            None => vec![1],
        };
        let mut path = ControlPath {
            vision: args.iter().any(|a| a == "--vision"),
            ..Default::default()
        };
        let Some(low) = RealtimePriority::new(low).map_err(anyhow::Error::msg)? else {
            path.describe = format!(
                "control path normal scheduling; camera and vision pipeline {}",
                if path.vision { "running" } else { "off" }
            );
            return Ok(path);
        };
        let high = low.get() + 10;
        for (name, is_high) in services {
            let p = if *is_high { high } else { low.get() };
            path.realtime.push((name.to_string(), p));
            if !pin.is_empty() {
                path.cpu_affinity.push((name.to_string(), pin.clone()));
            }
        }
        if let Ok(Some(bench)) = RealtimePriority::new(high) {
            set_bench_realtime(bench, pin.clone());
        }
        path.describe = format!(
            "control path SCHED_FIFO {} (P = {}, P + 10 = {high}; the bench P + 10) on CPUs {pin:?}; \
             camera and vision pipeline {}",
            services
                .iter()
                .map(|(n, h)| format!("{n} {}", if *h { "P + 10" } else { "P" }))
                .collect::<Vec<_>>()
                .join(", "),
            low.get(),
            if path.vision { "running" } else { "off" }
        );
        Ok(path)
    }

    /// `opts` with this control path's scheduling and load, and the services to
    /// wait for: `services`, with the camera and the vision pipeline when they run.
    pub fn mesh(
        self,
        opts: MeshOptions,
        services: &[&'static str],
    ) -> (MeshOptions, Vec<&'static str>) {
        let mut wait = services.to_vec();
        if self.vision {
            wait.extend(["camera", "vision-pipeline"]);
        }
        let opts = MeshOptions {
            vision: self.vision,
            realtime: self.realtime,
            cpu_affinity: self.cpu_affinity,
            ..opts
        };
        (opts, wait)
    }
}

/// `--name N` from the command line, else `default`.
pub fn arg(name: &str, default: u64) -> u64 {
    let args: Vec<String> = std::env::args().collect();
    args.windows(2)
        .find(|w| w[0] == name)
        .and_then(|w| w[1].parse().ok())
        .unwrap_or(default)
}

/// The `p` quantile (0..=1, nearest rank) of ascending `sorted`; NaN when empty.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let idx = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[idx.min(sorted.len() - 1)]
}

/// Forwards bytes both ways between autopilot-link (connecting to `listener`) and
/// vehicle-sim on `sim_port`, and hands every chunk autopilot-link writes to
/// `on_link_bytes` (a clone per connection) through autopilot-link's own
/// CRC-checked frame parser, with the time the chunk was read — after it has been
/// forwarded, so the tap adds no latency to what it measures.
pub fn mavlink_tap<F>(listener: TcpListener, sim_port: u16, on_link_bytes: F)
where
    F: FnMut(&mut FrameParser, Instant) + Clone + Send + 'static,
{
    mavlink_tap_both(
        listener,
        sim_port,
        on_link_bytes,
        |_: &mut FrameParser, _| {},
    );
}

/// [`mavlink_tap`] that also hands every chunk vehicle-sim writes (towards
/// autopilot-link) to `on_sim_bytes`, the same way: parsed after forwarding, with
/// the time the chunk was read.
pub fn mavlink_tap_both<F, G>(
    listener: TcpListener,
    sim_port: u16,
    on_link_bytes: F,
    on_sim_bytes: G,
) where
    F: FnMut(&mut FrameParser, Instant) + Clone + Send + 'static,
    G: FnMut(&mut FrameParser, Instant) + Clone + Send + 'static,
{
    std::thread::spawn(move || loop {
        // Its two forwarding threads inherit the policy.
        bench_thread_realtime();
        let Ok((link, _)) = listener.accept() else {
            return;
        };
        let Ok(sim) = TcpStream::connect(("127.0.0.1", sim_port)) else {
            continue;
        };
        let _ = link.set_nodelay(true);
        let _ = sim.set_nodelay(true);
        let (Ok(mut link_r), Ok(mut sim_w)) = (link.try_clone(), sim.try_clone()) else {
            continue;
        };
        let (mut sim_r, mut link_w) = (sim, link);
        let mut on_sim = on_sim_bytes.clone();
        std::thread::spawn(move || {
            let mut parser = FrameParser::new();
            let mut buf = [0u8; 4096];
            while let Ok(n) = sim_r.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let now = Instant::now();
                if link_w.write_all(&buf[..n]).is_err() {
                    break;
                }
                parser.push(&buf[..n]);
                on_sim(&mut parser, now);
            }
        });
        let mut on_bytes = on_link_bytes.clone();
        std::thread::spawn(move || {
            let mut parser = FrameParser::new();
            let mut buf = [0u8; 4096];
            while let Ok(n) = link_r.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let now = Instant::now();
                if sim_w.write_all(&buf[..n]).is_err() {
                    break;
                }
                parser.push(&buf[..n]);
                on_bytes(&mut parser, now);
            }
        });
    });
}

/// Starts a mesh whose vehicle 1 autopilot-link reaches its vehicle-sim through a
/// [`mavlink_tap`] feeding `on_link_bytes`, and waits until `services` run.
pub fn start_tapped_mesh<F>(opts: MeshOptions, services: &[&str], on_link_bytes: F) -> Result<Mesh>
where
    F: FnMut(&mut FrameParser, Instant) + Clone + Send + 'static,
{
    start_tapped_mesh_both(opts, services, on_link_bytes, |_: &mut FrameParser, _| {})
}

/// [`start_tapped_mesh`] with a [`mavlink_tap_both`]: `on_sim_bytes` sees what
/// vehicle-sim writes towards autopilot-link.
pub fn start_tapped_mesh_both<F, G>(
    opts: MeshOptions,
    services: &[&str],
    on_link_bytes: F,
    on_sim_bytes: G,
) -> Result<Mesh>
where
    F: FnMut(&mut FrameParser, Instant) + Clone + Send + 'static,
    G: FnMut(&mut FrameParser, Instant) + Clone + Send + 'static,
{
    let tap_listener = TcpListener::bind("127.0.0.1:0")?;
    let opts = MeshOptions {
        link_via: Some(tap_listener.local_addr()?.port()),
        ..opts
    };
    let mut mesh = Mesh::start(opts)?;
    mavlink_tap_both(tap_listener, mesh.mavlink_port, on_link_bytes, on_sim_bytes);
    for name in services {
        mesh.wait_running(name, Duration::from_secs(40))?;
    }
    Ok(mesh)
}

/// Operator: GUIDED, arm, take off to `alt` m, then give flight authority back.
pub async fn take_off(mesh: &Mesh, alt: f32) -> Result<()> {
    let bus = mesh.bus("bench-take-off")?;
    let mut status = bus.subscriber::<VehicleStatus>(&topics::vehicle_status(1))?;
    let mut state = bus.subscriber::<VehicleState>(&topics::vehicle_state(1))?;
    let mut acks = bus.subscriber::<CommandAck>(&topics::vehicle_command_ack(1))?;
    let mut cmds = bus.publisher::<VehicleCommand>(&topics::vehicle_command(1))?;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let s = status.recv_timeout(Duration::from_secs(5)).await?;
        if s.is_some_and(|s| s.ekf_healthy != 0) {
            break;
        }
        if Instant::now() > deadline {
            bail!("EKF never became healthy");
        }
    }
    let steps = [
        Command::SetMode(FlightMode::Guided),
        Command::Arm { force: false },
        Command::Takeoff { alt_rel_m: alt },
        Command::ReleaseFlightAuthority,
    ];
    for (i, cmd) in steps.iter().enumerate() {
        let id = 9000 + i as u32;
        cmds.publish(VehicleCommand::new(1, CommandSource::Operator, id, cmd)?)?;
        loop {
            let a = acks
                .recv_timeout(Duration::from_secs(10))
                .await?
                .context("no command ack")?;
            if a.command_id == id {
                if a.result() != Some(AckResult::Accepted) {
                    bail!("{cmd:?} refused: {a:?}");
                }
                break;
            }
        }
        if matches!(cmd, Command::Takeoff { .. }) {
            // Keep flight authority while the take-off flies (a grab each second):
            // the arbiter brakes a position target whose source went quiet.
            let mut grab = Instant::now();
            let mut keep_id = 9100;
            loop {
                if Instant::now() >= grab {
                    grab += Duration::from_secs(1);
                    keep_id += 1;
                    let keep = Command::GrabFlightAuthority;
                    cmds.publish(VehicleCommand::new(
                        1,
                        CommandSource::Operator,
                        keep_id,
                        &keep,
                    )?)?;
                }
                let s = state
                    .recv_timeout(Duration::from_secs(5))
                    .await?
                    .context("no vehicle state")?;
                if s.alt_rel_m > alt - 0.5 {
                    break;
                }
                if Instant::now() > deadline {
                    bail!("take-off did not reach {alt} m");
                }
            }
        }
    }
    Ok(())
}
