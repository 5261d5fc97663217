//! The sim as a skymesh service: config through the shared runtime, readiness once
//! the MAVLink endpoint is bound, and its counters exported through the stats sample.

use std::sync::Arc;
use std::time::Duration;

use skymesh_runtime::{ConfigError, Context, ServiceConfig, Stats};

use crate::config::{RawConfig, Settings, DEFAULT_CONFIG_TOML};
use crate::stats::{SimStats, SimStatsSnapshot};

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = DEFAULT_CONFIG_TOML;

    fn validate(self) -> Result<Settings, ConfigError> {
        RawConfig::validate(self).map_err(|e| ConfigError::invalid("vehicle-sim", e.to_string()))
    }
}

/// Binds the endpoint, reports ready and simulates until shutdown.
pub async fn run_service(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let bound = crate::bind_all(&settings).await?;
    tracing::info!(
        endpoint = %bound[0].local_addr()?,
        system_id = settings.system_id,
        vehicles = bound.len(),
        "serving MAVLink"
    );
    let stats = Arc::new(SimStats::default());
    let exporter = tokio::spawn(export_stats(
        stats.clone(),
        ctx.stats.clone(),
        ctx.shutdown.clone(),
    ));
    ctx.ready();
    let result = crate::run_all(settings, bound, stats, ctx.shutdown.clone()).await;
    ctx.shutdown.cancel();
    let _ = exporter.await;
    result
}

/// Copies the sim's counters into the service's stats registry once a second.
/// A swarm exports the same fixed set of series as one vehicle (every vehicle
/// counted together, the payload gauges the first vehicle's), so the size of
/// the stats sample does not grow with the swarm.
async fn export_stats(sim: Arc<SimStats>, stats: Stats, stop: tokio_util::sync::CancellationToken) {
    let frames_in = stats.counter("skymesh_sim_mavlink_frames_total", &[("direction", "in")]);
    let frames_out = stats.counter("skymesh_sim_mavlink_frames_total", &[("direction", "out")]);
    let dropped = stats.counter("skymesh_sim_mavlink_frames_dropped_total", &[]);
    let bad = stats.counter("skymesh_sim_mavlink_bad_frames_total", &[]);
    let garbage = stats.counter("skymesh_sim_mavlink_garbage_bytes_total", &[]);
    let clients = stats.gauge("skymesh_sim_clients", &[]);
    let clients_total = stats.counter("skymesh_sim_clients_total", &[]);
    let rejected = stats.counter("skymesh_sim_clients_rejected_total", &[]);
    let by_result = |r: &str| stats.counter("skymesh_sim_commands_total", &[("result", r)]);
    let (accepted, temp, denied, unsupported, failed) = (
        by_result("accepted"),
        by_result("temporarily_rejected"),
        by_result("denied"),
        by_result("unsupported"),
        by_result("failed"),
    );
    let gopro_recording = stats.gauge("skymesh_sim_gopro_recording", &[]);
    let gopro_photos = stats.counter("skymesh_sim_gopro_photos_total", &[]);
    let gopro = |request: &str, status: &str| {
        stats.counter(
            "skymesh_sim_gopro_requests_total",
            &[("request", request), ("status", status)],
        )
    };
    let (set_ok, set_failed, get_ok, get_failed) = (
        gopro("set", "success"),
        gopro("set", "failed"),
        gopro("get", "success"),
        gopro("get", "failed"),
    );
    let vehicles = stats.gauge("skymesh_sim_vehicles", &[]);
    let vehicles_armed = stats.gauge("skymesh_sim_vehicles_armed", &[]);
    let vehicles_linked = stats.gauge("skymesh_sim_vehicles_linked", &[]);
    let steps_skipped = stats.counter("skymesh_sim_physics_steps_skipped_total", &[]);
    let gimbal_pitch = stats.gauge("skymesh_sim_gimbal_pitch_degrees", &[]);
    let gimbal_yaw = stats.gauge("skymesh_sim_gimbal_yaw_degrees", &[]);
    let mut prev = SimStatsSnapshot::default();
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        let stopping = tokio::select! {
            _ = tick.tick() => false,
            _ = stop.cancelled() => true,
        };
        let now = sim.snapshot();
        // Counters are monotonic in the sim; export the increase since last time.
        frames_in.add(now.frames_in.saturating_sub(prev.frames_in));
        frames_out.add(now.frames_out.saturating_sub(prev.frames_out));
        dropped.add(now.frames_dropped.saturating_sub(prev.frames_dropped));
        bad.add(now.bad_frames.saturating_sub(prev.bad_frames));
        garbage.add(now.garbage_bytes.saturating_sub(prev.garbage_bytes));
        clients_total.add(now.clients_total.saturating_sub(prev.clients_total));
        rejected.add(now.clients_rejected.saturating_sub(prev.clients_rejected));
        accepted.add(now.commands_accepted.saturating_sub(prev.commands_accepted));
        temp.add(
            now.commands_temporarily_rejected
                .saturating_sub(prev.commands_temporarily_rejected),
        );
        denied.add(now.commands_denied.saturating_sub(prev.commands_denied));
        unsupported.add(
            now.commands_unsupported
                .saturating_sub(prev.commands_unsupported),
        );
        failed.add(now.commands_failed.saturating_sub(prev.commands_failed));
        clients.set(now.clients_connected as f64);
        gopro_recording.set(now.gopro_recording as f64);
        gopro_photos.add(now.gopro_photos.saturating_sub(prev.gopro_photos));
        set_ok.add(now.gopro_set_success.saturating_sub(prev.gopro_set_success));
        set_failed.add(now.gopro_set_failed.saturating_sub(prev.gopro_set_failed));
        get_ok.add(now.gopro_get_success.saturating_sub(prev.gopro_get_success));
        get_failed.add(now.gopro_get_failed.saturating_sub(prev.gopro_get_failed));
        vehicles.set(now.vehicles as f64);
        vehicles_armed.set(now.vehicles_armed as f64);
        vehicles_linked.set(now.vehicles_linked as f64);
        steps_skipped.add(now.steps_skipped.saturating_sub(prev.steps_skipped));
        gimbal_pitch.set(now.gimbal_pitch_cdeg as f64 / 100.0);
        gimbal_yaw.set(now.gimbal_yaw_cdeg as f64 / 100.0);
        prev = now;
        if stopping {
            return;
        }
    }
}
