//! skymesh groundcontrol-gateway: lets a swarm application written for
//! GroundControl's external interface (for example its public Unity client) drive
//! skymesh drones.
//!
//! The gateway *translates*: it serves GroundControl's state server (TCP 8000,
//! fixed 32-byte records, privileged and non-privileged clients) and its pose
//! broadcast (UDP 6666, one datagram of 84-byte records per frame). Commands become
//! `SwarmCommand` samples for the swarm queue, which *decides*; its replies come back
//! as `ACK_CMD_SUCCESS`/`ACK_CMD_TIMEOUT` records and `CHECK_ALL_IDLE` answers (a
//! refusal has no record and is only logged, except a refused geofence command:
//! `ACK_CMD_TIMEOUT`, so a box the arbiter did not take never looks in force), and
//! its `SwarmState` becomes the broadcast.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`privilege`] | the privileged address/network list |
//! | [`inbound`] | what one record from a client becomes (pure): privilege, parameter records, validation |
//! | `session` | one connection: reader (records → bus) and writer (bounded queue) |
//! | `hub` | accept (`max_clients`), connection ids, reply routing |
//! | [`broadcast`] | the UDP pose broadcast |
//! | `ipc` | every bus call |
//! | [`metrics`], `drops` | counters; rate-limited logging of refusals |
//! | [`client`], [`cli`] | the client side: for tests and the `skymesh-gc` CLI |
//! | [`service`] | runtime glue for `service_main` |
//!
//! Entry points: [`Sockets::bind`] then [`run`].
#![forbid(unsafe_code)]

pub mod broadcast;
pub mod cli;
pub mod client;
pub mod config;
mod drops;
mod hub;
pub mod inbound;
mod ipc;
pub mod metrics;
pub mod privilege;
pub mod service;
mod session;

use std::net::SocketAddr;

use anyhow::Context as _;
use skymesh_runtime::Context;
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::mpsc;
use tokio_util::task::TaskTracker;

pub use config::{RawConfig, Settings};

/// Queue of session-ended events into the hub.
const EVENT_QUEUE: usize = 256;

/// The gateway's two sockets, bound before [`run`] (tests bind port 0).
#[derive(Debug)]
pub struct Sockets {
    /// The state server.
    pub tcp: TcpListener,
    /// The pose broadcast's sender (`SO_BROADCAST` set).
    pub broadcast: UdpSocket,
}

impl Sockets {
    /// Binds `settings.listen` and `settings.broadcast_bind`.
    pub async fn bind(settings: &Settings) -> anyhow::Result<Sockets> {
        let tcp = TcpListener::bind(settings.listen)
            .await
            .with_context(|| format!("binding the state server on tcp {}", settings.listen))?;
        let broadcast = UdpSocket::bind(settings.broadcast_bind)
            .await
            .with_context(|| {
                format!(
                    "binding the pose broadcast sender on udp {}",
                    settings.broadcast_bind
                )
            })?;
        broadcast
            .set_broadcast(true)
            .context("setting SO_BROADCAST on the pose broadcast socket")?;
        Ok(Sockets { tcp, broadcast })
    }

    /// The bound addresses (state server, broadcast sender).
    pub fn local_addrs(&self) -> std::io::Result<(SocketAddr, SocketAddr)> {
        Ok((self.tcp.local_addr()?, self.broadcast.local_addr()?))
    }
}

/// Runs the gateway on already-bound sockets until `ctx.shutdown` is cancelled
/// (then `Ok`) or the bus fails (then `Err`). Marks the service ready once its bus
/// ports exist.
pub async fn run(settings: Settings, sockets: Sockets, ctx: Context) -> anyhow::Result<()> {
    let (tcp_addr, udp_addr) = sockets.local_addrs().context("reading bound addresses")?;
    let ports = ipc::Ports::open(&ctx.bus)?;
    let drops = drops::Drops::new(metrics::Metrics::new(&ctx.stats));
    let (ended_tx, ended_rx) = mpsc::channel(EVENT_QUEUE);
    let stop = ctx.shutdown.child_token();
    let tracker = TaskTracker::new();

    let broadcast = broadcast::Broadcast {
        socket: sockets.broadcast,
        destinations: settings.broadcast_destinations.clone(),
        period: settings.broadcast_period,
        liveness: settings.liveness.to_wire(),
        state_timeout: settings.state_timeout,
        drops: drops.clone(),
    };
    let broadcast_task = tokio::spawn(broadcast.run(ports.state, ports.watch, stop.clone()));

    let destinations: Vec<String> = settings
        .broadcast_destinations
        .iter()
        .map(ToString::to_string)
        .collect();
    tracing::info!(
        listen = %tcp_addr,
        broadcast_from = %udp_addr,
        broadcast_to = ?destinations,
        broadcast_hz = 1.0 / settings.broadcast_period.as_secs_f64(),
        privileged = %settings.privileged,
        max_clients = settings.max_clients,
        "groundcontrol-gateway serving the GroundControl state server and pose broadcast"
    );
    ctx.ready();
    let mut hub = hub::Hub::new(
        settings,
        ports.commands,
        ports.replies,
        drops,
        ended_tx,
        stop.clone(),
        tracker.clone(),
    );
    let mut broadcast_task = std::pin::pin!(broadcast_task);
    let mut broadcast_done = false;
    let result = tokio::select! {
        r = hub.run(sockets.tcp, ended_rx, &ctx.shutdown) => r,
        r = &mut broadcast_task => {
            broadcast_done = true;
            match r {
                Ok(Ok(())) => Ok(()),
                Ok(Err(e)) => Err(anyhow::Error::new(e).context("reading the swarm state")),
                Err(e) => Err(anyhow::anyhow!("the pose broadcast task failed: {e}")),
            }
        }
    };
    stop.cancel();
    if !broadcast_done {
        if let Ok(Err(e)) = broadcast_task.await {
            tracing::warn!(error = %e, "the pose broadcast failed while stopping");
        }
    }
    tracker.close();
    tracker.wait().await;
    tracing::info!("groundcontrol-gateway stopped");
    result
}
