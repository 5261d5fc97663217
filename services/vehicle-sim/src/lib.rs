//! skymesh vehicle-sim: a simulated multicopter that looks like ArduCopter on
//! the MAVLink 2 wire — the embedded default autopilot when no aircraft is
//! attached, and the test target for `autopilot-link`.
//!
//! Layers, each usable on its own:
//! - [`model`]: the vehicle, a pure point-mass simulation stepped with an
//!   explicit `dt` (modes, arming, guidance, battery), its gimbal and the GoPro
//!   behind the gimbal's MAVLink bridge.
//! - [`handler`]: MAVLink message in → vehicle change + replies out (pure).
//! - [`telemetry`] / [`streams`]: state → messages, and which are due when.
//! - [`codec`]: MAVLink 1/2 framing over byte buffers (pure).
//! - `engine` + `server`: the tokio task that owns the model and steps it at
//!   100 Hz, and the thin TCP/UDP layer around it.
//!
//! Entry points: [`bind`] then [`run`].

#![forbid(unsafe_code)]

pub mod codec;
pub mod config;
mod engine;
pub mod handler;
pub mod model;
mod server;
pub mod service;
pub mod stats;
pub mod streams;
pub mod telemetry;

use std::sync::Arc;

use anyhow::Context;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;
use tracing::info;

pub use config::{Endpoint, RawConfig, Settings};
pub use server::{bind, BoundEndpoint};
pub use stats::{SimStats, SimStatsSnapshot};

/// Inbound frames queued from all links to the simulation task; a full queue
/// makes readers wait (TCP back-pressure) rather than drop commands.
const EVENT_QUEUE: usize = 1024;

/// Serve the simulated vehicle on `listener` until `shutdown` is cancelled,
/// then stop accepting, close every client and return `Ok`. `stats` is
/// updated live. An error means the endpoint failed or the simulation task
/// died; `shutdown` is not cancelled by `run` itself.
pub async fn run(
    settings: Settings,
    listener: BoundEndpoint,
    stats: Arc<SimStats>,
    shutdown: CancellationToken,
) -> anyhow::Result<()> {
    let local = listener.local_addr().context("reading bound address")?;
    info!(
        endpoint = %settings.endpoint,
        %local,
        system_id = settings.system_id,
        "vehicle-sim serving MAVLink"
    );
    // A child token: a failure here stops our tasks without cancelling the caller's token.
    let stop = shutdown.child_token();
    let (events_tx, events_rx) = mpsc::channel(EVENT_QUEUE);
    let tracker = TaskTracker::new();
    let mut engine =
        tokio::spawn(engine::Engine::new(&settings, stats.clone()).run(events_rx, stop.clone()));
    let mut io = tokio::spawn(server::serve(
        listener,
        events_tx,
        settings.max_clients,
        stats,
        stop.clone(),
        tracker.clone(),
    ));

    let result = tokio::select! {
        r = &mut io => {
            stop.cancel();
            let engine_result = (&mut engine).await;
            flatten(r).and(engine_result.context("simulation task"))
        }
        r = &mut engine => {
            let cancelled = stop.is_cancelled();
            stop.cancel();
            let io_result = flatten((&mut io).await);
            match r {
                // Shutdown reached the engine first: a normal stop.
                Ok(()) if cancelled => io_result,
                Ok(()) => Err(anyhow::anyhow!("simulation task ended unexpectedly")),
                Err(e) => Err(anyhow::Error::new(e).context("simulation task")),
            }
        }
    };
    tracker.close();
    tracker.wait().await;
    info!("vehicle-sim stopped");
    result
}

fn flatten(r: Result<anyhow::Result<()>, tokio::task::JoinError>) -> anyhow::Result<()> {
    r.context("server task")?
}
