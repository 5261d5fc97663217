//! skymesh shot-engine: the smart shots an app asks for (the Solo app's ShotManager).
//!
//! App gateways (`solo-gateway`) own the app's sockets and hand every request to this
//! engine as a protocol-neutral `ShotRequest`; the engine answers with `ShotEvent`s
//! (the gateway translates both ways, the engine knows no wire format), reads the
//! vehicle from `autopilot-link`, and flies the smart shots (selfie, orbit, follow,
//! cable cam, multipoint spline cable cam, zipline, pano, rewind, site scan) only
//! through `VehicleCommand`s from source `ShotEngine`, which the arbiter admits or
//! refuses (authority, setpoint freshness, geofence envelope). The app's geofence is
//! validated here, handed to the arbiter, and checked predictively every tick.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`engine`] | the ShotManager state machine (pure; time passed in) |
//! | [`shots`] | shot geometry: velocity and camera per tick (pure) |
//! | [`persist`] | button mappings, GoPro enable, active shot: a JSON file written atomically |
//! | [`metrics`] | the exported `skymesh_shot_*` series |
//! | [`ipc`] | the bus ports |
//! | `service` | the event loop tying them together |
//! | [`tasks`] | the task runner: gateways' tasks (takeoff, fly-to, POI orbit, panorama sweep) over the bus |
//!
//! A restarted engine never resumes a shot: the arbiter's freshness brake stopped
//! the vehicle when the setpoints stopped, and the engine only tells the app.
#![forbid(unsafe_code)]

pub mod config;
pub mod engine;
pub mod ipc;
pub mod metrics;
pub mod persist;
mod service;
pub mod shots;
pub mod tasks;

use skymesh_runtime::{Bus, CancellationToken, Context, Stats};

pub use config::{RawConfig, Settings};
pub use engine::{Engine, Outputs};

/// The service entry point for `service_main`.
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let (bus, stats, shutdown) = (ctx.bus.clone(), ctx.stats.clone(), ctx.shutdown.clone());
    run_with(settings, bus, stats, shutdown, || ctx.ready()).await
}

/// Runs the engine on `bus` until `shutdown` is cancelled; `ready` is called once
/// every port is open.
///
/// Subscribes to `skymesh/shot/{from_app,app_geofence,app_session}`,
/// `skymesh/input/buttons` and
/// `skymesh/vehicle/{vehicle_id}/{state,status,payload,authority,arbiter_events,command_ack}`;
/// publishes `skymesh/vehicle/{vehicle_id}/{command,geofence}`, `skymesh/shot/to_app`
/// and `skymesh/shot/status`.
pub async fn run_with(
    settings: Settings,
    bus: Bus,
    stats: Stats,
    shutdown: CancellationToken,
    ready: impl FnOnce(),
) -> anyhow::Result<()> {
    let ports = ipc::Ports::open(&bus, settings.vehicle_id)?;
    let metrics = metrics::Metrics::new(&stats);
    let overruns = metrics.overruns.clone();
    tracing::info!(
        vehicle_id = settings.vehicle_id,
        loop_period = ?settings.loop_period,
        state_file = %settings.state_file.display(),
        "shot-engine starting"
    );
    let period = settings.loop_period;
    // Tasks asked by gateways (the DJI gateway's takeoff, fly-to, POI and panorama).
    tasks::spawn(&bus, settings.vehicle_id, shutdown.clone())?;
    let engine = Engine::open(settings, metrics);
    ready();
    service::run_loop(engine, ports, period, shutdown, overruns).await
}
