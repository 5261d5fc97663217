//! skymesh vehicle-sim: a simulated multicopter that looks like ArduCopter on
//! the MAVLink 2 wire — the embedded default autopilot when no aircraft is
//! attached, and the test target for `autopilot-link`.
//!
//! Layers, each usable on its own:
//! - [`model`]: the vehicle, a pure point-mass simulation stepped with an
//!   explicit `dt` (modes, arming, guidance, battery, motor outputs and the
//!   ground motor test), its gimbal, the camera (mode, zoom, focus, image
//!   sequences) and the GoPro behind the gimbal's MAVLink bridge.
//! - [`handler`]: MAVLink message in → vehicle change + replies out (pure).
//! - [`telemetry`] / [`streams`]: state → messages, and which are due when.
//! - MAVLink framing is the `mavlink-frame` crate's (shared with autopilot-link).
//! - `engine` + `server`: the tokio task that owns the model and steps it at
//!   100 Hz, and the thin TCP/UDP layer around it.
//!
//! Entry points: [`bind`] then [`run`] for one vehicle; [`bind_all`] then
//! [`run_all`] for every vehicle of a `[swarm]` (one process, one simulation
//! task stepping every vehicle, one MAVLink endpoint per vehicle).

#![forbid(unsafe_code)]

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
use tokio::task::JoinSet;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;
use tracing::{debug, info};

pub use config::{
    Endpoint, RawConfig, RawSwarm, Settings, SwarmLayout, SwarmSettings, VehicleSpec,
};
pub use server::{bind, bind_all, BoundEndpoint};
pub use stats::{SimStats, SimStatsSnapshot};

/// Inbound frames queued from all links to the simulation task; a full queue
/// makes readers wait (TCP back-pressure) rather than drop commands.
const EVENT_QUEUE: usize = 1024;

/// Serve the simulated vehicle on `listener` until `shutdown` is cancelled,
/// then stop accepting, close every client and return `Ok`. `stats` is
/// updated live. An error means the endpoint failed or the simulation task
/// died; `shutdown` is not cancelled by `run` itself. One vehicle only: a swarm
/// (`[swarm]` count ≥ 2) is served by [`run_all`] with [`bind_all`]'s endpoints.
pub async fn run(
    settings: Settings,
    listener: BoundEndpoint,
    stats: Arc<SimStats>,
    shutdown: CancellationToken,
) -> anyhow::Result<()> {
    run_all(settings, vec![listener], stats, shutdown).await
}

/// Serve every vehicle of `settings` ([`Settings::vehicles`]), vehicle `i` on
/// `listeners[i]`, from one simulation task (one physics tick loop for all of
/// them), until `shutdown` is cancelled. As [`run`] otherwise; `stats` counts
/// every vehicle together.
pub async fn run_all(
    settings: Settings,
    listeners: Vec<BoundEndpoint>,
    stats: Arc<SimStats>,
    shutdown: CancellationToken,
) -> anyhow::Result<()> {
    let specs = settings.vehicles();
    anyhow::ensure!(
        listeners.len() == specs.len(),
        "{} endpoints bound for {} vehicles",
        listeners.len(),
        specs.len()
    );
    for (spec, listener) in specs.iter().zip(&listeners) {
        let local = listener.local_addr().context("reading bound address")?;
        let fields = (spec.index, spec.system_id);
        if specs.len() == 1 {
            info!(endpoint = %settings.endpoint, %local, system_id = fields.1, "vehicle-sim serving MAVLink");
        } else {
            debug!(vehicle = fields.0, system_id = fields.1, %local, "serving MAVLink");
        }
    }
    if specs.len() > 1 {
        let first = listeners[0].local_addr().context("reading bound address")?;
        let last = listeners[specs.len() - 1]
            .local_addr()
            .context("reading bound address")?;
        info!(
            vehicles = specs.len(),
            first = %first,
            last = %last,
            system_ids = %format!("{}..={}", specs[0].system_id, specs[specs.len() - 1].system_id),
            "vehicle-sim serving a swarm over MAVLink"
        );
    }
    // A child token: a failure here stops our tasks without cancelling the caller's token.
    let stop = shutdown.child_token();
    let (events_tx, events_rx) = mpsc::channel(EVENT_QUEUE);
    let tracker = TaskTracker::new();
    let timer = skymesh_runtime::timer::Timer::new().context("creating the simulation timer")?;
    let mut engine = tokio::spawn(engine::Engine::new(&settings, stats.clone()).run(
        events_rx,
        timer,
        stop.clone(),
    ));
    let mut io = JoinSet::new();
    for (spec, listener) in specs.iter().zip(listeners) {
        io.spawn(server::serve(
            listener,
            spec.index,
            events_tx.clone(),
            settings.max_clients,
            stats.clone(),
            stop.clone(),
            tracker.clone(),
        ));
    }
    drop(events_tx);

    let result = tokio::select! {
        Some(r) = io.join_next() => {
            stop.cancel();
            let engine_result = (&mut engine).await;
            let mut result = flatten(r).and(engine_result.context("simulation task"));
            while let Some(r) = io.join_next().await {
                result = result.and(flatten(r));
            }
            result
        }
        r = &mut engine => {
            let cancelled = stop.is_cancelled();
            stop.cancel();
            let mut io_result = Ok(());
            while let Some(r) = io.join_next().await {
                io_result = io_result.and(flatten(r));
            }
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
