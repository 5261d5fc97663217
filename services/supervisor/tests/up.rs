//! The supervisor against real processes: `/bin/sh` children that exit, crash, hang
//! or sleep; heartbeats published by the test itself on the real bus; the `skymesh`
//! binary's CLI. Every test has its own iceoryx2 domain and binds 127.0.0.1:0.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use skymesh_ipc_types::{topics, FixedStr, ServiceHealth, ServiceId, ServiceState};
use skymesh_runtime::{Bus, Domain, Stats};
use skymesh_supervisor::child::Output;
use skymesh_supervisor::config::Settings;
use skymesh_supervisor::state::StatusEntry;
use skymesh_supervisor::{monitor, run_up, status_cmd, Up};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A domain no other test (or mesh) uses.
fn unique_domain() -> String {
    format!(
        "sup{}x{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// A mesh config with `/bin/sh -c` services; `services` is `(name, script, extra keys)`.
fn mesh_toml(services: &[(&str, &str, &str)]) -> String {
    let mut t = String::from(
        "[supervisor]\nheartbeat_ms = 100\nmissed_heartbeats = 4\ngrace_period_ms = 2000\n",
    );
    for (name, script, extra) in services {
        t.push_str(&format!(
            "\n[[service]]\nname = \"{name}\"\nbinary = \"/bin/sh\"\nargs = [\"-c\", '''{script}''']\n{extra}\n"
        ));
    }
    t
}

struct Harness {
    addr: SocketAddr,
    domain: Domain,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
    dir: tempfile::TempDir,
}

impl Harness {
    async fn start(toml: &str) -> Harness {
        Harness::start_with(toml, false).await
    }

    async fn start_with(toml: &str, monitor_only: bool) -> Harness {
        let dir = tempfile::tempdir().unwrap();
        let settings = Settings::parse(toml, "test", dir.path()).expect("test config");
        let domain = Domain::load(&unique_domain(), None).unwrap();
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let shutdown = CancellationToken::new();
        let up = Up {
            settings,
            domain: domain.clone(),
            listener,
            monitor_only,
            status_file: None,
            output: Output::Inherit,
            table: false,
            log_format: None,
            supervisor_log: None,
        };
        let task = tokio::spawn(run_up(up, shutdown.clone()));
        Harness {
            addr,
            domain,
            shutdown,
            task: Some(task),
            dir,
        }
    }

    /// `/status`, as typed entries (see [`Harness::ask`]).
    async fn status(&self) -> Vec<StatusEntry> {
        self.ask("/status", || status_cmd::fetch(self.addr)).await
    }

    /// `f`, asked again while the supervisor does not answer, for up to 15 s. One ask
    /// gives up after `status_cmd::TIMEOUT` (3 s): on a loaded CI machine a whole ask
    /// once went unanswered at startup, and what these tests check is the
    /// supervision, not the HTTP server's latency. A supervisor that stays silent
    /// still fails them, with the last error.
    async fn ask<T, F: std::future::Future<Output = anyhow::Result<T>>>(
        &self,
        what: &str,
        f: impl Fn() -> F,
    ) -> T {
        let start = Instant::now();
        loop {
            match f().await {
                Ok(v) => return v,
                Err(e) if start.elapsed() < Duration::from_secs(15) => {
                    eprintln!("{what} did not answer yet ({e:#}); asking again");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                Err(e) => panic!("{what}: {e:#}"),
            }
        }
    }

    async fn service(&self, name: &str) -> StatusEntry {
        self.status()
            .await
            .into_iter()
            .find(|s| s.name == name)
            .expect("service in /status")
    }

    async fn metrics(&self) -> String {
        let (code, body) = self
            .ask("/metrics", || status_cmd::http_get(self.addr, "/metrics"))
            .await;
        assert_eq!(code, 200);
        body
    }

    /// Polls `/status` until `f` accepts the entry of `name`.
    async fn wait_for(
        &self,
        name: &str,
        what: &str,
        timeout: Duration,
        f: impl Fn(&StatusEntry) -> bool,
    ) -> StatusEntry {
        let start = Instant::now();
        loop {
            let s = self.service(name).await;
            if f(&s) {
                return s;
            }
            assert!(
                start.elapsed() < timeout,
                "timed out waiting for {name}: {what}; last {s:?}"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// SIGTERM-equivalent: cancels and waits for a clean return.
    async fn stop(&mut self) {
        self.shutdown.cancel();
        let task = self.task.take().expect("running");
        tokio::time::timeout(Duration::from_secs(20), task)
            .await
            .expect("supervisor stops in time")
            .expect("supervisor task")
            .expect("supervisor returns Ok");
    }
}

impl Drop for Harness {
    fn drop(&mut self) {
        self.shutdown.cancel();
    }
}

fn series(text: &str, name_and_labels: &str) -> Option<f64> {
    text.lines().find_map(|l| {
        l.strip_prefix(name_and_labels)?
            .strip_prefix(' ')?
            .parse()
            .ok()
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn crash_is_restarted_with_backoff_and_counted() {
    let toml = mesh_toml(&[(
        "crashy",
        "sleep 0.05; exit 3",
        "heartbeat = false\nrestart = { initial_backoff_ms = 20, max_backoff_ms = 200, budget = 1000 }",
    )]);
    let mut h = Harness::start(&toml).await;
    let s = h
        .wait_for("crashy", "3 restarts", Duration::from_secs(20), |s| {
            s.restarts >= 3
        })
        .await;
    assert_eq!(s.last_exit_code, Some(3));
    assert!(
        matches!(s.state.as_str(), "running" | "backoff" | "starting"),
        "{s:?}"
    );
    let m = h.metrics().await;
    assert!(
        series(&m, r#"skymesh_service_restarts_total{service="crashy"}"#).unwrap() >= 3.0,
        "{m}"
    );
    assert_eq!(
        series(&m, r#"skymesh_service_last_exit_code{service="crashy"}"#),
        Some(3.0),
        "{m}"
    );
    h.stop().await;
    assert!(
        h.domain.leftover_files().is_empty(),
        "{:?}",
        h.domain.leftover_files()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn exit_64_is_a_config_error_and_never_restarted() {
    let toml = mesh_toml(&[("badconf", "exit 64", "heartbeat = false")]);
    let mut h = Harness::start(&toml).await;
    let s = h
        .wait_for("badconf", "config-error", Duration::from_secs(10), |s| {
            s.state == "config-error"
        })
        .await;
    assert_eq!((s.pid, s.restarts, s.last_exit_code), (None, 0, Some(64)));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let s = h.service("badconf").await;
    assert_eq!((s.state.as_str(), s.restarts), ("config-error", 0));
    let m = h.metrics().await;
    assert_eq!(
        series(&m, r#"skymesh_service_up{service="badconf"}"#),
        Some(0.0)
    );
    assert_eq!(
        series(
            &m,
            r#"skymesh_service_state{service="badconf",state="config-error"}"#
        ),
        Some(1.0)
    );
    h.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn spent_restart_budget_leaves_the_service_failed() {
    let toml = mesh_toml(&[(
        "flaky",
        "exit 1",
        "heartbeat = false\nrestart = { initial_backoff_ms = 10, budget = 2, budget_window_s = 60 }",
    )]);
    let mut h = Harness::start(&toml).await;
    let s = h
        .wait_for("flaky", "failed", Duration::from_secs(10), |s| {
            s.state == "failed"
        })
        .await;
    assert_eq!((s.restarts, s.pid, s.last_exit_code), (2, None, Some(1)));
    h.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_service_that_never_sends_a_heartbeat_is_killed_and_restarted() {
    let toml = mesh_toml(&[("silent", "exec sleep 60", "")])
        .replace("[supervisor]\n", "[supervisor]\nstartup_timeout_ms = 300\n");
    let mut h = Harness::start(&toml).await;
    let first = h
        .wait_for("silent", "started", Duration::from_secs(10), |s| {
            s.pid.is_some()
        })
        .await;
    let s = h
        .wait_for(
            "silent",
            "killed and restarted",
            Duration::from_secs(10),
            |s| s.restarts >= 1,
        )
        .await;
    assert_eq!(s.last_exit_code, Some(137), "killed with SIGKILL: {s:?}");
    assert!(
        !monitor::process_exists(first.pid.unwrap()),
        "the hung process is reaped"
    );
    h.stop().await;
}

/// Publishes heartbeats for `name` on the bus, as a service's runtime would.
fn heartbeat_publisher(
    domain: &Domain,
    name: &str,
) -> (Bus, skymesh_runtime::Publisher<ServiceHealth>) {
    let bus = Bus::open(domain, "test-heart", ServiceId::Tool, 0, Stats::new()).unwrap();
    let publisher = bus
        .publisher::<ServiceHealth>(&topics::service_health(name))
        .unwrap();
    (bus, publisher)
}

fn health(name: &str, pid: u32, state: ServiceState) -> ServiceHealth {
    ServiceHealth {
        name: FixedStr::new(name),
        pid,
        state: state.to_wire(),
        period_ms: 100,
        uptime_ms: 1000,
        ..Default::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn heartbeats_make_a_service_running_and_their_loss_gets_it_killed() {
    let toml = mesh_toml(&[("beating", "exec sleep 60", "critical = true")]);
    let mut h = Harness::start(&toml).await;
    let s = h
        .wait_for("beating", "spawned", Duration::from_secs(10), |s| {
            s.pid.is_some()
        })
        .await;
    assert_eq!(s.state, "starting");
    let pid = s.pid.unwrap();
    let (bus, mut publisher) = heartbeat_publisher(&h.domain, "beating");
    // Beat for a while: running, with a fresh heartbeat age.
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(800) {
        publisher
            .publish(health("beating", pid, ServiceState::Running))
            .unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let s = h.service("beating").await;
    assert_eq!((s.state.as_str(), s.pid), ("running", Some(pid)), "{s:?}");
    assert!(s.heartbeat_age_s.unwrap() < 1.0, "{s:?}");
    // Stop beating (a hung process): after 4 periods it is killed and restarted.
    let s = h
        .wait_for(
            "beating",
            "killed and restarted",
            Duration::from_secs(10),
            |s| s.restarts >= 1,
        )
        .await;
    assert_eq!(s.last_exit_code, Some(137), "{s:?}");
    assert!(!monitor::process_exists(pid));
    drop(publisher);
    drop(bus);
    h.stop().await;
    assert!(
        h.domain.leftover_files().is_empty(),
        "{:?}",
        h.domain.leftover_files()
    );
}

/// Services publish their periodic heartbeats without waking the supervisor (only
/// a new state does): it drains them on its own clock, often enough that a service
/// beating quietly for many times its allowed silence (4 × 100 ms here) is never
/// taken for hung, and sees a new state at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn quiet_heartbeats_are_drained_in_time_and_a_new_state_is_seen_at_once() {
    let toml = mesh_toml(&[("quiet", "exec sleep 60", "critical = true")]);
    let mut h = Harness::start(&toml).await;
    let s = h
        .wait_for("quiet", "spawned", Duration::from_secs(10), |s| {
            s.pid.is_some()
        })
        .await;
    let pid = s.pid.unwrap();
    let (bus, mut publisher) = heartbeat_publisher(&h.domain, "quiet");
    publisher
        .publish(health("quiet", pid, ServiceState::Running))
        .unwrap();
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(2500) {
        publisher
            .publish_quiet(health("quiet", pid, ServiceState::Running))
            .unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let s = h.service("quiet").await;
    assert_eq!(
        (s.state.as_str(), s.pid, s.restarts),
        ("running", Some(pid), 0),
        "{s:?}"
    );
    assert!(s.heartbeat_age_s.unwrap() < 0.4, "{s:?}");
    // A state change wakes the supervisor: seen well before the next drain could
    // matter (the wait is short, the quiet beats go on).
    publisher
        .publish(health("quiet", pid, ServiceState::Degraded))
        .unwrap();
    let seen = Instant::now();
    h.wait_for("quiet", "degraded", Duration::from_secs(5), |s| {
        s.state == "degraded"
    })
    .await;
    assert!(seen.elapsed() < Duration::from_secs(5));
    // Quiet beats stop: killed after the allowed silence like any hung service.
    let s = h
        .wait_for(
            "quiet",
            "killed and restarted",
            Duration::from_secs(10),
            |s| s.restarts >= 1,
        )
        .await;
    assert_eq!(s.last_exit_code, Some(137), "{s:?}");
    drop(publisher);
    drop(bus);
    h.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn monitor_only_watches_heartbeats_without_spawning() {
    let toml = mesh_toml(&[("watched", "exit 99", "")]);
    let mut h = Harness::start_with(&toml, true).await;
    let s = h.service("watched").await;
    assert_eq!((s.state.as_str(), s.pid), ("down", None));
    let me = std::process::id();
    let (bus, mut publisher) = heartbeat_publisher(&h.domain, "watched");
    for _ in 0..6 {
        publisher
            .publish(health("watched", me, ServiceState::Degraded))
            .unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let s = h
        .wait_for("watched", "degraded", Duration::from_secs(5), |s| {
            s.state == "degraded"
        })
        .await;
    assert_eq!(s.pid, Some(me));
    // Heartbeats stop while the process (this test) lives: stale.
    h.wait_for("watched", "stale", Duration::from_secs(5), |s| {
        s.state == "stale"
    })
    .await;
    let m = h.metrics().await;
    assert_eq!(
        series(
            &m,
            r#"skymesh_service_state{service="watched",state="stale"}"#
        ),
        Some(1.0),
        "{m}"
    );
    drop(publisher);
    drop(bus);
    h.stop().await;
}

fn promtool() -> Option<PathBuf> {
    std::env::split_paths(&std::env::var_os("PATH")?)
        .map(|d| d.join("promtool"))
        .find(|p| p.is_file())
}

fn skymesh() -> Command {
    Command::new(env!("CARGO_BIN_EXE_skymesh"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dependency_order_http_endpoints_status_cli_and_clean_shutdown() {
    // Listed in reverse: `third` waits for `second`, which waits for `first`. A
    // dependency is up once its heartbeat says running, which the test controls.
    let toml = mesh_toml(&[
        (
            "third",
            "exec sleep 60",
            "heartbeat = false\nafter = [\"second\"]",
        ),
        (
            "second",
            "exec sleep 60",
            "after = [\"first\"]\ncritical = true",
        ),
        (
            "first",
            "trap 'exit 0' TERM; while :; do sleep 0.1; done",
            "",
        ),
    ]);
    let mut h = Harness::start(&toml).await;
    let first = h
        .wait_for("first", "spawned", Duration::from_secs(10), |s| {
            s.pid.is_some()
        })
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    for name in ["second", "third"] {
        let s = h.service(name).await;
        assert_eq!(
            (s.state.as_str(), s.pid),
            ("starting", None),
            "{name} waits for its dependency"
        );
    }
    let beat_stop = CancellationToken::new();
    let beating = {
        let (domain, stop) = (h.domain.clone(), beat_stop.clone());
        tokio::spawn(async move {
            let (bus, mut first_pub) = heartbeat_publisher(&domain, "first");
            let mut second_pub = bus
                .publisher::<ServiceHealth>(&topics::service_health("second"))
                .unwrap();
            let mut with_second = false;
            while !stop.is_cancelled() {
                first_pub
                    .publish(health("first", 0, ServiceState::Running))
                    .unwrap();
                if with_second {
                    second_pub
                        .publish(health("second", 0, ServiceState::Running))
                        .unwrap();
                }
                tokio::time::sleep(Duration::from_millis(30)).await;
                with_second = true;
            }
        })
    };
    h.wait_for("first", "running", Duration::from_secs(10), |s| {
        s.state == "running"
    })
    .await;
    let second = h
        .wait_for("second", "spawned", Duration::from_secs(10), |s| {
            s.pid.is_some()
        })
        .await;
    for name in ["first", "second", "third"] {
        h.wait_for(name, "running", Duration::from_secs(10), |s| {
            s.state == "running"
        })
        .await;
    }
    let third = h.service("third").await;
    assert!(
        first.pid < second.pid && second.pid < third.pid,
        "spawned in dependency order"
    );

    // /status: the documented fields, in start order.
    let (code, body) = status_cmd::http_get(h.addr, "/status").await.unwrap();
    assert_eq!(code, 200);
    let v: serde_json::Value = serde_json::from_str(&body).unwrap();
    let arr = v.as_array().unwrap();
    let names: Vec<&str> = arr.iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["first", "second", "third"]);
    for s in arr {
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
            assert!(s.get(key).is_some(), "{key} missing in {s}");
        }
        assert!(
            s["pid"].as_u64().is_some() && s["uptime_s"].as_f64().is_some(),
            "{s}"
        );
    }
    assert_eq!(arr[1]["critical"], true);
    let (code, _) = status_cmd::http_get(h.addr, "/nope").await.unwrap();
    assert_eq!(code, 404);

    // /metrics: well-formed exposition, checked by promtool when it is installed.
    let m = h.metrics().await;
    for name in ["first", "second", "third"] {
        assert_eq!(
            series(&m, &format!("skymesh_service_up{{service=\"{name}\"}}")),
            Some(1.0),
            "{m}"
        );
        assert!(
            series(
                &m,
                &format!("skymesh_service_resident_memory_bytes{{service=\"{name}\"}}")
            )
            .unwrap()
                > 0.0
        );
        assert!(series(
            &m,
            &format!("skymesh_service_cpu_seconds_total{{service=\"{name}\"}}")
        )
        .is_some());
        assert!(series(
            &m,
            &format!("skymesh_service_uptime_seconds{{service=\"{name}\"}}")
        )
        .is_some());
    }
    assert_eq!(m.matches("# TYPE skymesh_service_up gauge").count(), 1);
    if let Some(promtool) = promtool() {
        let file = h.dir.path().join("scrape.prom");
        std::fs::write(&file, &m).unwrap();
        let out = Command::new(promtool)
            .args(["check", "metrics"])
            .stdin(std::fs::File::open(&file).unwrap())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "promtool: {}{}\n{m}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    // `skymesh status` against the running supervisor.
    let addr = h.addr.to_string();
    let out = tokio::task::spawn_blocking(move || {
        skymesh()
            .args(["status", "--metrics", &addr])
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    let table = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{table}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        table.starts_with("SERVICE") && table.contains("second*") && table.contains("running"),
        "{table}"
    );
    let addr = h.addr.to_string();
    let out = tokio::task::spawn_blocking(move || {
        skymesh()
            .args(["status", "--json", "--metrics", &addr])
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 3);
    assert_eq!(json[0]["state"], "running");

    // Shutdown: every child reaped, nothing of the domain left in /dev/shm.
    let pids: Vec<u32> = h.status().await.iter().filter_map(|s| s.pid).collect();
    assert_eq!(pids.len(), 3);
    beat_stop.cancel();
    beating.await.unwrap();
    h.stop().await;
    for pid in pids {
        assert!(!monitor::process_exists(pid), "child {pid} still alive");
    }
    assert!(
        h.domain.leftover_files().is_empty(),
        "{:?}",
        h.domain.leftover_files()
    );
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn cli_exit_codes_for_config_problems() {
    let dir = tempfile::tempdir().unwrap();
    let bad = write(
        dir.path(),
        "bad.toml",
        "[supervisor]\nmetrics = \"nowhere\"\n",
    );
    let out = skymesh()
        .args(["up", "--config"])
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(64),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("supervisor.metrics"));

    let missing_bin = write(
        dir.path(),
        "m.toml",
        "[[service]]\nname = \"x\"\nbinary = \"skymesh-no-such-service\"\n",
    );
    let out = skymesh()
        .args(["up", "--check-config", "--config"])
        .arg(&missing_bin)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(64));
    assert!(String::from_utf8_lossy(&out.stderr).contains("skymesh-no-such-service"));

    let good = write(
        dir.path(),
        "good.toml",
        &mesh_toml(&[("a", "exit 0", "heartbeat = false")]),
    );
    let out = skymesh()
        .args(["up", "--check-config", "--config"])
        .arg(&good)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("configuration OK"));

    // No --config and nothing in the search path (run from an empty directory).
    let out = skymesh()
        .arg("up")
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !Path::new("/etc/skymesh/skymesh.toml").exists() {
        assert_eq!(out.status.code(), Some(64), "{stderr}");
        assert!(stderr.contains("deploy/skymesh.toml"), "{stderr}");
    }

    let out = skymesh().arg("print-default-config").output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("[[service]]"));
    let out = skymesh().arg("--print-default-config").output().unwrap();
    assert!(String::from_utf8_lossy(&out.stdout).contains("name = \"vehicle-sim\""));
    let out = skymesh().arg("--help").output().unwrap();
    assert!(String::from_utf8_lossy(&out.stdout).contains("status"));

    // Nobody listening: exit 2 (as bad as a critical service down) with a clear message.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let out = skymesh()
        .args(["status", "--metrics", &port.to_string()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no skymesh supervisor answers"));
}

#[test]
fn skymesh_up_binary_serves_and_stops_cleanly_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let domain = unique_domain();
    let config = write(
        dir.path(),
        "skymesh.toml",
        &mesh_toml(&[
            (
                "one",
                "trap 'exit 0' TERM; while :; do sleep 0.1; done",
                "heartbeat = false",
            ),
            (
                "two",
                "exec sleep 60",
                "heartbeat = false\nafter = [\"one\"]",
            ),
        ]),
    );
    let status_file = dir.path().join("addr");
    let mut child = skymesh()
        .args(["up", "--metrics", "127.0.0.1:0", "--config"])
        .arg(&config)
        .arg("--status-file")
        .arg(&status_file)
        .env("SKYMESH_DOMAIN", &domain)
        .env_remove("NOTIFY_SOCKET")
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let start = Instant::now();
    let (addr, pids) = loop {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "supervisor did not come up"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "supervisor exited early"
        );
        if let Some(addr) = std::fs::read_to_string(&status_file)
            .ok()
            .and_then(|t| t.trim().parse::<SocketAddr>().ok())
        {
            if let Ok(rows) = rt.block_on(status_cmd::fetch(addr)) {
                if rows.iter().all(|r| r.state == "running") {
                    break (addr, rows.iter().filter_map(|r| r.pid).collect::<Vec<_>>());
                }
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(pids.len(), 2);
    let out = skymesh()
        .args(["status", "--metrics", &addr.to_string()])
        .output()
        .unwrap();
    // Every service runs: exit 0, /healthz 200, and the build is stamped.
    assert_eq!(out.status.code(), Some(0));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("health: ok (2/2 running)"), "{table}");
    let (code, body) = rt.block_on(status_cmd::http_get(addr, "/healthz")).unwrap();
    assert_eq!(code, 200, "{body}");
    assert!(body.contains(r#""health":"ok""#), "{body}");
    let (_, metrics) = rt.block_on(status_cmd::http_get(addr, "/metrics")).unwrap();
    assert!(
        metrics.contains(&format!(
            r#"skymesh_build_info{{git="{}",version="{}"}} 1"#,
            skymesh_supervisor::GIT,
            skymesh_supervisor::VERSION
        )),
        "{metrics}"
    );
    let out = skymesh().arg("--version").output().unwrap();
    let version = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && version.contains(skymesh_supervisor::GIT),
        "{version}"
    );

    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "no exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(status.code(), Some(0));
    for pid in pids {
        assert!(!monitor::process_exists(pid), "child {pid} survived");
    }
    assert!(!status_file.exists(), "status file removed on exit");
    let d = Domain::load(&domain, None).unwrap();
    assert!(d.leftover_files().is_empty(), "{:?}", d.leftover_files());
}
