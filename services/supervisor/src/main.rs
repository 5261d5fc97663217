//! `skymesh`: the thin CLI around the supervisor library. Parses arguments, loads and
//! validates the config (exit 64 when bad), sets up logs, binds the HTTP address,
//! runs, and maps the outcome to an exit code.

use std::io::IsTerminal;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use skymesh_runtime::logging::{self, LogFormat, LOG_FORMATS};
use skymesh_runtime::{exit, signals, ConfigError, Domain};
use skymesh_supervisor::child::Output;
use skymesh_supervisor::config::{self, Settings};
use skymesh_supervisor::{default_log_dir, run_up, status_cmd, Up};
use tokio_util::sync::CancellationToken;

#[derive(Debug, Parser)]
#[command(
    name = "skymesh",
    version = concat!(env!("CARGO_PKG_VERSION"), " (git ", env!("SKYMESH_GIT"), ")"),
    about = "Starts, watches and restarts the skymesh services; exports Prometheus metrics",
    arg_required_else_help = true
)]
struct Cli {
    /// Log format (default: $SKYMESH_LOG_FORMAT, else auto: journald when systemd connected stderr to the journal, else text). Given explicitly, it is passed on to the services.
    #[arg(long, global = true, value_parser = LOG_FORMATS)]
    log_format: Option<String>,
    /// Print the commented default deploy/skymesh.toml and exit.
    #[arg(long)]
    print_default_config: bool,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Start every service of the config in dependency order and supervise them (Ctrl-C or SIGTERM stops the mesh).
    Up(UpArgs),
    /// Show the state of the running mesh (asks the supervisor's /status endpoint); exits 0 all running, 1 degraded/restarting, 2 a critical service down or no supervisor.
    Status(StatusArgs),
    /// Print the commented default deploy/skymesh.toml.
    PrintDefaultConfig,
    /// Record bus topics to an MCAP file (JSON samples, JSON schemas; Foxglove opens it) until SIGINT or SIGTERM.
    Record(RecordArgs),
    /// Publish an MCAP recording of `skymesh record` onto the mesh at its recorded pace.
    Replay(ReplayArgs),
}

#[derive(Debug, Args)]
struct RecordArgs {
    /// The MCAP file to write (replaced if it exists).
    #[arg(long, short = 'o')]
    output: PathBuf,
    /// Topic names or globs (`*` within a `/` segment, `**` across, `?` one character), e.g. `skymesh/vehicle/*/state`; globs pick up matching topics that appear later.
    #[arg(required = true)]
    topics: Vec<String>,
}

#[derive(Debug, Args)]
struct ReplayArgs {
    /// An MCAP file written by `skymesh record`.
    input: PathBuf,
    /// Speed-up: 2 replays twice as fast as recorded.
    #[arg(long, default_value_t = 1.0)]
    rate: f64,
}

#[derive(Debug, Args)]
struct UpArgs {
    /// Mesh config; default deploy/skymesh.toml in the current directory, else /etc/skymesh/skymesh.toml.
    #[arg(long, short = 'c')]
    config: Option<PathBuf>,
    /// Address for /metrics and /status (overrides supervisor.metrics; port 0 picks a free port).
    #[arg(long)]
    metrics: Option<SocketAddr>,
    /// Spawn nothing: watch services that systemd runs as their own units, clean, export.
    #[arg(long)]
    monitor_only: bool,
    /// Validate the config (and find every binary and file it names), then exit: 0 good, 64 bad.
    #[arg(long)]
    check_config: bool,
    /// Write the bound HTTP address (`ip:port`) to this file once listening.
    #[arg(long)]
    status_file: Option<PathBuf>,
    /// No live table even on a terminal: log lines, children write to the terminal.
    #[arg(long)]
    no_table: bool,
}

#[derive(Debug, Args)]
struct StatusArgs {
    /// Print the JSON array instead of a table.
    #[arg(long)]
    json: bool,
    /// Supervisor address; default from the config, else 127.0.0.1:9464.
    #[arg(long)]
    metrics: Option<SocketAddr>,
    /// Config to read the address from (default: the one `skymesh up` would use).
    #[arg(long, short = 'c')]
    config: Option<PathBuf>,
}

fn init_tracing(format: &str, file: Option<std::fs::File>) {
    // clap and `main` let only `LOG_FORMATS` through.
    logging::init(format.parse().unwrap_or_default(), file);
}

fn config_error(e: &ConfigError) -> ExitCode {
    tracing::error!(error = %e, "bad configuration");
    eprintln!("skymesh: bad configuration: {e}");
    ExitCode::from(exit::CONFIG)
}

fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("skymesh")
        .enable_all()
        .build()
}

/// Loads the config `up` would use, applying `--metrics`.
fn load(explicit: Option<&Path>, metrics: Option<SocketAddr>) -> Result<Settings, ConfigError> {
    let path = config::find_config(explicit)?;
    let mut settings = Settings::load(&path)?;
    if let Some(m) = metrics {
        settings.metrics = m;
    }
    Ok(settings)
}

fn up(args: UpArgs, log_format: &str, explicit_log_format: Option<String>) -> ExitCode {
    let prepared = load(args.config.as_deref(), args.metrics).and_then(|settings| {
        let settings = if args.monitor_only {
            settings
        } else {
            let exe = std::env::current_exe().map_err(|e| {
                ConfigError::invalid("binary", format!("cannot find the skymesh executable: {e}"))
            })?;
            let exe_dir = exe.parent().unwrap_or(Path::new("/")).to_path_buf();
            settings.locate_files(&exe_dir)?
        };
        let settings = settings.read_console_token()?;
        let domain = Domain::from_env(settings.ipc_config.as_deref())?;
        Ok((settings, domain))
    });
    let (settings, domain) = match prepared {
        Ok(v) => v,
        Err(e) => {
            init_tracing(log_format, None);
            return config_error(&e);
        }
    };
    if args.check_config {
        println!(
            "skymesh: configuration OK: {} ({} services, domain {}, iceoryx2 config {})",
            settings.origin,
            settings.services.len(),
            domain.name,
            domain.origin
        );
        return ExitCode::from(exit::OK);
    }

    let table = !args.no_table && std::io::stdout().is_terminal();
    let log_dir = settings
        .log_dir
        .clone()
        .unwrap_or_else(|| default_log_dir(&domain.name));
    let output = if table || settings.log_dir.is_some() {
        Output::Files(log_dir.clone())
    } else {
        Output::Inherit
    };
    // With the live table on the terminal, the supervisor's own logs go to a file.
    let mut supervisor_log = None;
    let log_file = if table {
        let path = log_dir.join("skymesh.log");
        let opened = std::fs::create_dir_all(&log_dir).and_then(|()| {
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
        });
        match opened {
            Ok(f) => {
                supervisor_log = Some(path);
                Some(f)
            }
            Err(e) => {
                eprintln!("skymesh: cannot open {}: {e}", path.display());
                return ExitCode::from(exit::FAILURE);
            }
        }
    } else {
        None
    };
    init_tracing(log_format, log_file);

    let rt = match runtime() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("skymesh: cannot start the async runtime: {e}");
            return ExitCode::from(exit::FAILURE);
        }
    };
    let result = rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(settings.metrics)
            .await
            .map_err(|e| {
                anyhow::Error::new(e).context(format!(
                    "cannot listen on {} for /metrics and /status",
                    settings.metrics
                ))
            })?;
        let shutdown = CancellationToken::new();
        signals::spawn_shutdown_on_signal(shutdown.clone())?;
        let up = Up {
            settings,
            domain,
            listener,
            monitor_only: args.monitor_only,
            status_file: args.status_file,
            output,
            table,
            log_format: explicit_log_format,
            supervisor_log,
        };
        run_up(up, shutdown).await
    });
    rt.shutdown_timeout(std::time::Duration::from_secs(1));
    match result {
        Ok(()) => ExitCode::from(exit::OK),
        Err(e) => {
            tracing::error!(error = format!("{e:#}"), "supervisor failed");
            eprintln!("skymesh: {e:#}");
            ExitCode::from(exit::code_for(&e))
        }
    }
}

fn status(args: StatusArgs) -> ExitCode {
    let addr = match (args.metrics, &args.config) {
        (Some(a), _) => a,
        (None, Some(path)) => match Settings::load(path) {
            Ok(s) => s.metrics,
            Err(e) => return config_error(&e),
        },
        // Whatever `up` would read, if it is there and valid; else the default.
        (None, None) => config::find_config(None)
            .and_then(|p| Settings::load(&p))
            .map(|s| s.metrics)
            .unwrap_or_else(|_| {
                config::DEFAULT_METRICS
                    .parse()
                    .unwrap_or(SocketAddr::from(([127, 0, 0, 1], 9464)))
            }),
    };
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("skymesh: cannot start the async runtime: {e}");
            return ExitCode::from(exit::FAILURE);
        }
    };
    // 0 every service runs, 1 degraded/restarting, 2 a critical one down or no answer.
    let outcome = rt.block_on(status_cmd::run(addr, args.json));
    if let Err(e) = &outcome {
        eprintln!("skymesh status: {e:#}");
    }
    ExitCode::from(status_cmd::exit_code(&outcome))
}

/// Runs a bus tool (record, replay) in the mesh's domain until it ends or SIGINT/SIGTERM.
fn bus_tool<T>(
    what: &str,
    run: impl AsyncFnOnce(Domain, CancellationToken) -> anyhow::Result<T>,
) -> Result<T, ExitCode> {
    let domain = match Domain::from_env(None) {
        Ok(d) => d,
        Err(e) => return Err(config_error(&e)),
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| {
            eprintln!("skymesh: cannot start the async runtime: {e}");
            ExitCode::from(exit::FAILURE)
        })?;
    rt.block_on(async move {
        let stop = CancellationToken::new();
        signals::spawn_shutdown_on_signal(stop.clone())?;
        run(domain, stop).await
    })
    .map_err(|e| {
        eprintln!("skymesh {what}: {e:#}");
        ExitCode::from(exit::FAILURE)
    })
}

fn record(args: RecordArgs) -> ExitCode {
    let req = skymesh_record::RecordRequest {
        output: args.output,
        patterns: args.topics,
    };
    match bus_tool("record", async |domain, stop| {
        skymesh_record::record(&domain, &req, stop).await
    }) {
        Ok(s) => {
            eprintln!(
                "skymesh record: wrote {} messages of {} topics, {} bytes, to {}",
                s.messages,
                s.topics.len(),
                s.bytes,
                req.output.display()
            );
            ExitCode::from(exit::OK)
        }
        Err(code) => code,
    }
}

fn replay(args: ReplayArgs) -> ExitCode {
    let req = skymesh_record::replay::ReplayRequest {
        input: args.input,
        rate: args.rate,
    };
    match bus_tool("replay", async |domain, stop| {
        skymesh_record::replay::replay(&domain, &req, stop).await
    }) {
        Ok(s) => {
            eprintln!(
                "skymesh replay: published {} messages of {} topics ({} skipped: not decodable)",
                s.messages, s.channels, s.skipped
            );
            ExitCode::from(exit::OK)
        }
        Err(code) => code,
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let log_format = cli
        .log_format
        .clone()
        .or_else(|| {
            std::env::var("SKYMESH_LOG_FORMAT")
                .ok()
                .filter(|f| LOG_FORMATS.contains(&f.as_str()))
        })
        .unwrap_or_else(|| LogFormat::Auto.to_string());
    if cli.print_default_config {
        print!("{}", config::DEFAULT_TOML);
        return ExitCode::from(exit::OK);
    }
    match cli.command {
        Some(Command::PrintDefaultConfig) => {
            print!("{}", config::DEFAULT_TOML);
            ExitCode::from(exit::OK)
        }
        Some(Command::Up(args)) => up(args, &log_format, cli.log_format),
        Some(Command::Status(args)) => {
            init_tracing(&log_format, None);
            status(args)
        }
        Some(Command::Record(args)) => {
            init_tracing(&log_format, None);
            record(args)
        }
        Some(Command::Replay(args)) => {
            init_tracing(&log_format, None);
            replay(args)
        }
        // `arg_required_else_help` prints the help when nothing is given.
        None => {
            eprintln!(
                "skymesh: a command is needed (up, status, record, replay, print-default-config); see --help"
            );
            ExitCode::from(2)
        }
    }
}
