//! The service through real iceoryx2 shared memory, in one process: a "tool" node
//! plays groundcontrol-gateway and a fake autopilot-link (the library's kinematic
//! `FakeVehicle` behind each vehicle's command/ack/state/status topics); the queue
//! runs `run_with` on its own domain. Waits are bounded by generous timeouts;
//! nothing asserts timing.

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_ipc_types::{
    drone_flags, swarm_flags, topics, CommandAck, DroneState, ServiceId, SwarmCommand,
    SwarmCommandKind, SwarmReply, SwarmResult, SwarmState, SwarmWatch, VehicleCommand,
    VehicleState, VehicleStatus, ALL_DRONES,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::ipc::DomainGuard;
use skymesh_runtime::{Bus, CancellationToken, Domain, Publisher, Stats, Subscriber};
use skymesh_swarm_queue::fake::FakeVehicle;
use skymesh_swarm_queue::{RawConfig, Settings};

const PATIENCE: Duration = Duration::from_secs(30);
const VEHICLES: [u8; 2] = [41, 42];

/// A fresh domain whose shared-memory files go when the test ends (declared
/// before the buses, so their nodes are gone first).
fn unique_domain() -> DomainGuard {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "sq{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    DomainGuard(Domain::load(&name, None).expect("domain"))
}

fn settings(extra: &str) -> Settings {
    let text = format!(
        "site_origin = {{ lat_deg = -35.363261, lon_deg = 149.165230, alt_msl_m = 584.0 }}\n\
         drones = {{ first_id = 1, count = 2, first_vehicle_id = {} }}\n{extra}\n",
        VEHICLES[0]
    );
    let raw: RawConfig = toml::from_str(&text).expect("toml");
    raw.validate_in(std::path::Path::new("/nonexistent"))
        .expect("settings")
}

/// The vehicles behind their autopilot links, stepped every 20 ms in a task.
fn spawn_autopilots(
    bus: Bus,
    settings: &Settings,
    stop: CancellationToken,
) -> tokio::task::JoinHandle<()> {
    struct Link {
        v: FakeVehicle,
        commands: Subscriber<VehicleCommand>,
        acks: Publisher<CommandAck>,
        state: Publisher<VehicleState>,
        status: Publisher<VehicleStatus>,
    }
    let site = settings.site;
    let mut links: Vec<Link> = VEHICLES
        .iter()
        .enumerate()
        .map(|(i, id)| Link {
            v: FakeVehicle::new(*id, site, [i as f64 * 4.0, 0.0, 0.0]),
            commands: bus.subscriber(&topics::vehicle_command(*id)).unwrap(),
            acks: bus.publisher(&topics::vehicle_command_ack(*id)).unwrap(),
            state: bus.publisher(&topics::vehicle_state(*id)).unwrap(),
            status: bus.publisher(&topics::vehicle_status(*id)).unwrap(),
        })
        .collect();
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_millis(20));
        while !stop.is_cancelled() {
            tick.tick().await;
            for l in links.iter_mut() {
                while let Some(c) = l.commands.try_recv().unwrap() {
                    if let Some(ack) = l.v.handle(&c) {
                        l.acks.publish(ack).unwrap();
                    }
                }
                l.v.step(0.02);
                l.state.publish(l.v.state(monotonic_ns())).unwrap();
                l.status.publish(l.v.status()).unwrap();
            }
        }
    })
}

struct Gateway {
    commands: Publisher<SwarmCommand>,
    replies: Subscriber<SwarmReply>,
    state: Subscriber<SwarmState>,
    next: u32,
    seen: Vec<SwarmReply>,
}

impl Gateway {
    /// The gateway's ports on `tool`'s bus.
    fn open(tool: &Bus) -> Gateway {
        Gateway {
            commands: tool.publisher(&topics::swarm_command()).unwrap(),
            replies: tool.subscriber(&topics::swarm_reply()).unwrap(),
            state: tool.subscriber(&topics::swarm_state()).unwrap(),
            next: 0,
            seen: Vec::new(),
        }
    }

    fn send(
        &mut self,
        drone: u16,
        kind: SwarmCommandKind,
        set: impl FnOnce(&mut SwarmCommand),
    ) -> u32 {
        self.next += 1;
        let mut c = SwarmCommand {
            request_id: self.next,
            client: 1,
            drone,
            kind: kind.to_wire(),
            ..SwarmCommand::default()
        };
        set(&mut c);
        c.validate().expect("a valid command");
        self.commands.publish(c).unwrap();
        self.next
    }

    /// Waits for the reply to `request` from `drone`.
    async fn reply(&mut self, request: u32, drone: u16) -> SwarmReply {
        let found = |seen: &[SwarmReply]| {
            seen.iter()
                .find(|r| r.request_id == request && r.drone == drone)
                .copied()
        };
        let wait = async {
            loop {
                if let Some(r) = found(&self.seen) {
                    return r;
                }
                let r = self.replies.recv().await.unwrap();
                self.seen.push(r);
            }
        };
        tokio::time::timeout(PATIENCE, wait)
            .await
            .unwrap_or_else(|_| {
                panic!("no reply to {request} for drone {drone} within {PATIENCE:?}")
            })
    }

    /// The next state published (older buffered ones skipped).
    async fn state(&mut self) -> SwarmState {
        while self.state.try_recv().unwrap().is_some() {}
        tokio::time::timeout(PATIENCE, self.state.recv())
            .await
            .expect("swarm state in time")
            .unwrap()
    }
}

/// Runs the queue on its own bus of `domain` until `stop`; returns once it is ready.
async fn start_queue(
    domain: &Domain,
    settings: Settings,
    stop: &CancellationToken,
) -> (tokio::task::JoinHandle<anyhow::Result<()>>, Stats) {
    let stats = Stats::new();
    let bus = Bus::open(
        domain,
        "swarm-queue",
        ServiceId::SwarmQueue,
        0,
        stats.clone(),
    )
    .unwrap();
    let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
    let queue = tokio::spawn(skymesh_swarm_queue::run_with(
        settings,
        bus,
        stats.clone(),
        stop.clone(),
        move || {
            let _ = ready_tx.send(());
        },
    ));
    tokio::time::timeout(PATIENCE, ready_rx)
        .await
        .unwrap()
        .unwrap();
    (queue, stats)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn takeoff_and_a_waypoint_over_the_bus() {
    let domain = unique_domain();
    let tool = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let settings = settings("");
    let stop = CancellationToken::new();
    let autopilots = spawn_autopilots(tool.clone(), &settings, stop.clone());
    let mut gw = Gateway::open(&tool);

    let (queue, stats) = start_queue(&domain, settings, &stop).await;

    // The state comes at the tick rate, with both drones on the ground.
    let s = loop {
        let s = gw.state().await;
        if s.drones()
            .iter()
            .all(|d| d.flags & drone_flags::POSE_VALID != 0)
        {
            break s;
        }
    };
    assert_eq!(s.count, 2);
    assert_eq!(s.drones[0].drone, 1);
    assert_eq!(s.drones[1].vehicle_id, 42);
    assert_eq!(s.drones[0].drone_state, DroneState::OnGround.to_wire());
    assert!(
        (s.drones[1].tracking[0] - 4.0).abs() < 0.01,
        "{:?}",
        s.drones[1].tracking
    );

    let up = gw.send(ALL_DRONES, SwarmCommandKind::ExtGoExternal, |_| {});
    for d in [1, 2] {
        let r = gw.reply(up, d).await;
        assert_eq!(r.result(), Ok(SwarmResult::Success), "{:?}", r.reason);
        assert_eq!(r.kind, SwarmCommandKind::ExtGoExternal.to_wire());
        assert_eq!(r.client, 1);
    }

    let w = gw.send(1, SwarmCommandKind::ExtWaypoint, |c| {
        c.f[..4].copy_from_slice(&[2.0, 3.0, 4.0, 3.0]);
    });
    let r = gw.reply(w, 1).await;
    assert_eq!(r.result(), Ok(SwarmResult::Success), "{:?}", r.reason);
    let s = gw.state().await;
    let d = s.drones[0];
    let err: f32 = (0..3)
        .map(|i| (d.tracking[i] - [2.0, 3.0, 4.0][i]).powi(2))
        .sum::<f32>()
        .sqrt();
    assert!(err < 0.6, "{:?}", d.tracking);
    assert_eq!(d.drone_state, DroneState::FollowTarget.to_wire());

    let idle = gw.send(ALL_DRONES, SwarmCommandKind::ExtCheckAllIdle, |_| {});
    for d in [1, 2] {
        let r = gw.reply(idle, d).await;
        assert_eq!((r.result(), r.value), (Ok(SwarmResult::IdleState), 1));
    }
    let unknown = gw.send(9, SwarmCommandKind::ExtHalt, |_| {});
    assert_eq!(gw.reply(unknown, 9).await.reason.as_str(), "unknown drone");

    stop.cancel();
    queue.await.unwrap().expect("clean stop");
    autopilots.await.unwrap();
    let replies = stats.counter(
        "skymesh_swarm_commands_total",
        &[("kind", "ext_go_external"), ("outcome", "success")],
    );
    assert_eq!(replies.get(), 2);
}

/// Waits until `skymesh_swarm_resting` reads `want`.
async fn until_resting(stats: &Stats, want: bool) {
    let gauge = stats.gauge("skymesh_swarm_resting", &[]);
    let want = if want { 1.0 } else { 0.0 };
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while gauge.get() != want {
        assert!(
            tokio::time::Instant::now() < deadline,
            "skymesh_swarm_resting never read {want}"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// The queue's ticks within `window`.
async fn ticks_within(stats: &Stats, window: Duration) -> u64 {
    let ticks = stats.histogram(
        "skymesh_swarm_tick_seconds",
        &[],
        &skymesh_runtime::stats::LATENCY_BOUNDS_S,
    );
    let before = ticks.count();
    tokio::time::sleep(window).await;
    ticks.count() - before
}

/// Says on the watch topic whether the test reads the state at the queue's rate.
fn say_watching(watch: &mut Publisher<SwarmWatch>, watching: bool) {
    watch
        .publish(SwarmWatch {
            watching: u8::from(watching),
            ..SwarmWatch::default()
        })
        .unwrap();
}

/// With nothing to fly and no reader watching its state, the queue ticks once a
/// second instead of 30 times; a command that arrives then sees the vehicles'
/// current state (the last tick's is stale by then); a reader's word that it
/// watches brings the full rate back at once, and a word that it stopped, or a
/// word not renewed, the rest.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn at_rest_and_unwatched_the_queue_ticks_once_a_second() {
    let domain = unique_domain();
    let tool = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    // A pose is fresh for 0.1 s: much less than a rest period.
    let settings = settings("pose_timeout_s = 0.1");
    let stop = CancellationToken::new();
    let autopilots = spawn_autopilots(tool.clone(), &settings, stop.clone());
    let mut gw = Gateway::open(&tool);
    let mut watch = tool
        .publisher::<SwarmWatch>(&topics::swarm_watch())
        .unwrap();
    let (queue, stats) = start_queue(&domain, settings, &stop).await;

    // Nobody watches, nothing to fly: a tick a second.
    until_resting(&stats, true).await;
    let resting = ticks_within(&stats, Duration::from_secs(3)).await;
    assert!(resting <= 5, "{resting} ticks in 3 s at rest");

    // RESET_HOME_POSITION needs a fresh position. At rest, 0.3 s after a tick, the
    // position that tick read is older than pose_timeout_s.
    for _ in 0..2 {
        until_resting(&stats, true).await;
        tokio::time::sleep(Duration::from_millis(300)).await;
        let home = gw.send(1, SwarmCommandKind::ResetHomePosition, |c| {
            c.flags |= swarm_flags::PRIVILEGED;
        });
        let r = gw.reply(home, 1).await;
        assert_eq!(r.result(), Ok(SwarmResult::Success), "{:?}", r.reason);
    }

    // A reader watches: the full rate, and a state at once.
    until_resting(&stats, true).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    while gw.state.try_recv().unwrap().is_some() {}
    let said = tokio::time::Instant::now();
    say_watching(&mut watch, true);
    gw.state().await;
    // With the word, not at the next rest tick (0.7 s on).
    let after = said.elapsed();
    assert!(
        after < Duration::from_millis(600),
        "a state {after:?} after the word"
    );
    let watched = ticks_within(&stats, Duration::from_secs(2)).await;
    assert!(watched >= 20, "{watched} ticks in 2 s while watched");
    assert_eq!(stats.gauge("skymesh_swarm_resting", &[]).get(), 0.0);

    // The reader stops watching: the rest again.
    say_watching(&mut watch, false);
    until_resting(&stats, true).await;

    // A word not renewed lapses (after 3 s).
    say_watching(&mut watch, true);
    until_resting(&stats, false).await;
    until_resting(&stats, true).await;

    stop.cancel();
    queue.await.unwrap().expect("clean stop");
    autopilots.await.unwrap();
}

/// How many file descriptors the ports of a 250-drone queue take. Run with
/// `cargo test -p skymesh-swarm-queue --test bus -- --ignored --nocapture`.
#[test]
#[ignore = "measurement: opens about a thousand ports"]
fn file_descriptors_for_250_drones() {
    skymesh_swarm_queue::fdlimit::raise_nofile_limit().unwrap();
    let domain = unique_domain();
    let text = "site_origin = { lat_deg = 0.0, lon_deg = 0.0, alt_msl_m = 0.0 }\n\
                drones = { first_id = 1, count = 250, first_vehicle_id = 1 }\nhardware_drone = 1\n";
    let raw: RawConfig = toml::from_str(text).unwrap();
    let settings = raw.validate_in(std::path::Path::new("/x")).unwrap();
    let stats = Stats::new();
    // As the service does: its own series first.
    let ids: Vec<u16> = settings.drones.iter().map(|d| d.id).collect();
    let _metrics = skymesh_swarm_queue::metrics::Metrics::new(&stats, &ids);
    let bus = Bus::open(
        &domain,
        "swarm-queue",
        ServiceId::SwarmQueue,
        0,
        stats.clone(),
    )
    .unwrap();
    let before = skymesh_swarm_queue::fdlimit::open_fds().unwrap();
    let t = std::time::Instant::now();
    let ports = skymesh_swarm_queue::ipc::Ports::open(&bus, &settings).unwrap();
    let took = t.elapsed();
    let after = skymesh_swarm_queue::fdlimit::open_fds().unwrap();
    let mut sample = skymesh_ipc_types::ServiceStats::default();
    stats.snapshot_into(&mut sample);
    println!(
        "250 drones: {} file descriptors for the ports ({} before), opened in {took:?}; \
         stats series {} exported, {} dropped",
        after - before,
        before,
        sample.len,
        sample.dropped
    );
    let exported = |name: &str, labels: &str| {
        sample
            .entries()
            .iter()
            .any(|e| e.name.as_str() == name && e.labels.as_str() == labels)
    };
    println!(
        "queue depth of drone 250 exported: {}; tick histogram exported: {}",
        exported("skymesh_swarm_queue_depth", "drone=250"),
        exported("skymesh_swarm_tick_seconds", "")
    );
    assert_eq!(sample.dropped, 0, "every series fits the stats sample");
    assert!(exported("skymesh_swarm_queue_depth", "drone=250"));
    if std::env::var_os("SWARM_FD_DETAIL").is_some() {
        let mut kinds = std::collections::BTreeMap::<String, usize>::new();
        for e in std::fs::read_dir("/proc/self/fd").unwrap().flatten() {
            let t = std::fs::read_link(e.path())
                .map(|p| p.display().to_string())
                .unwrap_or_default();
            let k = t
                .split(['_', '/'])
                .filter(|s| !s.is_empty())
                .map(|s| {
                    if s.chars().any(|c| c.is_ascii_digit()) {
                        "#"
                    } else {
                        s
                    }
                })
                .collect::<Vec<_>>()
                .join("/");
            let k: String = k.chars().take(70).collect();
            *kinds.entry(k).or_default() += 1;
        }
        for (k, n) in kinds {
            println!("{n:6} {k}");
        }
    }
    drop(ports);
}
