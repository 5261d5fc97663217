//! Adopting services that an earlier supervisor started.
//!
//! Every child leads its own process group, so when the supervisor dies (SIGKILL, a
//! crash, the OOM killer) its children keep running, re-parented to init or the
//! nearest subreaper. A restarted `skymesh up` looks for them before it starts
//! anything: a process is an instance of service `name` in our domain when
//!
//! - its environment says `SKYMESH_DOMAIN` = our domain and `SKYMESH_SERVICE_NAME` =
//!   `name` (the supervisor sets both; `/proc/<pid>/environ` is readable for the same
//!   user),
//! - it leads its own process group (the supervisor spawns every child that way; what a
//!   service forks inherits the environment but not the leadership),
//! - its executable (`/proc/<pid>/exe`) is the configured program, and
//! - it is not a zombie.
//!
//! Its identity is (pid, start time in clock ticks since boot): a pid reused by
//! another process has another start time, so every later look at the process
//! (liveness, signals) checks both. An adopted process is not our child, so its exit
//! is seen through a pidfd (readable once the process has exited; polled in a thread
//! of its own) or, on kernels without pidfds, by a look at `/proc` every 500 ms.

use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::time::Duration;

use rustix::event::{PollFd, PollFlags};
use tokio::sync::watch;

use crate::config::ServiceSpec;

/// How often the fallback checks an adopted process without a pidfd.
const POLL: Duration = Duration::from_millis(500);

/// A `/proc` file system: the real one, or a fake directory in tests.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProcFs {
    root: PathBuf,
}

/// The fields of `/proc/<pid>/stat` adoption looks at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatFields {
    /// `R`, `S`, `D`, `Z`, …
    pub state: char,
    pub pgid: i64,
    /// Clock ticks after boot at which the process started.
    pub start_ticks: u64,
}

/// A process found running as an instance of a service.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Instance {
    pub pid: u32,
    pub start_ticks: u64,
    /// Its executable as the kernel names it.
    pub exe: PathBuf,
}

/// Fields 3 (state), 5 (pgrp) and 22 (starttime) of a `/proc/<pid>/stat` line.
pub fn parse_stat(stat: &str) -> Option<StatFields> {
    let fields = crate::procfs::StatLine::parse(stat)?;
    Some(StatFields {
        state: fields.field(3)?.chars().next()?,
        pgid: fields.number(5)?,
        start_ticks: fields.number(22)?,
    })
}

/// True if `pid` exited and waits for its parent to reap it (a zombie).
pub fn is_zombie(pid: i32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| parse_stat(&s))
        .is_some_and(|f| f.state == 'Z')
}

/// The value of `key` in a NUL-separated `/proc/<pid>/environ`.
pub fn environ_var<'a>(environ: &'a [u8], key: &str) -> Option<&'a [u8]> {
    environ.split(|&b| b == 0).find_map(|kv| {
        kv.strip_prefix(key.as_bytes())
            .and_then(|rest| rest.strip_prefix(b"="))
    })
}

/// The path `program` runs as: symlinks resolved (`/bin/sh` → `/usr/bin/dash`), as
/// `/proc/<pid>/exe` shows it.
pub fn canonical_program(program: &Path) -> PathBuf {
    std::fs::canonicalize(program).unwrap_or_else(|_| program.to_path_buf())
}

impl ProcFs {
    /// The system's `/proc`.
    pub fn system() -> Self {
        ProcFs::at("/proc")
    }

    /// A `/proc`-shaped directory at `root`.
    pub fn at(root: impl Into<PathBuf>) -> Self {
        ProcFs { root: root.into() }
    }

    fn stat(&self, pid: u32) -> Option<StatFields> {
        let text = std::fs::read_to_string(self.root.join(pid.to_string()).join("stat")).ok()?;
        parse_stat(&text)
    }

    /// The start time of `pid` if it exists and has not exited (zombies count as gone).
    pub fn start_ticks(&self, pid: u32) -> Option<u64> {
        self.stat(pid)
            .filter(|s| !matches!(s.state, 'Z' | 'X' | 'x'))
            .map(|s| s.start_ticks)
    }

    /// True while the process `pid` that started at `start_ticks` is alive.
    pub fn is_alive(&self, pid: u32, start_ticks: u64) -> bool {
        self.start_ticks(pid) == Some(start_ticks)
    }

    /// How long ago a process that started at `start_ticks` started (from `uptime`).
    pub fn age(&self, start_ticks: u64) -> Option<Duration> {
        let uptime = std::fs::read_to_string(self.root.join("uptime")).ok()?;
        let since_boot: f64 = uptime.split_ascii_whitespace().next()?.parse().ok()?;
        let started = start_ticks as f64 / crate::procfs::ticks_per_second();
        Some(Duration::from_secs_f64((since_boot - started).max(0.0)))
    }

    /// `pid` as an instance of one of `services` (`(name, canonical program)`) in
    /// `domain`: the index of that service and the instance.
    pub fn instance_of(
        &self,
        pid: u32,
        domain: &str,
        services: &[(String, PathBuf)],
    ) -> Option<(usize, Instance)> {
        let dir = self.root.join(pid.to_string());
        let environ = std::fs::read(dir.join("environ")).ok()?;
        if environ_var(&environ, "SKYMESH_DOMAIN")? != domain.as_bytes() {
            return None;
        }
        let name = environ_var(&environ, "SKYMESH_SERVICE_NAME")?;
        let idx = services.iter().position(|(n, _)| n.as_bytes() == name)?;
        let stat = self.stat(pid)?;
        if matches!(stat.state, 'Z' | 'X' | 'x') || stat.pgid != i64::from(pid) {
            return None;
        }
        let exe = std::fs::read_link(dir.join("exe")).ok()?;
        // A binary replaced on disk (an upgrade) shows as "<path> (deleted)".
        let shown = exe.to_string_lossy();
        let exe_path = Path::new(shown.strip_suffix(" (deleted)").unwrap_or(&shown));
        if exe_path != services[idx].1 {
            return None;
        }
        Some((
            idx,
            Instance {
                pid,
                start_ticks: stat.start_ticks,
                exe,
            },
        ))
    }

    /// Every running instance of each of `services` in `domain`, oldest first; the
    /// calling process is never one.
    pub fn find(&self, domain: &str, services: &[(String, PathBuf)]) -> Vec<Vec<Instance>> {
        let mut found = vec![Vec::new(); services.len()];
        let Ok(dir) = std::fs::read_dir(&self.root) else {
            return found;
        };
        let me = std::process::id();
        for entry in dir.flatten() {
            let Some(pid) = entry
                .file_name()
                .to_str()
                .and_then(|s| s.parse::<u32>().ok())
            else {
                continue;
            };
            if pid == me {
                continue;
            }
            if let Some((idx, inst)) = self.instance_of(pid, domain, services) {
                found[idx].push(inst);
            }
        }
        for list in &mut found {
            list.sort_by_key(|i| (i.start_ticks, i.pid));
        }
        found
    }
}

/// Finds the running instances of `specs` in `domain` in the system's `/proc`.
pub fn find_running(domain: &str, specs: &[ServiceSpec]) -> Vec<Vec<Instance>> {
    let services: Vec<(String, PathBuf)> = specs
        .iter()
        .map(|s| (s.name.clone(), canonical_program(&s.program)))
        .collect();
    ProcFs::system().find(domain, &services)
}

/// How the exit of an adopted process is seen.
#[derive(Debug)]
enum ExitWatch {
    /// Set to true by a watcher thread once the pidfd says the process exited.
    Pidfd(watch::Receiver<bool>),
    /// No pidfd (old kernel): look at `/proc` every [`POLL`].
    Poll,
}

/// Waits on `pidfd` in a thread of its own (a pidfd turns readable when its process
/// exits; tokio's `AsyncFd` can no longer take an fd without `unsafe`). The thread
/// wakes once a second only to see whether anyone still listens.
fn pidfd_watcher(pid: u32, pidfd: OwnedFd) -> std::io::Result<watch::Receiver<bool>> {
    let (tx, rx) = watch::channel(false);
    std::thread::Builder::new()
        .name(format!("pidfd-{pid}"))
        .spawn(move || {
            let second = rustix::event::Timespec {
                tv_sec: 1,
                tv_nsec: 0,
            };
            loop {
                let mut fds = [PollFd::new(&pidfd, PollFlags::IN)];
                match rustix::event::poll(&mut fds, Some(&second)) {
                    Ok(0) | Err(rustix::io::Errno::INTR) => {}
                    Ok(_) => {
                        let _ = tx.send(true);
                        return;
                    }
                    Err(e) => {
                        // Dropping `tx` without `true` makes the waiter fall back to /proc.
                        tracing::warn!(pid, error = %e, "polling the pidfd failed");
                        return;
                    }
                }
                if tx.is_closed() {
                    return;
                }
            }
        })?;
    Ok(rx)
}

/// A running process another supervisor started, now watched by this one.
#[derive(Debug)]
pub struct Adopted {
    pub pid: u32,
    pub start_ticks: u64,
    /// How long it had been running when adopted.
    pub age: Duration,
    proc: ProcFs,
    watch: ExitWatch,
}

impl Adopted {
    /// Starts watching `inst`; `None` if it is already gone.
    pub fn watch(inst: &Instance) -> Option<Adopted> {
        let proc = ProcFs::system();
        let pidfd = rustix::process::Pid::from_raw(i32::try_from(inst.pid).ok()?)
            .map(|p| rustix::process::pidfd_open(p, rustix::process::PidfdFlags::empty()))?;
        let watch = match pidfd {
            Ok(fd) => match pidfd_watcher(inst.pid, fd) {
                Ok(rx) => ExitWatch::Pidfd(rx),
                Err(e) => {
                    tracing::warn!(pid = inst.pid, error = %e, "cannot start the pidfd watcher; checking the process every 500 ms instead");
                    ExitWatch::Poll
                }
            },
            Err(rustix::io::Errno::SRCH) => return None,
            Err(e) => {
                tracing::warn!(pid = inst.pid, error = %e, "pidfd_open failed; checking the process every 500 ms instead");
                ExitWatch::Poll
            }
        };
        // The pidfd names whatever process has the pid now: make sure it is still the
        // one found (not a reuse of its pid since the scan).
        if !proc.is_alive(inst.pid, inst.start_ticks) {
            return None;
        }
        let age = proc.age(inst.start_ticks).unwrap_or_default();
        Some(Adopted {
            pid: inst.pid,
            start_ticks: inst.start_ticks,
            age,
            proc,
            watch,
        })
    }

    /// True while the adopted process runs.
    pub fn is_alive(&self) -> bool {
        self.proc.is_alive(self.pid, self.start_ticks)
    }

    /// Resolves once the process has exited.
    pub async fn exited(&self) {
        if let ExitWatch::Pidfd(rx) = &self.watch {
            if rx.clone().wait_for(|exited| *exited).await.is_ok() {
                return;
            }
            // The watcher thread gave up: fall back to looking at /proc.
        }
        while self.is_alive() {
            tokio::time::sleep(POLL).await;
        }
    }

    /// After [`Adopted::exited`]: waits (up to `limit`) for the new parent to reap the
    /// process, so iceoryx2 sees its node as dead. Returns true once reaped.
    pub async fn reaped(&self, limit: Duration) -> bool {
        let dir = self.proc.root.join(self.pid.to_string());
        let gone = || match std::fs::read_to_string(dir.join("stat")) {
            Err(_) => true,
            Ok(s) => parse_stat(&s).is_none_or(|f| f.start_ticks != self.start_ticks),
        };
        let deadline = tokio::time::Instant::now() + limit;
        while !gone() {
            if tokio::time::Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        true
    }

    /// Sends `sig` to the process group the adopted process leads, if it still runs
    /// (never to a process that merely reuses its pid).
    pub fn signal_group(&self, sig: nix::sys::signal::Signal) {
        if self.is_alive() {
            crate::child::signal_group(self.pid, sig);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STAT: &str = "4242 (s h) S 1 4242 4242 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 1 0 987654 1000000 200 18446744073709551615";

    fn fake_proc(
        root: &Path,
        pid: u32,
        stat: &str,
        environ: &[(&str, &str)],
        exe: &str,
    ) -> PathBuf {
        let dir = root.join(pid.to_string());
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("stat"), stat).unwrap();
        let mut env = Vec::new();
        for (k, v) in environ {
            env.extend_from_slice(format!("{k}={v}").as_bytes());
            env.push(0);
        }
        std::fs::write(dir.join("environ"), env).unwrap();
        std::os::unix::fs::symlink(exe, dir.join("exe")).unwrap();
        dir
    }

    fn env(domain: &str, name: &str) -> Vec<(&'static str, String)> {
        vec![
            ("PATH", "/usr/bin".to_string()),
            ("SKYMESH_DOMAIN", domain.to_string()),
            ("SKYMESH_SERVICE_NAME", name.to_string()),
        ]
    }

    fn add(root: &Path, pid: u32, start: u64, pgid: u32, env: &[(&str, String)], exe: &str) {
        let stat = STAT
            .replacen("4242 (", &format!("{pid} ("), 1)
            .replacen(" 1 4242 4242 ", &format!(" 1 {pgid} {pgid} "), 1)
            .replacen(" 987654 ", &format!(" {start} "), 1);
        let e: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
        fake_proc(root, pid, &stat, &e, exe);
    }

    #[test]
    fn parses_state_group_and_start_time() {
        assert_eq!(
            parse_stat(STAT),
            Some(StatFields {
                state: 'S',
                pgid: 4242,
                start_ticks: 987654
            })
        );
        assert_eq!(parse_stat("12 (x) S 1 2"), None);
        assert_eq!(parse_stat("garbage"), None);
        let env = b"A=1\0SKYMESH_DOMAIN=d1\0SKYMESH_DOMAIN_X=no\0";
        assert_eq!(environ_var(env, "SKYMESH_DOMAIN"), Some(&b"d1"[..]));
        assert_eq!(environ_var(env, "A"), Some(&b"1"[..]));
        assert_eq!(environ_var(env, "SKYMESH"), None);
    }

    #[test]
    fn only_group_leading_instances_of_the_configured_program_in_our_domain_match() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        let services = vec![
            ("nav".to_string(), PathBuf::from("/opt/sky/nav")),
            ("cam".to_string(), PathBuf::from("/opt/sky/cam")),
        ];
        // The real instance of `nav`, and an older one of `cam` running from a
        // binary that was replaced on disk since.
        add(root, 100, 5000, 100, &env("d1", "nav"), "/opt/sky/nav");
        add(
            root,
            300,
            4000,
            300,
            &env("d1", "cam"),
            "/opt/sky/cam (deleted)",
        );
        add(root, 301, 7000, 301, &env("d1", "cam"), "/opt/sky/cam");
        // A process the service forked: same environment, not a group leader.
        add(root, 101, 5001, 100, &env("d1", "nav"), "/opt/sky/nav");
        // The pid of a dead instance reused by another program that inherited the
        // variables (e.g. a shell started from the service): not adopted.
        add(root, 200, 9000, 200, &env("d1", "nav"), "/usr/bin/bash");
        // Another domain, an unknown service, no skymesh variables at all.
        add(root, 400, 100, 400, &env("d2", "nav"), "/opt/sky/nav");
        add(root, 401, 100, 401, &env("d1", "other"), "/opt/sky/nav");
        add(root, 402, 100, 402, &[], "/opt/sky/nav");
        // A zombie.
        let zombie = STAT
            .replacen("4242 (", "500 (", 1)
            .replacen(") S ", ") Z ", 1)
            .replacen(" 1 4242 4242 ", " 1 500 500 ", 1);
        let e = env("d1", "nav");
        let e: Vec<(&str, &str)> = e.iter().map(|(k, v)| (*k, v.as_str())).collect();
        fake_proc(root, 500, &zombie, &e, "/opt/sky/nav");
        // Not a process directory.
        std::fs::create_dir_all(root.join("self")).unwrap();
        std::fs::write(root.join("uptime"), "120.50 200.00\n").unwrap();

        let p = ProcFs::at(root);
        let found = p.find("d1", &services);
        assert_eq!(
            found[0],
            vec![Instance {
                pid: 100,
                start_ticks: 5000,
                exe: PathBuf::from("/opt/sky/nav")
            }]
        );
        let cams: Vec<u32> = found[1].iter().map(|i| i.pid).collect();
        assert_eq!(cams, [300, 301], "oldest first");
        assert!(p.find("d3", &services).iter().all(Vec::is_empty));

        // Identity checks: the start time tells a reused pid apart.
        assert!(p.is_alive(100, 5000));
        assert!(!p.is_alive(100, 5001));
        assert!(!p.is_alive(500, p.stat(500).unwrap().start_ticks), "zombie");
        assert!(!p.is_alive(999, 1));
        let ticks = crate::procfs::ticks_per_second();
        let age = p.age((20.5 * ticks) as u64).unwrap();
        assert!((age.as_secs_f64() - 100.0).abs() < 0.1, "{age:?}");
    }

    #[tokio::test]
    async fn a_process_we_did_not_spawn_is_watched_until_it_exits() {
        use std::os::unix::process::CommandExt;
        // Spawned by std and reaped by a helper thread, as an orphan is by init.
        let mut child = std::process::Command::new("/bin/sh")
            .args(["-c", "sleep 30"])
            .process_group(0)
            .spawn()
            .unwrap();
        let pid = child.id();
        let proc = ProcFs::system();
        let start_ticks = proc.start_ticks(pid).unwrap();
        let a = Adopted::watch(&Instance {
            pid,
            start_ticks,
            exe: PathBuf::new(),
        })
        .expect("alive");
        assert!(matches!(a.watch, ExitWatch::Pidfd(_)), "{:?}", a.watch);
        assert!(a.is_alive());
        // A wrong start time is a different process: not adopted.
        assert!(Adopted::watch(&Instance {
            pid,
            start_ticks: start_ticks + 1,
            exe: PathBuf::new()
        })
        .is_none());
        let reaper = std::thread::spawn(move || child.wait().unwrap());
        a.signal_group(nix::sys::signal::Signal::SIGKILL);
        tokio::time::timeout(Duration::from_secs(10), a.exited())
            .await
            .expect("exit seen");
        assert!(a.reaped(Duration::from_secs(10)).await);
        assert!(!a.is_alive());
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(reaper.join().unwrap().signal(), Some(9));
    }
}
