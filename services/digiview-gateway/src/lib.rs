//! skymesh digiview-gateway: serves Synclair Vision DigiView's TCP protocol (port
//! 8555, fixed 88-byte frames, `../shared/specs/digiview-vision.md` corrected by
//! FACTS.md) on top of the vision pipeline, so a DigiView client drives skymesh's
//! virtual cameras, detections and tracker.
//!
//! The gateway *translates*: GETs are answered from the pipeline's newest
//! `VisionState` (CAM_OFFSET by the pipeline's `DirectionAt` answer); SETs are
//! checked (FORBIDDEN for addresses not in `write_allowed`, DATA_ERROR for payloads
//! out of range) and sent as the pipeline's `ViewControl`, in its units; the
//! pipeline *decides* and its `ViewReply` becomes ACKNOWLEDGEMENT, DATA_ERROR or
//! UNKNOWN. The gateway knows the DigiView wire; the pipeline never sees it.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`privilege`] | the `write_allowed` address/network list |
//! | [`handler`] | what one frame becomes (pure; the fuzz target's entry) |
//! | [`answer`] | GET answers from a `VisionState` (pure) |
//! | [`translate`] | DigiView parameters ↔ `ViewControl` / `ViewReply` (pure) |
//! | [`reply`] | outgoing frames; pipeline result → DigiView code |
//! | [`refusal`] | why a frame was refused: metric label and reply type |
//! | `session` | one connection: reader (frames, SETs, periodic GETs, limits) and writer (bounded queue) |
//! | [`ipc`] | every bus call, in one task |
//! | [`metrics`], `drops` | counters; rate-limited logging of refusals |
//! | [`service`] | runtime glue for `service_main` |
//!
//! Entry points: bind a listener ([`bind`]) then [`run`].
#![forbid(unsafe_code)]

pub mod answer;
pub mod config;
mod drops;
pub mod handler;
pub mod ipc;
pub mod metrics;
pub mod privilege;
pub mod refusal;
pub mod reply;
pub mod service;
mod session;
pub mod translate;

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use skymesh_runtime::Context;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tokio_util::task::TaskTracker;

pub use config::{RawConfig, Settings};

use crate::handler::Rules;
use crate::metrics::{ConnectionResult, Metrics};
use crate::session::SessionCtx;

/// After a failed `accept` (out of file descriptors, ...), wait this long.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// Binds `settings.listen` (tests bind port 0).
pub async fn bind(settings: &Settings) -> anyhow::Result<TcpListener> {
    TcpListener::bind(settings.listen)
        .await
        .with_context(|| format!("binding the DigiView server on tcp {}", settings.listen))
}

/// Runs the gateway on an already-bound listener until `ctx.shutdown` is cancelled
/// (then `Ok`) or the bus fails (then `Err`). Marks the service ready once the
/// pipeline's state is in (a GET can be answered), or after `state_timeout` without
/// it (GETs are then answered UNKNOWN until it comes).
pub async fn run(settings: Settings, listener: TcpListener, ctx: Context) -> anyhow::Result<()> {
    let addr = listener.local_addr().context("reading the bound address")?;
    let (bus_task, bus) = ipc::BusTask::open(&ctx.bus)?;
    let drops = drops::Drops::new(Metrics::new(&ctx.stats));
    let stop = ctx.shutdown.child_token();
    let tracker = TaskTracker::new();
    let mut bus_task = std::pin::pin!(tokio::spawn(bus_task.run(stop.clone())));
    tracing::info!(
        listen = %addr,
        write_allowed = %settings.write_allowed,
        max_clients = settings.max_clients,
        "digiview-gateway serving DigiView clients"
    );
    // Ready means able to serve: a new subscriber gets the pipeline's state with
    // the pipeline's next publication (within its 1 s period).
    let waited = std::time::Instant::now();
    let have_state = tokio::select! {
        _ = ctx.shutdown.cancelled() => true,
        ok = bus.first_state(settings.state_timeout) => ok,
    };
    if have_state {
        tracing::debug!(
            waited_ms = waited.elapsed().as_millis() as u64,
            "vision state received"
        );
    } else {
        tracing::info!(
            waited_ms = waited.elapsed().as_millis() as u64,
            "no VisionState from the vision pipeline yet: serving, GETs are answered UNKNOWN until it comes"
        );
    }
    ctx.ready();
    let settings = Arc::new(settings);
    let slots = Arc::new(Semaphore::new(settings.max_clients));
    let mut last_client: u64 = 0;
    let metrics = drops.metrics().clone();
    let result = loop {
        tokio::select! {
            biased;
            _ = ctx.shutdown.cancelled() => break Ok(()),
            r = &mut bus_task => break match r {
                Ok(Ok(())) => Ok(()),
                Ok(Err(e)) => Err(anyhow::Error::new(e).context("the vision bus failed")),
                Err(e) => Err(anyhow::anyhow!("the bus task failed: {e}")),
            },
            accepted = listener.accept() => {
                let (stream, peer) = match accepted {
                    Ok(a) => a,
                    Err(e) => {
                        tracing::warn!(error = %e, "accepting a DigiView client failed");
                        tokio::time::sleep(ACCEPT_BACKOFF).await;
                        continue;
                    }
                };
                let Ok(permit) = slots.clone().try_acquire_owned() else {
                    metrics.connection(ConnectionResult::RefusedMaxClients);
                    if let Some(hidden) = drops.allow("max_clients") {
                        tracing::warn!(%peer, max_clients = settings.max_clients,
                            similar_since_last_warning = hidden,
                            "DigiView client refused: max_clients are connected");
                    }
                    continue;
                };
                metrics.connection(ConnectionResult::Accepted);
                if let Err(e) = stream.set_nodelay(true) {
                    tracing::debug!(%peer, error = %e, "cannot set TCP_NODELAY");
                }
                last_client += 1;
                let may_set = settings.may_set(peer.ip());
                let sctx = SessionCtx {
                    client: last_client,
                    peer,
                    rules: Rules { may_set, roi_rel_frame: settings.roi_rel_frame },
                    settings: settings.clone(),
                    bus: bus.clone(),
                    drops: drops.clone(),
                };
                let (cancel, metrics, slots) = (stop.child_token(), metrics.clone(), slots.clone());
                let max = settings.max_clients;
                tracing::info!(%peer, client = last_client, may_set, "DigiView client connected");
                metrics.clients.set((max - slots.available_permits()) as f64);
                bus.set_clients(max - slots.available_permits());
                let bus = bus.clone();
                tracker.spawn(async move {
                    let client = sctx.client;
                    let end = session::run(stream, sctx, cancel).await;
                    drop(permit);
                    metrics.disconnect(end.reason());
                    metrics.clients.set((max - slots.available_permits()) as f64);
                    bus.set_clients(max - slots.available_permits());
                    tracing::info!(%peer, client, reason = %end, "DigiView client disconnected");
                });
            }
        }
    };
    stop.cancel();
    tracker.close();
    tracker.wait().await;
    metrics.clients.set(0.0);
    tracing::info!("digiview-gateway stopped");
    result
}
