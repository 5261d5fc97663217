//! The supervisor dies (SIGKILL): its services keep running, and the next `skymesh up`
//! on the same config and domain adopts them instead of starting duplicates; it
//! restarts an adopted service that dies or hangs, and stops them all on SIGTERM.
//! Runs the real `skymesh` binary with `/bin/sh` services in a domain of its own.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use skymesh_ipc_types::{topics, FixedStr, ServiceHealth, ServiceId, ServiceState};
use skymesh_runtime::{Bus, Domain, Stats};
use skymesh_supervisor::state::StatusEntry;
use skymesh_supervisor::{monitor, status_cmd};

const LOOP: &str = "trap 'exit 0' TERM; while :; do sleep 0.1; done";

fn config(dir: &Path) -> PathBuf {
    let mut t = format!(
        "[supervisor]\nheartbeat_ms = 100\nmissed_heartbeats = 20\ngrace_period_ms = 3000\nlog_dir = \"{}\"\n\n[restart]\ninitial_backoff_ms = 20\n",
        dir.join("logs").display()
    );
    for (name, extra) in [
        ("alpha", "heartbeat = false"),
        ("beta", "heartbeat = false\nafter = [\"alpha\"]"),
        ("gamma", "critical = true"),
    ] {
        t.push_str(&format!(
            "\n[[service]]\nname = \"{name}\"\nbinary = \"/bin/sh\"\nargs = [\"-c\", \"{LOOP}\"]\n{extra}\n"
        ));
    }
    let p = dir.join("skymesh.toml");
    std::fs::write(&p, t).unwrap();
    p
}

/// One `skymesh up` process; killed (SIGKILL) on drop if still running.
struct Supervisor {
    child: Child,
    log: PathBuf,
    status_file: PathBuf,
}

impl Supervisor {
    fn start(dir: &Path, config: &Path, domain: &str, run: &str) -> Supervisor {
        let log = dir.join(format!("{run}.log"));
        let status_file = dir.join(format!("{run}.addr"));
        let out = std::fs::File::create(&log).unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_skymesh"))
            .args(["up", "--no-table", "--metrics", "127.0.0.1:0", "--config"])
            .arg(config)
            .arg("--status-file")
            .arg(&status_file)
            .env("SKYMESH_DOMAIN", domain)
            .env_remove("NOTIFY_SOCKET")
            .env_remove("WATCHDOG_USEC")
            .stdout(out.try_clone().unwrap())
            .stderr(out)
            .spawn()
            .unwrap();
        Supervisor {
            child,
            log,
            status_file,
        }
    }

    fn pid(&self) -> Pid {
        Pid::from_raw(self.child.id() as i32)
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    fn addr(&mut self, deadline: Instant) -> SocketAddr {
        loop {
            if let Some(a) = std::fs::read_to_string(&self.status_file)
                .ok()
                .and_then(|t| t.trim().parse().ok())
            {
                return a;
            }
            self.alive_until(deadline, "listening");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn alive_until(&mut self, deadline: Instant, what: &str) {
        if let Some(s) = self.child.try_wait().unwrap() {
            panic!(
                "supervisor exited ({s}) waiting for {what}:\n{}",
                self.log()
            );
        }
        assert!(
            Instant::now() < deadline,
            "timed out waiting for {what}:\n{}",
            self.log()
        );
    }

    /// Polls `/status` until `f` accepts it.
    fn wait_for(
        &mut self,
        rt: &tokio::runtime::Runtime,
        what: &str,
        f: impl Fn(&[StatusEntry]) -> bool,
    ) -> Vec<StatusEntry> {
        let deadline = Instant::now() + Duration::from_secs(30);
        let addr = self.addr(deadline);
        loop {
            if let Ok(rows) = rt.block_on(status_cmd::fetch(addr)) {
                if f(&rows) {
                    return rows;
                }
            }
            self.alive_until(deadline, what);
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn metrics(&mut self, rt: &tokio::runtime::Runtime) -> String {
        let addr = self.addr(Instant::now() + Duration::from_secs(30));
        let (code, body) = rt.block_on(status_cmd::http_get(addr, "/metrics")).unwrap();
        assert_eq!(code, 200);
        body
    }

    fn wait_exit(&mut self) -> std::process::ExitStatus {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s;
            }
            assert!(Instant::now() < deadline, "no exit:\n{}", self.log());
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Every process whose environment says it belongs to `domain` (the services and
/// anything they forked).
fn processes_of(domain: &str) -> Vec<u32> {
    let want = format!("SKYMESH_DOMAIN={domain}");
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            std::fs::read(format!("/proc/{pid}/environ"))
                .is_ok_and(|env| env.split(|&b| b == 0).any(|kv| kv == want.as_bytes()))
        })
        .filter(|&pid| pid != std::process::id())
        .collect()
}

/// Kills whatever of `domain` is left (a failed test must not leave orphans behind).
struct Reaper(String);

impl Drop for Reaper {
    fn drop(&mut self) {
        for pid in processes_of(&self.0) {
            let _ = kill(Pid::from_raw(pid as i32), Signal::SIGKILL);
        }
    }
}

/// Publishes `gamma`'s heartbeats, as its runtime would, while `beating` is set.
fn heartbeats(
    domain: String,
    beating: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let d = Domain::load(&domain, None).unwrap();
        let bus = Bus::open(&d, "test-heart", ServiceId::Tool, 0, Stats::new()).unwrap();
        let mut publisher = bus
            .publisher::<ServiceHealth>(&topics::service_health("gamma"))
            .unwrap();
        while !stop.load(Ordering::Relaxed) {
            if beating.load(Ordering::Relaxed) {
                publisher
                    .publish(ServiceHealth {
                        name: FixedStr::new("gamma"),
                        pid: 0,
                        state: ServiceState::Running.to_wire(),
                        period_ms: 100,
                        uptime_ms: 1000,
                        ..Default::default()
                    })
                    .unwrap();
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    })
}

fn series(text: &str, name_and_labels: &str) -> Option<f64> {
    text.lines().find_map(|l| {
        l.strip_prefix(name_and_labels)?
            .strip_prefix(' ')?
            .parse()
            .ok()
    })
}

fn pid_of(rows: &[StatusEntry], name: &str) -> Option<u32> {
    rows.iter().find(|r| r.name == name).and_then(|r| r.pid)
}

fn row<'a>(rows: &'a [StatusEntry], name: &str) -> &'a StatusEntry {
    rows.iter().find(|r| r.name == name).unwrap()
}

const NAMES: [&str; 3] = ["alpha", "beta", "gamma"];

#[test]
fn a_restarted_supervisor_adopts_the_services_of_one_that_was_killed() {
    let dir = tempfile::tempdir().unwrap();
    let domain = format!("adopt{}", std::process::id());
    let _reaper = Reaper(domain.clone());
    let config = config(dir.path());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let beating = Arc::new(AtomicBool::new(true));
    let stop_beating = Arc::new(AtomicBool::new(false));
    let heart = heartbeats(domain.clone(), beating.clone(), stop_beating.clone());

    // The first supervisor starts the mesh.
    let mut first = Supervisor::start(dir.path(), &config, &domain, "first");
    let rows = first.wait_for(&rt, "all running", |rows| {
        rows.iter().all(|r| r.state == "running")
    });
    let pids: Vec<u32> = NAMES.iter().map(|n| pid_of(&rows, n).unwrap()).collect();
    assert!(rows.iter().all(|r| !r.adopted), "{rows:?}");

    // It dies without a chance to clean up: the services keep running.
    kill(first.pid(), Signal::SIGKILL).unwrap();
    first.wait_exit();
    std::thread::sleep(Duration::from_millis(300));
    for pid in &pids {
        assert!(
            monitor::process_exists(*pid),
            "service {pid} died with the supervisor"
        );
    }

    // A new supervisor on the same config and domain adopts them: same pids.
    let mut second = Supervisor::start(dir.path(), &config, &domain, "second");
    let rows = second.wait_for(&rt, "all running", |rows| {
        rows.iter().all(|r| r.state == "running")
    });
    for (name, pid) in NAMES.iter().zip(&pids) {
        let r = row(&rows, name);
        assert_eq!(
            (r.pid, r.adopted, r.restarts),
            (Some(*pid), true, 0),
            "{r:?}"
        );
    }
    let m = second.metrics(&rt);
    for name in NAMES {
        let l = format!("{{service=\"{name}\"}}");
        assert_eq!(
            series(&m, &format!("skymesh_supervisor_adopted_total{l}")),
            Some(1.0),
            "{m}"
        );
        assert_eq!(
            series(&m, &format!("skymesh_service_restarts_total{l}")),
            Some(0.0),
            "{m}"
        );
        assert_eq!(
            series(&m, &format!("skymesh_service_up{l}")),
            Some(1.0),
            "{m}"
        );
    }
    assert!(
        second.log().contains("adopted the running instance"),
        "{}",
        second.log()
    );
    // No duplicate was started: exactly one group leader per service.
    let leaders: Vec<u32> = processes_of(&domain)
        .into_iter()
        .filter(|&p| {
            nix::unistd::getpgid(Some(Pid::from_raw(p as i32))).ok()
                == Some(Pid::from_raw(p as i32))
        })
        .collect();
    let mut sorted = pids.clone();
    sorted.sort_unstable();
    let mut leaders_sorted = leaders.clone();
    leaders_sorted.sort_unstable();
    assert_eq!(leaders_sorted, sorted, "one process per service");

    // An adopted service dies: restarted by the normal policy, exit status unknown.
    kill(Pid::from_raw(pids[0] as i32), Signal::SIGKILL).unwrap();
    let rows = second.wait_for(&rt, "alpha restarted", |rows| {
        let a = row(rows, "alpha");
        a.state == "running" && a.pid.is_some_and(|p| p != pids[0])
    });
    let a = row(&rows, "alpha");
    assert_eq!((a.restarts, a.adopted), (1, false), "{a:?}");
    assert!(!monitor::process_exists(pids[0]));

    // An adopted service hangs (no more heartbeats): killed and restarted, and the
    // new process is up again once heartbeats come back.
    beating.store(false, Ordering::Relaxed);
    let rows = second.wait_for(&rt, "gamma killed", |rows| {
        let g = row(rows, "gamma");
        g.restarts == 1 && g.pid != Some(pids[2])
    });
    assert_eq!(row(&rows, "gamma").last_exit_code, Some(137), "{rows:?}");
    assert!(
        !monitor::process_exists(pids[2]),
        "the hung process is killed"
    );
    beating.store(true, Ordering::Relaxed);
    let rows = second.wait_for(&rt, "gamma running again", |rows| {
        let g = row(rows, "gamma");
        g.state == "running" && g.pid.is_some()
    });
    let g = row(&rows, "gamma");
    assert_eq!((g.restarts, g.adopted), (1, false), "{g:?}");
    let b = row(&rows, "beta");
    assert_eq!(
        (b.pid, b.adopted, b.restarts),
        (Some(pids[1]), true, 0),
        "{b:?}"
    );
    let m = second.metrics(&rt);
    assert_eq!(
        series(&m, r#"skymesh_service_restarts_total{service="alpha"}"#),
        Some(1.0),
        "{m}"
    );
    assert_eq!(
        series(&m, r#"skymesh_service_restarts_total{service="beta"}"#),
        Some(0.0),
        "{m}"
    );
    assert_eq!(
        series(&m, r#"skymesh_supervisor_adopted_total{service="alpha"}"#),
        Some(1.0),
        "{m}"
    );
    let all: Vec<u32> = rows.iter().filter_map(|r| r.pid).collect();
    assert_eq!(all.len(), 3);

    // SIGTERM: every service, adopted or spawned, is stopped; nothing is left.
    stop_beating.store(true, Ordering::Relaxed);
    heart.join().unwrap();
    kill(second.pid(), Signal::SIGTERM).unwrap();
    let status = second.wait_exit();
    assert_eq!(status.code(), Some(0), "{}", second.log());
    for pid in all {
        // A stopped adopted service may still be a zombie waiting for init to reap it.
        assert!(
            !monitor::process_exists(pid) || skymesh_supervisor::adopt::is_zombie(pid as i32),
            "service {pid} survived"
        );
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while !processes_of(&domain).is_empty() {
        assert!(
            Instant::now() < deadline,
            "left running: {:?}",
            processes_of(&domain)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let log = second.log();
    assert!(
        log.contains("stopped (adopted; exit status unknown)"),
        "{log}"
    );
    let d = Domain::load(&domain, None).unwrap();
    assert!(d.leftover_files().is_empty(), "{:?}", d.leftover_files());
}
