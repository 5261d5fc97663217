//! ArduPilot SITL as the autopilot of an end-to-end mesh: a real ArduCopter in
//! place of vehicle-sim (issue 42, "A real autopilot in CI"; `docs/sitl.md`).
//!
//! [`locate`] finds the binary: `SKYMESH_SITL` (a path to `arducopter`) or
//! `../shared/ardupilot-sitl/arducopter` next to the repository. Without either a
//! test calls [`skip`], which prints the one line `SITL not available: <why>`, and
//! returns. `SKYMESH_SITL` naming something that is not there is an error, not a
//! skip: whoever sets it (CI) wants the tests to run.
//!
//! [`Sitl::start`] runs it in a temp working directory of its own (it writes
//! `eeprom.bin` and `logs/` there: a fresh one means default parameters), as
//! instance `I` whose serial 0 (TCP 5760 + 10·I) is free, in its own process
//! group. Dropping the [`Sitl`] SIGKILLs the whole group. A small `sh` watchdog
//! leads that group and reads a pipe from this process: if the test process dies
//! without dropping it (SIGKILL, a runner's timeout), the pipe closes and the
//! watchdog kills the group, so no autopilot is left running at full CPU.
//!
//! [`SitlMesh::start`] then starts a [`Mesh`] whose autopilot-link connects to that
//! port ([`MeshOptions::autopilot_tcp`]; no vehicle-sim), and [`SitlMesh::wait_ready`]
//! waits on the bus until the EKF has a GPS position and the autopilot a home: SITL
//! needs 30–45 s for that, and arming earlier is refused. [`Phases`] times each
//! phase of a test and prints it, outside the test harness's capture (the numbers
//! are wanted in CI logs too).

use std::fmt::Write as _;
use std::io::Write as _;
use std::net::TcpListener;
use std::os::unix::process::CommandExt as _;
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context as _, Result};
use nix::sys::signal::{killpg, Signal};
use nix::unistd::Pid;
use skymesh_ipc_types::{topics, GpsFix, VehicleState, VehicleStatus};

use crate::{repo_root, Mesh, MeshBus, MeshOptions};

/// Environment variable naming the `arducopter` binary.
pub const SITL_ENV: &str = "SKYMESH_SITL";
/// Environment variable naming the defaults file (default: `copter.parm` next to
/// the binary).
pub const DEFAULTS_ENV: &str = "SKYMESH_SITL_DEFAULTS";
/// The shared prebuilt SITL, relative to the repository root.
pub const SHARED_SITL: &str = "../shared/ardupilot-sitl/arducopter";
/// Home of every SITL vehicle: vehicle-sim's, so site frames and fences built for
/// vehicle-sim tests mean the same place (ArduPilot's CMAC field).
pub const SITL_HOME: [f64; 4] = [crate::HOME[0], crate::HOME[1], crate::HOME[2], 0.0];
/// Serial 0 of instance `I` listens on `BASE_PORT + 10·I`.
pub const BASE_PORT: u16 = 5760;
/// Instances tried, from 1 (instance 0's 5760 is the embedded mesh's vehicle-sim
/// port and a developer's usual SITL).
const INSTANCES: std::ops::RangeInclusive<u16> = 1..=40;
/// How long SITL may take to open its serial 0 port.
const LISTEN_TIMEOUT: Duration = Duration::from_secs(20);

/// Instances taken by this process (tests run on parallel threads); other processes
/// are seen through their bound ports.
static CLAIMED: Mutex<Vec<u16>> = Mutex::new(Vec::new());

/// Where the SITL binary and its defaults are.
#[derive(Debug, Clone)]
pub struct SitlFiles {
    pub binary: PathBuf,
    pub defaults: PathBuf,
}

/// Finds the SITL binary and its defaults file. `Ok(None)` with the reason when
/// there is none (the caller skips); an error when `SKYMESH_SITL` or
/// `SKYMESH_SITL_DEFAULTS` name something that is not a file.
pub fn locate() -> Result<std::result::Result<SitlFiles, String>> {
    let binary = match std::env::var_os(SITL_ENV) {
        Some(p) if !p.is_empty() => {
            let p = PathBuf::from(p);
            if !p.is_file() {
                bail!("{SITL_ENV}={} is not a file", p.display());
            }
            p
        }
        _ => {
            let p = repo_root().join(SHARED_SITL);
            if !p.is_file() {
                return Ok(Err(format!(
                    "{SITL_ENV} is not set and {} does not exist",
                    p.display()
                )));
            }
            p
        }
    };
    let defaults = match std::env::var_os(DEFAULTS_ENV) {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => binary.with_file_name("copter.parm"),
    };
    if !defaults.is_file() {
        bail!(
            "SITL defaults {} not found (set {DEFAULTS_ENV} to ArduPilot's \
             Tools/autotest/default_params/copter.parm)",
            defaults.display()
        );
    }
    Ok(Ok(SitlFiles { binary, defaults }))
}

/// Prints the one skip line of a test without SITL, outside the test harness's
/// output capture so that it shows in a passing run.
pub fn skip(why: &str) {
    uncaptured(&format!("SITL not available: {why}\n"));
}

/// Writes to this process's stderr directly (libtest captures only `print!`).
pub fn uncaptured(text: &str) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_all(text.as_bytes());
    let _ = err.flush();
}

/// Runs `arducopter` as the first argument with the rest, leading a process group
/// with it; the group is SIGKILLed when stdin (a pipe from the test) closes or when
/// arducopter exits.
const WATCHDOG: &str = r#"exec 3<&0
{ read -r _ <&3; kill -KILL 0; } &
"$@" </dev/null 3<&-
echo "sitl watchdog: arducopter exited with status $?" >&2
kill -KILL 0
"#;

/// One running ArduCopter SITL.
#[derive(Debug)]
pub struct Sitl {
    /// Its `-I` instance.
    pub instance: u16,
    /// Its serial 0 (MAVLink TCP server, one client at a time) on 127.0.0.1.
    pub port: u16,
    /// Its working directory (`eeprom.bin`, `logs/`, `sitl.log`).
    pub dir: tempfile::TempDir,
    /// The watchdog shell leading its process group (pgid = its pid).
    child: Child,
    /// Closing this pipe ends the group.
    watchdog: Option<ChildStdin>,
    /// This process's claim on `instance`.
    claim: InstanceClaim,
}

#[derive(Debug)]
struct InstanceClaim(u16);

impl Drop for InstanceClaim {
    fn drop(&mut self) {
        CLAIMED
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .retain(|i| *i != self.0);
    }
}

/// An instance no thread of this process uses whose three serial ports are free.
fn claim_instance(skip_below: u16) -> Result<InstanceClaim> {
    let mut claimed = CLAIMED.lock().unwrap_or_else(|p| p.into_inner());
    for i in INSTANCES.filter(|i| *i >= skip_below) {
        if claimed.contains(&i) {
            continue;
        }
        let base = BASE_PORT + 10 * i;
        // SITL binds 0.0.0.0: serial 0, 1 and 2.
        if [base, base + 2, base + 3]
            .iter()
            .all(|p| TcpListener::bind(("0.0.0.0", *p)).is_ok())
        {
            claimed.push(i);
            return Ok(InstanceClaim(i));
        }
    }
    bail!("no free SITL instance in {INSTANCES:?} (ports 5760 + 10·I in use)")
}

impl Sitl {
    /// Starts SITL on the first free instance and returns once its serial 0 listens.
    pub fn start(files: &SitlFiles) -> Result<Sitl> {
        let mut next = *INSTANCES.start();
        let mut failures = String::new();
        // Another process may bind the ports between the check and SITL's bind:
        // then SITL exits and the next instance is tried.
        for _ in 0..3 {
            let claim = claim_instance(next)?;
            next = claim.0 + 1;
            match Sitl::start_instance(files, claim) {
                Ok(s) => return Ok(s),
                Err(e) => {
                    let _ = writeln!(failures, "{e:#}");
                }
            }
        }
        bail!("SITL did not start:\n{failures}")
    }

    fn start_instance(files: &SitlFiles, claim: InstanceClaim) -> Result<Sitl> {
        let instance = claim.0;
        let port = BASE_PORT + 10 * instance;
        let dir = tempfile::Builder::new().prefix("skymesh-sitl-").tempdir()?;
        let log = std::fs::File::create(dir.path().join("sitl.log"))?;
        let home = SITL_HOME.map(|v| v.to_string()).join(",");
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(WATCHDOG)
            .arg("sitl-watchdog")
            .arg(&files.binary)
            .args(["--model", "+", "--speedup", "1"])
            .arg(format!("-I{instance}"))
            .arg("--home")
            .arg(home)
            .arg("--defaults")
            .arg(&files.defaults)
            .current_dir(dir.path())
            .process_group(0)
            .stdin(Stdio::piped())
            .stdout(log.try_clone()?)
            .stderr(log)
            .spawn()
            .with_context(|| format!("starting {}", files.binary.display()))?;
        let watchdog = child.stdin.take();
        let mut sitl = Sitl {
            instance,
            port,
            dir,
            child,
            watchdog,
            claim,
        };
        // The line SITL prints once serial 0 listens (it then waits for a client
        // before it runs the vehicle). Not a connection attempt: serial 0 serves
        // one client, and that is autopilot-link.
        let start = Instant::now();
        loop {
            if sitl.log().contains("Waiting for connection") {
                return Ok(sitl);
            }
            if let Ok(Some(status)) = sitl.child.try_wait() {
                bail!(
                    "SITL instance {instance} exited ({status}) before listening on {port}:\n{}",
                    sitl.log()
                );
            }
            if start.elapsed() > LISTEN_TIMEOUT {
                bail!(
                    "SITL instance {instance} not listening on {port} after {LISTEN_TIMEOUT:?}:\n{}",
                    sitl.log()
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Everything SITL wrote to stdout and stderr.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("sitl.log")).unwrap_or_default()
    }

    /// Whether the autopilot (its watchdog) still runs.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Sitl {
    fn drop(&mut self) {
        if std::thread::panicking() {
            let log = self.log();
            let tail: Vec<&str> = log.lines().rev().take(40).collect();
            eprintln!(
                "===== SITL instance {} (port {}), last {} lines of its output =====",
                self.instance,
                self.port,
                tail.len()
            );
            for line in tail.iter().rev() {
                eprintln!("{line}");
            }
        }
        self.watchdog.take();
        if let Ok(pgid) = i32::try_from(self.child.id()) {
            let _ = killpg(Pid::from_raw(pgid), Signal::SIGKILL);
        }
        let _ = self.child.wait();
        let _ = &self.claim;
    }
}

/// Times the phases of a test and prints each as it ends (uncaptured):
/// `SITL phase <name>: <s> s (at <s> s)`.
#[derive(Debug)]
pub struct Phases {
    start: Instant,
    last: Instant,
    done: Vec<(String, Duration)>,
    notes: Vec<String>,
}

impl Default for Phases {
    fn default() -> Self {
        Phases::new()
    }
}

impl Phases {
    pub fn new() -> Phases {
        let now = Instant::now();
        Phases {
            start: now,
            last: now,
            done: Vec::new(),
            notes: Vec::new(),
        }
    }

    /// Ends the current phase (started by the previous `end` or by `new`); returns
    /// its duration.
    pub fn end(&mut self, name: &str) -> Duration {
        let now = Instant::now();
        let took = now - self.last;
        self.last = now;
        uncaptured(&format!(
            "SITL phase {name}: {:.1} s (at {:.1} s)\n",
            took.as_secs_f64(),
            (now - self.start).as_secs_f64()
        ));
        self.done.push((name.to_string(), took));
        took
    }

    /// Prints a measurement of the current phase (uncaptured) and keeps it for the
    /// summary.
    pub fn note(&mut self, text: &str) {
        uncaptured(&format!("SITL note: {text}\n"));
        self.notes.push(text.to_string());
    }

    /// Every phase so far, one `name: seconds` per line, the total, then the notes.
    pub fn summary(&self) -> String {
        let mut out = String::new();
        for (name, d) in &self.done {
            let _ = writeln!(out, "  {name}: {:.1} s", d.as_secs_f64());
        }
        let _ = writeln!(
            out,
            "  total: {:.1} s",
            (self.last - self.start).as_secs_f64()
        );
        for note in &self.notes {
            let _ = writeln!(out, "  {note}");
        }
        out
    }
}

/// A mesh flying ArduPilot SITL: the mesh is dropped (its processes killed) before
/// the autopilot.
#[derive(Debug)]
pub struct SitlMesh {
    pub mesh: Mesh,
    pub sitl: Sitl,
    pub phases: Phases,
}

impl SitlMesh {
    /// Starts SITL, then `opts`' mesh with vehicle 1's autopilot-link connected to
    /// it. `Ok(None)` after printing the skip line when there is no SITL.
    pub fn start(mut opts: MeshOptions) -> Result<Option<SitlMesh>> {
        let files = match locate()? {
            Ok(f) => f,
            Err(why) => {
                skip(&why);
                return Ok(None);
            }
        };
        let mut phases = Phases::new();
        let sitl = Sitl::start(&files)?;
        uncaptured(&format!(
            "SITL: {} instance {} on tcp 127.0.0.1:{} (working directory {})\n",
            files.binary.display(),
            sitl.instance,
            sitl.port,
            sitl.dir.path().display()
        ));
        phases.end("start SITL");
        opts.autopilot_tcp = Some(sitl.port);
        let mesh = Mesh::start(opts)?;
        phases.end("start mesh");
        Ok(Some(SitlMesh { mesh, sitl, phases }))
    }

    /// Waits until autopilot-link reports the link up, a 3D GPS fix, a healthy EKF
    /// (absolute horizontal and vertical position among its flags), a home and a
    /// valid position: what ArduCopter needs before it arms in GUIDED. Call inside a
    /// tokio runtime. Returns the status and state seen.
    pub async fn wait_ready(
        &mut self,
        bus: &MeshBus,
        timeout: Duration,
    ) -> Result<(VehicleStatus, VehicleState)> {
        let mut status = bus.subscriber::<VehicleStatus>(&topics::vehicle_status(1))?;
        let state = bus.subscriber::<VehicleState>(&topics::vehicle_state(1))?;
        let deadline = Instant::now() + timeout;
        let mut last: Option<VehicleStatus> = None;
        loop {
            if !self.sitl.is_running() {
                bail!(
                    "SITL exited while waiting for its EKF:\n{}",
                    self.sitl.log()
                );
            }
            if let Some(s) = status.recv_timeout(Duration::from_millis(500)).await? {
                last = Some(s);
            }
            if let Some(s) = last.filter(|s| {
                s.link_up == 1
                    && s.ekf_healthy == 1
                    && s.home_valid == 1
                    && s.gps_fix >= GpsFix::Fix3d.to_wire()
            }) {
                if let Some(p) = state.latest()?.filter(|p| p.position_valid == 1) {
                    return Ok((s, p));
                }
            }
            if Instant::now() > deadline {
                return Err(anyhow!(
                    "SITL not ready after {timeout:?} (link up, 3D fix, EKF position, home); \
                     last status: {last:?}"
                ));
            }
        }
    }
}
