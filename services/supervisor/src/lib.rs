//! The skymesh supervisor (`skymesh up`, `skymesh status`).
//!
//! `skymesh up` starts every service of `deploy/skymesh.toml` in dependency order,
//! watches each one (process exit, heartbeats over the bus), restarts crashed or hung
//! ones with jittered exponential backoff inside a budget, cleans the stale iceoryx2
//! resources a dead process leaves, and exports the mesh's state as Prometheus
//! metrics and a JSON status on one HTTP address. With `--monitor-only` it spawns
//! nothing (systemd runs each service as its own unit) and only watches, cleans and
//! exports.
//!
//! If the supervisor itself dies, the services keep running (each leads its own
//! process group); the next `skymesh up` on the same domain adopts them instead of
//! starting duplicates ([`adopt`]).
//!
//! Layout: [`config`] (TOML → settings), [`policy`] (pure restart decisions),
//! [`child`] (spawn/stop/reap), [`adopt`] (finding and watching survivors), [`monitor`] (heartbeats and stats), [`supervise`]
//! (one task per service), [`state`] (the shared view), [`procfs`], [`metrics`]
//! (the Prometheus collector, `skymesh_build_info`), [`http`], [`health`] (the 0/1/2 and
//! 200/503 verdict of `skymesh status` and `/healthz`), [`table`], [`status_cmd`],
//! [`vehicles`] (the vehicles' topics: gauges and the console's view), [`console`]
//! (the web console at `/`).
#![forbid(unsafe_code)]

pub mod adopt;
pub mod child;
pub mod config;
pub mod console;
pub mod health;
pub mod http;
pub mod metrics;
pub mod monitor;
pub mod policy;
pub mod procfs;
pub mod state;
pub mod status_cmd;
pub mod supervise;
pub mod table;
pub mod vehicles;

use std::io::IsTerminal;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use skymesh_ipc_types::ServiceId;
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{systemd, Bus, Domain, Stats};
use tokio::net::TcpListener;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::child::{Environment, Output};
use crate::config::Settings;
use crate::monitor::LivenessRule;
use crate::state::Mesh;
use crate::supervise::{clean_dead_nodes, Shared};

/// The version this binary was built as (the workspace version).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
/// The commit it was built from (`git rev-parse --short HEAD` at build time), or
/// `unknown` when built without git (see `build.rs`).
pub const GIT: &str = env!("SKYMESH_GIT");

/// Name of the supervisor's own iceoryx2 node.
pub const NODE_NAME: &str = "skymesh-supervisor";

/// Everything `skymesh up` runs with, already loaded and bound (tests build their own).
#[derive(Debug)]
pub struct Up {
    /// Validated config; binaries already located unless `monitor_only`.
    pub settings: Settings,
    /// The mesh's iceoryx2 domain; its name is passed to children as `SKYMESH_DOMAIN`.
    pub domain: Domain,
    /// Where `/metrics` and `/status` are served.
    pub listener: TcpListener,
    /// Spawn nothing; only watch, clean and export.
    pub monitor_only: bool,
    /// Write the bound `ip:port` here (removed again on exit).
    pub status_file: Option<PathBuf>,
    /// Where children's stdout/stderr go.
    pub output: Output,
    /// Redraw the status table on stdout about once a second.
    pub table: bool,
    /// Passed to children as `SKYMESH_LOG_FORMAT` when set.
    pub log_format: Option<String>,
    /// The supervisor's own log file, shown under the table.
    pub supervisor_log: Option<PathBuf>,
}

/// The default directory for children's logs: `/tmp/skymesh-<domain>/logs`.
pub fn default_log_dir(domain: &str) -> PathBuf {
    PathBuf::from(format!("/tmp/skymesh-{domain}/logs"))
}

fn write_status_file(path: &Path, addr: SocketAddr) -> std::io::Result<()> {
    // Written whole under another name, then renamed: a reader never sees half of it.
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, addr.to_string())?;
    std::fs::rename(&tmp, path)
}

/// `--monitor-only`: derives each service's state from its heartbeats and cleans
/// stale resources of dead nodes every `cleanup_interval`.
async fn observe(
    mesh: Arc<Mesh>,
    rule: LivenessRule,
    domain: Domain,
    cleanup_interval: Duration,
    stop: CancellationToken,
) {
    // On the drain clock's grid, half a drain period after each drain.
    let mut timer = monitor::timerfd();
    let mut last_clean: Option<Instant> = None;
    loop {
        let grid = monitor::drain_period(&rule, &mesh);
        let at = monitor::on_grid(monotonic_ns() + 1, grid, grid / 2);
        tokio::select! {
            _ = stop.cancelled() => return,
            () = monitor::sleep_until(&mut timer, monitor::instant_at(at)) => {}
        }
        let now = monotonic_ns();
        for idx in 0..mesh.len() {
            mesh.update(idx, |e| {
                let (phase, pid) =
                    rule.observed(e.heartbeat.as_ref(), now, monitor::process_exists);
                e.phase = phase;
                e.pid = pid;
                if pid.is_none() {
                    e.stats = None;
                }
            });
        }
        if last_clean.is_none_or(|t| t.elapsed() >= cleanup_interval) {
            clean_dead_nodes(&domain, &mesh).await;
            last_clean = Some(Instant::now());
        }
    }
}

/// Periodic work of the main loop: systemd watchdog and readiness, the live table.
struct Housekeeping {
    mesh: Arc<Mesh>,
    watchdog: bool,
    ready_sent: bool,
    table: Option<table::LiveHeader>,
    drawn: bool,
}

impl Housekeeping {
    fn tick(&mut self, starting: bool) {
        // From the main loop, so a wedged supervisor stops pinging and systemd kills it.
        if self.watchdog {
            systemd::notify_watchdog();
        }
        if starting && !self.ready_sent && (self.mesh.monitor_only || self.mesh.ready()) {
            self.ready_sent = true;
            tracing::info!(monitor_only = self.mesh.monitor_only, "mesh ready");
            systemd::notify_ready();
        }
        self.draw();
    }

    fn draw(&mut self) {
        if let Some(h) = &self.table {
            let frame = table::live_frame(
                h,
                &self.mesh.status(),
                &self.mesh.recent_events(),
                self.mesh.started,
                Instant::now(),
            );
            if !self.drawn {
                // Clear once; later frames overwrite in place.
                table::draw("\x1b[2J");
                self.drawn = true;
            }
            table::draw(&frame);
        }
    }
}

/// Runs the mesh until `shutdown` is cancelled, then stops every child in reverse
/// start order (SIGTERM, grace period, SIGKILL), reaps them, and removes the domain's
/// shared-memory files once no node of it is left.
pub async fn run_up(up: Up, shutdown: CancellationToken) -> anyhow::Result<()> {
    let Up {
        settings,
        domain,
        listener,
        monitor_only,
        status_file,
        output,
        table,
        log_format,
        supervisor_log,
    } = up;
    let addr = listener.local_addr().context("reading the bound address")?;
    let services: Vec<(String, bool)> = settings
        .services
        .iter()
        .map(|s| (s.name.clone(), s.critical))
        .collect();
    let mesh = Arc::new(Mesh::new(&services, monitor_only));
    let registry = metrics::registry(mesh.clone()).context("registering the metrics collector")?;
    let vehicles = Arc::new(vehicles::VehicleGauges::new(&settings.vehicles));
    registry
        .register(Box::new(
            vehicles::Collect::new(vehicles.clone()).context("describing the vehicle gauges")?,
        ))
        .context("registering the vehicle gauges")?;
    let restarts = Arc::new(supervise::RestartRequests::new(services.len()));
    let console = Arc::new(console::Console::new(
        mesh.clone(),
        vehicles.clone(),
        (!monitor_only).then(|| restarts.clone()),
        settings.console.clone(),
    ));
    if let Output::Files(dir) = &output {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating log directory {}", dir.display()))?;
    }
    tracing::info!(
        http = %addr,
        domain = %domain.name,
        ipc_config = %domain.origin,
        config = %settings.origin,
        services = services.len(),
        monitor_only,
        version = VERSION,
        git = GIT,
        console_actions = settings.console.actions(),
        console_remote = settings.console.remote,
        "skymesh supervisor listening on http://{addr} (the console at /; /metrics, /status, /healthz)"
    );
    for name in &settings.disabled {
        tracing::info!(service = %name, "disabled in the config; not started");
    }
    // Answer /status and /metrics from the first moment: the steps below touch the
    // domain's files (the dead-node cleanup, our own node) and can take a while on a
    // loaded machine or after a crash that left many nodes behind; a caller of
    // `skymesh status` or a health check sees the services as starting meanwhile, not
    // a silent port. If a step fails, the guard stops the server with us.
    let http_stop = CancellationToken::new();
    let http_stop_guard = http_stop.clone().drop_guard();
    let http_tasks = TaskTracker::new();
    let server = tokio::spawn(http::serve(
        listener,
        http::App::new(mesh.clone(), registry, console.clone()),
        http_stop.clone(),
        http_tasks.clone(),
    ));

    // Leftovers of an earlier run that died without cleaning up.
    clean_dead_nodes(&domain, &mesh).await;
    let bus = Bus::open(&domain, NODE_NAME, ServiceId::Supervisor, 0, Stats::new())
        .context("joining the mesh's iceoryx2 domain")?;
    let watch_stop = CancellationToken::new();
    let watchers = TaskTracker::new();
    let rule = LivenessRule {
        period: settings.heartbeat,
        missed: settings.missed_heartbeats,
        startup_timeout: settings.startup_timeout,
    };
    monitor::spawn_watchers(&bus, &mesh, rule, &watch_stop, &watchers)
        .context("subscribing to service heartbeats")?;
    vehicles
        .attach(&bus)
        .context("subscribing to the vehicles' topics")?;
    console
        .attach(&bus)
        .context("opening the console's command publishers")?;

    if let Some(f) = &status_file {
        write_status_file(f, addr)
            .with_context(|| format!("writing status file {}", f.display()))?;
    }

    let mut supervisors = Vec::new();
    if monitor_only {
        watchers.spawn(observe(
            mesh.clone(),
            rule,
            domain.clone(),
            settings.cleanup_interval,
            watch_stop.clone(),
        ));
    } else {
        let shared = Arc::new(Shared {
            mesh: mesh.clone(),
            domain: domain.clone(),
            env: Environment {
                domain: domain.name.clone(),
                ipc_config: settings.ipc_config.clone(),
                heartbeat: settings.heartbeat,
                log_format,
                no_color: !matches!(output, Output::Inherit) || !std::io::stderr().is_terminal(),
                output: output.clone(),
            },
            rule,
            grace: settings.grace,
            shutdown: shutdown.clone(),
            restarts: restarts.clone(),
        });
        // Services an earlier supervisor of this domain started and left running.
        let specs = settings.services.clone();
        let name = domain.name.clone();
        let found = tokio::task::spawn_blocking(move || adopt::find_running(&name, &specs))
            .await
            .context("scanning /proc for running services")?;
        for (idx, spec) in settings.services.iter().enumerate() {
            let mut instances = found[idx].iter();
            // Oldest first: the one that has been running the longest is kept.
            let adopted = instances.by_ref().find_map(adopt::Adopted::watch);
            let extra: Vec<u32> = instances.map(|i| i.pid).collect();
            if !extra.is_empty() {
                tracing::warn!(service = %spec.name, adopted = adopted.as_ref().map(|a| a.pid), others = ?extra, "more than one running instance of the service; adopting the oldest, leaving the others alone (stop them by hand)");
            }
            let stop = CancellationToken::new();
            let task = tokio::spawn(supervise::supervise(
                shared.clone(),
                idx,
                spec.clone(),
                stop.clone(),
                adopted,
            ));
            supervisors.push((spec.name.clone(), task, stop));
        }
    }

    let watchdog = systemd::watchdog_interval();
    let period = watchdog.map_or(Duration::from_secs(1), |w| {
        (w / 2).min(Duration::from_secs(1))
    });
    let period = period.max(Duration::from_millis(10));
    // On a timerfd, on the drain clock's grid (the same instants with the default
    // 1 s): the housekeeping shares the drain's wake-up.
    let mut timer = monitor::timerfd();
    let next_tick =
        || monitor::instant_at(monitor::on_grid(monotonic_ns() + 1, period, Duration::ZERO));
    let logs = match (&output, &supervisor_log) {
        (Output::Files(dir), Some(own)) => Some(format!(
            "{}/<service>.log, supervisor: {}",
            dir.display(),
            own.display()
        )),
        (Output::Files(dir), None) => Some(format!("{}/<service>.log", dir.display())),
        (Output::Inherit, _) => None,
    };
    let mut house = Housekeeping {
        mesh: mesh.clone(),
        watchdog: watchdog.is_some(),
        ready_sent: false,
        table: table.then(|| table::LiveHeader {
            domain: domain.name.clone(),
            http: format!("http://{addr}"),
            logs,
            monitor_only,
        }),
        drawn: false,
    };
    let mut changes = mesh.subscribe();
    loop {
        tokio::select! {
            _ = shutdown.cancelled() => break,
            () = monitor::sleep_until(&mut timer, next_tick()) => house.tick(true),
            // Readiness as soon as it happens, not up to a second later.
            r = changes.changed(), if !house.ready_sent => if r.is_ok() && mesh.ready() { house.tick(true) },
        }
    }

    tracing::info!("shutting down: stopping services in reverse start order");
    systemd::notify_stopping();
    let stopping = async {
        for (name, task, stop) in supervisors.into_iter().rev() {
            stop.cancel();
            if let Err(e) = task.await {
                tracing::error!(service = %name, error = %e, "supervision task failed");
            }
        }
    };
    let mut stopping = std::pin::pin!(stopping);
    loop {
        tokio::select! {
            _ = &mut stopping => break,
            () = monitor::sleep_until(&mut timer, next_tick()) => house.tick(false),
        }
    }
    house.draw();

    watch_stop.cancel();
    watchers.close();
    watchers.wait().await;
    // Our own node must be gone before asking whether any node of the domain is alive
    // (the vehicle gauges' subscribers hold it too).
    vehicles.detach();
    console.detach();
    drop(bus);
    // An adopted service that stopped is reaped by its parent (init), not by us, and
    // iceoryx2 takes a zombie's node for alive: give init a moment (it may reap only
    // every few seconds), for all of them at once.
    let reap_deadline = Instant::now() + Duration::from_secs(5);
    loop {
        clean_dead_nodes(&domain, &mesh).await;
        let d = domain.clone();
        let zombies = tokio::task::spawn_blocking(move || {
            d.live_nodes()
                .into_iter()
                .filter(|(_, pid)| adopt::is_zombie(*pid))
                .count()
        })
        .await
        .context("zombie check")?;
        if zombies == 0 || Instant::now() >= reap_deadline {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let d = domain.clone();
    let (live, removed) = tokio::task::spawn_blocking(move || {
        let live = d.live_nodes();
        let removed = if live.is_empty() {
            d.remove_leftover_files()
        } else {
            0
        };
        (live, removed)
    })
    .await
    .context("final cleanup task")?;
    if live.is_empty() {
        tracing::info!(removed, domain = %domain.name, "removed the domain's shared-memory files");
    } else {
        tracing::info!(live_nodes = ?live, "other nodes of the domain are alive; leaving its shared memory in place");
    }

    drop(http_stop_guard);
    http_tasks.close();
    let _ = tokio::time::timeout(Duration::from_secs(2), http_tasks.wait()).await;
    if let Err(e) = server.await {
        tracing::warn!(error = %e, "http server task failed");
    }
    if let Some(f) = &status_file {
        let _ = std::fs::remove_file(f);
    }
    tracing::info!("stopped");
    Ok(())
}
