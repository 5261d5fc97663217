//! The mesh spine end to end: real supervisor, real vehicle-sim, real autopilot-link,
//! observed through the bus, the supervisor's HTTP endpoints and `/proc`.

use std::time::Duration;

use nix::sys::signal::Signal;
use skymesh_e2e::{signal, Mesh, MeshOptions};
use skymesh_ipc_types::{
    topics, AckResult, Command, CommandAck, CommandSource, FlightMode, VehicleCommand, VehicleState,
};
use skymesh_runtime::Subscriber;

const STARTUP: Duration = Duration::from_secs(30);

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// The next VehicleState, failing the test if none arrives in time.
async fn next_state(sub: &mut Subscriber<VehicleState>, timeout: Duration) -> VehicleState {
    sub.recv_timeout(timeout)
        .await
        .unwrap()
        .unwrap_or_else(|| panic!("no VehicleState within {timeout:?}"))
}

#[test]
fn mesh_comes_up_and_vehicle_state_flows() {
    let mut mesh = Mesh::start(MeshOptions::default()).unwrap();
    mesh.wait_running("vehicle-sim", STARTUP).unwrap();
    mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let rt = runtime();
    rt.block_on(async {
        let bus = mesh.bus("e2e-observer").unwrap();
        let mut sub = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(1))
            .unwrap();
        // Skip history; then count a second of fresh samples.
        let first = next_state(&mut sub, STARTUP).await;
        assert_eq!(first.vehicle_id, 1);
        let start = std::time::Instant::now();
        let mut n = 0;
        let mut last = first;
        while start.elapsed() < Duration::from_secs(1) {
            last = next_state(&mut sub, Duration::from_secs(2)).await;
            n += 1;
        }
        // 50 Hz requested; the machine may be loaded, so only require a clear stream.
        assert!(n >= 10, "only {n} VehicleState samples in 1 s");
        assert_eq!(last.position_valid, 1, "{last:?}");
        // vehicle-sim's default home is CMAC (-35.36, 149.17), on the ground.
        assert!((last.lat_deg + 35.363).abs() < 0.01, "{last:?}");
        assert!(last.alt_rel_m.abs() < 1.0, "{last:?}");
    });
    let metrics = mesh.http_get("/metrics").unwrap();
    for series in [
        "skymesh_service_up{service=\"vehicle-sim\"}",
        "skymesh_service_up{service=\"autopilot-link\"}",
    ] {
        assert_eq!(
            skymesh_e2e::find_metric(&metrics, series),
            Some(1.0),
            "{series} in\n{metrics}"
        );
    }
    // A service's own counters reach /metrics with its next stats sample (every
    // second), which the supervisor drains on its clock (every second): poll.
    let series = "skymesh_topic_samples_published_total{service=\"autopilot-link\",topic=\"skymesh/vehicle/1/state\"}";
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    let mut metrics = metrics;
    while skymesh_e2e::find_metric(&metrics, series).unwrap_or(0.0) <= 0.0 {
        assert!(
            std::time::Instant::now() < deadline,
            "{series} not above 0 within 10 s:\n{metrics}"
        );
        std::thread::sleep(Duration::from_millis(100));
        metrics = mesh.http_get("/metrics").unwrap();
    }
}

#[test]
fn guided_arm_takeoff_climbs_to_10_metres() {
    let mut mesh = Mesh::start(MeshOptions::default()).unwrap();
    mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let rt = runtime();
    rt.block_on(async {
        let bus = mesh.bus("e2e-pilot").unwrap();
        let mut state = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(1))
            .unwrap();
        let mut acks = bus
            .subscriber::<CommandAck>(&topics::vehicle_command_ack(1))
            .unwrap();
        let mut cmds = bus
            .publisher::<VehicleCommand>(&topics::vehicle_command(1))
            .unwrap();
        next_state(&mut state, STARTUP).await; // the link is up

        let sequence = [
            Command::SetMode(FlightMode::Guided),
            Command::Arm { force: false },
            Command::Takeoff { alt_rel_m: 10.0 },
        ];
        for (id, cmd) in sequence.iter().enumerate() {
            let id = 100 + id as u32;
            cmds.publish(VehicleCommand::new(1, CommandSource::Operator, id, cmd).unwrap())
                .unwrap();
            let ack = loop {
                let a = acks
                    .recv_timeout(Duration::from_secs(10))
                    .await
                    .unwrap()
                    .expect("no CommandAck within 10 s");
                if a.command_id == id {
                    break a;
                }
            };
            assert_eq!(ack.result(), Some(AckResult::Accepted), "{cmd:?} → {ack:?}");
        }
        let deadline = std::time::Instant::now() + Duration::from_secs(40);
        let mut alt = 0.0;
        let mut stable = 0;
        // The operator keeps its flight authority while the take-off flies (a grab
        // each second), as a source flying a position target must.
        let mut grab = std::time::Instant::now();
        let mut keep_id = 200;
        while std::time::Instant::now() < deadline {
            if std::time::Instant::now() >= grab {
                grab += Duration::from_secs(1);
                keep_id += 1;
                let keep = VehicleCommand::new(
                    1,
                    CommandSource::Operator,
                    keep_id,
                    &Command::GrabFlightAuthority,
                );
                cmds.publish(keep.unwrap()).unwrap();
            }
            alt = next_state(&mut state, Duration::from_secs(2))
                .await
                .alt_rel_m;
            // Count consecutive samples inside 10 ± 1 m: it must get there and stay.
            stable = if (alt - 10.0).abs() <= 1.0 {
                stable + 1
            } else {
                0
            };
            if stable >= 50 {
                break;
            }
        }
        assert!(
            stable >= 50,
            "vehicle did not hold 10 ± 1 m; last altitude {alt:.2} m"
        );
    });
}

#[test]
fn sigkilled_autopilot_link_is_restarted_and_state_flows_again() {
    let mut mesh = Mesh::start(MeshOptions::default()).unwrap();
    let old_pid = mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let rt = runtime();
    rt.block_on(async {
        let bus = mesh.bus("e2e-kill").unwrap();
        let mut sub = bus
            .subscriber::<VehicleState>(&topics::vehicle_state(1))
            .unwrap();
        next_state(&mut sub, STARTUP).await;
        signal(old_pid, Signal::SIGKILL).unwrap();
        let new_pid = mesh
            .wait_for(STARTUP, "autopilot-link restarted", |m| {
                let s = m.service("autopilot-link").ok()?;
                let pid = s["pid"].as_u64()? as u32;
                (s["state"] == "running" && pid != old_pid && s["restarts"] == 1).then_some(pid)
            })
            .unwrap();
        assert_ne!(new_pid, old_pid);
        // The old process is dead, so a sample stamped after the restart was seen
        // can only come from the new one.
        let restarted_at = skymesh_runtime::clock::monotonic_ns();
        let deadline = std::time::Instant::now() + STARTUP;
        loop {
            let s = next_state(&mut sub, STARTUP).await;
            if s.header.stamp_ns > restarted_at {
                break;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "no VehicleState from the restarted autopilot-link"
            );
        }
    });
    let restarts = mesh
        .metric("skymesh_service_restarts_total{service=\"autopilot-link\"}")
        .unwrap();
    assert_eq!(
        restarts,
        Some(1.0),
        "{}",
        mesh.http_get("/metrics").unwrap_or_default()
    );
}

#[test]
fn a_service_with_bad_config_exits_64_and_is_not_restarted() {
    let opts = MeshOptions {
        autopilot_link_extra: "no_such_option = true".into(),
        ..Default::default()
    };
    let mut mesh = Mesh::start(opts).unwrap();
    mesh.wait_for(STARTUP, "autopilot-link config-error", |m| {
        let s = m.service("autopilot-link").ok()?;
        (s["state"] == "config-error").then_some(())
    })
    .unwrap();
    // Give a restart loop time to show itself if there were one.
    std::thread::sleep(Duration::from_secs(2));
    let s = mesh.service("autopilot-link").unwrap();
    assert_eq!(s["state"], "config-error", "{s}");
    assert_eq!(s["restarts"], 0, "{s}");
    assert_eq!(s["last_exit_code"], 64, "{s}");
    assert_eq!(
        mesh.metric("skymesh_service_last_exit_code{service=\"autopilot-link\"}")
            .unwrap(),
        Some(64.0)
    );
    // The healthy service is unaffected.
    mesh.wait_running("vehicle-sim", STARTUP).unwrap();
}

#[test]
fn a_hung_service_is_detected_and_restarted() {
    let opts = MeshOptions {
        heartbeat_ms: 200,
        missed_heartbeats: 5,
        ..Default::default()
    };
    let mut mesh = Mesh::start(opts).unwrap();
    let old_pid = mesh.wait_running("autopilot-link", STARTUP).unwrap();
    signal(old_pid, Signal::SIGSTOP).unwrap();
    let new_pid = mesh
        .wait_for(STARTUP, "hung autopilot-link replaced", |m| {
            let s = m.service("autopilot-link").ok()?;
            let pid = s["pid"].as_u64()? as u32;
            (s["state"] == "running" && pid != old_pid).then_some(pid)
        })
        .unwrap();
    assert_ne!(new_pid, old_pid);
    // The stopped process was killed and reaped, not left behind.
    assert!(
        !mesh.processes().contains(&old_pid),
        "old pid {old_pid} still alive"
    );
    assert_eq!(mesh.service("autopilot-link").unwrap()["restarts"], 1);
}

#[test]
fn sigterm_leaves_no_process_and_no_shared_memory() {
    let mut mesh = Mesh::start(MeshOptions::default()).unwrap();
    mesh.wait_running("vehicle-sim", STARTUP).unwrap();
    mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let domain = mesh.ipc_domain().unwrap();
    assert!(
        !domain.leftover_files().is_empty(),
        "a running mesh has shared memory"
    );
    assert!(
        mesh.processes().len() >= 3,
        "supervisor + 2 services: {:?}",
        mesh.processes()
    );

    let status = mesh.stop(Duration::from_secs(20)).unwrap();
    assert!(
        status.success(),
        "supervisor exit {status}\n{}",
        mesh.output()
    );
    let left = mesh.processes();
    assert!(left.is_empty(), "processes left: {left:?}");
    let files = domain.leftover_files();
    assert!(
        files.is_empty(),
        "files left in /dev/shm or the iceoryx2 root: {files:?}"
    );
}

/// A test's own bus that outlives the mesh (the mesh moved into a context declared
/// after the bus) keeps the domain's files while its node lives, and they go when it
/// does: test runs leave nothing in `/dev/shm`.
#[test]
fn a_test_bus_outliving_its_mesh_takes_the_domain_files_with_it() {
    let mut mesh = Mesh::start(MeshOptions::default()).unwrap();
    mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let domain = mesh.ipc_domain().unwrap();
    let rt = runtime();
    let _enter = rt.enter();
    let bus = mesh.bus("e2e-outliver").unwrap();
    let sub = bus
        .subscriber::<VehicleState>(&topics::vehicle_state(1))
        .unwrap();
    drop(mesh);
    assert!(
        !domain.leftover_files().is_empty(),
        "the domain's files were removed under a live node"
    );
    drop(sub);
    drop(bus);
    let files = domain.leftover_files();
    assert!(files.is_empty(), "files left: {files:?}");
}

/// Policy (field 41) and rt_priority (field 40) of every thread of `pid`.
fn thread_scheduling(pid: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task"))
        .unwrap()
        .flatten()
    {
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue; // the thread ended meanwhile
        };
        let (_, rest) = stat.rsplit_once(')').unwrap();
        let f: Vec<&str> = rest.split_ascii_whitespace().collect();
        // After `)`, field 3 is index 0: rt_priority (40) is 37, policy (41) is 38.
        out.push((f[38].parse().unwrap(), f[37].parse().unwrap()));
    }
    out
}

/// `Cpus_allowed_list` of every thread of `pid`.
fn thread_cpus(pid: u32) -> Vec<String> {
    let mut out = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task"))
        .unwrap()
        .flatten()
    {
        let Ok(status) = std::fs::read_to_string(task.path().join("status")) else {
            continue;
        };
        if let Some(l) = status.lines().find(|l| l.starts_with("Cpus_allowed_list:")) {
            out.push(l["Cpus_allowed_list:".len()..].trim().to_string());
        }
    }
    out
}

/// `realtime_priority` and `cpu_affinity` reach the service: every thread of
/// autopilot-link runs SCHED_FIFO at the priority on the one CPU, again after a
/// restart, the supervisor's gauge reads the priority back, and vehicle-sim (not
/// configured) stays at normal scheduling on every CPU. Where the kernel refuses
/// real-time priority to this user, the service runs anyway and says why.
#[test]
fn a_realtime_priority_and_cpu_reach_every_thread_and_survive_a_restart() {
    // Whether this user may use SCHED_FIFO at all: tried on a thread of our own.
    let permitted = std::thread::spawn(|| {
        let p = skymesh_runtime::realtime::RealtimePriority::new(1)
            .unwrap()
            .unwrap();
        skymesh_runtime::realtime::apply(p).is_ok()
    })
    .join()
    .unwrap();
    // The last CPU this test may use (CPU 1 on a two-CPU machine).
    let all = skymesh_runtime::realtime::current_cpus();
    let cpu = *all.last().unwrap();
    let mut mesh = Mesh::start(MeshOptions {
        realtime: vec![("autopilot-link".into(), 21)],
        cpu_affinity: vec![("autopilot-link".into(), vec![cpu])],
        ..Default::default()
    })
    .unwrap();
    let link = mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let sim = mesh.wait_running("vehicle-sim", STARTUP).unwrap();
    let gauge = |m: &Mesh, s: &str| {
        m.metric(&format!(
            "skymesh_service_realtime_priority{{service=\"{s}\"}}"
        ))
        .unwrap()
    };
    let expect_fifo = |pid: u32| {
        let pinned = thread_cpus(pid);
        assert!(pinned.iter().all(|c| *c == cpu.to_string()), "{pinned:?}");
        let threads = thread_scheduling(pid);
        assert!(threads.len() > 1, "{threads:?}");
        if permitted {
            // SCHED_FIFO is policy 1.
            assert!(threads.iter().all(|t| *t == (1, 21)), "{threads:?}");
        } else {
            assert!(threads.iter().all(|t| *t == (0, 0)), "{threads:?}");
        }
    };
    expect_fifo(link);
    let want = if permitted { 21.0 } else { 0.0 };
    assert_eq!(gauge(&mesh, "autopilot-link"), Some(want));
    assert!(thread_scheduling(sim).iter().all(|t| *t == (0, 0)));
    if all.len() > 1 {
        let sim_cpus = thread_cpus(sim);
        assert!(
            sim_cpus.iter().all(|c| *c != cpu.to_string()),
            "{sim_cpus:?}"
        );
    }
    assert_eq!(gauge(&mesh, "vehicle-sim"), Some(0.0));
    if !permitted {
        assert!(
            mesh.output().contains("real-time priority refused"),
            "{}",
            mesh.output()
        );
    }
    signal(link, Signal::SIGKILL).unwrap();
    let again = mesh
        .wait_restarted("autopilot-link", link, STARTUP)
        .unwrap();
    expect_fifo(again);
}
