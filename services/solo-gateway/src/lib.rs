//! skymesh solo-gateway: lets a phone app written for the 3DR Solo connect to
//! skymesh unchanged.
//!
//! The gateway *translates*: it speaks the app's TLV protocol on TCP (ShotManager's
//! port 5507) and the follow stream on UDP (14558), checks every message with the
//! `solo-proto` codec, and forwards what is valid to the shot engine as
//! protocol-neutral `ShotRequest`s; the engine's `ShotEvent`s come back and are
//! written to the app as Solo messages ([`translate`]). The shot engine *decides*. One app at a time, as ShotManager.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`framing`] | TLV frames from a byte stream, with a per-frame deadline |
//! | [`inbound`] | what to do with one frame from the app (pure) |
//! | [`translate`] | Solo messages ↔ the engine's `ShotRequest`/`ShotEvent` (pure) |
//! | `session` | one connection: reader (check, publish) and writer (bounded queue) |
//! | `hub` | the app slot: one-app rule, engine → app routing, `AppSession` |
//! | [`follow`] | the UDP follow stream |
//! | `ipc` | every bus call |
//! | [`metrics`], `drops` | counters; rate-limited logging of dropped input |
//! | [`client`], [`describe`], [`cli`] | the app side: a client for tests and the `skymesh-solo` CLI |
//! | [`service`] | runtime glue for `service_main` |
//!
//! Entry points: [`Sockets::bind`] then [`run`].
#![forbid(unsafe_code)]

pub mod cli;
pub mod client;
pub mod config;
pub mod describe;
mod drops;
pub mod follow;
pub mod framing;
mod hub;
pub mod inbound;
mod ipc;
pub mod metrics;
pub mod service;
mod session;
pub mod translate;

use std::net::SocketAddr;

use anyhow::Context as _;
use skymesh_runtime::Context;
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::{mpsc, watch};
use tokio_util::task::TaskTracker;

pub use config::{RawConfig, Settings};

/// Queue of session-ended and fatal events into the hub.
const EVENT_QUEUE: usize = 64;

/// The gateway's two sockets, bound before [`run`] (tests bind port 0).
#[derive(Debug)]
pub struct Sockets {
    /// The app's TCP connections.
    pub tcp: TcpListener,
    /// The follow stream.
    pub follow: UdpSocket,
}

impl Sockets {
    /// Binds `settings.listen` and `settings.follow_listen`.
    pub async fn bind(settings: &Settings) -> anyhow::Result<Sockets> {
        let tcp = TcpListener::bind(settings.listen)
            .await
            .with_context(|| format!("binding the Solo app listener on tcp {}", settings.listen))?;
        let follow = UdpSocket::bind(settings.follow_listen)
            .await
            .with_context(|| {
                format!(
                    "binding the follow stream on udp {}",
                    settings.follow_listen
                )
            })?;
        Ok(Sockets { tcp, follow })
    }

    /// The bound addresses (TCP, UDP).
    pub fn local_addrs(&self) -> std::io::Result<(SocketAddr, SocketAddr)> {
        Ok((self.tcp.local_addr()?, self.follow.local_addr()?))
    }
}

/// Runs the gateway on already-bound sockets until `ctx.shutdown` is cancelled
/// (then `Ok`) or the bus fails (then `Err`). Marks the service ready once its bus
/// ports exist.
pub async fn run(settings: Settings, sockets: Sockets, ctx: Context) -> anyhow::Result<()> {
    let (tcp_addr, udp_addr) = sockets.local_addrs().context("reading bound addresses")?;
    let ports = ipc::Ports::open(&ctx.bus)?;
    let drops = drops::Drops::new(metrics::Metrics::new(&ctx.stats));
    let (app_tx, app_rx) = watch::channel(None);
    let (events_tx, events_rx) = mpsc::channel(EVENT_QUEUE);
    let stop = ctx.shutdown.child_token();
    let tracker = TaskTracker::new();

    {
        let (from_app, drops, stop, events) = (
            ports.from_app.clone(),
            drops.clone(),
            stop.clone(),
            events_tx.clone(),
        );
        let socket = sockets.follow;
        let follow_max_per_s = settings.follow_max_per_s;
        tracker.spawn(async move {
            let follow = follow::run(socket, app_rx, from_app, drops, follow_max_per_s, stop);
            if let Err(e) = follow.await {
                let e = anyhow::Error::new(e).context("publishing a follow-stream location");
                let _ = events.send(hub::Event::Fatal(e)).await;
            }
        });
    }
    tracing::info!(
        listen = %tcp_addr,
        follow_listen = %udp_addr,
        frame_timeout_s = settings.frame_timeout.as_secs_f64(),
        outgoing_queue = settings.outgoing_queue,
        "solo-gateway serving the Solo app protocol"
    );
    ctx.ready();
    let mut hub = hub::Hub::new(
        settings,
        ports,
        drops,
        app_tx,
        events_tx,
        stop.clone(),
        tracker.clone(),
    );
    let result = hub.run(sockets.tcp, events_rx, &ctx.shutdown).await;
    stop.cancel();
    tracker.close();
    tracker.wait().await;
    tracing::info!("solo-gateway stopped");
    result
}
