//! `service_main`: the thin `main` every service shares.

use std::future::Future;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Args, CommandFactory, FromArgMatches, Parser};
use skymesh_ipc_types::{topics, ServiceId, ServiceState};
use tokio_util::sync::CancellationToken;

use crate::config::{self, ConfigError, ServiceConfig};
use crate::exit;
use crate::health::{self, HealthState};
use crate::ipc::{self, Bus, Domain};
use crate::logging::{self, LOG_FORMATS};
use crate::stats::Stats;
use crate::{realtime, signals, systemd};

/// Overrides the number of tokio worker threads of a service (1..=16).
pub const WORKERS_ENV: &str = "SKYMESH_TOKIO_WORKERS";
/// One worker by default. Every service's async work is light (the heavy parts —
/// camera rendering, vision analysis, the autopilot link's reads and writes — run
/// in `block_in_place` or on their own threads), and a second worker mostly added
/// wake-ups: a sample or frame handed to the runtime from outside woke one worker
/// and that one often woke the other to look for work. Measured on the control
/// mesh (docs/benchmarks.md): autopilot-link 219 → 146 wake-ups/s.
pub const DEFAULT_WORKERS: usize = 1;

fn workers_from_env() -> Result<usize, ConfigError> {
    match std::env::var(WORKERS_ENV) {
        Ok(v) if !v.trim().is_empty() => v
            .trim()
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=16).contains(n))
            .ok_or_else(|| ConfigError::Env {
                name: WORKERS_ENV,
                message: format!("`{v}` is not a worker count in 1..=16"),
            }),
        _ => Ok(DEFAULT_WORKERS),
    }
}

/// What a service tells the runtime about itself.
#[derive(Debug, Clone, Copy)]
pub struct ServiceSpec {
    pub kind: ServiceId,
    /// One line for `--help`.
    pub about: &'static str,
}

/// Options every service accepts.
#[derive(Debug, Clone, Args)]
pub struct CommonArgs {
    /// Service config file (TOML). Without it the embedded default is used.
    #[arg(long, short = 'c', env = "SKYMESH_CONFIG")]
    pub config: Option<PathBuf>,
    /// Validate the configuration (service and iceoryx2) and exit: 0 if good, 64 if bad.
    #[arg(long)]
    pub check_config: bool,
    /// Print the commented default configuration and exit.
    #[arg(long)]
    pub print_default_config: bool,
    /// Instance name (topics and node name); defaults to the service kind.
    #[arg(long, env = "SKYMESH_SERVICE_NAME")]
    pub name: Option<String>,
    /// Instance number carried in sample headers (e.g. the vehicle-sim index).
    #[arg(long, env = "SKYMESH_INSTANCE", default_value_t = 0)]
    pub instance: u16,
    /// iceoryx2 config file; default `$SKYMESH_IPC_CONFIG`, else the embedded deploy/iceoryx2.toml.
    #[arg(long)]
    pub ipc_config: Option<PathBuf>,
    /// Log format: `auto` is journald when systemd connected stderr to the journal
    /// (`JOURNAL_STREAM`), else text.
    #[arg(long, env = "SKYMESH_LOG_FORMAT", default_value = "auto", value_parser = LOG_FORMATS)]
    pub log_format: String,
}

#[derive(Debug, Parser)]
struct Cli {
    #[command(flatten)]
    common: CommonArgs,
}

/// What a running service gets from the runtime.
#[derive(Debug, Clone)]
pub struct Context {
    /// The service's handle on the mesh.
    pub bus: Bus,
    /// Cancelled on SIGTERM/SIGINT; every task stops taking work when it fires.
    pub shutdown: CancellationToken,
    /// Metrics exported through the supervisor.
    pub stats: Stats,
    /// Instance name.
    pub name: String,
    health: HealthState,
}

impl Context {
    /// A context around an existing bus, for in-process tests and embedding.
    pub fn new(
        bus: Bus,
        shutdown: CancellationToken,
        stats: Stats,
        name: impl Into<String>,
    ) -> Self {
        Context {
            bus,
            shutdown,
            stats,
            name: name.into(),
            health: HealthState::default(),
        }
    }

    /// Marks the service running (heartbeat state) and tells systemd `READY=1`.
    pub fn ready(&self) {
        self.health.set(ServiceState::Running);
        systemd::notify_ready();
        tracing::info!(service = %self.name, "ready");
    }

    /// Reports a degraded or recovered state in the heartbeat.
    pub fn set_state(&self, state: ServiceState) {
        self.health.set(state);
    }
}

fn init_tracing(format: &str) {
    // clap already refused anything but `LOG_FORMATS`.
    logging::init(format.parse().unwrap_or_default(), None);
}

/// Refuses to start (`Err(exit code)`) when `/dev/shm` has less than `need` bytes
/// free, before iceoryx2 maps anything there; warns when it is low.
fn check_shm(need: u64) -> Result<(), u8> {
    let dir = std::path::Path::new(ipc::SHM_DIR);
    match ipc::check_shm_room(dir, need) {
        Ok(Some(space)) if space.free < ipc::SHM_LOW_FREE_BYTES.max(need) => {
            tracing::warn!(
                dir = ipc::SHM_DIR,
                free_bytes = space.free,
                size_bytes = space.size,
                "shared memory is low: size /dev/shm up (a segment that cannot grow ends in SIGBUS)"
            );
            Ok(())
        }
        Ok(_) => Ok(()),
        Err(e) => {
            tracing::error!(error = %e, code = exit::SHM_FULL, "cannot join the mesh: shared memory full");
            Err(exit::SHM_FULL)
        }
    }
}

/// How long a service may take to finish after shutdown was requested.
const GRACE: Duration = Duration::from_secs(5);

/// Parses the CLI, loads and validates config (exit 64 if bad), sets up logs, the
/// bus, heartbeats and signals, runs `run`, and maps the outcome to an exit code.
pub fn service_main<C, F, Fut>(spec: ServiceSpec, run: F) -> ExitCode
where
    C: ServiceConfig,
    F: FnOnce(C::Settings, Context) -> Fut,
    Fut: Future<Output = anyhow::Result<()>> + Send + 'static,
{
    let cmd = Cli::command()
        .name(spec.kind.as_str())
        .about(spec.about)
        .version(env!("CARGO_PKG_VERSION"));
    let matches = cmd.get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(c) => c,
        Err(e) => e.exit(),
    };
    let args = cli.common;
    init_tracing(&args.log_format);

    if args.print_default_config {
        print!("{}", C::DEFAULT_TOML);
        return ExitCode::from(exit::OK);
    }

    let loaded = config::load::<C>(args.config.as_deref()).and_then(|settings| {
        let domain = Domain::from_env(args.ipc_config.as_deref())?;
        let name = args
            .name
            .clone()
            .unwrap_or_else(|| spec.kind.as_str().to_string());
        if !topics::is_valid_instance_name(&name) {
            return Err(ConfigError::invalid(
                "--name",
                format!("`{name}` must be 1-32 characters of [A-Za-z0-9_-]"),
            ));
        }
        let shm_min_free = ipc::shm_min_free_from_env()?;
        let workers = workers_from_env()?;
        let sched = (realtime::cpus_from_env()?, realtime::from_env()?);
        Ok((settings, domain, name, shm_min_free, workers, sched))
    });
    let (settings, domain, name, shm_min_free, workers, (cpus, realtime)) = match loaded {
        Ok(v) => v,
        Err(e) => {
            tracing::error!(error = %e, "bad configuration");
            eprintln!("{}: bad configuration: {e}", spec.kind.as_str());
            return ExitCode::from(exit::CONFIG);
        }
    };
    if args.check_config {
        println!(
            "{}: configuration OK (iceoryx2 config {}, domain {})",
            spec.kind.as_str(),
            domain.origin,
            domain.name
        );
        return ExitCode::from(exit::OK);
    }

    if let Err(code) = check_shm(shm_min_free) {
        return ExitCode::from(code);
    }

    // Before the tokio runtime starts its threads: they inherit affinity and policy.
    realtime::apply_at_start(&cpus, realtime);
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(workers)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            tracing::error!(error = %e, "cannot start tokio runtime");
            return ExitCode::from(exit::FAILURE);
        }
    };
    let code = rt.block_on(async move {
        let stats = Stats::new();
        let bus = match Bus::open(&domain, &name, spec.kind, args.instance, stats.clone()) {
            Ok(b) => b,
            Err(e) => {
                tracing::error!(error = %e, "cannot join the mesh");
                // Filled up meanwhile (e.g. by another service starting)?
                return check_shm(shm_min_free).err().unwrap_or(exit::FAILURE);
            }
        };
        tracing::info!(service = %name, domain = %domain.name, ipc_config = %domain.origin, pid = std::process::id(), "starting");
        let shutdown = CancellationToken::new();
        if let Err(e) = signals::spawn_shutdown_on_signal(shutdown.clone()) {
            tracing::error!(error = %e, "cannot install signal handlers");
            return exit::FAILURE;
        }
        let health = HealthState::default();
        let hb_stop = CancellationToken::new();
        let hb = tokio::spawn(health::run_heartbeat(
            bus.clone(),
            health.clone(),
            health::heartbeat_period_from_env(),
            health::heartbeat_quiet_from_env(),
            hb_stop.clone(),
        ));
        let ctx = Context { bus, shutdown: shutdown.clone(), stats, name: name.clone(), health: health.clone() };
        // The service runs as a task on the runtime's workers, not in `block_on` on
        // the main thread: polled there, every timer or sample that woke it woke two
        // threads (a worker, then the main thread) — measured at idle, half the
        // wake-ups of a quiet service. A panic is re-raised here as before.
        let mut task = tokio::spawn(run(settings, ctx));
        let joined = |r: Result<anyhow::Result<()>, tokio::task::JoinError>| match r {
            Ok(r) => r,
            Err(e) if e.is_panic() => std::panic::resume_unwind(e.into_panic()),
            Err(e) => Err(anyhow::anyhow!("service task ended: {e}")),
        };
        let result = tokio::select! {
            r = &mut task => joined(r),
            _ = shutdown.cancelled() => {
                health.set(ServiceState::Stopping);
                systemd::notify_stopping();
                match tokio::time::timeout(GRACE, &mut task).await {
                    Ok(r) => joined(r),
                    Err(_) => {
                        task.abort();
                        Err(anyhow::anyhow!("did not stop within {GRACE:?} of the shutdown request"))
                    }
                }
            }
        };
        hb_stop.cancel();
        match hb.await {
            Ok(Err(e)) => tracing::warn!(error = %e, "heartbeat publishing failed"),
            Err(e) => tracing::warn!(error = %e, "heartbeat task panicked"),
            Ok(Ok(())) => {}
        }
        match result {
            Ok(()) => {
                tracing::info!(service = %name, "stopped");
                exit::OK
            }
            Err(e) if exit::is_addr_in_use(&e) => {
                tracing::error!(
                    service = %name,
                    error = format!("{e:#}"),
                    code = exit::ADDR_IN_USE,
                    "failed: address already in use (another program holds it; restarted with backoff until it is free)"
                );
                exit::ADDR_IN_USE
            }
            Err(e) => {
                tracing::error!(service = %name, error = format!("{e:#}"), "failed");
                exit::code_for(&e)
            }
        }
    });
    // Drop the runtime (and with it every port and the node) before exiting, so
    // iceoryx2 removes this node's resources instead of leaving them for cleanup.
    rt.shutdown_timeout(Duration::from_secs(1));
    ExitCode::from(code)
}
