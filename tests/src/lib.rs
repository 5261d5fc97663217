//! End-to-end harness: starts the real `skymesh` supervisor and real services,
//! each mesh in its own temp dir, with generated configs, its own iceoryx2 domain
//! and its own ports; talks to it through the real bus, HTTP and CLI; kills every
//! process of the mesh on drop and prints every process's output when a test fails.
//!
//! The binaries are taken from the cargo target directory this test runs from;
//! `cargo test --workspace` builds them before any test runs.

use std::fmt::Write as _;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context as _, Result};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use skymesh_ipc_types::ServiceId;
use skymesh_runtime::{Bus, Domain, Stats};

pub mod bench;
pub mod fault_link;
pub mod first_requests;
pub mod ground;
pub mod sitl;
pub mod transport_bench;

/// Meshes are heavy for a 2-core machine: run one at a time so timing-sensitive
/// behaviour (heartbeats, backoff) is tested, not the scheduler.
static ONE_MESH_AT_A_TIME: Mutex<()> = Mutex::new(());
static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The repository root (this package lives in `<root>/tests`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// The directory holding the workspace binaries (`target/<profile>`): the parent of
/// this executable, or of its `deps/` folder for a test executable.
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap_or_default();
    let dir = exe.parent().map(Path::to_path_buf).unwrap_or_default();
    if dir.file_name().is_some_and(|n| n == "deps") {
        dir.parent().map(Path::to_path_buf).unwrap_or_default()
    } else {
        dir
    }
}

/// Path of a workspace binary; fails with a clear message if it was not built.
pub fn binary(name: &str) -> PathBuf {
    let p = bin_dir().join(name);
    assert!(
        p.exists(),
        "{} not built: run `cargo build --workspace` (or `cargo test --workspace`)",
        p.display()
    );
    p
}

/// A TCP port free on 127.0.0.1 right now (for protocols that cannot take port 0
/// through a config file, the supervisor's children are told a concrete port).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or(0)
}

/// A UDP port free on 127.0.0.1 right now.
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .unwrap_or(0)
}

/// `n` consecutive TCP ports free on 127.0.0.1 right now (for a `sim_swarm`,
/// whose vehicles listen on consecutive ports).
pub fn free_port_run(n: u8) -> Result<u16> {
    for _ in 0..100 {
        let base = free_port();
        if base == 0 || u32::from(base) + u32::from(n) > u32::from(u16::MAX) {
            continue;
        }
        if (1..u16::from(n)).all(|i| std::net::TcpListener::bind(("127.0.0.1", base + i)).is_ok()) {
            return Ok(base);
        }
    }
    bail!("no {n} consecutive free TCP ports")
}

/// How a test wants its mesh.
#[derive(Debug, Clone)]
pub struct MeshOptions {
    /// Heartbeat period handed to every service.
    pub heartbeat_ms: u64,
    /// Missed heartbeat periods before a hung service is killed.
    pub missed_heartbeats: u32,
    /// Extra TOML appended to autopilot-link's config (e.g. a bad key).
    pub autopilot_link_extra: String,
    /// ATTITUDE rate requested by autopilot-link.
    pub attitude_hz: f64,
    /// Extra TOML placed after the `[supervisor]` table (e.g. a `[restart]` policy).
    pub supervisor_extra: String,
    /// Number of vehicles: one vehicle-sim + autopilot-link pair per id 1..=N. With
    /// more than one, services are named `vehicle-sim-<id>` / `autopilot-link-<id>`.
    pub vehicles: u8,
    /// Also run the Solo app gateway and the shot engine (for vehicle 1).
    pub solo: bool,
    /// Extra TOML appended to the shot engine's config.
    pub shot_engine_extra: String,
    /// Extra TOML appended to the Solo gateway's config.
    pub solo_gateway_extra: String,
    /// Vehicle 1's autopilot-link connects to this port on 127.0.0.1 instead of
    /// straight to its vehicle-sim (a benchmark's tap sits there and forwards).
    pub link_via: Option<u16>,
    /// Vehicle 1's autopilot-link connects to this TCP port on 127.0.0.1 (a real
    /// autopilot: ArduPilot SITL, [`sitl`]) and no vehicle-sim is started for it.
    pub autopilot_tcp: Option<u16>,
    /// Also run the hardware service and the IMC gateway (for vehicle 1).
    pub imc: bool,
    /// Extra TOML appended to the IMC gateway's config. Without an
    /// `announce_destinations` key of its own, Announce is off (`[]`).
    pub imc_gateway_extra: String,
    /// Extra TOML appended to the hardware service's config (deploy/hardware.toml
    /// with `state_dir` inside the mesh's temp dir).
    pub hardware_extra: String,
    /// MAVLink router endpoints of vehicle 1's autopilot-link (default none: tests
    /// never send to a ground station's port unless they ask).
    pub link_endpoints: Vec<String>,
    /// One vehicle-sim (service `vehicle-sim`) in swarm mode serves every vehicle,
    /// on consecutive ports, homes on a grid `sim_spacing_m` apart east and north of
    /// vehicle 1's; still one autopilot-link per vehicle (named as without this).
    pub sim_swarm: bool,
    /// Grid spacing of a `sim_swarm`, metres.
    pub sim_spacing_m: f64,
    /// Also run the swarm queue and the GroundControl gateway: drones 1..=N ↔
    /// vehicles 1..=N, site origin = vehicle 1's home, animations in
    /// [`Mesh::animations_dir`], the state server on [`Mesh::gc_port`], the pose
    /// broadcast to 127.0.0.1:[`Mesh::pose_port`] (the test binds it).
    pub swarm: bool,
    /// The gateway's privileged client addresses.
    pub gc_privileged: Vec<String>,
    /// Extra TOML appended to the swarm queue's config.
    pub swarm_queue_extra: String,
    /// Extra TOML appended to the GroundControl gateway's config.
    pub gc_gateway_extra: String,
    /// Also run the embedded MQTT broker (service `mqtt-broker`, on a free
    /// 127.0.0.1 port: [`Mesh::mqtt_addr`]) and the DJI Cloud API gateway (service
    /// `dji-gateway`, for vehicle 1, serial number [`Mesh::gateway_sn`], connected
    /// to that broker). The broker restarts 1.5 s after it dies (a test can take it
    /// away with [`Mesh::kill_service`]).
    pub dji: bool,
    /// Extra TOML appended to the DJI gateway's config. It is written after the
    /// `[broker]` table: lines before the first table header of their own land in
    /// `[broker]` (e.g. `reconnect_max_ms = 500`), then e.g. `[drc]` tables.
    pub dji_gateway_extra: String,
    /// Extra TOML appended to the MQTT broker's config (e.g. `[[user]]` entries).
    pub mqtt_broker_extra: String,
    /// Also run the camera (synthetic scene, stream `main`), the vision pipeline and
    /// the DigiView gateway (on [`Mesh::digiview_port`]) for vehicle 1. Vehicle 1's
    /// autopilot-link serves the virtual cameras only if `autopilot_link_extra` has a
    /// `[vision]` table saying so.
    pub vision: bool,
    /// TOML of the camera's config after `vehicle_id = 1` (size, lens, mount, targets).
    pub camera_extra: String,
    /// TOML of the vision pipeline's config after `vehicle_id = 1`.
    pub vision_extra: String,
    /// TOML appended to the DigiView gateway's config (after `listen`).
    pub digiview_extra: String,
    /// Per-service restart policies: (service name, TOML inline table for its
    /// `restart` key), e.g. a slower restart so a test sees what happens meanwhile.
    /// Not for `mqtt-broker`, which has one already.
    pub restart: Vec<(String, String)>,
    /// Per-service `realtime_priority` (service name, SCHED_FIFO priority 1..=99).
    pub realtime: Vec<(String, u8)>,
    /// Per-service `cpu_affinity` (service name, CPUs).
    pub cpu_affinity: Vec<(String, Vec<usize>)>,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            heartbeat_ms: 200,
            missed_heartbeats: 6,
            autopilot_link_extra: String::new(),
            attitude_hz: 50.0,
            supervisor_extra: String::new(),
            vehicles: 1,
            solo: false,
            shot_engine_extra: String::new(),
            solo_gateway_extra: String::new(),
            link_via: None,
            autopilot_tcp: None,
            imc: false,
            imc_gateway_extra: String::new(),
            hardware_extra: String::new(),
            link_endpoints: Vec::new(),
            sim_swarm: false,
            sim_spacing_m: 3.0,
            swarm: false,
            gc_privileged: vec!["127.0.0.1".to_string()],
            swarm_queue_extra: String::new(),
            gc_gateway_extra: String::new(),
            dji: false,
            dji_gateway_extra: String::new(),
            mqtt_broker_extra: String::new(),
            vision: false,
            camera_extra: String::new(),
            vision_extra: String::new(),
            digiview_extra: String::new(),
            restart: Vec::new(),
            realtime: Vec::new(),
            cpu_affinity: Vec::new(),
        }
    }
}

/// Vehicle 1's home (vehicle-sim's default; a `sim_swarm` or a fleet is laid out
/// east and north of it): latitude, longitude (degrees), altitude MSL (metres).
pub const HOME: [f64; 3] = [-35.363261, 149.165230, 584.0];

/// A running mesh: the supervisor with vehicle-sim and autopilot-link.
#[derive(Debug)]
pub struct Mesh {
    pub dir: tempfile::TempDir,
    pub domain: String,
    /// MAVLink port of vehicle 1's simulator.
    pub mavlink_port: u16,
    /// Solo app TCP port (with `MeshOptions::solo`).
    pub solo_port: u16,
    /// Solo follow-stream UDP port (with `MeshOptions::solo`).
    pub follow_port: u16,
    /// The IMC gateway's UDP port (with `MeshOptions::imc`).
    pub imc_port: u16,
    /// The hardware service's state directory (with `MeshOptions::imc`).
    pub hardware_dir: PathBuf,
    /// MAVLink port of every vehicle's simulator, vehicle 1 first.
    pub mavlink_ports: Vec<u16>,
    /// The GroundControl state server's TCP port (with `MeshOptions::swarm`).
    pub gc_port: u16,
    /// The UDP port on 127.0.0.1 the pose broadcast is sent to (with `MeshOptions::swarm`).
    pub pose_port: u16,
    /// The swarm queue's animations (`drone_<id>.csv`, with `MeshOptions::swarm`).
    pub animations_dir: PathBuf,
    /// The embedded MQTT broker's address (with `MeshOptions::dji`; port 0 without).
    pub mqtt_addr: SocketAddr,
    /// The DJI gateway's serial number, unique per mesh (with `MeshOptions::dji`).
    pub gateway_sn: String,
    /// The DigiView gateway's TCP port on 127.0.0.1 (with `MeshOptions::vision`).
    pub digiview_port: u16,
    supervisor: Option<Child>,
    metrics_addr: Option<SocketAddr>,
    /// Removes the domain's shared-memory files once the mesh and every
    /// [`MeshBus`] of it are gone.
    cleanup: Arc<DomainCleanup>,
    _serial: MutexGuard<'static, ()>,
}

/// Removes a mesh's shared-memory files (`/dev/shm`: nodes, services, the topics'
/// event counts) when the last holder drops it: the [`Mesh`], whose drop has killed
/// every process of the domain by then, or a [`MeshBus`] that outlives it (a test
/// that moves its mesh into a context declared after its bus).
#[derive(Debug)]
struct DomainCleanup {
    domain: String,
}

impl Drop for DomainCleanup {
    fn drop(&mut self) {
        let Ok(d) = mesh_domain(&self.domain) else {
            return;
        };
        d.cleanup_dead_nodes();
        // A bus of the test's own still open (a clone kept past its `MeshBus`)
        // keeps its node alive: leave the files rather than pull them from under it.
        if d.live_nodes().is_empty() {
            d.remove_leftover_files();
        }
    }
}

/// The iceoryx2 domain `name` of a test mesh, with the shared deploy config.
fn mesh_domain(name: &str) -> Result<Domain> {
    Ok(Domain::load(
        name,
        Some(&repo_root().join("deploy/iceoryx2.toml")),
    )?)
}

/// A bus node of the test itself in a mesh's domain ([`Mesh::bus`]): a [`Bus`]
/// (through `Deref`) that keeps the domain's files until it is dropped too.
#[derive(Debug)]
pub struct MeshBus {
    // Fields drop in declaration order: the node before the cleanup.
    bus: Bus,
    _cleanup: Arc<DomainCleanup>,
}

impl std::ops::Deref for MeshBus {
    type Target = Bus;
    fn deref(&self) -> &Bus {
        &self.bus
    }
}

impl Mesh {
    /// Writes the configs and starts `skymesh up`; returns once its HTTP endpoint answers.
    pub fn start(opts: MeshOptions) -> Result<Mesh> {
        let serial = ONE_MESH_AT_A_TIME.lock().unwrap_or_else(|p| p.into_inner());
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let domain = format!("e2e{}x{n}", std::process::id());
        let dir = tempfile::Builder::new().prefix("skymesh-e2e-").tempdir()?;
        let root = repo_root();
        let d = dir.path();
        let bins = bin_dir();
        let mut services = String::new();
        let mut mavlink_ports = Vec::new();
        let swarm_base = opts
            .sim_swarm
            .then(|| free_port_run(opts.vehicles.max(1)))
            .transpose()?;
        for id in 1..=opts.vehicles.max(1) {
            let real_autopilot = opts.autopilot_tcp.filter(|_| id == 1);
            let port = match (real_autopilot, swarm_base) {
                (Some(autopilot), _) => autopilot,
                (None, Some(base)) => base + u16::from(id - 1),
                (None, None) => free_port(),
            };
            mavlink_ports.push(port);
            // One vehicle keeps the default names; a fleet gets `-<id>` suffixes.
            let suffix = if opts.vehicles > 1 {
                format!("-{id}")
            } else {
                String::new()
            };
            // With `sim_swarm`, one simulator (configured after this loop) serves every vehicle.
            let sim = if opts.sim_swarm {
                "vehicle-sim".to_string()
            } else {
                format!("vehicle-sim{suffix}")
            };
            if !opts.sim_swarm && real_autopilot.is_none() {
                // Vehicles stand 10 m apart (east) so a fleet does not share one spot.
                let home_lon = 149.165230
                    + f64::from(id - 1) * 10.0 / (111_320.0 * (35.363261f64).to_radians().cos());
                std::fs::write(
                    d.join(format!("{sim}.toml")),
                    format!("endpoint = \"tcp:127.0.0.1:{port}\"\nsystem_id = {id}\nhome_lon = {home_lon}\n"),
                )?;
                let _ = write!(
                    services,
                    r#"
[[service]]
name = "{sim}"
binary = "{bins}/skymesh-vehicle-sim"
config = "{sim}.toml"
critical = true
"#,
                    bins = bins.display(),
                );
            }
            let link_port = match opts.link_via {
                Some(via) if id == 1 => via,
                _ => port,
            };
            // Started after its simulator; a real autopilot is not the supervisor's.
            let after = if real_autopilot.is_some() {
                "[]".to_string()
            } else {
                format!("[\"{sim}\"]")
            };
            let endpoints = if id == 1 {
                format!("{:?}", opts.link_endpoints)
            } else {
                "[]".to_string()
            };
            std::fs::write(
                d.join(format!("autopilot-link{suffix}.toml")),
                format!(
                    // No router endpoints unless asked: tests never send to a ground station's port.
                    "connection = \"tcpout:127.0.0.1:{link_port}\"\nvehicle_id = {id}\nattitude_hz = {}\nendpoints = {endpoints}\n{}\n",
                    opts.attitude_hz, opts.autopilot_link_extra
                ),
            )?;
            let _ = write!(
                services,
                r#"
[[service]]
name = "autopilot-link{suffix}"
binary = "{bins}/skymesh-autopilot-link"
config = "autopilot-link{suffix}.toml"
after = {after}
critical = true
"#,
                bins = bins.display(),
            );
        }
        let mavlink_port = mavlink_ports[0];
        if let Some(base) = swarm_base {
            std::fs::write(
                d.join("vehicle-sim.toml"),
                format!(
                    "endpoint = \"tcp:127.0.0.1:{base}\"\nsystem_id = 1\n\
                     [swarm]\ncount = {}\nport_step = 1\nspacing_m = {}\nlayout = \"grid\"\n",
                    opts.vehicles.max(1),
                    opts.sim_spacing_m
                ),
            )?;
            // First, so it reads first in the supervisor's config.
            services.insert_str(
                0,
                &format!(
                    r#"
[[service]]
name = "vehicle-sim"
binary = "{bins}/skymesh-vehicle-sim"
config = "vehicle-sim.toml"
critical = true
"#,
                    bins = bins.display(),
                ),
            );
        }
        let (mut gc_port, mut pose_port) = (0, 0);
        let animations_dir = d.join("animations");
        if opts.swarm {
            gc_port = free_port();
            pose_port = free_udp_port();
            std::fs::create_dir_all(&animations_dir)?;
            let n = opts.vehicles.max(1);
            std::fs::write(
                d.join("swarm-queue.toml"),
                format!(
                    "site_origin = {{ lat_deg = {}, lon_deg = {}, alt_msl_m = {} }}\n\
                     drones = {{ first_id = 1, count = {n}, first_vehicle_id = 1 }}\n\
                     animations_dir = {:?}\n{}\n",
                    HOME[0],
                    HOME[1],
                    HOME[2],
                    animations_dir.display().to_string(),
                    opts.swarm_queue_extra
                ),
            )?;
            std::fs::write(
                d.join("groundcontrol-gateway.toml"),
                format!(
                    "listen = \"127.0.0.1:{gc_port}\"\nprivileged = {:?}\n\
                     broadcast_destinations = [\"127.0.0.1:{pose_port}\"]\n\
                     broadcast_bind = \"127.0.0.1:0\"\n{}\n",
                    opts.gc_privileged, opts.gc_gateway_extra
                ),
            )?;
            let links: Vec<String> = (1..=n)
                .map(|id| {
                    if opts.vehicles > 1 {
                        format!("autopilot-link-{id}")
                    } else {
                        "autopilot-link".to_string()
                    }
                })
                .collect();
            let _ = write!(
                services,
                r#"
[[service]]
name = "swarm-queue"
binary = "{bins}/skymesh-swarm-queue"
config = "swarm-queue.toml"
after = {links:?}

[[service]]
name = "groundcontrol-gateway"
binary = "{bins}/skymesh-groundcontrol-gateway"
config = "groundcontrol-gateway.toml"
after = ["swarm-queue"]
"#,
                bins = bins.display(),
            );
        }
        let (mut solo_port, mut follow_port) = (0, 0);
        if opts.solo {
            solo_port = free_port();
            follow_port = free_udp_port();
            std::fs::write(
                d.join("solo-gateway.toml"),
                format!(
                    "listen = \"127.0.0.1:{solo_port}\"\nfollow_listen = \"127.0.0.1:{follow_port}\"\n{}\n",
                    opts.solo_gateway_extra
                ),
            )?;
            std::fs::write(
                d.join("shot-engine.toml"),
                format!(
                    "vehicle_id = 1\nstate_file = \"{}\"\n{}\n",
                    d.join("shot-engine-state.json").display(),
                    opts.shot_engine_extra
                ),
            )?;
            let _ = write!(
                services,
                r#"
[[service]]
name = "solo-gateway"
binary = "{bins}/skymesh-solo-gateway"
config = "solo-gateway.toml"

[[service]]
name = "shot-engine"
binary = "{bins}/skymesh-shot-engine"
config = "shot-engine.toml"
after = ["autopilot-link"]
"#,
                bins = bins.display(),
            );
        }
        let mut imc_port = 0;
        let hardware_dir = d.join("hardware");
        if opts.imc {
            imc_port = free_udp_port();
            // The shipped hardware config (its devices, simulated) with the state in
            // this mesh's temp dir.
            let shipped = std::fs::read_to_string(root.join("deploy/hardware.toml"))?;
            let state_dir = format!("state_dir = {:?}", hardware_dir.display().to_string());
            let mut replaced = false;
            let mut hardware: String = shipped
                .lines()
                .map(|l| {
                    if l.starts_with("state_dir =") {
                        replaced = true;
                        state_dir.clone()
                    } else {
                        l.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join("\n");
            if !replaced {
                hardware = format!("{state_dir}\n{hardware}");
            }
            std::fs::write(
                d.join("hardware.toml"),
                format!("{hardware}\n{}\n", opts.hardware_extra),
            )?;
            let announce = if opts.imc_gateway_extra.contains("announce_destinations") {
                ""
            } else {
                "announce_destinations = []\n"
            };
            std::fs::write(
                d.join("imc-gateway.toml"),
                format!(
                    "listen = \"127.0.0.1:{imc_port}\"\nvehicle_id = 1\n{announce}{}\n",
                    opts.imc_gateway_extra
                ),
            )?;
            let link = if opts.vehicles > 1 {
                "autopilot-link-1"
            } else {
                "autopilot-link"
            };
            let _ = write!(
                services,
                r#"
[[service]]
name = "hardware"
binary = "{bins}/skymesh-hardware"
config = "hardware.toml"

[[service]]
name = "imc-gateway"
binary = "{bins}/skymesh-imc-gateway"
config = "imc-gateway.toml"
after = ["{link}", "hardware"]
"#,
                bins = bins.display(),
            );
        }

        let mut mqtt_addr = SocketAddr::from(([127, 0, 0, 1], 0));
        let gateway_sn = format!("E2E-{}-{n}", std::process::id());
        if opts.dji {
            mqtt_addr.set_port(free_port());
            std::fs::write(
                d.join("mqtt-broker.toml"),
                format!(
                    "listen = \"{mqtt_addr}\"\nmeters_interval_s = 1\n{}\n",
                    opts.mqtt_broker_extra
                ),
            )?;
            // Fast reconnection (the shipped default backs off up to 10 s) so a broker
            // outage costs a test seconds, not tens of seconds.
            std::fs::write(
                d.join("dji-gateway.toml"),
                format!(
                    "gateway_sn = \"{gateway_sn}\"\nvehicle_id = 1\n\
                     [broker]\naddress = \"{mqtt_addr}\"\nreconnect_initial_ms = 200\nreconnect_max_ms = 1000\n{}\n",
                    opts.dji_gateway_extra
                ),
            )?;
            let link = if opts.vehicles > 1 {
                "autopilot-link-1"
            } else {
                "autopilot-link"
            };
            // The broker comes back 1.5 s after it dies: long enough that its clients
            // notice the outage and retry, short enough for a test.
            let _ = write!(
                services,
                r#"
[[service]]
name = "mqtt-broker"
binary = "{bins}/skymesh-mqtt-broker"
config = "mqtt-broker.toml"
restart = {{ initial_backoff_ms = 1500, jitter = 0.0 }}

[[service]]
name = "dji-gateway"
binary = "{bins}/skymesh-dji-gateway"
config = "dji-gateway.toml"
after = ["{link}", "mqtt-broker", "shot-engine"]
"#,
                bins = bins.display(),
            );
            // The DJI gateway's takeoff, fly-to and POI are flown by the shot engine's
            // task runner: a mesh without the Solo services gets the engine alone.
            if !opts.solo {
                std::fs::write(
                    d.join("shot-engine.toml"),
                    format!(
                        "vehicle_id = 1\nstate_file = \"{}\"\n{}\n",
                        d.join("shot-engine-state.json").display(),
                        opts.shot_engine_extra
                    ),
                )?;
                let _ = write!(
                    services,
                    r#"
[[service]]
name = "shot-engine"
binary = "{bins}/skymesh-shot-engine"
config = "shot-engine.toml"
after = ["{link}"]
"#,
                    bins = bins.display(),
                );
            }
        }

        let mut digiview_port = 0;
        if opts.vision {
            digiview_port = free_port();
            std::fs::write(
                d.join("camera.toml"),
                format!("vehicle_id = 1\n{}\n", opts.camera_extra),
            )?;
            std::fs::write(
                d.join("vision-pipeline.toml"),
                format!("vehicle_id = 1\n{}\n", opts.vision_extra),
            )?;
            std::fs::write(
                d.join("digiview-gateway.toml"),
                format!(
                    "listen = \"127.0.0.1:{digiview_port}\"\n{}\n",
                    opts.digiview_extra
                ),
            )?;
            let link = if opts.vehicles > 1 {
                "autopilot-link-1"
            } else {
                "autopilot-link"
            };
            let _ = write!(
                services,
                r#"
[[service]]
name = "camera"
binary = "{bins}/skymesh-camera"
config = "camera.toml"
after = ["{link}"]

[[service]]
name = "vision-pipeline"
binary = "{bins}/skymesh-vision"
config = "vision-pipeline.toml"
after = ["camera"]

[[service]]
name = "digiview-gateway"
binary = "{bins}/skymesh-digiview"
config = "digiview-gateway.toml"
after = ["vision-pipeline"]
"#,
                bins = bins.display(),
            );
        }

        // Keys for single services, placed right after their `name`.
        let per_service = opts
            .restart
            .iter()
            .map(|(name, table)| (name, format!("restart = {table}")))
            .chain(
                opts.realtime
                    .iter()
                    .map(|(name, p)| (name, format!("realtime_priority = {p}"))),
            )
            .chain(
                opts.cpu_affinity
                    .iter()
                    .map(|(name, cpus)| (name, format!("cpu_affinity = {cpus:?}"))),
            );
        for (name, line) in per_service {
            let key = format!("name = \"{name}\"\n");
            if !services.contains(&key) {
                bail!("`{line}` for {name}: no such service in this mesh");
            }
            services = services.replace(&key, &format!("{key}{line}\n"));
        }
        std::fs::write(
            d.join("skymesh.toml"),
            format!(
                r#"[supervisor]
metrics = "127.0.0.1:0"
ipc_config = "{ipc}"
heartbeat_ms = {hb}
missed_heartbeats = {missed}
grace_period_ms = 3000

{extra}
{services}"#,
                ipc = root.join("deploy/iceoryx2.toml").display(),
                hb = opts.heartbeat_ms,
                missed = opts.missed_heartbeats,
                extra = opts.supervisor_extra,
            ),
        )?;
        let child = spawn_supervisor(d, &domain)?;
        let mut mesh = Mesh {
            dir,
            domain: domain.clone(),
            mavlink_port,
            solo_port,
            follow_port,
            imc_port,
            hardware_dir,
            mavlink_ports,
            gc_port,
            pose_port,
            animations_dir,
            mqtt_addr,
            gateway_sn,
            digiview_port,
            supervisor: Some(child),
            metrics_addr: None,
            cleanup: Arc::new(DomainCleanup {
                domain: domain.clone(),
            }),
            _serial: serial,
        };
        mesh.wait_http()?;
        Ok(mesh)
    }

    /// Waits until the supervisor has written its HTTP address and answers on it.
    fn wait_http(&mut self) -> Result<()> {
        let status_file = self.dir.path().join("metrics.addr");
        let addr = self.wait_for(Duration::from_secs(20), "supervisor status file", |m| {
            let text = std::fs::read_to_string(&status_file).ok()?;
            text.trim()
                .parse::<SocketAddr>()
                .ok()
                .filter(|_| m.http_get("/status").is_ok())
        })?;
        self.metrics_addr = Some(addr);
        Ok(())
    }

    /// SIGKILLs the supervisor (its services keep running) and reaps it; returns its pid.
    pub fn kill_supervisor(&mut self) -> Result<u32> {
        let mut child = self
            .supervisor
            .take()
            .ok_or_else(|| anyhow!("no supervisor running"))?;
        let pid = child.id();
        child.kill()?;
        child.wait()?;
        self.metrics_addr = None;
        let _ = std::fs::remove_file(self.dir.path().join("metrics.addr"));
        Ok(pid)
    }

    /// Starts `skymesh up` again on the same config and domain (after
    /// [`Mesh::kill_supervisor`]); returns once its HTTP endpoint answers.
    pub fn restart_supervisor(&mut self) -> Result<()> {
        if self.supervisor.is_some() {
            bail!("the supervisor is still running");
        }
        self.supervisor = Some(spawn_supervisor(self.dir.path(), &self.domain)?);
        self.wait_http()
    }

    /// The supervisor's HTTP address.
    pub fn metrics_addr(&self) -> SocketAddr {
        self.metrics_addr
            .unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 0)))
    }

    /// The supervisor's pid.
    pub fn supervisor_pid(&self) -> Option<u32> {
        self.supervisor.as_ref().map(Child::id)
    }

    /// This mesh's iceoryx2 domain, with the shared deploy config.
    pub fn ipc_domain(&self) -> Result<Domain> {
        mesh_domain(&self.domain)
    }

    /// A bus node for the test itself, in the mesh's domain. Call inside a tokio
    /// runtime. The domain's files stay until it is dropped, even after the mesh.
    pub fn bus(&self, name: &str) -> Result<MeshBus> {
        Ok(MeshBus {
            bus: Bus::open(&self.ipc_domain()?, name, ServiceId::Tool, 0, Stats::new())?,
            _cleanup: Arc::clone(&self.cleanup),
        })
    }

    /// Plain HTTP/1.0 GET against the supervisor (test-side client).
    pub fn http_get(&self, path: &str) -> Result<String> {
        let addr = match self.metrics_addr {
            Some(a) => a,
            None => std::fs::read_to_string(self.dir.path().join("metrics.addr"))?
                .trim()
                .parse()?,
        };
        let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2))?;
        s.set_read_timeout(Some(Duration::from_secs(5)))?;
        write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n")?;
        let mut resp = String::new();
        s.read_to_string(&mut resp)?;
        let (head, body) = resp
            .split_once("\r\n\r\n")
            .ok_or_else(|| anyhow!("no HTTP header end"))?;
        if !head.starts_with("HTTP/1.1 200") && !head.starts_with("HTTP/1.0 200") {
            bail!("GET {path}: {}", head.lines().next().unwrap_or(""));
        }
        Ok(body.to_string())
    }

    /// `/status` as JSON.
    pub fn status(&self) -> Result<Vec<serde_json::Value>> {
        let v: serde_json::Value = serde_json::from_str(&self.http_get("/status")?)?;
        v.as_array()
            .cloned()
            .ok_or_else(|| anyhow!("/status is not an array: {v}"))
    }

    /// The `/status` entry of one service.
    pub fn service(&self, name: &str) -> Result<serde_json::Value> {
        self.status()?
            .into_iter()
            .find(|s| s["name"] == name)
            .ok_or_else(|| anyhow!("service {name} not in /status"))
    }

    /// The value of one Prometheus series (exact name and label set as rendered).
    pub fn metric(&self, series: &str) -> Result<Option<f64>> {
        let text = self.http_get("/metrics")?;
        Ok(find_metric(&text, series))
    }

    /// Polls `f` every 50 ms until it returns `Some` or `timeout` passes.
    pub fn wait_for<T>(
        &mut self,
        timeout: Duration,
        what: &str,
        mut f: impl FnMut(&mut Self) -> Option<T>,
    ) -> Result<T> {
        let start = Instant::now();
        loop {
            if let Some(v) = f(self) {
                return Ok(v);
            }
            if let Some(child) = self.supervisor.as_mut() {
                if let Ok(Some(status)) = child.try_wait() {
                    bail!("supervisor exited ({status}) while waiting for {what}");
                }
            }
            if start.elapsed() > timeout {
                bail!("timed out after {timeout:?} waiting for {what}");
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits until `name` is `running` in `/status` and returns its pid.
    pub fn wait_running(&mut self, name: &str, timeout: Duration) -> Result<u32> {
        self.wait_for(timeout, &format!("{name} running"), |m| {
            let s = m.service(name).ok()?;
            (s["state"] == "running")
                .then(|| s["pid"].as_u64())
                .flatten()
                .map(|p| p as u32)
        })
    }

    /// Waits until `/status` lists every service `running` (polled every 10 ms, as
    /// closely as a client watching for "ready" would); returns their names.
    pub fn wait_all_running(&mut self, timeout: Duration) -> Result<Vec<String>> {
        let start = Instant::now();
        loop {
            if let Ok(status) = self.status() {
                if !status.is_empty() && status.iter().all(|s| s["state"] == "running") {
                    return Ok(status
                        .iter()
                        .filter_map(|s| s["name"].as_str().map(str::to_string))
                        .collect());
                }
            }
            if let Some(child) = self.supervisor.as_mut() {
                if let Ok(Some(status)) = child.try_wait() {
                    bail!("supervisor exited ({status}) before every service ran");
                }
            }
            if start.elapsed() > timeout {
                bail!(
                    "not every service running after {timeout:?}: {:?}",
                    self.status()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Waits until every service in `names` runs; panics naming the first that does
    /// not, with the mesh's output.
    pub fn expect_running(&mut self, names: &[&str], timeout: Duration) {
        for name in names {
            if let Err(e) = self.wait_running(name, timeout) {
                panic!("{name} did not start: {e:#}\n{}", self.output());
            }
        }
    }

    /// SIGKILLs service `name` (the supervisor restarts it by its policy) and
    /// returns the killed pid.
    pub fn kill_service(&mut self, name: &str) -> Result<u32> {
        let pid = self.wait_running(name, Duration::from_secs(10))?;
        signal(pid, Signal::SIGKILL)?;
        Ok(pid)
    }

    /// Waits until `name` runs again with a pid other than `old_pid`; returns it.
    pub fn wait_restarted(&mut self, name: &str, old_pid: u32, timeout: Duration) -> Result<u32> {
        self.wait_for(timeout, &format!("{name} restarted"), |m| {
            let s = m.service(name).ok()?;
            let pid = s["pid"].as_u64()? as u32;
            (s["state"] == "running" && pid != old_pid).then_some(pid)
        })
    }

    /// Sends SIGTERM to the supervisor and waits for it to exit.
    pub fn stop(&mut self, timeout: Duration) -> Result<std::process::ExitStatus> {
        let mut child = self
            .supervisor
            .take()
            .ok_or_else(|| anyhow!("already stopped"))?;
        signal(child.id(), Signal::SIGTERM)?;
        let start = Instant::now();
        loop {
            if let Some(status) = child.try_wait()? {
                return Ok(status);
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let _ = child.wait();
                bail!("supervisor did not exit within {timeout:?} of SIGTERM");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Every process (other than this test) whose environment names this mesh's domain.
    pub fn processes(&self) -> Vec<u32> {
        processes_with_env("SKYMESH_DOMAIN", &self.domain)
    }

    /// All captured output, for failure reports.
    pub fn output(&self) -> String {
        let mut out = String::new();
        for f in ["supervisor.stdout", "supervisor.stderr"] {
            let text = std::fs::read_to_string(self.dir.path().join(f)).unwrap_or_default();
            let _ = writeln!(out, "===== {f} (supervisor and its children) =====\n{text}");
        }
        out
    }
}

impl Drop for Mesh {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("{}", self.output());
        }
        if let Some(mut child) = self.supervisor.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
        // Children live in their own process groups: find them by their domain.
        for pid in self.processes() {
            let _ = signal(pid, Signal::SIGKILL);
        }
        // Killed, not yet gone: give the kernel a moment before `DomainCleanup` (the
        // field, dropped after this) looks for live nodes.
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Starts `skymesh up` for the mesh in `dir` (output appended to
/// `supervisor.stdout` / `supervisor.stderr` there, its children's too).
fn spawn_supervisor(dir: &Path, domain: &str) -> Result<Child> {
    let append = |name: &str| {
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join(name))
    };
    Command::new(binary("skymesh"))
        .arg("up")
        .arg("--config")
        .arg(dir.join("skymesh.toml"))
        .arg("--metrics")
        .arg("127.0.0.1:0")
        .arg("--status-file")
        .arg(dir.join("metrics.addr"))
        .env("SKYMESH_DOMAIN", domain)
        .env("RUST_LOG", "info")
        .env_remove("NOTIFY_SOCKET")
        .stdin(Stdio::null())
        .stdout(append("supervisor.stdout")?)
        .stderr(append("supervisor.stderr")?)
        .spawn()
        .context("spawning skymesh up")
}

/// Sends `sig` to `pid`.
pub fn signal(pid: u32, sig: Signal) -> Result<()> {
    kill(Pid::from_raw(pid as i32), sig).with_context(|| format!("kill({pid}, {sig})"))
}

/// Pids of live (not zombie) processes whose environment contains `key=value`, except this one.
pub fn processes_with_env(key: &str, value: &str) -> Vec<u32> {
    let needle = format!("{key}={value}");
    let me = std::process::id();
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in rd.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        if pid == me {
            continue;
        }
        let Ok(env) = std::fs::read(e.path().join("environ")) else {
            continue;
        };
        if env.split(|b| *b == 0).any(|kv| kv == needle.as_bytes()) {
            let stat = std::fs::read_to_string(e.path().join("stat")).unwrap_or_default();
            // Field 3 (after the parenthesised comm) is the state; Z = zombie.
            let state = stat
                .rsplit_once(')')
                .and_then(|(_, rest)| rest.trim_start().chars().next());
            if state != Some('Z') {
                out.push(pid);
            }
        }
    }
    out
}

/// Finds `series` (e.g. `skymesh_service_up{service="vehicle-sim"}`) in Prometheus text.
/// Labels are compared as a set, so their order in the exposition does not matter.
pub fn find_metric(text: &str, series: &str) -> Option<f64> {
    let (want_name, want_labels) = split_series(series);
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .find_map(|line| {
            let (s, value) = line.rsplit_once(' ')?;
            let (name, labels) = split_series(s);
            (name == want_name && labels == want_labels)
                .then(|| value.parse().ok())
                .flatten()
        })
}

fn split_series(s: &str) -> (&str, Vec<String>) {
    match s.split_once('{') {
        None => (s.trim(), Vec::new()),
        Some((name, rest)) => {
            let mut labels: Vec<String> = rest
                .trim_end_matches('}')
                .split(',')
                .filter(|l| !l.is_empty())
                .map(str::to_string)
                .collect();
            labels.sort();
            (name.trim(), labels)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metric_lookup_ignores_label_order() {
        let text = "# HELP x y\nx_total{b=\"2\",a=\"1\"} 5\nx_total{a=\"1\"} 3\n";
        assert_eq!(find_metric(text, "x_total{a=\"1\",b=\"2\"}"), Some(5.0));
        assert_eq!(find_metric(text, "x_total{a=\"1\"}"), Some(3.0));
        assert_eq!(find_metric(text, "x_total"), None);
    }

    /// Binaries built without a test harness (`test = false`, to spare `cargo test`
    /// one compile and link each: 27 of them) must not hold tests, or those tests
    /// would silently never run. Their code lives in libraries, tested there.
    #[test]
    fn binaries_without_a_test_harness_hold_no_tests() {
        let root = repo_root();
        let manifest: toml::Table =
            toml::from_str(&std::fs::read_to_string(root.join("Cargo.toml")).unwrap()).unwrap();
        let members = manifest["workspace"]["members"].as_array().unwrap();
        let mut untested = 0;
        for member in members {
            let dir = root.join(member.as_str().unwrap());
            let text = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
            let crate_manifest: toml::Table = toml::from_str(&text).unwrap();
            let Some(bins) = crate_manifest.get("bin").and_then(|b| b.as_array()) else {
                continue;
            };
            for bin in bins {
                if bin.get("test").and_then(|t| t.as_bool()) != Some(false) {
                    continue;
                }
                untested += 1;
                let path = dir.join(bin["path"].as_str().unwrap());
                let source = std::fs::read_to_string(&path).unwrap();
                for (n, line) in source.lines().enumerate() {
                    let code = line.trim_start();
                    let file_module = code.starts_with("mod ") && code.ends_with(';');
                    assert!(
                        !(code.starts_with("#[test]") || code.contains("cfg(test)") || file_module),
                        "{}:{}: `{code}` in a binary built with `test = false`: its tests \
                         would never run (move the code into the library, or drop \
                         `test = false`)",
                        path.display(),
                        n + 1
                    );
                }
            }
        }
        assert!(
            untested > 0,
            "no `test = false` binary found: is the manifest walk broken?"
        );
    }
}
