//! Fault injection under load (issue 11): one mesh with every gateway, the shot
//! engine, the swarm queue, the embedded broker and the vision services, the vehicle
//! in the air, clients connected on every protocol and frames flowing. Every service
//! is SIGKILLed in turn (`SKYMESH_FAULT_ROUNDS` rounds, default 1 to keep CI
//! short; the soak runs 8: 104 kills) and after each kill the test checks, through the real protocols:
//!
//! - the supervisor restarts it, and its clients get served again (the Solo app, an
//!   IMC peer, the DJI cloud over MQTT, a GroundControl client, a DigiView client,
//!   bus readers of vehicle, swarm and vision state);
//! - when the process that was commanding the vehicle dies (imc-gateway relaying an
//!   operator's teleoperation stream), the arbiter brakes the vehicle: a
//!   `StaleBrake` event for that source and the vehicle stopping;
//! - no stale command is executed after a restart: teleoperation sent while
//!   autopilot-link was dead does not move the vehicle once it is back, and a
//!   restarted autopilot (vehicle-sim) is not re-armed or re-commanded by anyone;
//! - nothing leaks: the supervisor's file descriptors, the file descriptors and
//!   shared-memory mappings of a long-lived service (autopilot-link, which outlives
//!   eleven restarts of its peers each round), the domain's files in `/dev/shm` and
//!   the iceoryx2 root, no zombie children; the restart counters match the kills;
//!   after the mesh stops, no process and no file of its domain is left.
//!
//! Recovery times (kill → running again, kill → served again, kill → brake) are
//! printed per service as `faults: …` lines with p50/p99 over the rounds.

mod solo_common;

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use digiview_proto::{Frame, MessageType, ParamType, FRAME_LEN};
use gc_proto::{NetCmdType as T, Record, RECORD_LEN};
use imc_proto::Message;
use serde_json::json;
use skymesh_dji_gateway::cloud::Cloud;
use skymesh_e2e::{Mesh, MeshBus, MeshOptions};
use skymesh_imc_gateway::client::ImcClient;
use skymesh_ipc_types::{
    topics, ArbiterEvent, ArbiterEventKind, CommandSource, SwarmState, VehicleCommand,
    VehicleState, VehicleStatus, VisionState,
};
use skymesh_runtime::ipc::Subscriber;
use skymesh_solo_gateway::client::AppClient;
use solo_common::{runtime, speed, Vehicle, STARTUP};
use solo_proto::SoloMessage;

/// Waiting for something that should come back (never a latency claim).
const PATIENCE: Duration = Duration::from_secs(20);
/// autopilot-link's `setpoint_max_age_ms` (its default): a setpoint stream that
/// stops for longer is braked.
const SETPOINT_MAX_AGE_MS: u64 = 500;
/// The arbiter's poll period and the bus hop on top of the freshness limit.
const BRAKE_SLACK_MS: u64 = 250;
/// The IMC gateway's address (its default).
const IMC_GATEWAY: u16 = 0x2c01;

/// The services of the mesh, in the order each round kills them: the command source
/// first (while it relays a teleoperation stream), vehicle-sim last (its restart
/// lands the vehicle: the next round takes off again).
const ORDER: [&str; 13] = [
    "imc-gateway",
    "hardware",
    "solo-gateway",
    "shot-engine",
    "mqtt-broker",
    "dji-gateway",
    "swarm-queue",
    "groundcontrol-gateway",
    "camera",
    "vision-pipeline",
    "digiview-gateway",
    "autopilot-link",
    "vehicle-sim",
];

fn rounds() -> usize {
    std::env::var("SKYMESH_FAULT_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|n| *n >= 1)
        .unwrap_or(1)
}

/// A small synthetic camera: frames flow without loading the machine.
fn camera_config() -> String {
    "stream = \"main\"\nwidth = 320\nheight = 240\nfps = 10\nformat = \"rgb24\"\n\
     [synthetic]\nrender_threads = 1\n"
        .to_string()
}

/// Measured recovery times of one kind, in ms.
#[derive(Default)]
struct Times(BTreeMap<String, Vec<f64>>);

impl Times {
    fn add(&mut self, key: &str, d: Duration) {
        self.0
            .entry(key.to_string())
            .or_default()
            .push(d.as_secs_f64() * 1e3);
    }

    fn print(&self, what: &str) {
        for (k, v) in &self.0 {
            let mut v = v.clone();
            v.sort_by(f64::total_cmp);
            let pct = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
            eprintln!(
                "faults: {what} {k}: n={} p50={:.0} ms p99={:.0} ms max={:.0} ms",
                v.len(),
                pct(0.5),
                pct(0.99),
                v[v.len() - 1]
            );
        }
    }
}

/// Open file descriptors of `pid`.
fn fds(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count())
}

/// Mappings of `/dev/shm` files in `pid`'s address space.
fn shm_maps(pid: u32) -> usize {
    std::fs::read_to_string(format!("/proc/{pid}/maps"))
        .map(|m| m.lines().filter(|l| l.contains("/dev/shm/")).count())
        .unwrap_or(0)
}

/// SIGKILLs service `name` once it runs (a service may be `degraded` for a moment
/// after a peer's restart, e.g. vision-pipeline without frames); returns its pid.
fn kill(mesh: &mut Mesh, name: &str) -> u32 {
    let pid = mesh
        .wait_for(PATIENCE, &format!("{name} up"), |m| {
            let s = m.service(name).ok()?;
            (s["state"] == "running" || s["state"] == "degraded")
                .then(|| s["pid"].as_u64())
                .flatten()
                .map(|p| p as u32)
        })
        .unwrap();
    skymesh_e2e::signal(pid, nix::sys::signal::Signal::SIGKILL).unwrap();
    pid
}

/// Waits until `name` is up again with a pid other than `old`; returns it.
fn restarted(mesh: &mut Mesh, name: &str, old: u32) -> u32 {
    mesh.wait_for(PATIENCE, &format!("{name} restarted"), |m| {
        let s = m.service(name).ok()?;
        let pid = s["pid"].as_u64()? as u32;
        ((s["state"] == "running" || s["state"] == "degraded") && pid != old).then_some(pid)
    })
    .unwrap()
}

/// Zombie children of `parent` (exited, never reaped).
fn zombies_of(parent: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let stat = std::fs::read_to_string(e.path().join("stat")).unwrap_or_default();
        let Some((_, rest)) = stat.rsplit_once(')') else {
            continue;
        };
        let mut f = rest.split_whitespace();
        let (state, ppid) = (f.next(), f.next().and_then(|p| p.parse::<u32>().ok()));
        if state == Some("Z") && ppid == Some(parent) {
            out.push(pid);
        }
    }
    out
}

/// Zombies that stay zombies for a second (a child between exit and reap is one briefly).
fn lasting_zombies(parent: u32) -> Vec<u32> {
    let first = zombies_of(parent);
    if first.is_empty() {
        return first;
    }
    std::thread::sleep(Duration::from_secs(1));
    let second = zombies_of(parent);
    first.into_iter().filter(|p| second.contains(p)).collect()
}

/// The domain's files in /dev/shm and the iceoryx2 root, once the list is stable
/// (a restart's cleanup and re-creation take a moment).
fn settled_files(mesh: &Mesh) -> Vec<String> {
    let d = mesh.ipc_domain().unwrap();
    let list = || {
        let mut v: Vec<String> = d
            .leftover_files()
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        v.sort();
        v
    };
    let mut last = list();
    for _ in 0..40 {
        std::thread::sleep(Duration::from_millis(250));
        let now = list();
        if now == last {
            return now;
        }
        last = now;
    }
    last
}

/// Drains `sub`, then waits for a sample for which `f` holds.
async fn fresh<T: skymesh_ipc_types::Sample + Copy>(
    sub: &mut Subscriber<T>,
    what: &str,
    mut f: impl FnMut(&T) -> bool,
) -> T {
    while sub.try_recv().unwrap().is_some() {}
    let deadline = Instant::now() + PATIENCE;
    while Instant::now() < deadline {
        if let Some(s) = sub.recv_timeout(Duration::from_secs(1)).await.unwrap() {
            if f(&s) {
                return s;
            }
        }
    }
    panic!("{what}: no such sample within {PATIENCE:?}");
}

/// A DigiView GET SYSTEM_STATUS over a new connection; true once answered.
fn digiview_answers(port: u16) -> bool {
    let Ok(mut s) = TcpStream::connect(SocketAddr::from(([127, 0, 0, 1], port))) else {
        return false;
    };
    let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
    if s.write_all(&Frame::new(MessageType::Get, ParamType::SystemStatus).encode())
        .is_err()
    {
        return false;
    }
    let mut b = [0u8; FRAME_LEN];
    s.read_exact(&mut b).is_ok() && Frame::decode(&b).is_ok()
}

/// A GroundControl PING over a new connection; true once PING_RESPONSE came.
fn groundcontrol_answers(port: u16) -> bool {
    let Ok(mut s) = TcpStream::connect(SocketAddr::from(([127, 0, 0, 1], port))) else {
        return false;
    };
    let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
    if s.write_all(&Record::ping_request(77, 0.0, 0.0).encode())
        .is_err()
    {
        return false;
    }
    let mut b = [0u8; RECORD_LEN];
    while s.read_exact(&mut b).is_ok() {
        if Record::from_prefix(&b).is_some_and(|r| r.kind == T::PingResponse.id()) {
            return true;
        }
    }
    false
}

/// A Solo app connects and is told the current shot (solo-gateway → shot-engine).
async fn solo_answers(port: u16) {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Ok(mut app) = AppClient::connect(SocketAddr::from(([127, 0, 0, 1], port))).await {
            let shot = app
                .recv_until(Duration::from_secs(3), |m| {
                    matches!(m, SoloMessage::GetCurrentShot(_))
                })
                .await;
            if shot.is_some() {
                return;
            }
        }
        assert!(
            Instant::now() < deadline,
            "the Solo app is not served again"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Polls `f` until it holds; panics after `PATIENCE`.
async fn until(what: &str, mut f: impl FnMut() -> bool) {
    let deadline = Instant::now() + PATIENCE;
    while !f() {
        assert!(Instant::now() < deadline, "{what}: not within {PATIENCE:?}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The DJI gateway answers an unknown method (it is connected to the broker).
async fn dji_answers(cloud: &Cloud) {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let tid = cloud.send("skymesh_faults_ping", json!({})).await.unwrap();
        if cloud.reply(&tid, Duration::from_secs(1)).await.is_ok() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "the DJI gateway never answered again"
        );
    }
}

/// An IMC power channel query answered (imc-gateway → hardware → imc-gateway).
async fn imc_hardware_answers(peer: &ImcClient) {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let got = peer
            .request(
                &Message::QueryPowerChannelState,
                Duration::from_secs(1),
                |m| matches!(m, Message::PowerChannelState { .. }),
            )
            .await
            .unwrap();
        if got.is_some() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "the IMC gateway / hardware never answered a power channel query again"
        );
    }
}

/// Reads vehicle states until `f` holds (tolerates a gap while the link restarts).
async fn vehicle_until(
    state: &mut Subscriber<VehicleState>,
    what: &str,
    mut f: impl FnMut(&VehicleState) -> bool,
) -> VehicleState {
    let deadline = Instant::now() + PATIENCE;
    let mut last = None;
    while Instant::now() < deadline {
        if let Some(s) = state.recv_timeout(Duration::from_secs(1)).await.unwrap() {
            if f(&s) {
                return s;
            }
            last = Some(s);
        }
    }
    panic!("{what}: not within {PATIENCE:?}; last state {last:?}");
}

/// Sends "Forward" at 10 Hz from its own IMC peer while `on` is set.
fn teleop(port: u16, on: Arc<AtomicBool>, stop: Arc<AtomicBool>) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut peer = ImcClient::connect(SocketAddr::from(([127, 0, 0, 1], port)))
            .await
            .unwrap();
        peer.identity.dst = IMC_GATEWAY;
        while !stop.load(Ordering::Relaxed) {
            if on.load(Ordering::Relaxed) {
                // The gateway may be dead: a refused datagram is part of the test.
                let _ = peer
                    .send(&Message::RemoteActions {
                        actions: "Forward=1;Right=0;Up=0;Yaw=0".into(),
                    })
                    .await;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    })
}

/// Everything the test keeps open on the mesh.
struct Load {
    /// The test's bus node (its subscribers live as long as it).
    _bus: MeshBus,
    v: Vehicle,
    status: Subscriber<VehicleStatus>,
    events: Subscriber<ArbiterEvent>,
    /// Every VehicleCommand to vehicle 1 (the arbiter's input).
    cmds: Subscriber<VehicleCommand>,
    swarm: Subscriber<SwarmState>,
    vision: Subscriber<VisionState>,
    imc: ImcClient,
    cloud: Cloud,
    teleop_on: Arc<AtomicBool>,
}

#[test]
fn every_service_killed_under_load_recovers_and_leaks_nothing() {
    let rounds = rounds();
    let rt = runtime();
    let mut mesh = Mesh::start(MeshOptions {
        solo: true,
        imc: true,
        dji: true,
        swarm: true,
        vision: true,
        camera_extra: camera_config(),
        // Frames flow with no DigiView client: the recovery checks read the
        // pipeline's state on the bus.
        vision_extra: "always_on = true\n".into(),
        attitude_hz: 25.0,
        // The commanding gateway stays dead longer than the freshness limit, so the
        // arbiter's brake is what stops the vehicle (a faster restart can resume the
        // stream within the limit, when no brake is due).
        // autopilot-link likewise, so the teleoperation the test sends while it is
        // down (300 ms) certainly ends before a new process subscribes: what is
        // checked is that nothing sent during the outage is executed afterwards.
        restart: vec![
            (
                "imc-gateway".into(),
                "{ initial_backoff_ms = 1000, jitter = 0.0 }".into(),
            ),
            (
                "autopilot-link".into(),
                "{ initial_backoff_ms = 1000, jitter = 0.0 }".into(),
            ),
        ],
        ..MeshOptions::default()
    })
    .unwrap();
    mesh.expect_running(&ORDER, STARTUP);
    let supervisor = mesh.supervisor_pid().unwrap();
    let mut running = Times::default();
    let mut served = Times::default();
    let mut braked = Times::default();
    let stop_teleop = Arc::new(AtomicBool::new(false));

    rt.block_on(async {
        let bus = mesh.bus("e2e-faults").unwrap();
        let mut load = Load {
            v: Vehicle::new(&bus),
            status: bus.subscriber(&topics::vehicle_status(1)).unwrap(),
            events: bus.subscriber(&topics::vehicle_arbiter_events(1)).unwrap(),
            cmds: bus.subscriber(&topics::vehicle_command(1)).unwrap(),
            swarm: bus.subscriber(&topics::swarm_state()).unwrap(),
            vision: bus.subscriber(&topics::vision_state()).unwrap(),
            imc: {
                let mut p = ImcClient::connect(SocketAddr::from(([127, 0, 0, 1], mesh.imc_port)))
                    .await
                    .unwrap();
                p.identity.dst = IMC_GATEWAY;
                p
            },
            cloud: Cloud::connect(mesh.mqtt_addr, &mesh.gateway_sn)
                .await
                .unwrap(),
            teleop_on: Arc::new(AtomicBool::new(false)),
            _bus: bus,
        };
        let teleop_task = teleop(mesh.imc_port, load.teleop_on.clone(), stop_teleop.clone());
        // Every client served once before the first kill.
        dji_answers(&load.cloud).await;
        imc_hardware_answers(&load.imc).await;
        solo_answers(mesh.solo_port).await;
        until("GroundControl answers", || {
            groundcontrol_answers(mesh.gc_port)
        })
        .await;
        until("DigiView answers", || digiview_answers(mesh.digiview_port)).await;
        fresh(&mut load.vision, "frames processed", |s| {
            s.streams[0].last_frame_seq > 0
        })
        .await;

        let files = settled_files(&mesh);
        // A scrape first: the vehicle gauges connect to the vehicle topics at the
        // first /metrics, which is the supervisor's steady state, not a leak.
        mesh.http_get("/metrics").expect("/metrics");
        let sup_fds_start = fds(supervisor);
        for round in 1..=rounds {
            load.v.take_off(10.0).await;
            let link = mesh.wait_running("autopilot-link", STARTUP).unwrap();
            let (link_fds, link_maps) = (fds(link), shm_maps(link));
            for name in ORDER {
                if name == "autopilot-link" {
                    // It lived through every other restart of this round.
                    let (f, m) = (fds(link), shm_maps(link));
                    eprintln!(
                        "faults: round {round}: autopilot-link fds {link_fds} → {f}, \
                         shm mappings {link_maps} → {m}"
                    );
                    assert!(
                        f <= link_fds + 2,
                        "autopilot-link's fds grew {link_fds} → {f} over its peers' restarts"
                    );
                    assert!(
                        m <= link_maps + 2,
                        "autopilot-link's shm mappings grew {link_maps} → {m}"
                    );
                }
                kill_and_check(
                    &mut mesh,
                    &mut load,
                    name,
                    (&mut running, &mut served, &mut braked),
                )
                .await;
                eprintln!("faults: round {round}: {name} killed and recovered");
            }
            let now_files = settled_files(&mesh);
            let kinds = |l: &[String]| -> BTreeMap<String, usize> {
                let mut m = BTreeMap::new();
                for f in l {
                    let kind = f.rsplit('.').next().unwrap_or("").to_string();
                    *m.entry(kind).or_insert(0) += 1;
                }
                m
            };
            eprintln!(
                "faults: round {round}: domain files {} → {} {:?}",
                files.len(),
                now_files.len(),
                kinds(&now_files)
            );
            // Nodes, services, data segments, events: exactly as many as before
            // the kills. Pub-sub connections may differ: a subscriber that has not
            // read since its publisher died keeps that connection mapped until it
            // reads (or iceoryx2 reclaims it for a new publisher), so each one
            // must be held by a live process of the mesh — none orphaned.
            let (mut before, mut after) = (kinds(&files), kinds(&now_files));
            before.remove("connection");
            after.remove("connection");
            if after != before {
                let states: Vec<String> = mesh
                    .status()
                    .unwrap()
                    .iter()
                    .map(|s| format!("{} {} {}", s["name"], s["state"], s["pid"]))
                    .collect();
                panic!(
                    "round {round}: the domain's files by kind went {before:?} → {after:?}; \
                     services {states:?}"
                );
            }
            let mut pids = mesh.processes();
            pids.push(std::process::id());
            let held: String = pids
                .iter()
                .map(|p| std::fs::read_to_string(format!("/proc/{p}/maps")).unwrap_or_default())
                .collect();
            let orphans: Vec<&String> = now_files
                .iter()
                .filter(|f| f.ends_with(".connection") && !held.contains(f.as_str()))
                .collect();
            assert!(
                orphans.is_empty(),
                "round {round}: connections no live process holds: {orphans:#?}"
            );
        }
        // Restart counters match the kills, every service is up; nothing piled up
        // in the supervisor.
        for name in ORDER {
            let s = mesh.service(name).unwrap();
            assert_eq!(s["restarts"], rounds, "{name}: {s}");
            assert_eq!(s["state"], "running", "{name}: {s}");
            let up = mesh
                .metric(&format!("skymesh_service_up{{service=\"{name}\"}}"))
                .unwrap();
            assert_eq!(up, Some(1.0), "{name} not up in the metrics");
            let restarts = mesh
                .metric(&format!(
                    "skymesh_service_restarts_total{{service=\"{name}\"}}"
                ))
                .unwrap();
            assert_eq!(restarts, Some(rounds as f64), "{name}: restarts metric");
        }
        let sup_fds = fds(supervisor);
        eprintln!(
            "faults: supervisor fds {sup_fds_start} → {sup_fds} after {} kills; domain files {}",
            rounds * ORDER.len(),
            files.len()
        );
        assert!(
            sup_fds <= sup_fds_start + 2,
            "the supervisor's fds grew {sup_fds_start} → {sup_fds} over {} kills",
            rounds * ORDER.len()
        );
        let zombies = lasting_zombies(supervisor);
        assert!(zombies.is_empty(), "zombie children: {zombies:?}");

        // The supervisor itself dies: the services keep flying the vehicle, and a new
        // supervisor adopts every one of them instead of starting duplicates.
        supervisor_dies_and_is_replaced(&mut mesh, &mut load).await;

        stop_teleop.store(true, Ordering::Relaxed);
        teleop_task.await.unwrap();
        drop(load);
    });

    running.print("kill → running again");
    served.print("kill → served again");
    braked.print("kill → stale brake");

    mesh.stop(Duration::from_secs(20)).unwrap();
    let left = mesh.processes();
    assert!(left.is_empty(), "processes left after stop: {left:?}");
    let files = mesh.ipc_domain().unwrap().leftover_files();
    assert!(files.is_empty(), "files left after stop: {files:?}");
}

/// SIGKILLs the supervisor with the vehicle in the air: the command path keeps
/// working without it (teleoperation through imc-gateway moves the vehicle, the
/// arbiter brakes when it stops); a new `skymesh up` on the same config adopts
/// every running service (same pids, no restart) and restarts one that dies later.
async fn supervisor_dies_and_is_replaced(mesh: &mut Mesh, load: &mut Load) {
    load.v.take_off(5.0).await;
    let before: BTreeMap<&str, u64> = ORDER
        .iter()
        .map(|n| (*n, mesh.service(n).unwrap()["pid"].as_u64().unwrap()))
        .collect();
    let t0 = Instant::now();
    let old = mesh.kill_supervisor().unwrap();
    load.teleop_on.store(true, Ordering::Relaxed);
    vehicle_until(
        &mut load.v.state,
        "teleoperation without a supervisor",
        |s| speed(s) > 1.2,
    )
    .await;
    load.teleop_on.store(false, Ordering::Relaxed);
    vehicle_until(&mut load.v.state, "braked without a supervisor", |s| {
        speed(s) < 0.3
    })
    .await;
    for (name, pid) in &before {
        assert!(
            std::path::Path::new(&format!("/proc/{pid}")).exists(),
            "{name} ({pid}) died with the supervisor ({old})"
        );
    }
    mesh.restart_supervisor().unwrap();
    for (name, pid) in &before {
        let s = mesh
            .wait_for(PATIENCE, &format!("{name} adopted"), |m| {
                let s = m.service(name).ok()?;
                (s["state"] == "running" || s["state"] == "degraded").then_some(s)
            })
            .unwrap();
        assert_eq!(s["pid"].as_u64(), Some(*pid), "{name} not adopted: {s}");
        assert_eq!(s["adopted"], true, "{name}: {s}");
        assert_eq!(s["restarts"], 0, "{name}: {s}");
        let adopted = mesh
            .metric(&format!(
                "skymesh_supervisor_adopted_total{{service=\"{name}\"}}"
            ))
            .unwrap();
        assert_eq!(adopted, Some(1.0), "{name}: adopted metric");
    }
    eprintln!(
        "faults: supervisor {old} killed and replaced, {} services adopted in {:.1} s",
        before.len(),
        t0.elapsed().as_secs_f64()
    );
    let duplicates: Vec<u32> = mesh
        .processes()
        .into_iter()
        .filter(|p| {
            !before.values().any(|b| *b == u64::from(*p)) && Some(*p) != mesh.supervisor_pid()
        })
        .collect();
    assert!(
        duplicates.is_empty(),
        "processes besides the adopted ones: {duplicates:?}"
    );
    // An adopted service that dies is restarted by the new supervisor and served again.
    let old = kill(mesh, "solo-gateway");
    restarted(mesh, "solo-gateway", old);
    solo_answers(mesh.solo_port).await;
}

/// Kills `name` and checks what its death and restart must (and must not) cause.
async fn kill_and_check(
    mesh: &mut Mesh,
    load: &mut Load,
    name: &str,
    (running, served, braked): (&mut Times, &mut Times, &mut Times),
) {
    match name {
        "imc-gateway" => {
            // The operator flies through the IMC gateway, then the gateway dies.
            load.teleop_on.store(true, Ordering::Relaxed);
            vehicle_until(&mut load.v.state, "teleoperation moving the vehicle", |s| {
                speed(s) > 1.2
            })
            .await;
            // (The setpoint subscriber is not drained: its buffer holds the old
            // gateway's last setpoints.)
            while load.events.try_recv().unwrap().is_some() {}
            let t0 = Instant::now();
            let old = kill(mesh, name);
            // Read the setpoint stream (as the arbiter sees it) and the arbiter's events
            // all along, until the operator's stream moves the vehicle again through
            // the new gateway.
            let mut stamps = Vec::new();
            let mut brakes = Vec::new();
            let mut new = None;
            let deadline = Instant::now() + PATIENCE;
            loop {
                while let Some(c) = load.cmds.try_recv().unwrap() {
                    if c.source == CommandSource::Imc.to_wire() {
                        stamps.push((c.header.seq, c.header.stamp_ns));
                    }
                }
                while let Some(e) = load.events.try_recv().unwrap() {
                    if e.event_kind() == Some(ArbiterEventKind::StaleBrake)
                        && e.source == CommandSource::Imc.to_wire()
                    {
                        brakes.push(e.header.stamp_ns);
                    }
                }
                // A new publisher numbers its samples from 1 again.
                let restarted_stream = stamps.windows(2).any(|w| w[1].0 < w[0].0);
                if new.is_none() {
                    let s = mesh.service(name).unwrap();
                    let pid = s["pid"].as_u64().map(|p| p as u32);
                    if s["state"] == "running" && pid.is_some_and(|p| p != old) {
                        new = pid;
                        running.add(name, t0.elapsed());
                    }
                }
                let state = load.v.state.recv_timeout(Duration::from_millis(50)).await;
                if new.is_some()
                    && restarted_stream
                    && state.unwrap().is_some_and(|s| speed(&s) > 1.2)
                {
                    break;
                }
                assert!(
                    Instant::now() < deadline,
                    "imc-gateway restarted ({new:?}) but teleoperation did not move the vehicle again; \
                     setpoints seen (seq, stamp): {:?}; metrics: {}",
                    &stamps[stamps.len().saturating_sub(20)..],
                    mesh.http_get("/metrics").unwrap_or_default().lines().filter(|l| l.contains("imc") && !l.starts_with('#')).collect::<Vec<_>>().join("\n")
                );
            }
            served.add(name, t0.elapsed());
            let new = new.unwrap();
            // If the setpoints stopped for longer than the freshness limit, the vehicle
            // must have been braked in the gap, within the limit.
            let split = stamps
                .windows(2)
                .position(|w| w[1].0 < w[0].0)
                .map(|i| i + 1);
            let last_old = split.map(|i| stamps[i - 1].1);
            let first_new = split.map(|i| stamps[i].1);
            let (Some(last_old), Some(first_new)) = (last_old, first_new) else {
                panic!("setpoints around the kill not seen: {stamps:?}");
            };
            let gap_ms = (first_new - last_old) as f64 / 1e6;
            let brake = brakes
                .iter()
                .copied()
                .find(|b| *b > last_old && *b < first_new);
            eprintln!(
                "faults: imc-gateway {old} → {new}: setpoint gap {gap_ms:.0} ms, brake {:?} ms after the last setpoint",
                brake.map(|b| (b - last_old) / 1_000_000)
            );
            if gap_ms > (SETPOINT_MAX_AGE_MS + BRAKE_SLACK_MS) as f64 {
                let b = brake.unwrap_or_else(|| {
                    panic!(
                        "the commanding imc-gateway (pid {old}) died, its setpoints stopped for \
                         {gap_ms:.0} ms, and the arbiter did not brake"
                    )
                });
                let after_ms = (b - last_old) / 1_000_000;
                assert!(
                    after_ms <= SETPOINT_MAX_AGE_MS + BRAKE_SLACK_MS,
                    "braked {after_ms} ms after the last setpoint (freshness limit {SETPOINT_MAX_AGE_MS} ms)"
                );
                braked.add(name, Duration::from_millis(after_ms));
            }
            load.teleop_on.store(false, Ordering::Relaxed);
            vehicle_until(&mut load.v.state, "braked after teleoperation", |s| {
                speed(s) < 0.3
            })
            .await;
        }
        "autopilot-link" => {
            // Teleoperation sent while the link is dead must not be executed later.
            let t0 = Instant::now();
            let old = kill(mesh, name);
            load.teleop_on.store(true, Ordering::Relaxed);
            tokio::time::sleep(Duration::from_millis(300)).await;
            load.teleop_on.store(false, Ordering::Relaxed);
            restarted(mesh, name, old);
            running.add(name, t0.elapsed());
            fresh(
                &mut load.v.state,
                "vehicle state after the link restart",
                |_| true,
            )
            .await;
            served.add(name, t0.elapsed());
            let watch = Instant::now();
            while watch.elapsed() < Duration::from_secs(3) {
                if let Some(s) = load
                    .v
                    .state
                    .recv_timeout(Duration::from_secs(1))
                    .await
                    .unwrap()
                {
                    assert!(
                        speed(&s) < 0.5,
                        "the vehicle moved after the link restart (stale teleoperation?): {s:?}"
                    );
                }
            }
        }
        "vehicle-sim" => {
            // The autopilot reboots: it comes back on the ground, and nobody re-arms or
            // re-commands it with what was sent before.
            let t0 = Instant::now();
            let old = kill(mesh, name);
            restarted(mesh, name, old);
            running.add(name, t0.elapsed());
            fresh(&mut load.status, "the link up again", |s| s.is_link_up()).await;
            served.add(name, t0.elapsed());
            let watch = Instant::now();
            while watch.elapsed() < Duration::from_secs(2) {
                if let Some(s) = load
                    .status
                    .recv_timeout(Duration::from_secs(1))
                    .await
                    .unwrap()
                {
                    assert!(!s.is_armed(), "the restarted autopilot was armed: {s:?}");
                }
            }
        }
        _ => {
            let t0 = Instant::now();
            let old = kill(mesh, name);
            restarted(mesh, name, old);
            running.add(name, t0.elapsed());
            match name {
                "hardware" => imc_hardware_answers(&load.imc).await,
                "solo-gateway" | "shot-engine" => solo_answers(mesh.solo_port).await,
                "mqtt-broker" | "dji-gateway" => dji_answers(&load.cloud).await,
                "swarm-queue" => {
                    fresh(&mut load.swarm, "swarm state after the restart", |_| true).await;
                }
                "groundcontrol-gateway" => {
                    let port = mesh.gc_port;
                    until("GroundControl answers again", || {
                        groundcontrol_answers(port)
                    })
                    .await;
                }
                "camera" | "vision-pipeline" => {
                    // Two different frames processed after the restart.
                    let a = fresh(&mut load.vision, "frames after the restart", |_| true).await;
                    fresh(&mut load.vision, "a second frame", |s| {
                        s.streams[0].last_frame_seq != a.streams[0].last_frame_seq
                    })
                    .await;
                }
                "digiview-gateway" => {
                    let port = mesh.digiview_port;
                    until("DigiView answers again", || digiview_answers(port)).await;
                }
                other => panic!("no recovery check for {other}"),
            }
            served.add(name, t0.elapsed());
        }
    }
}
