//! The in-process harness: groundcontrol-gateway on loopback port 0 in its own
//! iceoryx2 domain, plus a "tool" node that plays the swarm queue (reads
//! `swarm_command`, writes `swarm_reply` and `swarm_state`), and a pose listener
//! the broadcast is sent to.
#![allow(dead_code)] // each test crate uses its own subset

use std::f32::consts::FRAC_1_SQRT_2;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_groundcontrol_gateway::client::PoseListener;
use skymesh_groundcontrol_gateway::{run, Settings, Sockets};
use skymesh_ipc_types::{
    topics, FixedStr, ServiceId, SwarmCommand, SwarmDrone, SwarmReply, SwarmResult, SwarmState,
    SwarmWatch,
};
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, Publisher, Stats, Subscriber};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// Generous bound for anything that should take a moment.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// A privileged client's address (the default list is `127.0.0.1`).
pub fn privileged_host() -> IpAddr {
    [127, 0, 0, 1].into()
}

/// Another loopback address: not on the privileged list.
pub fn other_host() -> IpAddr {
    [127, 0, 0, 2].into()
}

fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "gcgw{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

/// `n` drones with ids `100 + i`, drone i at (i, 2i, 10) heading 90°.
pub fn swarm_state(n: usize, time_s: f64) -> SwarmState {
    let mut s = SwarmState {
        count: n as u16,
        time_s,
        ..SwarmState::default()
    };
    for (i, d) in s.drones.iter_mut().take(n).enumerate() {
        let f = i as f32;
        *d = SwarmDrone {
            drone: 100 + i as u16,
            vehicle_id: i as u8 + 1,
            drone_state: 5,
            // idle + active + skymesh's POSE_VALID (masked off in the broadcast).
            flags: 0x103,
            tracking: [f, 2.0 * f, 10.0],
            tracking_yaw_deg: 90.0,
            quaternion: [0.0, 0.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2],
            target: [f + 5.0, 2.0 * f, 10.0],
            target_yaw_deg: 180.0,
            color: [0.0, 1.0, 0.0],
            ..SwarmDrone::default()
        };
    }
    s
}

/// groundcontrol-gateway running in-process, and the swarm-queue side of the bus.
pub struct Gateway {
    pub domain: Domain,
    pub stats: Stats,
    /// The state server.
    pub tcp: SocketAddr,
    /// Receives the pose broadcast.
    pub poses: PoseListener,
    pub commands: Subscriber<SwarmCommand>,
    pub replies: Publisher<SwarmReply>,
    pub state: Publisher<SwarmState>,
    /// The broadcast's words that it watches the state.
    pub watch: Subscriber<SwarmWatch>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Gateway {
    pub async fn start() -> Gateway {
        Gateway::start_with(|_| {}).await
    }

    /// Starts with the loopback defaults changed by `adjust`.
    pub async fn start_with(adjust: impl FnOnce(&mut Settings)) -> Gateway {
        let poses = PoseListener::bind(SocketAddr::from(([127, 0, 0, 1], 0)))
            .await
            .expect("pose listener");
        let mut settings = Settings::loopback_any_port(poses.local_addr().expect("addr"));
        adjust(&mut settings);
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "groundcontrol-gateway",
            ServiceId::GroundcontrolGateway,
            0,
            stats.clone(),
        )
        .expect("gateway bus");
        let tool = Bus::open(
            &domain,
            "swarm-queue-fake",
            ServiceId::Tool,
            0,
            Stats::new(),
        )
        .expect("tool bus");
        // Before the gateway runs: swarm_command has no history.
        let commands = tool
            .subscriber::<SwarmCommand>(&topics::swarm_command())
            .expect("swarm_command subscriber");
        let replies = tool
            .publisher::<SwarmReply>(&topics::swarm_reply())
            .expect("swarm_reply publisher");
        let state = tool
            .publisher::<SwarmState>(&topics::swarm_state())
            .expect("swarm_state publisher");
        let watch = tool
            .subscriber::<SwarmWatch>(&topics::swarm_watch())
            .expect("swarm_watch subscriber");
        let sockets = Sockets::bind(&settings).await.expect("bind");
        let (tcp, _) = sockets.local_addrs().expect("addresses");
        let shutdown = CancellationToken::new();
        let ctx = Context::new(
            bus,
            shutdown.clone(),
            stats.clone(),
            "groundcontrol-gateway",
        );
        let task = tokio::spawn(run(settings, sockets, ctx));
        Gateway {
            domain,
            stats,
            tcp,
            poses,
            commands,
            replies,
            state,
            watch,
            shutdown,
            task: Some(task),
        }
    }

    /// Stops the gateway (it must return `Ok` promptly) and cleans the domain.
    pub async fn stop(mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            tokio::time::timeout(Duration::from_secs(5), task)
                .await
                .expect("groundcontrol-gateway stops within 5 s")
                .expect("groundcontrol-gateway task")
                .expect("groundcontrol-gateway result");
        }
        let Gateway {
            domain,
            commands,
            replies,
            state,
            ..
        } = self;
        drop((commands, replies, state));
        domain.remove_leftover_files();
    }

    /// The next command the gateway publishes.
    pub async fn next_command(&mut self) -> SwarmCommand {
        self.commands
            .recv_timeout(PATIENCE)
            .await
            .expect("swarm_command")
            .unwrap_or_else(|| panic!("no SwarmCommand within {PATIENCE:?}"))
    }

    /// Asserts no command arrives within `window`.
    pub async fn no_command_for(&mut self, window: Duration) {
        if let Some(c) = self
            .commands
            .recv_timeout(window)
            .await
            .expect("swarm_command")
        {
            panic!("unexpected command {c:?}");
        }
    }

    /// Answers `cmd` as the queue would, for `drone`.
    pub fn reply(&mut self, cmd: &SwarmCommand, drone: u16, result: SwarmResult, value: i32) {
        self.replies
            .publish(SwarmReply {
                request_id: cmd.request_id,
                client: cmd.client,
                drone,
                kind: cmd.kind,
                result: result.to_wire(),
                value,
                reason: FixedStr::new(if result == SwarmResult::Refused {
                    "unknown drone"
                } else {
                    ""
                }),
                ..SwarmReply::default()
            })
            .expect("publish swarm_reply");
    }

    pub fn publish_state(&mut self, state: SwarmState) {
        self.state.publish(state).expect("publish swarm_state");
    }

    /// The current value of a series (`labels` as `k=v,k=v`), if registered.
    pub fn metric(&self, name: &str, labels: &str) -> Option<f64> {
        self.stats.value(name, labels)
    }

    /// Waits until a series reaches `value` (counters are updated by other tasks).
    pub async fn wait_metric(&self, name: &str, labels: &str, value: f64) {
        let deadline = Instant::now() + PATIENCE;
        while self.metric(name, labels) != Some(value) {
            assert!(
                Instant::now() < deadline,
                "{name}{{{labels}}} is {:?}, expected {value}",
                self.metric(name, labels)
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Waits until `skymesh_gc_refused_total{reason}` reaches `value`.
    pub async fn wait_refused(&self, reason: &str, value: f64) {
        self.wait_metric(
            "skymesh_gc_refused_total",
            &format!("reason={reason}"),
            value,
        )
        .await;
    }
}
