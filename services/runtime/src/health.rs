//! Heartbeat and stats publishing: what lets the supervisor see a service is alive.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use skymesh_ipc_types::{topics, FixedStr, ServiceHealth, ServiceState, ServiceStats};
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;

use crate::ipc::{Bus, IpcError};
use crate::systemd;

/// How often heartbeats are published unless `SKYMESH_HEARTBEAT_MS` says otherwise.
pub const DEFAULT_HEARTBEAT: Duration = Duration::from_millis(500);
/// How often the stats sample is published.
pub const STATS_PERIOD: Duration = Duration::from_secs(1);

/// The state a service reports in its heartbeat; set by the service, read by the
/// heartbeat task, which publishes a heartbeat at once when the state changes (so
/// the supervisor sees `Running` when the service is ready, not a period later).
#[derive(Debug, Clone)]
pub struct HealthState {
    state: Arc<AtomicU8>,
    changed: Arc<Notify>,
}

impl Default for HealthState {
    fn default() -> Self {
        HealthState {
            state: Arc::new(AtomicU8::new(ServiceState::Starting.to_wire())),
            changed: Arc::new(Notify::new()),
        }
    }
}

impl HealthState {
    pub fn set(&self, state: ServiceState) {
        if self.state.swap(state.to_wire(), Ordering::Relaxed) != state.to_wire() {
            // A stored permit if the heartbeat task is not waiting right now.
            self.changed.notify_one();
        }
    }
    pub fn get(&self) -> ServiceState {
        ServiceState::try_from(self.state.load(Ordering::Relaxed)).unwrap_or(ServiceState::Running)
    }
}

/// Heartbeat period from `SKYMESH_HEARTBEAT_MS` (set by the supervisor), else the default.
pub fn heartbeat_period_from_env() -> Duration {
    std::env::var("SKYMESH_HEARTBEAT_MS")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
        .filter(|ms| (10..=60_000).contains(ms))
        .map(Duration::from_millis)
        .unwrap_or(DEFAULT_HEARTBEAT)
}

/// Whether the watcher drains periodic heartbeats on its own clock
/// (`SKYMESH_HEARTBEAT_QUIET=1`, set by a supervisor that does, and by the systemd
/// units): only then may they be published without waking it. Unset (an older
/// supervisor, which only looks when woken), every heartbeat wakes the watcher.
pub fn heartbeat_quiet_from_env() -> bool {
    std::env::var("SKYMESH_HEARTBEAT_QUIET").is_ok_and(|v| v == "1")
}

/// Publishes `ServiceHealth` every `period` and `ServiceStats` every second until
/// `stop` is cancelled, then one last heartbeat saying `Stopping`. Pings the systemd
/// watchdog with each heartbeat, so a hung runtime stops both.
///
/// `quiet` (see [`heartbeat_quiet_from_env`]): only a heartbeat that says something
/// new (the first, a changed state, `Stopping`) wakes the subscribers; the periodic
/// ones and the stats are published without notifying, for the supervisor to drain
/// on its own clock (a wake-up per heartbeat of every service cost it 30 a second).
pub async fn run_heartbeat(
    bus: Bus,
    state: HealthState,
    period: Duration,
    quiet: bool,
    stop: CancellationToken,
) -> Result<(), IpcError> {
    let name = bus.name().to_string();
    let mut health_pub = bus.publisher::<ServiceHealth>(&topics::service_health(&name))?;
    let mut stats_pub = bus.publisher::<ServiceStats>(&topics::service_stats(&name))?;
    let started = Instant::now();
    let watchdog = systemd::watchdog_interval();
    let stats_name = FixedStr::new(&name);
    let snapshot = |out: &mut ServiceStats| {
        out.name = stats_name;
        bus.stats().snapshot_into(out);
    };
    // A timerfd: on tokio's wheel every tick longer than 64 ms costs a second
    // wake-up at the wheel's block boundary before its own (see crate::timer).
    let timer_err = IpcError::timer("the heartbeat timer");
    let mut tick = crate::timer::Ticker::new(period).map_err(timer_err)?;
    let mut last_stats = Instant::now() - STATS_PERIOD;
    let health = |state: ServiceState| ServiceHealth {
        name: FixedStr::new(&name),
        pid: std::process::id(),
        state: state.to_wire(),
        uptime_ms: started.elapsed().as_millis() as u64,
        period_ms: period.as_millis() as u32,
        ..Default::default()
    };
    let mut told: Option<ServiceState> = None;
    loop {
        tokio::select! {
            t = tick.tick() => { t.map_err(timer_err)?; }
            () = state.changed.notified() => {}
            _ = stop.cancelled() => break,
        }
        let now = state.get();
        if quiet && told.replace(now) == Some(now) {
            health_pub.publish_quiet(health(now))?;
        } else {
            health_pub.publish(health(now))?;
        }
        if watchdog.is_some() {
            systemd::notify_watchdog();
        }
        if last_stats.elapsed() >= STATS_PERIOD {
            last_stats = Instant::now();
            if quiet {
                stats_pub.publish_with_quiet(snapshot)?;
            } else {
                stats_pub.publish_with(snapshot)?;
            }
        }
    }
    let _ = stats_pub.publish_with(snapshot);
    let _ = health_pub.publish(health(ServiceState::Stopping));
    Ok(())
}
