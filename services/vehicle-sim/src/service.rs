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
    let bound = crate::bind(&settings).await?;
    tracing::info!(
        endpoint = %bound.local_addr()?,
        system_id = settings.system_id,
        "serving MAVLink"
    );
    let stats = Arc::new(SimStats::default());
    let exporter = tokio::spawn(export_stats(
        stats.clone(),
        ctx.stats.clone(),
        ctx.shutdown.clone(),
    ));
    ctx.ready();
    let result = crate::run(settings, bound, stats, ctx.shutdown.clone()).await;
    ctx.shutdown.cancel();
    let _ = exporter.await;
    result
}

/// Copies the sim's counters into the service's stats registry once a second.
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
        prev = now;
        if stopping {
            return;
        }
    }
}
