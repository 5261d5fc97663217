//! The supervisor's view of the mesh, shared by the supervision tasks (writers), the
//! heartbeat monitor (writer), and the HTTP endpoint, metrics and table (readers).
//!
//! One mutex around a small vector: every access is short and never held across an
//! `.await`.

use std::collections::VecDeque;
use std::sync::atomic::AtomicU64;
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use skymesh_ipc_types::{ServiceState, ServiceStats};
use skymesh_runtime::clock::monotonic_ns;
use tokio::sync::watch;

/// What the supervisor says about a service.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Phase {
    /// Waiting for its dependencies, or started and not yet reporting `running`.
    Starting,
    Running,
    /// Running, but the service reports a missing dependency.
    Degraded,
    /// Exited; waiting before the next start.
    Backoff,
    /// Being stopped (SIGTERM sent).
    Stopping,
    /// Not running and not going to be restarted (clean exit or shutdown).
    Stopped,
    /// Restart budget spent.
    Failed,
    /// Exited with 64: its configuration is bad; never restarted.
    ConfigError,
    /// `--monitor-only`: the process exists but its heartbeats stopped.
    Stale,
    /// `--monitor-only`: no process and no recent heartbeat.
    Down,
}

impl Phase {
    pub const ALL: [Phase; 10] = [
        Phase::Starting,
        Phase::Running,
        Phase::Degraded,
        Phase::Backoff,
        Phase::Stopping,
        Phase::Stopped,
        Phase::Failed,
        Phase::ConfigError,
        Phase::Stale,
        Phase::Down,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Starting => "starting",
            Phase::Running => "running",
            Phase::Degraded => "degraded",
            Phase::Backoff => "backoff",
            Phase::Stopping => "stopping",
            Phase::Stopped => "stopped",
            Phase::Failed => "failed",
            Phase::ConfigError => "config-error",
            Phase::Stale => "stale",
            Phase::Down => "down",
        }
    }

    /// Counts as up for `skymesh_service_up` and readiness.
    pub fn is_up(self) -> bool {
        matches!(self, Phase::Running | Phase::Degraded)
    }

    /// The supervisor will not start it again by itself.
    pub fn is_terminal(self) -> bool {
        matches!(self, Phase::Stopped | Phase::Failed | Phase::ConfigError)
    }
}

impl core::fmt::Display for Phase {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The last heartbeat of a service, as received.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heartbeat {
    /// `CLOCK_MONOTONIC` ns when the service published it.
    pub stamp_ns: u64,
    pub pid: u32,
    pub state: Option<ServiceState>,
    /// The period the service promises; 0 if it did not say.
    pub period_ms: u32,
    pub uptime_ms: u64,
}

/// Everything known about one service.
#[derive(Debug, Clone)]
pub struct ServiceEntry {
    pub name: String,
    pub critical: bool,
    pub phase: Phase,
    /// The running process (supervised), or the heartbeat's pid (monitor-only).
    pub pid: Option<u32>,
    pub restarts: u64,
    /// When the current process was started (supervised mode).
    pub started_at: Option<Instant>,
    /// `CLOCK_MONOTONIC` ns at spawn: heartbeats and stats stamped earlier belong to
    /// an older process and are ignored.
    pub spawned_ns: u64,
    pub last_exit_code: Option<i32>,
    pub heartbeat: Option<Heartbeat>,
    /// The newest stats sample of the current process.
    pub stats: Option<Box<ServiceStats>>,
    /// The current process was started by an earlier supervisor and adopted.
    pub adopted: bool,
    /// Processes of this service adopted from an earlier supervisor.
    pub adopted_total: u64,
}

impl ServiceEntry {
    fn new(name: &str, critical: bool, phase: Phase) -> Self {
        ServiceEntry {
            name: name.to_string(),
            critical,
            phase,
            pid: None,
            restarts: 0,
            started_at: None,
            spawned_ns: 0,
            last_exit_code: None,
            heartbeat: None,
            stats: None,
            adopted: false,
            adopted_total: 0,
        }
    }

    /// Seconds since the newest heartbeat was published.
    pub fn heartbeat_age_s(&self, now_ns: u64) -> Option<f64> {
        self.heartbeat
            .map(|h| now_ns.saturating_sub(h.stamp_ns) as f64 / 1e9)
    }

    /// Seconds the current process has been running; 0 when none runs.
    pub fn uptime_s(&self, now_ns: u64) -> f64 {
        if self.pid.is_none() {
            return 0.0;
        }
        match (self.started_at, self.heartbeat) {
            (Some(t), _) => t.elapsed().as_secs_f64(),
            // Monitor-only: the service's own uptime, aged to now.
            (None, Some(h)) => {
                h.uptime_ms as f64 / 1e3 + now_ns.saturating_sub(h.stamp_ns) as f64 / 1e9
            }
            (None, None) => 0.0,
        }
    }

    pub fn to_status(&self, now_ns: u64) -> StatusEntry {
        StatusEntry {
            name: self.name.clone(),
            pid: self.pid,
            state: self.phase.as_str().to_string(),
            restarts: self.restarts,
            uptime_s: round3(self.uptime_s(now_ns)),
            heartbeat_age_s: self.heartbeat_age_s(now_ns).map(round3),
            last_exit_code: self.last_exit_code,
            critical: self.critical,
            adopted: self.adopted,
        }
    }
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// One element of the `/status` JSON array (also what `skymesh status` reads).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StatusEntry {
    pub name: String,
    /// Null when no process runs.
    pub pid: Option<u32>,
    pub state: String,
    pub restarts: u64,
    /// Seconds the current process has been up; 0 when none runs.
    pub uptime_s: f64,
    /// Seconds since the last heartbeat; null before the first.
    pub heartbeat_age_s: Option<f64>,
    /// Exit code of the previous process (128 + signal when killed); null if none exited.
    pub last_exit_code: Option<i32>,
    pub critical: bool,
    /// The current process was started by an earlier supervisor and adopted by this one.
    #[serde(default)]
    pub adopted: bool,
}

/// A state change, kept for the live table.
#[derive(Debug, Clone)]
pub struct Event {
    pub at: Instant,
    pub text: String,
}

const EVENTS_KEPT: usize = 6;

/// The shared state of one mesh.
#[derive(Debug)]
pub struct Mesh {
    entries: Mutex<Vec<ServiceEntry>>,
    events: Mutex<VecDeque<Event>>,
    /// Bumped on every state change; readiness and dependency waits watch it.
    changed: watch::Sender<u64>,
    /// Dead nodes whose stale iceoryx2 resources were removed.
    pub stale_nodes_cleaned: AtomicU64,
    pub monitor_only: bool,
    pub started: Instant,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Entries are plain values; a panic elsewhere cannot leave them half-written in a
    // way that matters more than losing the supervisor's view. Keep going.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Mesh {
    /// A mesh of `(name, critical)` services, in start order.
    pub fn new(services: &[(String, bool)], monitor_only: bool) -> Self {
        let initial = if monitor_only {
            Phase::Down
        } else {
            Phase::Starting
        };
        Mesh {
            entries: Mutex::new(
                services
                    .iter()
                    .map(|(n, c)| ServiceEntry::new(n, *c, initial))
                    .collect(),
            ),
            events: Mutex::new(VecDeque::new()),
            changed: watch::Sender::new(0),
            stale_nodes_cleaned: AtomicU64::new(0),
            monitor_only,
            started: Instant::now(),
        }
    }

    pub fn len(&self) -> usize {
        lock(&self.entries).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Runs `f` on the entry `idx` under the lock; logs and records a phase change.
    pub fn update<R>(&self, idx: usize, f: impl FnOnce(&mut ServiceEntry) -> R) -> R {
        let (r, change) = {
            let mut entries = lock(&self.entries);
            let e = &mut entries[idx];
            let before = e.phase;
            let r = f(e);
            let change = (e.phase != before).then(|| (e.name.clone(), before, e.phase, e.pid));
            (r, change)
        };
        if let Some((name, from, to, pid)) = change {
            tracing::info!(service = %name, from = %from, to = %to, pid, "state");
            let mut events = lock(&self.events);
            if events.len() == EVENTS_KEPT {
                events.pop_front();
            }
            events.push_back(Event {
                at: Instant::now(),
                text: format!("{name}: {from} → {to}"),
            });
        }
        self.changed.send_modify(|v| *v = v.wrapping_add(1));
        r
    }

    /// Sets the phase of `idx`.
    pub fn set_phase(&self, idx: usize, phase: Phase) {
        self.update(idx, |e| e.phase = phase);
    }

    /// Reads entry `idx`.
    pub fn with<R>(&self, idx: usize, f: impl FnOnce(&ServiceEntry) -> R) -> R {
        f(&lock(&self.entries)[idx])
    }

    /// Reads every entry.
    pub fn with_all<R>(&self, f: impl FnOnce(&[ServiceEntry]) -> R) -> R {
        f(&lock(&self.entries))
    }

    pub fn index_of(&self, name: &str) -> Option<usize> {
        lock(&self.entries).iter().position(|e| e.name == name)
    }

    /// The `/status` array.
    pub fn status(&self) -> Vec<StatusEntry> {
        let now = monotonic_ns();
        self.with_all(|es| es.iter().map(|e| e.to_status(now)).collect())
    }

    pub fn recent_events(&self) -> Vec<Event> {
        lock(&self.events).iter().cloned().collect()
    }

    /// A receiver that sees every later change.
    pub fn subscribe(&self) -> watch::Receiver<u64> {
        self.changed.subscribe()
    }

    /// True when every critical service is up. Without critical services: when every
    /// service has at least been started (none still waiting in `starting`).
    pub fn ready(&self) -> bool {
        self.with_all(|es| {
            if es.iter().any(|e| e.critical) {
                es.iter().filter(|e| e.critical).all(|e| e.phase.is_up())
            } else {
                es.iter().all(|e| e.phase != Phase::Starting)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_has_the_documented_shape() {
        let mesh = Mesh::new(&[("a".into(), true), ("b".into(), false)], false);
        mesh.update(0, |e| {
            e.phase = Phase::Running;
            e.pid = Some(42);
            e.started_at = Some(Instant::now());
            e.last_exit_code = Some(137);
        });
        let v = serde_json::to_value(mesh.status()).unwrap();
        let a = &v[0];
        for key in [
            "name",
            "pid",
            "state",
            "restarts",
            "uptime_s",
            "heartbeat_age_s",
            "last_exit_code",
            "critical",
        ] {
            assert!(a.get(key).is_some(), "missing {key}: {a}");
        }
        assert_eq!(a["state"], "running");
        assert_eq!(a["pid"], 42);
        assert_eq!(v[1]["pid"], serde_json::Value::Null);
        assert_eq!(v[1]["state"], "starting");
        assert!(mesh.ready(), "the critical service runs");
        assert_eq!(mesh.recent_events().len(), 1);
    }

    #[test]
    fn phases_serialise_kebab_case() {
        for p in Phase::ALL {
            assert_eq!(serde_json::to_value(p).unwrap(), p.as_str());
        }
    }
}
