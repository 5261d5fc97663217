//! The gateway without its backend: a command waits up to `backend_wait_ms` for a
//! swarm queue to read the bus, then is answered ACK_CMD_TIMEOUT by the gateway
//! (issue 43, "Ready means able to serve": never silence).

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use gc_proto::{NetCmdType, Record};
use skymesh_groundcontrol_gateway::client::{GcClient, PoseListener};
use skymesh_groundcontrol_gateway::{run, Settings, Sockets};
use skymesh_ipc_types::{topics, ServiceId, SwarmCommand, SwarmCommandKind};
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, Stats};
use tokio::task::JoinHandle;
use tokio::time::Instant;

const PATIENCE: Duration = Duration::from_secs(30);

/// groundcontrol-gateway in its own domain, with no swarm queue on the bus.
struct Alone {
    domain: Domain,
    stats: Stats,
    client: GcClient,
    _poses: PoseListener,
    shutdown: CancellationToken,
    task: JoinHandle<anyhow::Result<()>>,
}

impl Alone {
    async fn start(backend_wait: Duration) -> Alone {
        static N: AtomicU32 = AtomicU32::new(0);
        let name = format!(
            "gcbk{}x{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        );
        let domain = Domain::load(&name, None).expect("domain");
        let poses = PoseListener::bind(SocketAddr::from(([127, 0, 0, 1], 0)))
            .await
            .expect("pose listener");
        let settings = Settings {
            backend_wait,
            ..Settings::loopback_any_port(poses.local_addr().expect("addr"))
        };
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "groundcontrol-gateway",
            ServiceId::GroundcontrolGateway,
            0,
            stats.clone(),
        )
        .expect("gateway bus");
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
        let client = GcClient::connect(tcp).await.expect("connect");
        Alone {
            domain,
            stats,
            client,
            _poses: poses,
            shutdown,
            task,
        }
    }

    fn backend_missing(&self) -> f64 {
        self.stats
            .value("skymesh_gc_refused_total", "reason=backend_missing")
            .unwrap_or(0.0)
    }

    /// The next record of type `t`.
    async fn next(&mut self, t: NetCmdType) -> Record {
        loop {
            let r = self
                .client
                .recv(PATIENCE)
                .await
                .expect("open")
                .unwrap_or_else(|| panic!("no {t:?} within {PATIENCE:?}"));
            if r.net_type() == Some(t) {
                return r;
            }
        }
    }

    async fn stop(self) {
        self.shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), self.task)
            .await
            .expect("groundcontrol-gateway stops within 5 s")
            .expect("groundcontrol-gateway task")
            .expect("groundcontrol-gateway result");
        self.domain.remove_leftover_files();
    }
}

#[tokio::test]
async fn without_a_swarm_queue_commands_are_answered_ack_cmd_timeout() {
    let wait = Duration::from_millis(300);
    let mut gw = Alone::start(wait).await;
    let sent = Instant::now();
    gw.client
        .send(&Record::new(NetCmdType::CmdExtGoExternal, 4))
        .await
        .expect("send");
    let ack = gw.next(NetCmdType::AckCmdTimeout).await;
    let waited = sent.elapsed();
    assert_eq!(
        (ack.context, ack.int1),
        (4, NetCmdType::CmdExtGoExternal.id())
    );
    assert!(waited >= wait, "answered after {waited:?}, before the wait");
    assert_eq!(gw.backend_missing(), 1.0);
    // The wait ran out: the next command is answered at once, not after another.
    let sent = Instant::now();
    gw.client
        .send(&Record::new(NetCmdType::CmdExtGoExternal, 5))
        .await
        .expect("send");
    let ack = gw.next(NetCmdType::AckCmdTimeout).await;
    assert_eq!(
        (ack.context, ack.int1),
        (5, NetCmdType::CmdExtGoExternal.id())
    );
    assert!(
        sent.elapsed() < wait,
        "second answer took {:?}",
        sent.elapsed()
    );
    assert_eq!(gw.backend_missing(), 2.0);
    // PING needs no queue: answered as always.
    gw.client
        .send(&Record::ping_request(7, 0.0, 0.0))
        .await
        .expect("send");
    assert_eq!(gw.next(NetCmdType::PingResponse).await.int1, 7);
    assert_eq!(gw.backend_missing(), 2.0);
    gw.stop().await;
}

#[tokio::test]
async fn a_swarm_queue_that_appears_within_the_wait_gets_the_command() {
    let mut gw = Alone::start(Duration::from_secs(10)).await;
    gw.client
        .send(&Record::new(NetCmdType::CmdExtGoExternal, 4))
        .await
        .expect("send");
    tokio::time::sleep(Duration::from_millis(300)).await;
    let queue = Bus::open(
        &gw.domain,
        "swarm-queue-fake",
        ServiceId::Tool,
        0,
        Stats::new(),
    )
    .expect("queue bus");
    let mut commands = queue
        .subscriber::<SwarmCommand>(&topics::swarm_command())
        .expect("swarm_command subscriber");
    let c = commands
        .recv_timeout(PATIENCE)
        .await
        .expect("swarm_command")
        .expect("the command, published once the queue reads");
    assert_eq!(c.kind(), Ok(SwarmCommandKind::ExtGoExternal));
    assert_eq!(c.drone, 4);
    assert_eq!(gw.backend_missing(), 0.0);
    drop(commands);
    drop(queue);
    gw.stop().await;
}
