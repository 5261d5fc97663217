//! Heartbeats and stats from the bus, and what they say about a service's liveness.
//!
//! One task per service writes what arrives on its `ServiceHealth` and `ServiceStats`
//! topics into the shared [`Mesh`]: at once for a heartbeat that says something new
//! (the first, a changed state, `Stopping`: those wake the subscriber), and on the
//! drain clock for the periodic heartbeats and the stats, which services publish
//! quietly — a wake-up per heartbeat of every service would cost the supervisor 30
//! a second. The clock runs often enough that a healthy service never looks hung
//! ([`drain_period`]). The rules that turn "last heartbeat at t" into hung / alive /
//! stale are pure functions below.

use std::sync::Arc;
use std::time::Duration;

use skymesh_ipc_types::{topics, ServiceHealth, ServiceState, ServiceStats};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer::Timer;
use skymesh_runtime::{Bus, IpcError, Subscriber};
use tokio::sync::watch;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::state::{Heartbeat, Mesh, Phase};

/// When a heartbeat counts as missing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LivenessRule {
    /// The period asked of the service, used until it reports its own.
    pub period: Duration,
    /// Periods without a heartbeat before the service counts as hung.
    pub missed: u32,
    /// How long a new process may take to send its first heartbeat.
    pub startup_timeout: Duration,
}

/// What the heartbeats say about a supervised process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveness {
    /// A heartbeat arrived within the allowed silence.
    Alive,
    /// Started recently; no heartbeat yet, still within the startup timeout.
    AwaitingFirst,
    /// Heartbeats stopped for longer than `missed` periods.
    Hung { silent: Duration },
    /// No heartbeat at all within the startup timeout.
    NeverBeat { waited: Duration },
}

impl LivenessRule {
    /// The longest silence allowed after `hb` (uses the period the service reports).
    pub fn allowed_silence(&self, hb: Option<&Heartbeat>) -> Duration {
        let period = match hb {
            Some(h) if h.period_ms > 0 => Duration::from_millis(u64::from(h.period_ms)),
            _ => self.period,
        };
        period * self.missed
    }

    /// The first instant (`CLOCK_MONOTONIC` ns) at which [`LivenessRule::evaluate`]
    /// says `Hung` if no heartbeat newer than `last` arrives; `None` without one.
    pub fn hung_at(&self, last: Option<&Heartbeat>) -> Option<u64> {
        let h = last?;
        let allowed = u64::try_from(self.allowed_silence(last).as_nanos()).unwrap_or(u64::MAX);
        // `evaluate` wants the silence strictly longer than the allowance.
        Some(h.stamp_ns.saturating_add(allowed).saturating_add(1))
    }

    /// Liveness of a process spawned at `spawned_ns` whose newest heartbeat is `last`.
    pub fn evaluate(&self, spawned_ns: u64, last: Option<&Heartbeat>, now_ns: u64) -> Liveness {
        match last {
            Some(h) if h.stamp_ns >= spawned_ns => {
                let silent = Duration::from_nanos(now_ns.saturating_sub(h.stamp_ns));
                if silent > self.allowed_silence(last) {
                    Liveness::Hung { silent }
                } else {
                    Liveness::Alive
                }
            }
            _ => {
                let waited = Duration::from_nanos(now_ns.saturating_sub(spawned_ns));
                if waited > self.startup_timeout {
                    Liveness::NeverBeat { waited }
                } else {
                    Liveness::AwaitingFirst
                }
            }
        }
    }

    /// `--monitor-only`: the phase and pid of a service run by someone else.
    /// `exists(pid)` tells whether that process is still there.
    pub fn observed(
        &self,
        last: Option<&Heartbeat>,
        now_ns: u64,
        exists: impl Fn(u32) -> bool,
    ) -> (Phase, Option<u32>) {
        let Some(h) = last else {
            return (Phase::Down, None);
        };
        let silent = Duration::from_nanos(now_ns.saturating_sub(h.stamp_ns));
        if silent <= self.allowed_silence(last) {
            (
                reported_phase(h.state).unwrap_or(Phase::Running),
                Some(h.pid),
            )
        } else if h.pid != 0 && exists(h.pid) {
            (Phase::Stale, Some(h.pid))
        } else {
            (Phase::Down, None)
        }
    }
}

/// The phase a service reports about itself in its heartbeat.
pub fn reported_phase(state: Option<ServiceState>) -> Option<Phase> {
    Some(match state? {
        ServiceState::Starting => Phase::Starting,
        ServiceState::Running => Phase::Running,
        ServiceState::Degraded => Phase::Degraded,
        ServiceState::Stopping => Phase::Stopping,
    })
}

/// True if a process with this pid exists (possibly owned by another user).
pub fn process_exists(pid: u32) -> bool {
    let Ok(raw) = i32::try_from(pid) else {
        return false;
    };
    match nix::sys::signal::kill(nix::unistd::Pid::from_raw(raw), None) {
        Ok(()) => true,
        Err(e) => e == nix::errno::Errno::EPERM,
    }
}

/// Records a heartbeat of service `idx`.
pub fn on_health(mesh: &Mesh, idx: usize, h: &ServiceHealth) {
    let hb = Heartbeat {
        stamp_ns: h.header.stamp_ns,
        pid: h.pid,
        state: h.service_state(),
        period_ms: h.period_ms,
        uptime_ms: h.uptime_ms,
    };
    let monitor_only = mesh.monitor_only;
    mesh.update(idx, |e| {
        if hb.stamp_ns < e.spawned_ns {
            return; // from a process that has since been replaced
        }
        if monitor_only {
            if e.heartbeat
                .is_some_and(|prev| prev.pid != hb.pid && prev.pid != 0)
            {
                e.restarts += 1; // systemd (or someone) started a new process
            }
            e.pid = Some(hb.pid);
            e.phase = reported_phase(hb.state).unwrap_or(Phase::Running);
        } else {
            if e.pid.is_none() {
                return; // a late sample of a process already reaped
            }
            if matches!(e.phase, Phase::Starting | Phase::Running | Phase::Degraded) {
                if let Some(p @ (Phase::Running | Phase::Degraded)) = reported_phase(hb.state) {
                    e.phase = p;
                }
            }
        }
        e.heartbeat = Some(hb);
    });
}

/// Records a stats sample of service `idx`.
pub fn on_stats(mesh: &Mesh, idx: usize, s: &ServiceStats) {
    let monitor_only = mesh.monitor_only;
    mesh.update(idx, |e| {
        if s.header.stamp_ns >= e.spawned_ns && (monitor_only || e.pid.is_some()) {
            // In place: the sample is ~130 KiB, too big to pass through the stack.
            let slot: &mut ServiceStats = e.stats.get_or_insert_with(Box::default);
            *slot = *s;
        }
    });
}

/// How often the watchers drain the quietly published heartbeats and stats: half
/// the slack between a service's heartbeat period and the silence allowed after it
/// (`(missed − 1) × period / 2`, for the shortest period any service reports), at
/// most a second. A healthy service's newest heartbeat is then at most one drain
/// period plus one heartbeat period old when it is looked at — within the
/// allowance by half the slack, so draining late never makes a live service look
/// hung.
pub fn drain_period(rule: &LivenessRule, mesh: &Mesh) -> Duration {
    let shortest = mesh.with_all(|es| {
        es.iter()
            .filter_map(|e| e.heartbeat.filter(|h| h.period_ms > 0))
            .map(|h| Duration::from_millis(u64::from(h.period_ms)))
            .fold(rule.period, Duration::min)
    });
    (shortest * rule.missed.saturating_sub(1) / 2)
        .clamp(Duration::from_millis(10), Duration::from_secs(1))
}

/// The machine-wide grid of `CLOCK_MONOTONIC` the services' tickers keep
/// (`skymesh_runtime::timer::grid_at_or_after`): the drain clock ticks on it — with
/// the services' heartbeats — and the hang checks half a period after it (when
/// that tick's drain has run), so one wake-up serves them all instead of one per
/// service at its own deadline.
pub use skymesh_runtime::timer::{grid_at_or_after as on_grid, instant_at};

/// A timerfd for the supervisor's deadlines, which are seconds away: on tokio's
/// wheel each would cost a second wake-up at a 64 ms block boundary (see
/// skymesh_runtime::timer). `None` (tokio's timer) if the kernel refuses one.
pub fn timerfd() -> Option<Timer> {
    Timer::new()
        .inspect_err(|e| tracing::warn!(error = %e, "no timerfd; using tokio's timer"))
        .ok()
}

/// Sleeps until `at` on `timer`, or on tokio's timer without one (also from the
/// first time the timerfd fails).
pub async fn sleep_until(timer: &mut Option<Timer>, at: tokio::time::Instant) {
    if let Some(t) = timer {
        match t.sleep_until(at).await {
            Ok(()) => return,
            Err(e) => {
                tracing::warn!(error = %e, "timerfd failed; using tokio's timer");
                *timer = None;
            }
        }
    }
    tokio::time::sleep_until(at).await;
}

/// Subscribes to every service's health and stats topics and spawns on `tracker`
/// one task per service that records samples, and the drain clock, until `stop` is
/// cancelled.
pub fn spawn_watchers(
    bus: &Bus,
    mesh: &Arc<Mesh>,
    rule: LivenessRule,
    stop: &CancellationToken,
    tracker: &TaskTracker,
) -> Result<(), IpcError> {
    let names: Vec<String> = mesh.with_all(|es| es.iter().map(|e| e.name.clone()).collect());
    let (clock, ticks) = watch::channel(());
    for (idx, name) in names.iter().enumerate() {
        let mut health = bus.subscriber::<ServiceHealth>(&topics::service_health(name))?;
        let mut stats = bus.subscriber::<ServiceStats>(&topics::service_stats(name))?;
        // Drained on the clock: samples overwritten in between are by design.
        health.set_newest_only();
        stats.set_newest_only();
        let ticks = ticks.clone();
        tracker.spawn(watch(health, stats, mesh.clone(), idx, ticks, stop.clone()));
    }
    tracker.spawn(drain_clock(clock, rule, mesh.clone(), stop.clone()));
    Ok(())
}

/// Ticks the watchers' drain every [`drain_period`] (one wake-up for all of them).
async fn drain_clock(
    clock: watch::Sender<()>,
    rule: LivenessRule,
    mesh: Arc<Mesh>,
    stop: CancellationToken,
) {
    let mut timer = timerfd();
    loop {
        let at = instant_at(on_grid(
            monotonic_ns() + 1,
            drain_period(&rule, &mesh),
            Duration::ZERO,
        ));
        tokio::select! {
            _ = stop.cancelled() => return,
            () = sleep_until(&mut timer, at) => {}
        }
        clock.send_replace(());
    }
}

async fn watch(
    mut health: Subscriber<ServiceHealth>,
    stats: Subscriber<ServiceStats>,
    mesh: Arc<Mesh>,
    idx: usize,
    mut ticks: watch::Receiver<()>,
    stop: CancellationToken,
) {
    loop {
        let failed = tokio::select! {
            _ = stop.cancelled() => return,
            // Woken only by a heartbeat that says something new (see the module).
            r = health.recv() => r.map(|h| on_health(&mesh, idx, &h)).err(),
            r = ticks.changed() => match r {
                Ok(()) => drain(&health, &stats, &mesh, idx).err(),
                Err(_) => return, // the clock stopped: so are we
            },
        };
        if let Some(e) = failed {
            tracing::warn!(service = %mesh.with(idx, |e| e.name.clone()), error = %e, "reading heartbeats failed; retrying");
            tokio::select! {
                _ = stop.cancelled() => return,
                _ = tokio::time::sleep(Duration::from_millis(500)) => {}
            }
        }
    }
}

/// Records every heartbeat and stats sample published since the last look.
fn drain(
    health: &Subscriber<ServiceHealth>,
    stats: &Subscriber<ServiceStats>,
    mesh: &Mesh,
    idx: usize,
) -> Result<(), IpcError> {
    while let Some(h) = health.try_recv()? {
        on_health(mesh, idx, &h);
    }
    while stats.try_recv_with(|s| on_stats(mesh, idx, s))?.is_some() {}
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::FixedStr;

    const S: u64 = 1_000_000_000;
    const MS: u64 = 1_000_000;

    fn rule() -> LivenessRule {
        LivenessRule {
            period: Duration::from_millis(500),
            missed: 6,
            startup_timeout: Duration::from_secs(10),
        }
    }

    fn hb(stamp_ns: u64, period_ms: u32) -> Heartbeat {
        Heartbeat {
            stamp_ns,
            pid: 7,
            state: Some(ServiceState::Running),
            period_ms,
            uptime_ms: 1000,
        }
    }

    #[test]
    fn on_grid_is_the_first_grid_instant_not_before() {
        let p = Duration::from_millis(1000);
        let half = Duration::from_millis(500);
        assert_eq!(on_grid(0, p, Duration::ZERO), 0);
        assert_eq!(on_grid(1, p, Duration::ZERO), S);
        assert_eq!(on_grid(S, p, Duration::ZERO), S);
        assert_eq!(on_grid(S + 1, p, Duration::ZERO), 2 * S);
        assert_eq!(on_grid(0, p, half), 500 * MS);
        assert_eq!(on_grid(500 * MS, p, half), 500 * MS);
        assert_eq!(on_grid(500 * MS + 1, p, half), 1500 * MS);
        assert_eq!(on_grid(7 * S + 200 * MS, p, half), 7 * S + 500 * MS);
        // An offset of a whole period or more wraps.
        assert_eq!(on_grid(S + 1, p, p + half), S + 500 * MS);
    }

    #[test]
    fn hung_at_is_the_first_instant_evaluate_says_hung() {
        let r = rule();
        let spawned = 100 * S;
        for period_ms in [0, 500, 2000] {
            let last = hb(101 * S, period_ms);
            let at = r.hung_at(Some(&last)).unwrap();
            assert_eq!(r.evaluate(spawned, Some(&last), at - 1), Liveness::Alive);
            assert!(matches!(
                r.evaluate(spawned, Some(&last), at),
                Liveness::Hung { .. }
            ));
        }
        assert_eq!(r.hung_at(None), None);
    }

    #[test]
    fn silence_beyond_n_periods_is_a_hang() {
        let r = rule();
        let spawned = 100 * S;
        let last = hb(101 * S, 500);
        assert_eq!(
            r.evaluate(spawned, Some(&last), 101 * S + 2900 * MS),
            Liveness::Alive
        );
        assert_eq!(r.evaluate(spawned, Some(&last), 104 * S), Liveness::Alive);
        assert_eq!(
            r.evaluate(spawned, Some(&last), 104 * S + MS),
            Liveness::Hung {
                silent: Duration::from_millis(3001)
            }
        );
        // A service that promises a slower period gets a proportionally longer allowance.
        let slow = hb(101 * S, 2000);
        assert_eq!(r.evaluate(spawned, Some(&slow), 112 * S), Liveness::Alive);
        assert!(matches!(
            r.evaluate(spawned, Some(&slow), 114 * S),
            Liveness::Hung { .. }
        ));
    }

    #[test]
    fn no_first_heartbeat_waits_for_the_startup_timeout() {
        let r = rule();
        let spawned = 100 * S;
        assert_eq!(r.evaluate(spawned, None, 105 * S), Liveness::AwaitingFirst);
        assert_eq!(
            r.evaluate(spawned, None, 111 * S),
            Liveness::NeverBeat {
                waited: Duration::from_secs(11)
            }
        );
        // A heartbeat from before the spawn belongs to the previous process.
        let old = hb(99 * S, 500);
        assert_eq!(
            r.evaluate(spawned, Some(&old), 105 * S),
            Liveness::AwaitingFirst
        );
    }

    #[test]
    fn monitor_only_tells_running_stale_and_down_apart() {
        let r = rule();
        let h = hb(100 * S, 500);
        assert_eq!(r.observed(None, 100 * S, |_| true), (Phase::Down, None));
        assert_eq!(
            r.observed(Some(&h), 101 * S, |_| false),
            (Phase::Running, Some(7))
        );
        assert_eq!(
            r.observed(Some(&h), 110 * S, |_| true),
            (Phase::Stale, Some(7))
        );
        assert_eq!(
            r.observed(Some(&h), 110 * S, |_| false),
            (Phase::Down, None)
        );
        let degraded = Heartbeat {
            state: Some(ServiceState::Degraded),
            ..h
        };
        assert_eq!(
            r.observed(Some(&degraded), 101 * S, |_| true).0,
            Phase::Degraded
        );
    }

    fn health(stamp_ns: u64, pid: u32, state: ServiceState) -> ServiceHealth {
        let mut h = ServiceHealth {
            name: FixedStr::new("a"),
            pid,
            state: state.to_wire(),
            period_ms: 500,
            ..Default::default()
        };
        h.header.stamp_ns = stamp_ns;
        h
    }

    #[test]
    fn heartbeats_drive_the_supervised_phase_and_old_ones_are_ignored() {
        let mesh = Mesh::new(&[("a".into(), true)], false);
        mesh.update(0, |e| {
            e.pid = Some(7);
            e.spawned_ns = 100 * S;
        });
        on_health(&mesh, 0, &health(99 * S, 6, ServiceState::Running));
        assert_eq!(
            mesh.with(0, |e| (e.phase, e.heartbeat.is_none())),
            (Phase::Starting, true)
        );
        on_health(&mesh, 0, &health(101 * S, 7, ServiceState::Starting));
        assert_eq!(mesh.with(0, |e| e.phase), Phase::Starting);
        on_health(&mesh, 0, &health(102 * S, 7, ServiceState::Running));
        assert_eq!(mesh.with(0, |e| e.phase), Phase::Running);
        assert!(mesh.ready());
        on_health(&mesh, 0, &health(103 * S, 7, ServiceState::Degraded));
        assert_eq!(mesh.with(0, |e| e.phase), Phase::Degraded);
        // Backoff is the supervisor's decision; a late heartbeat does not undo it.
        mesh.update(0, |e| {
            e.phase = Phase::Backoff;
            e.pid = None;
        });
        on_health(&mesh, 0, &health(104 * S, 7, ServiceState::Running));
        assert_eq!(mesh.with(0, |e| e.phase), Phase::Backoff);
    }

    #[test]
    fn monitor_only_counts_a_new_pid_as_a_restart() {
        let mesh = Mesh::new(&[("a".into(), false)], true);
        on_health(&mesh, 0, &health(S, 10, ServiceState::Running));
        on_health(&mesh, 0, &health(2 * S, 10, ServiceState::Running));
        assert_eq!(
            mesh.with(0, |e| (e.restarts, e.pid, e.phase)),
            (0, Some(10), Phase::Running)
        );
        on_health(&mesh, 0, &health(3 * S, 11, ServiceState::Starting));
        assert_eq!(
            mesh.with(0, |e| (e.restarts, e.pid, e.phase)),
            (1, Some(11), Phase::Starting)
        );
    }

    #[test]
    fn process_exists_sees_this_process() {
        assert!(process_exists(std::process::id()));
        assert!(!process_exists(u32::MAX));
    }
}
