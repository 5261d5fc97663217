//! The scaffolding of the services' command-line tests, in one place.
//!
//! Each service's `tests/cli.rs` keeps its own cases (which configs, which keys);
//! this crate runs them: every spawn gets its own iceoryx2 domain and a clean
//! environment (`SKYMESH_DOMAIN` set, `SKYMESH_IPC_CONFIG` and `SKYMESH_CONFIG`
//! removed), output is captured, every wait is bounded by a patience (never a timing
//! claim), and the domain's leftover iceoryx2 files are removed once the process
//! has exited.
//!
//! ```no_run
//! use skymesh_test_support::{shipped_config, Ready, ServiceCli};
//!
//! # async fn example() {
//! let cli = ServiceCli::new("target/debug/my-service", "mycli");
//! // exit 0 on the shipped config
//! cli.expect_config_ok(&shipped_config("my-service.toml")).await;
//! // exit 64 and the key named on stderr
//! cli.expect_config_errors(&[("max_clients = 0\n", "max_clients")]).await;
//! // still running after a while, then SIGTERM → exit 0
//! cli.sigterm_exits_cleanly(
//!     "listen = \"127.0.0.1:0\"\n",
//!     Ready::StillRunningAfter(std::time::Duration::from_secs(1), "without peers"),
//! )
//! .await;
//! # }
//! ```
#![forbid(unsafe_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use skymesh_runtime::ipc::{DOMAIN_ENV, IPC_CONFIG_ENV};
use skymesh_runtime::Domain;
use tokio::io::AsyncReadExt;
use tokio::process::{Child, Command};

/// How long a test waits for something that should happen (never a timing claim).
pub const PATIENCE: Duration = Duration::from_secs(20);

/// The environment variable a service reads its config path from; removed so a
/// developer's shell cannot change what a test runs.
const CONFIG_ENV: &str = "SKYMESH_CONFIG";

/// A domain name no other test (in this process or another) uses:
/// `{prefix}{pid}x{n}`. Keep `prefix` short: a domain is at most 24 characters.
pub fn unique_domain(prefix: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "{prefix}{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// A temporary file holding `text` (deleted when dropped).
pub fn config_file(text: &str) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().expect("temp file");
    f.write_all(text.as_bytes()).expect("write config");
    f
}

/// Exit status, stdout and stderr of a finished process, for assertion messages.
pub fn text(out: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// The workspace's root directory.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A config shipped in the workspace's `deploy/` directory, e.g.
/// `shipped_config("dji-gateway.toml")`.
pub fn shipped_config(name: &str) -> PathBuf {
    workspace_root().join("deploy").join(name)
}

/// Removes what iceoryx2 left behind in `domain` (a no-op for an invalid name).
pub fn remove_domain_leftovers(domain: &str) {
    if let Ok(d) = Domain::load(domain, None) {
        d.remove_leftover_files();
    }
}

/// When a freshly spawned service counts as started, for
/// [`ServiceCli::sigterm_exits_cleanly`] and [`Running::wait_ready`].
#[derive(Debug, Clone, Copy)]
pub enum Ready<'a> {
    /// It has no readiness signal: it must still be running after this long.
    /// The text says what it runs without (for the assertion message). A fixed wait
    /// can end before a loaded machine has let the process install its signal
    /// handlers, which makes a test flaky: prefer [`Ready::StderrContains`] with a
    /// line the process logs once it serves.
    StillRunningAfter(Duration, &'a str),
    /// Its stderr contains this text (read within the patience).
    StderrContains(&'a str),
}

/// One service binary under test: spawns it with `--config`, its own domain and a
/// clean environment.
#[derive(Debug, Clone)]
pub struct ServiceCli {
    binary: PathBuf,
    /// The script `binary` interprets, passed before every other argument.
    script: Option<PathBuf>,
    domain_prefix: String,
    patience: Duration,
}

impl ServiceCli {
    /// `binary` is the executable (`env!("CARGO_BIN_EXE_…")`); `domain_prefix`
    /// starts the name of every domain this harness makes (short, `[A-Za-z0-9]`).
    pub fn new(binary: impl Into<PathBuf>, domain_prefix: &str) -> Self {
        ServiceCli {
            binary: binary.into(),
            script: None,
            domain_prefix: domain_prefix.to_string(),
            patience: PATIENCE,
        }
    }

    /// A script run by `interpreter` (`/bin/sh`), which is what is executed; the
    /// script is only read. A script this process has just written must not be
    /// executed itself: a child another thread forks meanwhile holds the write
    /// descriptor until its own exec, and the kernel refuses to execute a file open
    /// for writing (`ETXTBSY`, "Text file busy": a CI run failed on it).
    pub fn script(
        interpreter: impl Into<PathBuf>,
        script: impl Into<PathBuf>,
        domain_prefix: &str,
    ) -> Self {
        ServiceCli {
            script: Some(script.into()),
            ..ServiceCli::new(interpreter, domain_prefix)
        }
    }

    /// Waits at most `patience` for each thing (default [`PATIENCE`]).
    pub fn with_patience(mut self, patience: Duration) -> Self {
        self.patience = patience;
        self
    }

    /// How long this harness waits for each thing.
    pub fn patience(&self) -> Duration {
        self.patience
    }

    /// The binary's file name, for messages.
    fn name(&self) -> String {
        let path = self.script.as_ref().unwrap_or(&self.binary);
        path.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string())
    }

    /// Starts the binary with `--config config` and `extra` in a new domain.
    pub fn spawn(&self, config: &Path, extra: &[&str]) -> Running {
        let domain = unique_domain(&self.domain_prefix);
        let child = Command::new(&self.binary)
            .args(&self.script)
            .arg("--config")
            .arg(config)
            .args(extra)
            .env(DOMAIN_ENV, &domain)
            .env_remove(IPC_CONFIG_ENV)
            .env_remove(CONFIG_ENV)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .unwrap_or_else(|e| panic!("spawn {}: {e}", self.binary.display()));
        Running {
            child,
            domain,
            name: self.name(),
            patience: self.patience,
            config: None,
            stderr_seen: Vec::new(),
        }
    }

    /// [`spawn`](Self::spawn) with `toml` written to a temporary config file that
    /// lives as long as the returned process handle.
    pub fn spawn_toml(&self, toml: &str, extra: &[&str]) -> Running {
        let file = config_file(toml);
        let mut running = self.spawn(file.path(), extra);
        running.config = Some(file);
        running
    }

    /// Runs the binary on the config at `config` until it exits (within patience).
    pub async fn run(&self, config: &Path, extra: &[&str]) -> Output {
        self.spawn(config, extra).finish().await
    }

    /// Runs the binary on the config text `toml` until it exits (within patience).
    pub async fn run_toml(&self, toml: &str, extra: &[&str]) -> Output {
        self.spawn_toml(toml, extra).finish().await
    }

    /// `--check-config` on the config at `config` exits 0.
    pub async fn expect_config_ok(&self, config: &Path) {
        let out = self.run(config, &["--check-config"]).await;
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    }

    /// `--check-config` on `toml` exits 64 and names `key` on stderr.
    pub async fn expect_config_error(&self, toml: &str, key: &str) {
        let out = self.run_toml(toml, &["--check-config"]).await;
        assert_eq!(out.status.code(), Some(64), "{toml:?}\n{}", text(&out));
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(key),
            "{toml:?} should name {key}\n{}",
            text(&out)
        );
    }

    /// [`expect_config_error`](Self::expect_config_error) for each `(toml, key)`.
    pub async fn expect_config_errors(&self, cases: &[(&str, &str)]) {
        for (toml, key) in cases {
            self.expect_config_error(toml, key).await;
        }
    }

    /// Starts the binary on `toml`, waits until it is `ready`, sends SIGTERM and
    /// asserts it exits 0 within patience. Returns its output.
    pub async fn sigterm_exits_cleanly(&self, toml: &str, ready: Ready<'_>) -> Output {
        let mut running = self.spawn_toml(toml, &[]);
        running.wait_ready(ready).await;
        running.sigterm();
        let out = running.finish().await;
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        out
    }
}

/// A spawned service (killed if dropped before [`finish`](Self::finish)).
#[derive(Debug)]
pub struct Running {
    child: Child,
    domain: String,
    name: String,
    patience: Duration,
    /// The temporary config file, kept while the process may read it.
    config: Option<tempfile::NamedTempFile>,
    /// Stderr already read by [`wait_stderr`](Self::wait_stderr).
    stderr_seen: Vec<u8>,
}

impl Running {
    /// The iceoryx2 domain the process runs in.
    pub fn domain(&self) -> &str {
        &self.domain
    }

    /// The child process (e.g. to take its stdout).
    pub fn child_mut(&mut self) -> &mut Child {
        &mut self.child
    }

    /// Whether the process has not exited yet.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Sends SIGTERM to the process.
    pub fn sigterm(&self) {
        let pid = self.child.id().expect("the process has not been reaped");
        let pid = i32::try_from(pid).expect("pid fits an i32");
        kill(Pid::from_raw(pid), Signal::SIGTERM).expect("SIGTERM");
    }

    /// Reads stderr until it contains `needle`; false if stderr ended first or the
    /// patience ran out. What was read goes into [`finish`](Self::finish)'s output.
    pub async fn wait_stderr(&mut self, needle: &str) -> bool {
        if String::from_utf8_lossy(&self.stderr_seen).contains(needle) {
            return true;
        }
        let Some(mut stderr) = self.child.stderr.take() else {
            return false;
        };
        let seen = &mut self.stderr_seen;
        let found = tokio::time::timeout(self.patience, async {
            let mut chunk = [0u8; 4096];
            loop {
                let n = stderr.read(&mut chunk).await.expect("read stderr");
                if n == 0 {
                    return false;
                }
                seen.extend_from_slice(&chunk[..n]);
                if String::from_utf8_lossy(seen).contains(needle) {
                    return true;
                }
            }
        })
        .await;
        // Hand the pipe back so `finish` collects the rest.
        self.child.stderr = Some(stderr);
        found == Ok(true)
    }

    /// Waits until the process counts as started (see [`Ready`]); panics if not.
    pub async fn wait_ready(&mut self, ready: Ready<'_>) {
        match ready {
            Ready::StillRunningAfter(after, without) => {
                tokio::time::sleep(after).await;
                assert!(
                    self.is_running(),
                    "{} must keep running {without}",
                    self.name
                );
            }
            Ready::StderrContains(needle) => {
                let found = self.wait_stderr(needle).await;
                assert!(
                    found,
                    "{} did not log {needle:?}; stderr so far:\n{}",
                    self.name,
                    String::from_utf8_lossy(&self.stderr_seen)
                );
            }
        }
    }

    /// Waits (within patience) for the process to exit, removes its domain's
    /// leftover iceoryx2 files and returns its output (stderr includes anything
    /// [`wait_stderr`](Self::wait_stderr) read).
    pub async fn finish(self) -> Output {
        let Running {
            child,
            domain,
            name,
            patience,
            config,
            stderr_seen,
        } = self;
        let mut out = tokio::time::timeout(patience, child.wait_with_output())
            .await
            .unwrap_or_else(|_| panic!("{name} exits within {patience:?}"))
            .expect("output");
        drop(config);
        remove_domain_leftovers(&domain);
        if !stderr_seen.is_empty() {
            let mut stderr = stderr_seen;
            stderr.append(&mut out.stderr);
            out.stderr = stderr;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unique_domains_differ_and_are_valid() {
        let a = unique_domain("t");
        let b = unique_domain("t");
        assert_ne!(a, b);
        assert!(Domain::load(&a, None).is_ok(), "{a}");
    }

    #[test]
    fn shipped_configs_are_found() {
        assert!(shipped_config("iceoryx2.toml").is_file());
    }

    /// A "service": a shell script, run by `/bin/sh` (see [`ServiceCli::script`]:
    /// these tests write scripts and fork at once, on several threads).
    fn fake_service(dir: &tempfile::TempDir, body: &str) -> ServiceCli {
        let script = dir.path().join("fake-service");
        std::fs::write(&script, format!("{body}\n")).expect("write script");
        ServiceCli::script("/bin/sh", &script, "tsup")
    }

    #[tokio::test]
    async fn stderr_is_waited_for_and_kept_in_the_output() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cli = fake_service(&dir, "echo started >&2\necho done");
        let mut running = cli.spawn_toml("", &[]);
        assert!(running.wait_stderr("started").await);
        assert!(!running.wait_stderr("ready").await, "stderr ended first");
        let out = running.finish().await;
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        assert_eq!(String::from_utf8_lossy(&out.stderr), "started\n");
        assert_eq!(String::from_utf8_lossy(&out.stdout), "done\n");
    }

    /// Eight tasks on four threads each write fresh scripts and run them at once:
    /// every fork may catch another thread's script open for writing. Executing the
    /// scripts themselves failed here with `ETXTBSY` in every try (as one CI run
    /// did); run by `/bin/sh` they are only read.
    #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
    async fn scripts_written_while_other_threads_fork_run() {
        let tasks: Vec<_> = (0..8)
            .map(|t| {
                tokio::spawn(async move {
                    for i in 0..25 {
                        let dir = tempfile::tempdir().expect("temp dir");
                        let out = fake_service(&dir, &format!("echo {t} {i}"))
                            .run(Path::new("/unused.toml"), &[])
                            .await;
                        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
                        assert_eq!(String::from_utf8_lossy(&out.stdout), format!("{t} {i}\n"));
                    }
                })
            })
            .collect();
        for task in tasks {
            task.await.expect("a task panicked");
        }
    }

    #[tokio::test]
    async fn arguments_and_environment_reach_the_process() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cli = fake_service(
            &dir,
            "echo \"$@\"; echo \"$SKYMESH_DOMAIN\"; echo \"${SKYMESH_CONFIG-unset}\"",
        );
        let out = cli
            .run(Path::new("/some/config.toml"), &["--check-config"])
            .await;
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let lines: Vec<&str> = stdout.lines().collect();
        assert_eq!(lines.len(), 3, "{}", text(&out));
        assert_eq!(lines[0], "--config /some/config.toml --check-config");
        assert!(lines[1].starts_with(&format!("tsup{}x", std::process::id())));
        assert_eq!(lines[2], "unset");
    }

    #[tokio::test]
    async fn config_errors_are_checked() {
        let dir = tempfile::tempdir().expect("temp dir");
        // Exits 64 naming whatever the config file holds.
        let cli = fake_service(&dir, "cat \"$2\" >&2; exit 64");
        cli.expect_config_errors(&[("bad_key = 1\n", "bad_key")])
            .await;
    }

    #[tokio::test]
    #[should_panic(expected = "should name other_key")]
    async fn a_config_error_not_naming_the_key_fails() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cli = fake_service(&dir, "cat \"$2\" >&2; exit 64");
        cli.expect_config_error("bad_key = 1\n", "other_key").await;
    }

    #[tokio::test]
    async fn sigterm_after_ready_exits_cleanly() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cli = fake_service(
            &dir,
            "trap 'exit 0' TERM\necho ready >&2\nwhile :; do sleep 0.05; done",
        );
        cli.sigterm_exits_cleanly("", Ready::StderrContains("ready"))
            .await;
        cli.sigterm_exits_cleanly(
            "",
            Ready::StillRunningAfter(Duration::from_millis(100), "in this test"),
        )
        .await;
    }

    #[tokio::test]
    #[should_panic(expected = "Some(0)")]
    async fn a_failing_exit_on_sigterm_fails() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cli = fake_service(
            &dir,
            "trap 'exit 3' TERM\necho ready >&2\nwhile :; do sleep 0.05; done",
        );
        cli.sigterm_exits_cleanly("", Ready::StderrContains("ready"))
            .await;
    }
}
