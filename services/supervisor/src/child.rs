//! Starting, stopping and reaping one child process.
//!
//! Each child leads its own process group: a Ctrl-C in the terminal reaches only the
//! supervisor, which then stops the children in order; and signals sent to the group
//! also reach anything the child forked. `tokio::process` reaps a child as soon as it
//! exits while someone awaits [`Child::wait`] — which matters, because iceoryx2 only
//! recognises a node as dead once its process is reaped.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{killpg, Signal};
use nix::unistd::Pid;
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::realtime;
use tokio::process::{Child, Command};

use crate::config::ServiceSpec;
use crate::policy::Ending;

/// Where a child's stdout and stderr go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Output {
    /// The supervisor's own stdout/stderr (not a terminal: a log collector captures them).
    Inherit,
    /// `<dir>/<name>.log`, appended to.
    Files(PathBuf),
}

impl Output {
    /// The log file of service `name`, if output goes to files.
    pub fn log_file(&self, name: &str) -> Option<PathBuf> {
        match self {
            Output::Inherit => None,
            Output::Files(dir) => Some(dir.join(format!("{name}.log"))),
        }
    }
}

/// What every child of one mesh shares.
#[derive(Debug, Clone)]
pub struct Environment {
    pub domain: String,
    pub ipc_config: Option<PathBuf>,
    pub heartbeat: Duration,
    /// Passed as `SKYMESH_LOG_FORMAT` when the supervisor was told a log format.
    pub log_format: Option<String>,
    /// Set `NO_COLOR=1` (no ANSI colours in logs) unless the service's `env` sets it:
    /// true when the output is a file or not a terminal.
    pub no_color: bool,
    pub output: Output,
}

/// A started child.
#[derive(Debug)]
pub struct Running {
    pub child: Child,
    pub pid: u32,
    pub started: Instant,
    /// `CLOCK_MONOTONIC` ns just before the spawn.
    pub spawned_ns: u64,
}

/// Builds the command for `spec`: its own process group, the mesh environment, and
/// none of systemd's notify/watchdog variables (those belong to the supervisor).
pub fn command(spec: &ServiceSpec, env: &Environment) -> std::io::Result<Command> {
    let mut cmd = Command::new(&spec.program);
    if let Some(c) = &spec.config {
        cmd.arg("--config").arg(c);
    }
    cmd.args(&spec.args)
        .envs(spec.env.iter().map(|(k, v)| (k, v)))
        .env("SKYMESH_SERVICE_NAME", &spec.name)
        .env("SKYMESH_DOMAIN", &env.domain)
        .env(
            "SKYMESH_HEARTBEAT_MS",
            env.heartbeat.as_millis().to_string(),
        )
        // We drain periodic heartbeats on our clock (crate::monitor): they need not
        // wake us.
        .env("SKYMESH_HEARTBEAT_QUIET", "1")
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID")
        .stdin(Stdio::null())
        .process_group(0)
        .kill_on_drop(true);
    if let Some(p) = &env.ipc_config {
        cmd.env("SKYMESH_IPC_CONFIG", p);
    }
    // Only from the service's own key: not inherited from the supervisor's
    // environment (a priority meant for one service must not reach every other).
    match spec.realtime_priority {
        Some(p) => cmd.env(realtime::REALTIME_ENV, p.to_string()),
        None => cmd.env_remove(realtime::REALTIME_ENV),
    };
    match &spec.cpu_affinity {
        Some(cpus) => cmd.env(realtime::AFFINITY_ENV, cpus),
        None => cmd.env_remove(realtime::AFFINITY_ENV),
    };
    if let Some(f) = &env.log_format {
        cmd.env("SKYMESH_LOG_FORMAT", f);
    }
    if env.no_color && !spec.env.iter().any(|(k, _)| k == "NO_COLOR") {
        cmd.env("NO_COLOR", "1");
    }
    if let Some(path) = env.output.log_file(&spec.name) {
        let mut file = open_log(&path)?;
        // A marker between runs, so one file tells the story of every restart.
        let _ = writeln!(
            file,
            "===== skymesh: starting {} ({}) =====",
            spec.name,
            spec.program.display()
        );
        cmd.stderr(file.try_clone()?).stdout(file);
    }
    Ok(cmd)
}

fn open_log(path: &Path) -> std::io::Result<std::fs::File> {
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
}

/// Starts `spec`.
pub fn spawn(spec: &ServiceSpec, env: &Environment) -> std::io::Result<Running> {
    let mut cmd = command(spec, env)?;
    let spawned_ns = monotonic_ns();
    let started = Instant::now();
    let child = cmd.spawn()?;
    let pid = child
        .id()
        .ok_or_else(|| std::io::Error::other("child exited before its pid was read"))?;
    Ok(Running {
        child,
        pid,
        started,
        spawned_ns,
    })
}

/// Sends `sig` to the process group led by `pid`; a group that is already gone is fine.
pub fn signal_group(pid: u32, sig: Signal) {
    let Ok(raw) = i32::try_from(pid) else { return };
    match killpg(Pid::from_raw(raw), sig) {
        Ok(()) | Err(nix::errno::Errno::ESRCH) => {}
        Err(e) => tracing::warn!(pid, signal = %sig, error = %e, "cannot signal process group"),
    }
}

/// How a reaped child ended.
pub fn ending(status: &ExitStatus) -> Ending {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(c), _) => Ending::Code(c),
        (None, Some(s)) => Ending::Signal(s),
        // Neither code nor signal cannot happen for a reaped child; treat as failure.
        (None, None) => Ending::Code(1),
    }
}

/// Kills the whole group at once (hang) and reaps the leader.
pub async fn kill(run: &mut Running) -> std::io::Result<ExitStatus> {
    signal_group(run.pid, Signal::SIGKILL);
    run.child.wait().await
}

/// Stops gracefully: SIGTERM to the group, up to `grace` for the leader to exit, then
/// SIGKILL. Stragglers of the group are killed once the leader is reaped.
pub async fn stop(run: &mut Running, grace: Duration) -> std::io::Result<ExitStatus> {
    signal_group(run.pid, Signal::SIGTERM);
    let status = match tokio::time::timeout(grace, run.child.wait()).await {
        Ok(r) => r?,
        Err(_) => {
            tracing::warn!(
                pid = run.pid,
                grace_ms = grace.as_millis() as u64,
                "did not stop in time; SIGKILL"
            );
            signal_group(run.pid, Signal::SIGKILL);
            run.child.wait().await?
        }
    };
    signal_group(run.pid, Signal::SIGKILL);
    Ok(status)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::RestartPolicy;

    fn sh(name: &str, script: &str) -> ServiceSpec {
        ServiceSpec {
            name: name.to_string(),
            program: PathBuf::from("/bin/sh"),
            config: None,
            args: vec!["-c".into(), script.into()],
            env: vec![("EXTRA".into(), "1".into())],
            after: vec![],
            critical: false,
            heartbeat: false,
            realtime_priority: Some(12),
            cpu_affinity: Some("0,1".into()),
            restart: RestartPolicy::default(),
        }
    }

    fn env(output: Output) -> Environment {
        Environment {
            domain: "childtest".into(),
            ipc_config: Some(PathBuf::from("/x/iceoryx2.toml")),
            heartbeat: Duration::from_millis(250),
            log_format: None,
            no_color: true,
            output,
        }
    }

    #[tokio::test]
    async fn child_gets_the_mesh_environment_its_own_group_and_a_log_file() {
        let dir = tempfile::tempdir().unwrap();
        let script = "echo $SKYMESH_SERVICE_NAME $SKYMESH_DOMAIN $SKYMESH_IPC_CONFIG $SKYMESH_HEARTBEAT_MS $SKYMESH_HEARTBEAT_QUIET $EXTRA ${NOTIFY_SOCKET:-none} $NO_COLOR $SKYMESH_REALTIME_PRIORITY $SKYMESH_CPU_AFFINITY; \
                      [ \"$(cut -d' ' -f5 /proc/$$/stat)\" = \"$$\" ] && echo own-group; exit 3";
        let mut run = spawn(
            &sh("a", script),
            &env(Output::Files(dir.path().to_path_buf())),
        )
        .unwrap();
        let status = run.child.wait().await.unwrap();
        assert_eq!(ending(&status), Ending::Code(3));
        let log = std::fs::read_to_string(dir.path().join("a.log")).unwrap();
        assert!(
            log.contains("a childtest /x/iceoryx2.toml 250 1 1 none 1 12 0,1"),
            "{log}"
        );
        assert!(log.contains("own-group"), "{log}");
    }

    #[tokio::test]
    async fn stop_escalates_to_sigkill_for_children_that_ignore_sigterm() {
        let mut run = spawn(
            &sh("b", "trap '' TERM; sleep 30 & wait; sleep 30"),
            &env(Output::Inherit),
        )
        .unwrap();
        tokio::time::sleep(Duration::from_millis(200)).await;
        let t0 = Instant::now();
        let status = stop(&mut run, Duration::from_millis(300)).await.unwrap();
        assert_eq!(ending(&status), Ending::Signal(9));
        assert!(t0.elapsed() < Duration::from_secs(5));
        assert!(!crate::monitor::process_exists(run.pid));
    }

    #[tokio::test]
    async fn graceful_stop_reports_the_exit() {
        let mut run = spawn(
            &sh("c", "trap 'exit 0' TERM; while :; do sleep 0.05; done"),
            &env(Output::Inherit),
        )
        .unwrap();
        tokio::time::sleep(Duration::from_millis(200)).await;
        let status = stop(&mut run, Duration::from_secs(5)).await.unwrap();
        assert!(
            matches!(ending(&status), Ending::Code(0) | Ending::Signal(15)),
            "{status:?}"
        );
    }
}
