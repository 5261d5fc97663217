//! `skymesh.toml`: raw TOML (serde, `deny_unknown_fields`) → validated [`Settings`].
//!
//! Paths in the file are relative to the file's directory. Binaries are resolved in a
//! second step ([`Settings::locate_files`]) because that needs the directory of the
//! running `skymesh` executable and touches the file system.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_ipc_types::topics;
use skymesh_runtime::config::{in_range, socket_addr};
use skymesh_runtime::{realtime, ConfigError};

use crate::console::ConsoleSettings;
use crate::policy::{RestartMode, RestartPolicy};

/// The commented default mesh (`deploy/skymesh.toml`), printed by `print-default-config`.
pub const DEFAULT_TOML: &str = include_str!("../../../../deploy/skymesh.toml");
/// Where `/metrics` and `/status` are served unless configured otherwise.
pub const DEFAULT_METRICS: &str = "127.0.0.1:9464";
/// Where `skymesh up` looks for its config when `--config` is not given, in order.
pub const SEARCH_PATHS: [&str; 2] = ["deploy/skymesh.toml", "/etc/skymesh/skymesh.toml"];

/// Environment variables the supervisor sets for every child; a service's `env` may not override them.
pub const RESERVED_ENV: [&str; 10] = [
    "SKYMESH_SERVICE_NAME",
    "SKYMESH_DOMAIN",
    "SKYMESH_IPC_CONFIG",
    "SKYMESH_HEARTBEAT_MS",
    "SKYMESH_HEARTBEAT_QUIET",
    // From the service's `realtime_priority` and `cpu_affinity` keys.
    realtime::REALTIME_ENV,
    realtime::AFFINITY_ENV,
    "NOTIFY_SOCKET",
    "WATCHDOG_USEC",
    "WATCHDOG_PID",
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    supervisor: RawSupervisor,
    #[serde(default)]
    restart: RawRestart,
    #[serde(default, rename = "service")]
    services: Vec<RawService>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RawSupervisor {
    metrics: String,
    heartbeat_ms: u64,
    missed_heartbeats: u32,
    startup_timeout_ms: u64,
    grace_period_ms: u64,
    cleanup_interval_ms: u64,
    ipc_config: Option<String>,
    log_dir: Option<String>,
    vehicles: Vec<i64>,
    console_token: Option<String>,
    console_token_file: Option<String>,
    console_remote: bool,
}

impl Default for RawSupervisor {
    fn default() -> Self {
        RawSupervisor {
            metrics: DEFAULT_METRICS.to_string(),
            heartbeat_ms: 500,
            missed_heartbeats: 6,
            startup_timeout_ms: 10_000,
            grace_period_ms: 5_000,
            cleanup_interval_ms: 2_000,
            ipc_config: None,
            log_dir: None,
            vehicles: vec![1],
            console_token: None,
            console_token_file: None,
            console_remote: false,
        }
    }
}

/// Restart settings; every key optional so a service can override only some.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRestart {
    mode: Option<String>,
    initial_backoff_ms: Option<u64>,
    max_backoff_ms: Option<u64>,
    jitter: Option<f64>,
    stable_after_s: Option<u64>,
    budget: Option<u32>,
    budget_window_s: Option<u64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawService {
    name: String,
    binary: String,
    config: Option<String>,
    #[serde(default)]
    args: Vec<String>,
    #[serde(default)]
    env: BTreeMap<String, String>,
    #[serde(default)]
    after: Vec<String>,
    #[serde(default)]
    critical: bool,
    #[serde(default = "yes")]
    enabled: bool,
    #[serde(default = "yes")]
    heartbeat: bool,
    /// `SCHED_FIFO` priority of every thread of the service (0: normal scheduling).
    #[serde(default)]
    realtime_priority: u8,
    /// CPUs every thread of the service may run on (empty: no pinning).
    #[serde(default)]
    cpu_affinity: Vec<usize>,
    restart: Option<RawRestart>,
}

fn yes() -> bool {
    true
}

/// The validated mesh configuration.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Where the config came from, for logs.
    pub origin: String,
    /// Directory relative paths were resolved against.
    pub base_dir: PathBuf,
    /// Address of `/metrics` and `/status`.
    pub metrics: SocketAddr,
    /// Heartbeat period asked of every child (`SKYMESH_HEARTBEAT_MS`).
    pub heartbeat: Duration,
    /// Heartbeat periods without a heartbeat before a service counts as hung.
    pub missed_heartbeats: u32,
    /// How long a new process may take to send its first heartbeat.
    pub startup_timeout: Duration,
    /// SIGTERM → SIGKILL delay when stopping a child.
    pub grace: Duration,
    /// How often `--monitor-only` removes stale resources of dead nodes.
    pub cleanup_interval: Duration,
    /// Absolute path of the iceoryx2 config, passed to children as `SKYMESH_IPC_CONFIG`.
    pub ipc_config: Option<PathBuf>,
    /// Where children's output goes (`<log_dir>/<name>.log`), if configured.
    pub log_dir: Option<PathBuf>,
    /// MAVLink system ids of the vehicles whose `skymesh_vehicle_*` gauges
    /// `/metrics` exports (crate::vehicles), ascending.
    pub vehicles: Vec<u8>,
    /// The web console's token (its actions) and reach (crate::console).
    pub console: ConsoleSettings,
    /// Enabled services in start order (every service after the ones it names in `after`).
    pub services: Vec<ServiceSpec>,
    /// Names of services configured with `enabled = false`.
    pub disabled: Vec<String>,
}

/// One service of the mesh.
#[derive(Debug, Clone)]
pub struct ServiceSpec {
    /// Instance name (topics, node name, log file, metrics label).
    pub name: String,
    /// Program to run: a path, or a bare name looked up next to `skymesh`, then in `PATH`.
    pub program: PathBuf,
    /// Absolute path of the service's config, passed as `--config`.
    pub config: Option<PathBuf>,
    pub args: Vec<String>,
    pub env: Vec<(String, String)>,
    /// Enabled services that must be up before this one starts.
    pub after: Vec<String>,
    /// The supervisor is ready (systemd `READY=1`) once every critical service runs.
    pub critical: bool,
    /// False for programs that publish no skymesh heartbeat (e.g. a third-party broker).
    pub heartbeat: bool,
    /// `SCHED_FIFO` priority for every thread of the service, passed as
    /// `SKYMESH_REALTIME_PRIORITY` (the runtime applies it); `None`: normal scheduling.
    pub realtime_priority: Option<u8>,
    /// CPUs for every thread of the service, passed as `SKYMESH_CPU_AFFINITY`
    /// (`1`, `2,3`); `None`: no pinning.
    pub cpu_affinity: Option<String>,
    pub restart: RestartPolicy,
}

fn resolve(base: &Path, p: &str) -> PathBuf {
    let path = Path::new(p);
    if path.is_absolute() {
        path.to_path_buf()
    } else {
        base.join(path)
    }
}

fn ms(v: u64) -> Duration {
    Duration::from_millis(v)
}

impl RawRestart {
    /// `base` with the keys given here replaced.
    fn apply(&self, field: &str, base: RestartPolicy) -> Result<RestartPolicy, ConfigError> {
        let f = |k: &str| format!("{field}.{k}");
        let mut p = base;
        if let Some(m) = &self.mode {
            p.mode = match m.as_str() {
                "on-failure" => RestartMode::OnFailure,
                "always" => RestartMode::Always,
                other => {
                    return Err(ConfigError::invalid(
                        f("mode"),
                        format!("`{other}` is neither \"on-failure\" nor \"always\""),
                    ))
                }
            };
        }
        if let Some(v) = self.initial_backoff_ms {
            p.backoff_initial = ms(in_range(&f("initial_backoff_ms"), v, 1, 60_000)?);
        }
        if let Some(v) = self.max_backoff_ms {
            p.backoff_max = ms(in_range(&f("max_backoff_ms"), v, 1, 3_600_000)?);
        }
        if let Some(v) = self.jitter {
            p.jitter = in_range(&f("jitter"), v, 0.0, 0.9)?;
        }
        if let Some(v) = self.stable_after_s {
            p.stable_after = Duration::from_secs(in_range(&f("stable_after_s"), v, 0, 86_400)?);
        }
        if let Some(v) = self.budget {
            p.max_restarts = in_range(&f("budget"), v, 0, 100_000)?;
        }
        if let Some(v) = self.budget_window_s {
            p.window = Duration::from_secs(in_range(&f("budget_window_s"), v, 1, 86_400)?);
        }
        if p.backoff_max < p.backoff_initial {
            return Err(ConfigError::invalid(
                f("max_backoff_ms"),
                format!(
                    "{} ms is below initial_backoff_ms ({} ms)",
                    p.backoff_max.as_millis(),
                    p.backoff_initial.as_millis()
                ),
            ));
        }
        Ok(p)
    }
}

impl Settings {
    /// Parses and validates `text`; relative paths resolve against `base_dir`.
    pub fn parse(text: &str, origin: &str, base_dir: &Path) -> Result<Settings, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        raw.validate(origin, base_dir)
    }

    /// Reads and validates the file at `path`.
    pub fn load(path: &Path) -> Result<Settings, ConfigError> {
        let text = skymesh_runtime::config::read_config_text(path)?;
        let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
        let base = abs.parent().unwrap_or(Path::new("/")).to_path_buf();
        Settings::parse(&text, &path.display().to_string(), &base)
    }

    /// Finds the binaries (next to `exe_dir`, else in `PATH`) and checks that every
    /// named file exists, so a typo fails now with exit 64 instead of at spawn time.
    pub fn locate_files(mut self, exe_dir: &Path) -> Result<Settings, ConfigError> {
        let path_var = std::env::var_os("PATH").unwrap_or_default();
        for (i, s) in self.services.iter_mut().enumerate() {
            let field = |k: &str| format!("service[{i}] ({}).{k}", s.name);
            if s.program.components().count() == 1 && !s.program.is_absolute() {
                let beside = exe_dir.join(&s.program);
                let found = if is_executable(&beside) {
                    Some(beside)
                } else {
                    std::env::split_paths(&path_var)
                        .map(|d| d.join(&s.program))
                        .find(|p| is_executable(p))
                };
                s.program = found.ok_or_else(|| {
                    ConfigError::invalid(
                        field("binary"),
                        format!(
                            "`{}` is neither in {} nor in PATH (build it with `cargo build --workspace`)",
                            s.program.display(),
                            exe_dir.display()
                        ),
                    )
                })?;
            } else if !is_executable(&s.program) {
                return Err(ConfigError::invalid(
                    field("binary"),
                    format!("{} is not an executable file", s.program.display()),
                ));
            }
            if let Some(c) = &s.config {
                if !c.is_file() {
                    return Err(ConfigError::invalid(
                        field("config"),
                        format!("{} does not exist", c.display()),
                    ));
                }
            }
        }
        Ok(self)
    }

    /// Reads `supervisor.console_token_file`, if set (a separate step: `skymesh
    /// status` loads the config too and needs no secret it may not be allowed to read).
    pub fn read_console_token(mut self) -> Result<Settings, ConfigError> {
        self.console.read_token_file()?;
        Ok(self)
    }

    pub fn service(&self, name: &str) -> Option<&ServiceSpec> {
        self.services.iter().find(|s| s.name == name)
    }
}

fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p)
        .map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
        .unwrap_or(false)
}

impl RawConfig {
    fn validate(self, origin: &str, base: &Path) -> Result<Settings, ConfigError> {
        let s = self.supervisor;
        let metrics = socket_addr("supervisor.metrics", &s.metrics)?;
        let heartbeat = ms(in_range(
            "supervisor.heartbeat_ms",
            s.heartbeat_ms,
            10,
            60_000,
        )?);
        let missed_heartbeats =
            in_range("supervisor.missed_heartbeats", s.missed_heartbeats, 2, 100)?;
        let startup_timeout = ms(in_range(
            "supervisor.startup_timeout_ms",
            s.startup_timeout_ms,
            100,
            600_000,
        )?);
        let grace = ms(in_range(
            "supervisor.grace_period_ms",
            s.grace_period_ms,
            0,
            300_000,
        )?);
        let cleanup_interval = ms(in_range(
            "supervisor.cleanup_interval_ms",
            s.cleanup_interval_ms,
            100,
            600_000,
        )?);
        let ipc_config = s.ipc_config.as_deref().map(|p| resolve(base, p));
        let log_dir = s.log_dir.as_deref().map(|p| resolve(base, p));
        let vehicles = vehicle_ids(&s.vehicles)?;
        let console = ConsoleSettings::from_raw(
            s.console_token.as_deref(),
            s.console_token_file.as_deref(),
            s.console_remote,
            base,
        )?;
        let default_policy = self.restart.apply("restart", RestartPolicy::default())?;

        let all_names: Vec<&str> = self.services.iter().map(|s| s.name.as_str()).collect();
        let disabled: Vec<String> = self
            .services
            .iter()
            .filter(|s| !s.enabled)
            .map(|s| s.name.clone())
            .collect();
        let mut services = Vec::new();
        for (i, raw) in self.services.iter().enumerate() {
            let field = |k: &str| format!("service[{i}].{k}");
            if !topics::is_valid_instance_name(&raw.name) {
                return Err(ConfigError::invalid(
                    field("name"),
                    format!("`{}` must be 1-32 characters of [A-Za-z0-9_-]", raw.name),
                ));
            }
            if all_names.iter().filter(|n| **n == raw.name).count() > 1 {
                return Err(ConfigError::invalid(
                    field("name"),
                    format!("`{}` is used by more than one service", raw.name),
                ));
            }
            if raw.binary.is_empty() {
                return Err(ConfigError::invalid(field("binary"), "must not be empty"));
            }
            for dep in &raw.after {
                if !all_names.contains(&dep.as_str()) {
                    return Err(ConfigError::invalid(
                        field("after"),
                        format!("`{}` names no service of this file", dep),
                    ));
                }
                if *dep == raw.name {
                    return Err(ConfigError::invalid(
                        field("after"),
                        format!("`{dep}` cannot start after itself"),
                    ));
                }
            }
            for key in raw.env.keys() {
                if RESERVED_ENV.contains(&key.as_str()) {
                    return Err(ConfigError::invalid(
                        field("env"),
                        format!("`{key}` is set by the supervisor and cannot be overridden"),
                    ));
                }
                if key.is_empty() || key.contains('=') || key.contains('\0') {
                    return Err(ConfigError::invalid(
                        field("env"),
                        format!("`{key}` is not a valid variable name"),
                    ));
                }
            }
            let realtime_priority = realtime::RealtimePriority::new(raw.realtime_priority)
                .map_err(|m| ConfigError::invalid(field("realtime_priority"), m))?
                .map(realtime::RealtimePriority::get);
            let cpu_affinity = realtime::cpu_list(&raw.cpu_affinity)
                .map_err(|m| ConfigError::invalid(field("cpu_affinity"), m))?;
            let restart = match &raw.restart {
                Some(r) => r.apply(&format!("service[{i}].restart"), default_policy)?,
                None => default_policy,
            };
            if !raw.enabled {
                continue;
            }
            let program = if raw.binary.contains('/') {
                resolve(base, &raw.binary)
            } else {
                PathBuf::from(&raw.binary)
            };
            services.push(ServiceSpec {
                name: raw.name.clone(),
                program,
                config: raw.config.as_deref().map(|c| resolve(base, c)),
                args: raw.args.clone(),
                env: raw
                    .env
                    .iter()
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect(),
                after: raw
                    .after
                    .iter()
                    .filter(|d| !disabled.contains(d))
                    .cloned()
                    .collect(),
                critical: raw.critical,
                heartbeat: raw.heartbeat,
                realtime_priority,
                cpu_affinity: (!cpu_affinity.is_empty()).then_some(cpu_affinity),
                restart,
            });
        }
        // Cycles are checked over every service, enabled or not, so enabling one later
        // cannot suddenly make the file invalid.
        let graph: Vec<(&str, Vec<&str>)> = self
            .services
            .iter()
            .map(|s| {
                (
                    s.name.as_str(),
                    s.after.iter().map(String::as_str).collect(),
                )
            })
            .collect();
        let order = start_order(&graph)?;
        let rank: HashMap<&str, usize> = order
            .iter()
            .enumerate()
            .map(|(r, i)| (graph[*i].0, r))
            .collect();
        services.sort_by_key(|s| rank.get(s.name.as_str()).copied().unwrap_or(usize::MAX));

        Ok(Settings {
            origin: origin.to_string(),
            base_dir: base.to_path_buf(),
            metrics,
            heartbeat,
            missed_heartbeats,
            startup_timeout,
            grace,
            cleanup_interval,
            ipc_config,
            log_dir,
            vehicles,
            console,
            services,
            disabled,
        })
    }
}

/// `supervisor.vehicles`: MAVLink system ids 1..=255, each once; sorted.
fn vehicle_ids(raw: &[i64]) -> Result<Vec<u8>, ConfigError> {
    const KEY: &str = "supervisor.vehicles";
    let mut ids = Vec::with_capacity(raw.len());
    for &v in raw {
        let id = u8::try_from(v).ok().filter(|id| *id >= 1).ok_or_else(|| {
            ConfigError::invalid(KEY, format!("{v} is not a MAVLink system id (1..=255)"))
        })?;
        if ids.contains(&id) {
            return Err(ConfigError::invalid(KEY, format!("{id} is listed twice")));
        }
        ids.push(id);
    }
    ids.sort_unstable();
    Ok(ids)
}

/// Topological order of `(name, after)` nodes (indices into `graph`); ties keep file
/// order. A cycle is a config error naming the services on it.
pub fn start_order(graph: &[(&str, Vec<&str>)]) -> Result<Vec<usize>, ConfigError> {
    let index: HashMap<&str, usize> = graph
        .iter()
        .enumerate()
        .map(|(i, (n, _))| (*n, i))
        .collect();
    let mut pending: Vec<usize> = graph.iter().map(|(_, deps)| deps.len()).collect();
    let mut dependents: Vec<Vec<usize>> = vec![Vec::new(); graph.len()];
    for (i, (_, deps)) in graph.iter().enumerate() {
        for d in deps {
            let j = *index.get(d).ok_or_else(|| {
                ConfigError::invalid("service.after", format!("`{d}` names no service"))
            })?;
            dependents[j].push(i);
        }
    }
    let mut done = vec![false; graph.len()];
    let mut order = Vec::with_capacity(graph.len());
    while order.len() < graph.len() {
        // The first (in file order) service whose dependencies have all started.
        let Some(next) = (0..graph.len()).find(|&i| !done[i] && pending[i] == 0) else {
            let cycle: Vec<&str> = (0..graph.len())
                .filter(|&i| !done[i])
                .map(|i| graph[i].0)
                .collect();
            return Err(ConfigError::invalid(
                "service.after",
                format!("dependency cycle among {}", cycle.join(", ")),
            ));
        };
        done[next] = true;
        order.push(next);
        for &d in &dependents[next] {
            pending[d] -= 1;
        }
    }
    Ok(order)
}

/// The config `skymesh up` uses: `explicit`, else the first of [`SEARCH_PATHS`] that exists.
pub fn find_config(explicit: Option<&Path>) -> Result<PathBuf, ConfigError> {
    if let Some(p) = explicit {
        return Ok(p.to_path_buf());
    }
    SEARCH_PATHS
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
        .ok_or_else(|| {
            ConfigError::invalid(
                "--config",
                format!(
                    "no config given and none found at {} (print one with `skymesh print-default-config`)",
                    SEARCH_PATHS.join(" or ")
                ),
            )
        })
}

#[cfg(test)]
mod tests;
