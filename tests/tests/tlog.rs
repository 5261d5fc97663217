//! Flight logs end to end: the real supervisor, vehicle-sim and autopilot-link with
//! `[tlog]` in `arming` mode; the vehicle arms and takes off, the mesh stops (which
//! ends the recording and closes the file), and the one `.tlog` written is read
//! twice: here, frame by frame with the `mavlink` crate, and by pymavlink's
//! `mavlogdump.py` (a second implementation of the format, as operators use it).
//!
//! pymavlink missing (no `python3`, or no `pymavlink` module): that part prints one
//! line and is skipped, unless `SKYMESH_REQUIRE_PYMAVLINK=1` (CI), where it fails.

use std::path::{Path, PathBuf};
use std::process::Command as Process;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use mavlink::dialects::ardupilotmega::{MavCmd, MavMessage};
use mavlink::MavlinkReader;
use skymesh_e2e::ground::{runtime, Ground, PATIENCE};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{AckResult, Command, CommandSource, FlightMode};

/// Generous: a take-off to 10 m takes about 10 s on an idle machine.
const FLIGHT: Duration = Duration::from_secs(90);

fn micros_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_micros() as u64
}

/// One record of the log: the big-endian µs stamp and the frame's bytes.
struct Record {
    stamp_us: u64,
    frame: Vec<u8>,
}

/// Splits a tlog into records by the MAVLink headers (written here, independently
/// of autopilot-link's own reader); every byte must belong to a whole record.
fn records(bytes: &[u8]) -> Vec<Record> {
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        assert!(at + 11 <= bytes.len(), "a torn record at byte {at}");
        let stamp_us = u64::from_be_bytes(bytes[at..at + 8].try_into().unwrap());
        let f = &bytes[at + 8..];
        let len = match f[0] {
            0xFD => 12 + usize::from(f[1]) + if f[2] & 1 != 0 { 13 } else { 0 },
            0xFE => 8 + usize::from(f[1]),
            other => panic!("byte {}: {other:#x} is not a MAVLink magic byte", at + 8),
        };
        assert!(at + 8 + len <= bytes.len(), "a torn frame at byte {at}");
        out.push(Record {
            stamp_us,
            frame: f[..len].to_vec(),
        });
        at += 8 + len;
    }
    out
}

/// The logs in `dir` (every file there must be a finished log).
fn logs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    for p in &v {
        let name = p.file_name().unwrap().to_str().unwrap();
        assert!(
            name.starts_with("skymesh-v1-") && name.ends_with(".tlog"),
            "unexpected file {name} (a log left unfinished?)"
        );
    }
    v
}

#[test]
fn a_take_off_is_recorded_in_a_tlog_every_reader_parses() {
    let dir = tempfile::tempdir().unwrap();
    let opts = MeshOptions {
        autopilot_link_extra: format!(
            // No free-space floor: the temp dir may be a small tmpfs (retention is
            // unit-tested in autopilot-link).
            "[tlog]\ndir = \"{}\"\nmode = \"arming\"\nmin_free_mb = 0\n",
            dir.path().display()
        ),
        ..MeshOptions::default()
    };
    let started_us = micros_now();
    let mut mesh = Mesh::start(opts).unwrap();
    mesh.wait_running("autopilot-link", PATIENCE).unwrap();
    runtime().block_on(async {
        let mut g = Ground::new(&mesh, "tlog");
        g.wait_status("EKF healthy", |s| s.ekf_healthy != 0).await;
        // Disarmed on the ground: nothing is recorded yet.
        assert!(logs(dir.path()).is_empty());
        let ok = |a: skymesh_ipc_types::CommandAck, what: &str| {
            assert_eq!(a.result(), Some(AckResult::Accepted), "{what}: {a:?}");
        };
        let guided = Command::SetMode(FlightMode::Guided);
        ok(g.command(CommandSource::Operator, &guided).await, "GUIDED");
        let arm = Command::Arm { force: false };
        ok(g.command(CommandSource::Operator, &arm).await, "ARM");
        let takeoff = Command::Takeoff { alt_rel_m: 10.0 };
        ok(
            g.command(CommandSource::Operator, &takeoff).await,
            "TAKEOFF",
        );
        // The operator keeps its flight authority while the take-off flies.
        let deadline = Instant::now() + FLIGHT;
        let mut grabbed = Instant::now();
        loop {
            let s = g.state.recv_timeout(PATIENCE).await.unwrap();
            let s = s.expect("VehicleState while taking off");
            if s.alt_rel_m > 5.0 {
                break;
            }
            assert!(Instant::now() < deadline, "no take-off: {s:?}");
            if grabbed.elapsed() >= Duration::from_secs(1) {
                grabbed = Instant::now();
                g.send(CommandSource::Operator, &Command::GrabFlightAuthority);
            }
        }
    });
    // Stopping ends the connection, hence the recording, and closes the file.
    mesh.stop(Duration::from_secs(20)).unwrap();
    let ended_us = micros_now();

    let found = logs(dir.path());
    assert_eq!(found.len(), 1, "one flight, one log: {found:?}");
    let path = &found[0];
    let recs = records(&std::fs::read(path).unwrap());
    let mut heartbeats = 0;
    let mut own_rate_requests = 0;
    let mut rel_alt_mm = Vec::new();
    for (i, r) in recs.iter().enumerate() {
        assert!(
            (started_us..=ended_us).contains(&r.stamp_us),
            "record {i}: stamp {} µs outside the test's {started_us}..={ended_us}",
            r.stamp_us
        );
        let mut reader = MavlinkReader::new(r.frame.as_slice());
        let (_, msg) = reader
            .read_any_message::<MavMessage>()
            .unwrap_or_else(|e| panic!("record {i} does not parse: {e:?}"));
        match msg {
            MavMessage::HEARTBEAT(_) => heartbeats += 1,
            MavMessage::GLOBAL_POSITION_INT(p) => rel_alt_mm.push(p.relative_alt),
            // autopilot-link's own frames are in the log too: the armed vehicle's
            // 50 Hz ATTITUDE request follows the armed HEARTBEAT that opened the log.
            MavMessage::COMMAND_LONG(c)
                if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL && c.param2 == 20_000.0 =>
            {
                own_rate_requests += 1
            }
            _ => {}
        }
    }
    assert!(heartbeats > 0, "no HEARTBEAT in {} records", recs.len());
    assert!(!rel_alt_mm.is_empty(), "no GLOBAL_POSITION_INT");
    assert!(
        own_rate_requests > 0,
        "autopilot-link's armed-rate SET_MESSAGE_INTERVAL is not in the log"
    );
    let first = rel_alt_mm[0];
    let top = *rel_alt_mm.iter().max().unwrap();
    assert!(first < 1000, "the log starts on the ground: {first} mm");
    assert!(top > 5000, "the take-off is in the log: at most {top} mm");
    println!(
        "tlog: {} ({} records, {} bytes): {heartbeats} HEARTBEAT, {} GLOBAL_POSITION_INT, \
         relative altitude {first} → {top} mm",
        path.display(),
        recs.len(),
        std::fs::metadata(path).unwrap().len(),
        rel_alt_mm.len()
    );
    pymavlink_check(path, &recs, &mesh);
}

/// `mavlogdump.py --format json` over the log: every record is a message (none is
/// BAD_DATA), with our stamps as its timestamps, HEARTBEAT and GLOBAL_POSITION_INT
/// among them, and the take-off in the relative altitude.
fn pymavlink_check(path: &Path, recs: &[Record], mesh: &Mesh) {
    let required = std::env::var("SKYMESH_REQUIRE_PYMAVLINK").is_ok_and(|v| v == "1");
    let has = Process::new("python3")
        .args(["-c", "import pymavlink.tools"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has {
        assert!(
            !required,
            "SKYMESH_REQUIRE_PYMAVLINK=1 but python3 with pymavlink is not available"
        );
        println!("tlog: pymavlink not available (python3 -m pip install pymavlink): mavlogdump check SKIPPED");
        return;
    }
    // `-m` runs the installed mavlogdump.py whether or not its script is on PATH.
    let out = Process::new("python3")
        .args(["-m", "pymavlink.tools.mavlogdump", "--format", "json"])
        .arg(path)
        .env("MAVLINK20", "1")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "mavlogdump.py failed: {}\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
        mesh.output()
    );
    let msgs: Vec<serde_json::Value> = stdout
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    let kind = |m: &serde_json::Value| m["meta"]["type"].as_str().unwrap_or("").to_string();
    let bad: Vec<_> = msgs.iter().filter(|m| kind(m) == "BAD_DATA").collect();
    assert!(bad.is_empty(), "mavlogdump.py found bad data: {bad:?}");
    assert_eq!(
        msgs.len(),
        recs.len(),
        "mavlogdump.py read {} messages of {} records",
        msgs.len(),
        recs.len()
    );
    for (i, (m, r)) in msgs.iter().zip(recs).enumerate() {
        let t = m["meta"]["timestamp"].as_f64().unwrap();
        assert!(
            (t - r.stamp_us as f64 / 1e6).abs() < 1e-3,
            "message {i}: pymavlink's timestamp {t} s, ours {} µs",
            r.stamp_us
        );
    }
    let count = |t: &str| msgs.iter().filter(|m| kind(m) == t).count();
    assert!(count("HEARTBEAT") > 0);
    let alts: Vec<i64> = msgs
        .iter()
        .filter(|m| kind(m) == "GLOBAL_POSITION_INT")
        .map(|m| m["data"]["relative_alt"].as_i64().unwrap())
        .collect();
    assert!(!alts.is_empty(), "mavlogdump.py: no GLOBAL_POSITION_INT");
    let top = *alts.iter().max().unwrap();
    assert!(
        alts[0] < 1000 && top > 5000,
        "mavlogdump.py: relative altitude {} → {top} mm",
        alts[0]
    );
    println!(
        "tlog: mavlogdump.py read {} messages ({} HEARTBEAT, {} GLOBAL_POSITION_INT), \
         relative altitude {} → {top} mm",
        msgs.len(),
        count("HEARTBEAT"),
        alts.len(),
        alts[0]
    );
}

/// CPU time of every live thread of `pid` (`/proc/<pid>/task/*/schedstat`), ns.
fn cpu_ns(pid: u32) -> u64 {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .unwrap()
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// One mesh with ATTITUDE at 50 Hz on the ground, recording (`connection` mode) or
/// not: autopilot-link's CPU over `window` (after the rates settled), and the
/// frames recorded in it.
fn recording_cost(tlog: bool, window: Duration) -> (f64, usize) {
    let dir = tempfile::tempdir().unwrap();
    let mut extra = "ground_attitude_hz = 50.0\n".to_string();
    if tlog {
        extra += &format!(
            "[tlog]\ndir = \"{}\"\nmode = \"connection\"\n",
            dir.path().display()
        );
    }
    let opts = MeshOptions {
        autopilot_link_extra: extra,
        attitude_hz: 50.0,
        ..MeshOptions::default()
    };
    let mut mesh = Mesh::start(opts).unwrap();
    let pid = mesh.wait_running("autopilot-link", PATIENCE).unwrap();
    runtime().block_on(async {
        let mut g = Ground::new(&mesh, "tlog-bench");
        g.wait_status("EKF healthy", |s| s.ekf_healthy != 0).await;
    });
    std::thread::sleep(Duration::from_secs(3));
    let (t0, cpu0) = (micros_now(), cpu_ns(pid));
    std::thread::sleep(window);
    let (t1, cpu1) = (micros_now(), cpu_ns(pid));
    mesh.stop(Duration::from_secs(20)).unwrap();
    let frames = logs(dir.path())
        .iter()
        .flat_map(|p| records(&std::fs::read(p).unwrap()))
        .filter(|r| (t0..t1).contains(&r.stamp_us))
        .count();
    let share = (cpu1 - cpu0) as f64 / ((t1 - t0) as f64 * 1e3);
    (share, frames)
}

/// Recording cost at 50 Hz ATTITUDE (docs/benchmarks.md): autopilot-link's CPU
/// with and without `[tlog]`, alternating, over the same window.
/// `cargo test -p skymesh-e2e --test tlog -- --ignored --nocapture`
/// (`TLOG_BENCH_S`: the window, seconds, default 20; `TLOG_BENCH_ROUNDS`, default 2).
#[test]
#[ignore = "benchmark: prints numbers, asserts nothing about them"]
fn tlog_recording_cost_at_50_hz_attitude() {
    let env = |k: &str, d: u64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let window = Duration::from_secs(env("TLOG_BENCH_S", 20));
    let rounds = env("TLOG_BENCH_ROUNDS", 2);
    let (mut off, mut on, mut frames) = (Vec::new(), Vec::new(), 0);
    for round in 1..=rounds {
        let (cpu_off, _) = recording_cost(false, window);
        let (cpu_on, n) = recording_cost(true, window);
        println!(
            "round {round}: autopilot-link CPU {:.2} % without tlog, {:.2} % recording \
             ({:.1} frames/s recorded)",
            cpu_off * 100.0,
            cpu_on * 100.0,
            n as f64 / window.as_secs_f64()
        );
        off.push(cpu_off);
        on.push(cpu_on);
        frames += n;
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let fps = frames as f64 / (window.as_secs_f64() * rounds as f64);
    let extra = mean(&on) - mean(&off);
    println!(
        "tlog recording cost: {:.2} % → {:.2} % of a core (+{:.2} points, {:.1} µs per recorded \
         frame at {fps:.1} frames/s)",
        mean(&off) * 100.0,
        mean(&on) * 100.0,
        extra * 100.0,
        extra * 1e6 / fps
    );
}
