//! One task per service: wait for its dependencies, start it, watch it (exit or
//! missing heartbeats), reap it, clean the dead node's shared memory, and apply the
//! restart policy — until its own stop token says to stop it.
//!
//! Two tokens: `shutdown` (the whole mesh is going down: start nothing new) and `stop`
//! (stop this service's process now). The caller cancels `shutdown` first, then each
//! service's `stop` in reverse start order.

use std::sync::Arc;
use std::time::{Duration, Instant};

use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::Domain;
use tokio_util::sync::CancellationToken;

use crate::child::{self, Environment, Running};
use crate::config::ServiceSpec;
use crate::monitor::{Liveness, LivenessRule};
use crate::policy::{Decision, Ending, RestartTracker};
use crate::state::{Mesh, Phase};

/// What every supervision task shares.
#[derive(Debug)]
pub struct Shared {
    pub mesh: Arc<Mesh>,
    pub domain: Domain,
    pub env: Environment,
    pub rule: LivenessRule,
    pub grace: Duration,
    /// Cancelled when the mesh shuts down: nothing is started or restarted after it.
    pub shutdown: CancellationToken,
}

/// Removes the stale resources of every dead node of the domain (blocking file work,
/// so off the async threads) and counts them.
pub async fn clean_dead_nodes(domain: &Domain, mesh: &Mesh) {
    let d = domain.clone();
    match tokio::task::spawn_blocking(move || d.cleanup_dead_nodes()).await {
        Ok((cleaned, failed)) => {
            if !cleaned.is_empty() {
                tracing::info!(nodes = ?cleaned, "removed stale iceoryx2 resources of dead nodes");
                mesh.stale_nodes_cleaned
                    .fetch_add(cleaned.len() as u64, std::sync::atomic::Ordering::Relaxed);
            }
            if failed > 0 {
                tracing::warn!(failed, "some dead nodes could not be cleaned; will retry");
            }
        }
        Err(e) => tracing::warn!(error = %e, "dead node cleanup task failed"),
    }
}

/// Waits until every dependency is up (or will not come up: failed, config error,
/// stopped), or the startup timeout passes. False if told to stop meanwhile.
async fn wait_for_dependencies(sh: &Shared, spec: &ServiceSpec, stop: &CancellationToken) -> bool {
    let deps: Vec<usize> = spec
        .after
        .iter()
        .filter_map(|d| sh.mesh.index_of(d))
        .collect();
    if deps.is_empty() {
        return true;
    }
    let mut changes = sh.mesh.subscribe();
    let deadline = tokio::time::Instant::now() + sh.rule.startup_timeout;
    tracing::info!(service = %spec.name, after = ?spec.after, "waiting for dependencies");
    loop {
        let settled = deps.iter().all(|&d| {
            sh.mesh
                .with(d, |e| e.phase.is_up() || e.phase.is_terminal())
        });
        if settled {
            return true;
        }
        tokio::select! {
            r = changes.changed() => if r.is_err() { return true },
            _ = tokio::time::sleep_until(deadline) => {
                tracing::warn!(service = %spec.name, after = ?spec.after, "dependencies not up within the startup timeout; starting anyway");
                return true;
            }
            _ = stop.cancelled() => return false,
            _ = sh.shutdown.cancelled() => return false,
        }
    }
}

/// Resolves when the heartbeats of `idx` say it is hung (or never started beating).
async fn hang_watch(sh: &Shared, idx: usize, heartbeat: bool) -> Liveness {
    if !heartbeat {
        return std::future::pending().await;
    }
    // Until the first heartbeat: a short tick (it may arrive any time and bring the
    // deadline forward from the startup timeout to its own silence allowance).
    let tick = (sh.rule.period / 2).clamp(Duration::from_millis(10), Duration::from_millis(250));
    loop {
        let (spawned_ns, hb) = sh.mesh.with(idx, |e| (e.spawned_ns, e.heartbeat));
        let now_ns = monotonic_ns();
        let wait = match sh.rule.evaluate(spawned_ns, hb.as_ref(), now_ns) {
            Liveness::AwaitingFirst => tick,
            // Then no periodic polling: the verdict can only change once the newest
            // heartbeat is older than its allowance, so sleep until exactly then and
            // look again (heartbeats that came meanwhile push the deadline on; a
            // process keeps the period it reports for its whole life).
            Liveness::Alive => sh
                .rule
                .hung_at(hb.as_ref())
                .map_or(tick, |at| Duration::from_nanos(at.saturating_sub(now_ns))),
            verdict => return verdict,
        };
        tokio::time::sleep(wait).await;
    }
}

enum Outcome {
    Exited(std::io::Result<std::process::ExitStatus>),
    Hung(Liveness),
    Stop,
}

/// Runs one start of the service until it ends. `None` means it was stopped on request.
async fn run_once(
    sh: &Shared,
    idx: usize,
    spec: &ServiceSpec,
    run: &mut Running,
    stop: &CancellationToken,
) -> Option<Ending> {
    let outcome = tokio::select! {
        r = run.child.wait() => Outcome::Exited(r),
        verdict = hang_watch(sh, idx, spec.heartbeat) => Outcome::Hung(verdict),
        _ = stop.cancelled() => Outcome::Stop,
    };
    let ending = match outcome {
        Outcome::Exited(Ok(status)) => child::ending(&status),
        Outcome::Exited(Err(e)) => {
            tracing::error!(service = %spec.name, pid = run.pid, error = %e, "waiting for the child failed; killing it");
            let _ = child::kill(run).await;
            Ending::Code(1)
        }
        Outcome::Hung(verdict) => {
            match verdict {
                Liveness::NeverBeat { waited } => {
                    tracing::warn!(service = %spec.name, pid = run.pid, waited_ms = waited.as_millis() as u64, "no heartbeat since start; killing (SIGKILL)")
                }
                Liveness::Hung { silent } => {
                    tracing::warn!(service = %spec.name, pid = run.pid, silent_ms = silent.as_millis() as u64, "heartbeats stopped; killing hung service (SIGKILL)")
                }
                _ => {}
            }
            if let Err(e) = child::kill(run).await {
                tracing::error!(service = %spec.name, pid = run.pid, error = %e, "reaping the killed child failed");
            }
            Ending::Hung
        }
        Outcome::Stop => {
            sh.mesh.set_phase(idx, Phase::Stopping);
            match child::stop(run, sh.grace).await {
                Ok(status) => {
                    let code = child::ending(&status).exit_code();
                    tracing::info!(service = %spec.name, pid = run.pid, exit_code = code, "stopped");
                    sh.mesh
                        .update(idx, |e| e.last_exit_code = code.or(e.last_exit_code));
                }
                Err(e) => {
                    tracing::error!(service = %spec.name, pid = run.pid, error = %e, "stopping failed")
                }
            }
            return None;
        }
    };
    // Anything the child forked dies with it, so no orphan keeps its shared memory.
    child::signal_group(run.pid, nix::sys::signal::Signal::SIGKILL);
    Some(ending)
}

fn log_ending(spec: &ServiceSpec, pid: Option<u32>, ending: Ending, ran_for: Duration) {
    let ran_ms = ran_for.as_millis() as u64;
    match ending {
        Ending::Code(0) => tracing::info!(service = %spec.name, pid, ran_ms, "exited cleanly"),
        Ending::Code(code) => tracing::warn!(service = %spec.name, pid, code, ran_ms, "exited"),
        Ending::Signal(signal) => {
            tracing::warn!(service = %spec.name, pid, signal, ran_ms, "killed by signal")
        }
        Ending::Hung => {
            tracing::warn!(service = %spec.name, pid, ran_ms, "killed after missing heartbeats")
        }
        Ending::SpawnFailed => {}
    }
}

/// Supervises service `idx` until `stop` is cancelled (or it reaches a state it is
/// not restarted from).
pub async fn supervise(sh: Arc<Shared>, idx: usize, spec: ServiceSpec, stop: CancellationToken) {
    if !wait_for_dependencies(&sh, &spec, &stop).await {
        sh.mesh.set_phase(idx, Phase::Stopped);
        return;
    }
    let mut tracker = RestartTracker::new(spec.restart);
    loop {
        sh.mesh.update(idx, |e| {
            e.phase = Phase::Starting;
            e.pid = None;
            e.heartbeat = None;
            e.stats = None;
        });
        let (ending, ran_for, pid) = match child::spawn(&spec, &sh.env) {
            Err(e) => {
                tracing::error!(service = %spec.name, program = %spec.program.display(), error = %e, "cannot start");
                (Ending::SpawnFailed, Duration::ZERO, None)
            }
            Ok(mut run) => {
                tracing::info!(service = %spec.name, pid = run.pid, program = %spec.program.display(), "started");
                sh.mesh.update(idx, |e| {
                    e.pid = Some(run.pid);
                    e.started_at = Some(run.started);
                    e.spawned_ns = run.spawned_ns;
                    if !spec.heartbeat {
                        e.phase = Phase::Running;
                    }
                });
                let ended = run_once(&sh, idx, &spec, &mut run, &stop).await;
                let ran_for = run.started.elapsed();
                sh.mesh.update(idx, |e| {
                    e.pid = None;
                    e.started_at = None;
                    e.stats = None;
                    if let Some(code) = ended.and_then(Ending::exit_code) {
                        e.last_exit_code = Some(code);
                    }
                });
                // The process is reaped: iceoryx2 can now see its node as dead.
                clean_dead_nodes(&sh.domain, &sh.mesh).await;
                let Some(ending) = ended else {
                    sh.mesh.set_phase(idx, Phase::Stopped);
                    return;
                };
                (ending, ran_for, Some(run.pid))
            }
        };
        log_ending(&spec, pid, ending, ran_for);
        if sh.shutdown.is_cancelled() {
            sh.mesh.set_phase(idx, Phase::Stopped);
            return;
        }
        match tracker.on_exit(Instant::now(), ran_for, ending, fastrand::f64()) {
            Decision::Restart { after } => {
                sh.mesh.set_phase(idx, Phase::Backoff);
                tracing::info!(service = %spec.name, delay_ms = after.as_millis() as u64, "restarting after backoff");
                tokio::select! {
                    _ = tokio::time::sleep(after) => {}
                    _ = stop.cancelled() => { sh.mesh.set_phase(idx, Phase::Stopped); return; }
                    _ = sh.shutdown.cancelled() => { sh.mesh.set_phase(idx, Phase::Stopped); return; }
                }
                sh.mesh.update(idx, |e| e.restarts += 1);
            }
            Decision::ConfigError => {
                tracing::error!(service = %spec.name, "exit code 64: bad configuration; not restarting (fix it, then restart the mesh)");
                sh.mesh.set_phase(idx, Phase::ConfigError);
                return;
            }
            Decision::Failed { restarts_in_window } => {
                tracing::error!(
                    service = %spec.name,
                    restarts_in_window,
                    window_s = spec.restart.window.as_secs(),
                    "restart budget spent; not restarting"
                );
                sh.mesh.set_phase(idx, Phase::Failed);
                return;
            }
            Decision::Stopped => {
                tracing::info!(service = %spec.name, "exited cleanly; not restarted (restart mode on-failure)");
                sh.mesh.set_phase(idx, Phase::Stopped);
                return;
            }
        }
    }
}
