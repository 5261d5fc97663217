//! One task per service: wait for its dependencies, start it, watch it (exit or
//! missing heartbeats), reap it, clean the dead node's shared memory, and apply the
//! restart policy — until its own stop token says to stop it.
//!
//! Two tokens: `shutdown` (the whole mesh is going down: start nothing new) and `stop`
//! (stop this service's process now). The caller cancels `shutdown` first, then each
//! service's `stop` in reverse start order.
//!
//! An operator (the web console) may ask for a restart ([`RestartRequests`]): a
//! running process is stopped like on `stop` (SIGTERM, grace, SIGKILL) and started
//! again at once; a service in backoff starts now; a service the supervisor gave up
//! on (failed, config error, exited cleanly) starts again with a fresh budget. Each
//! counts as a restart, none against the crash budget.

use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::Domain;
use tokio_util::sync::CancellationToken;

use crate::adopt::Adopted;
use crate::child::{self, Environment, Running};
use crate::config::ServiceSpec;
use crate::monitor::{self, Liveness, LivenessRule};
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
    /// Restarts asked for by an operator; the console holds the other end.
    pub restarts: Arc<RestartRequests>,
}

/// One restart request slot per service (by index in start order). A request made
/// while nobody waits is kept until the service's task looks (one at most).
#[derive(Debug)]
pub struct RestartRequests {
    slots: Vec<tokio::sync::Notify>,
}

impl RestartRequests {
    /// Slots for `services` services.
    pub fn new(services: usize) -> Self {
        RestartRequests {
            slots: (0..services).map(|_| tokio::sync::Notify::new()).collect(),
        }
    }

    /// Asks for a restart of service `idx`; false if there is no such service.
    pub fn request(&self, idx: usize) -> bool {
        self.slots.get(idx).map(|n| n.notify_one()).is_some()
    }

    /// Resolves when a restart of `idx` is asked for (never for an unknown index).
    pub(crate) async fn requested(&self, idx: usize) {
        match self.slots.get(idx) {
            Some(n) => n.notified().await,
            None => std::future::pending().await,
        }
    }
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
async fn hang_watch(sh: &Shared, rule: &LivenessRule, idx: usize, heartbeat: bool) -> Liveness {
    if !heartbeat {
        return std::future::pending().await;
    }
    // Until the first heartbeat: a short tick (it may arrive any time and bring the
    // deadline forward from the startup timeout to its own silence allowance).
    let tick = (rule.period / 2).clamp(Duration::from_millis(10), Duration::from_millis(250));
    let mut timer = monitor::timerfd();
    loop {
        let (spawned_ns, hb) = sh.mesh.with(idx, |e| (e.spawned_ns, e.heartbeat));
        let now_ns = monotonic_ns();
        let wait = match rule.evaluate(spawned_ns, hb.as_ref(), now_ns) {
            Liveness::AwaitingFirst => tick,
            // Then no periodic polling: the verdict can only change once the newest
            // heartbeat is older than its allowance, so sleep until then and look
            // again (heartbeats drained meanwhile push the deadline on; a process
            // keeps the period it reports for its whole life). "Then" is rounded up
            // to the drain clock's grid, half a drain period after a drain, so every
            // service's check shares one wake-up: a hang is seen at most one drain
            // period (1 s by default) after its deadline.
            Liveness::Alive => rule.hung_at(hb.as_ref()).map_or(tick, |at| {
                let grid = monitor::drain_period(rule, &sh.mesh);
                let at = monitor::on_grid(at, grid, grid / 2);
                Duration::from_nanos(at.saturating_sub(now_ns))
            }),
            verdict => return verdict,
        };
        monitor::sleep_until(&mut timer, tokio::time::Instant::now() + wait).await;
    }
}

enum Outcome {
    Exited(std::io::Result<std::process::ExitStatus>),
    Hung(Liveness),
    Stop,
    Restart,
}

/// How one run of a service ended.
#[derive(Debug, Clone, Copy)]
enum RunEnd {
    /// By itself (or killed as hung): the restart policy decides.
    Ended(Ending),
    /// Stopped on request (the mesh or the service is stopping).
    Stopped,
    /// Stopped for an operator's restart: start again now.
    Restart,
}

/// Runs one start of the service until it ends.
async fn run_once(
    sh: &Shared,
    idx: usize,
    spec: &ServiceSpec,
    run: &mut Running,
    stop: &CancellationToken,
) -> RunEnd {
    let outcome = tokio::select! {
        r = run.child.wait() => Outcome::Exited(r),
        verdict = hang_watch(sh, &sh.rule, idx, spec.heartbeat) => Outcome::Hung(verdict),
        _ = stop.cancelled() => Outcome::Stop,
        () = sh.restarts.requested(idx) => Outcome::Restart,
    };
    let restart = matches!(outcome, Outcome::Restart);
    if restart {
        tracing::info!(service = %spec.name, pid = run.pid, "restart asked for by an operator: stopping (SIGTERM)");
    }
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
        Outcome::Stop | Outcome::Restart => {
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
            return if restart {
                RunEnd::Restart
            } else {
                RunEnd::Stopped
            };
        }
    };
    // Anything the child forked dies with it, so no orphan keeps its shared memory.
    child::signal_group(run.pid, Signal::SIGKILL);
    RunEnd::Ended(ending)
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
        Ending::Lost => {
            tracing::warn!(service = %spec.name, pid, ran_ms, "adopted process ended (exit status unknown: not our child)")
        }
        Ending::SpawnFailed => {}
    }
}

/// Runs an adopted process (started by an earlier supervisor) until it ends.
/// Returns how it ended and how long it ran under us.
async fn run_adopted(
    sh: &Shared,
    idx: usize,
    spec: &ServiceSpec,
    adopted: Adopted,
    stop: &CancellationToken,
) -> (RunEnd, Duration) {
    let pid = adopted.pid;
    let since = Instant::now();
    tracing::info!(
        service = %spec.name,
        pid,
        running_s = adopted.age.as_secs(),
        program = %spec.program.display(),
        "adopted the running instance an earlier supervisor started; not starting a new one"
    );
    sh.mesh.update(idx, |e| {
        e.phase = if spec.heartbeat {
            Phase::Starting
        } else {
            Phase::Running
        };
        e.pid = Some(pid);
        e.started_at = since.checked_sub(adopted.age).or(Some(since));
        e.spawned_ns = monotonic_ns();
        e.heartbeat = None;
        e.stats = None;
        e.adopted = true;
        e.adopted_total += 1;
    });
    // It is already running: its next heartbeat is due within the usual silence
    // allowance, not the startup timeout.
    let rule = LivenessRule {
        startup_timeout: sh.rule.allowed_silence(None),
        ..sh.rule
    };
    enum Seen {
        Exited,
        Hung(Liveness),
        Stop,
        Restart,
    }
    let seen = tokio::select! {
        () = adopted.exited() => Seen::Exited,
        verdict = hang_watch(sh, &rule, idx, spec.heartbeat) => Seen::Hung(verdict),
        _ = stop.cancelled() => Seen::Stop,
        () = sh.restarts.requested(idx) => Seen::Restart,
    };
    let stopping = matches!(seen, Seen::Stop);
    let restart = matches!(seen, Seen::Restart);
    if restart {
        tracing::info!(service = %spec.name, pid, "restart asked for by an operator: stopping the adopted process (SIGTERM)");
    }
    let ending = match seen {
        Seen::Exited => Some(Ending::Lost),
        Seen::Hung(verdict) => {
            tracing::warn!(service = %spec.name, pid, verdict = ?verdict, "adopted service sends no heartbeats; killing (SIGKILL)");
            adopted.signal_group(Signal::SIGKILL);
            if tokio::time::timeout(Duration::from_secs(10), adopted.exited())
                .await
                .is_err()
            {
                tracing::error!(service = %spec.name, pid, "adopted process survives SIGKILL");
            }
            Some(Ending::Hung)
        }
        Seen::Stop | Seen::Restart => {
            sh.mesh.set_phase(idx, Phase::Stopping);
            adopted.signal_group(Signal::SIGTERM);
            if tokio::time::timeout(sh.grace, adopted.exited())
                .await
                .is_err()
            {
                tracing::warn!(service = %spec.name, pid, grace_ms = sh.grace.as_millis() as u64, "did not stop in time; SIGKILL");
                adopted.signal_group(Signal::SIGKILL);
                if tokio::time::timeout(Duration::from_secs(10), adopted.exited())
                    .await
                    .is_err()
                {
                    tracing::error!(service = %spec.name, pid, "adopted process survives SIGKILL");
                }
            }
            tracing::info!(service = %spec.name, pid, "stopped (adopted; exit status unknown)");
            None
        }
    };
    // Anything it forked dies with it. Its leader is gone: signal the group by id.
    child::signal_group(pid, Signal::SIGKILL);
    // Its new parent (init or a subreaper) reaps it; then iceoryx2 sees its node dead.
    // Not waited for when the mesh stops: init may reap only every few seconds, and
    // the final cleanup waits for every such zombie at once instead of one by one.
    if !stopping && !adopted.reaped(Duration::from_secs(2)).await {
        tracing::warn!(service = %spec.name, pid, "adopted process not reaped by its parent yet; its node is cleaned later");
    }
    sh.mesh.update(idx, |e| {
        e.pid = None;
        e.started_at = None;
        e.stats = None;
        e.adopted = false;
        if let Some(code) = ending.and_then(Ending::exit_code) {
            e.last_exit_code = Some(code);
        }
    });
    clean_dead_nodes(&sh.domain, &sh.mesh).await;
    let end = match ending {
        Some(e) => RunEnd::Ended(e),
        None if restart => RunEnd::Restart,
        None => RunEnd::Stopped,
    };
    (end, since.elapsed())
}

/// Supervises service `idx` until `stop` is cancelled (or it reaches a state it is
/// not restarted from). With `adopted`, the first run is that process (started by an
/// earlier supervisor) instead of a new one.
pub async fn supervise(
    sh: Arc<Shared>,
    idx: usize,
    spec: ServiceSpec,
    stop: CancellationToken,
    adopted: Option<Adopted>,
) {
    let mut adopted = adopted;
    // A running instance needs no waiting for its dependencies.
    if adopted.is_none() && !wait_for_dependencies(&sh, &spec, &stop).await {
        sh.mesh.set_phase(idx, Phase::Stopped);
        return;
    }
    let mut tracker = RestartTracker::new(spec.restart);
    loop {
        let (end, ran_for, pid) = match adopted.take() {
            Some(a) => {
                let pid = a.pid;
                let (end, ran_for) = run_adopted(&sh, idx, &spec, a, &stop).await;
                (end, ran_for, Some(pid))
            }
            None => run_new(&sh, idx, &spec, &stop).await,
        };
        let next = match end {
            RunEnd::Stopped => {
                sh.mesh.set_phase(idx, Phase::Stopped);
                return;
            }
            RunEnd::Restart if stop.is_cancelled() || sh.shutdown.is_cancelled() => {
                sh.mesh.set_phase(idx, Phase::Stopped);
                return;
            }
            RunEnd::Restart => {
                sh.mesh.update(idx, |e| e.restarts += 1);
                continue;
            }
            RunEnd::Ended(ending) => {
                decide(&sh, idx, &spec, &mut tracker, &stop, ending, ran_for, pid).await
            }
        };
        if next.is_break() {
            // Not restarted by the policy: only an operator's restart starts it again.
            if !wait_for_operator(&sh, idx, &spec, &stop).await {
                return;
            }
            tracker = RestartTracker::new(spec.restart);
            sh.mesh.update(idx, |e| e.restarts += 1);
        }
    }
}

/// Starts a new process of the service and runs it until it ends; returns how it
/// ended, how long it ran and its pid.
async fn run_new(
    sh: &Shared,
    idx: usize,
    spec: &ServiceSpec,
    stop: &CancellationToken,
) -> (RunEnd, Duration, Option<u32>) {
    sh.mesh.update(idx, |e| {
        e.phase = Phase::Starting;
        e.pid = None;
        e.heartbeat = None;
        e.stats = None;
    });
    let mut run = match child::spawn(spec, &sh.env) {
        Err(e) => {
            tracing::error!(service = %spec.name, program = %spec.program.display(), error = %e, "cannot start");
            return (RunEnd::Ended(Ending::SpawnFailed), Duration::ZERO, None);
        }
        Ok(run) => run,
    };
    tracing::info!(service = %spec.name, pid = run.pid, program = %spec.program.display(), "started");
    sh.mesh.update(idx, |e| {
        e.pid = Some(run.pid);
        e.started_at = Some(run.started);
        e.spawned_ns = run.spawned_ns;
        if !spec.heartbeat {
            e.phase = Phase::Running;
        }
    });
    let end = run_once(sh, idx, spec, &mut run, stop).await;
    let ran_for = run.started.elapsed();
    sh.mesh.update(idx, |e| {
        e.pid = None;
        e.started_at = None;
        e.stats = None;
        if let RunEnd::Ended(ending) = end {
            if let Some(code) = ending.exit_code() {
                e.last_exit_code = Some(code);
            }
        }
    });
    // The process is reaped: iceoryx2 can now see its node as dead.
    clean_dead_nodes(&sh.domain, &sh.mesh).await;
    (end, ran_for, Some(run.pid))
}

/// A service the policy does not restart (failed, config error, clean exit) waits
/// here for an operator's restart. False when told to stop instead.
async fn wait_for_operator(
    sh: &Shared,
    idx: usize,
    spec: &ServiceSpec,
    stop: &CancellationToken,
) -> bool {
    tokio::select! {
        biased;
        _ = stop.cancelled() => false,
        _ = sh.shutdown.cancelled() => false,
        () = sh.restarts.requested(idx) => {
            tracing::info!(service = %spec.name, "restart asked for by an operator: starting again with a fresh restart budget");
            true
        }
    }
}

/// After a run ended: logs it and applies the restart policy (waiting out the
/// backoff). `Continue` means start again; `Break` means the task is done.
#[allow(clippy::too_many_arguments)]
async fn decide(
    sh: &Shared,
    idx: usize,
    spec: &ServiceSpec,
    tracker: &mut RestartTracker,
    stop: &CancellationToken,
    ending: Ending,
    ran_for: Duration,
    pid: Option<u32>,
) -> ControlFlow<()> {
    let stopped = |phase| {
        sh.mesh.set_phase(idx, phase);
        ControlFlow::Break(())
    };
    log_ending(spec, pid, ending, ran_for);
    if sh.shutdown.is_cancelled() {
        return stopped(Phase::Stopped);
    }
    match tracker.on_exit(Instant::now(), ran_for, ending, fastrand::f64()) {
        Decision::Restart { after } => {
            sh.mesh.set_phase(idx, Phase::Backoff);
            tracing::info!(service = %spec.name, delay_ms = after.as_millis() as u64, "restarting after backoff");
            tokio::select! {
                _ = tokio::time::sleep(after) => {}
                _ = stop.cancelled() => return stopped(Phase::Stopped),
                _ = sh.shutdown.cancelled() => return stopped(Phase::Stopped),
                () = sh.restarts.requested(idx) => {
                    tracing::info!(service = %spec.name, "restart asked for by an operator: starting now");
                }
            }
            sh.mesh.update(idx, |e| e.restarts += 1);
            ControlFlow::Continue(())
        }
        Decision::ConfigError => {
            tracing::error!(service = %spec.name, "exit code 64: bad configuration; not restarting (fix it, then restart the mesh)");
            stopped(Phase::ConfigError)
        }
        Decision::Failed { restarts_in_window } => {
            tracing::error!(
                service = %spec.name,
                restarts_in_window,
                window_s = spec.restart.window.as_secs(),
                "restart budget spent; not restarting"
            );
            stopped(Phase::Failed)
        }
        Decision::Stopped => {
            tracing::info!(service = %spec.name, "exited cleanly; not restarted (restart mode on-failure)");
            stopped(Phase::Stopped)
        }
    }
}
