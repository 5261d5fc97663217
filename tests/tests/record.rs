//! `skymesh record` and `skymesh replay` (crates/record) through the real binaries:
//! record a flying mesh's vehicle topics and swarm state to MCAP, stop the recorder
//! with SIGTERM, read the file back in Rust (the `mcap` crate) and with a second
//! implementation (the `mcap` Python package, when python3 has it), then replay it
//! into a mesh without vehicle-sim and autopilot-link and watch the GroundControl
//! gateway's pose broadcast fly the recorded trajectory.

use std::collections::{BTreeMap, HashSet};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use serde_json::Value;
use skymesh_e2e::ground::{runtime, Ground};
use skymesh_e2e::{bin_dir, binary, free_port, free_udp_port, repo_root, Mesh, MeshOptions};
use skymesh_runtime::Domain;

const STARTUP: Duration = Duration::from_secs(30);
/// Generous bounds for events, never for how fast they come.
const FLIGHT: Duration = Duration::from_secs(120);
/// How long the recorder records (the take-off, then hovering).
const RECORD_FOR: Duration = Duration::from_secs(20);
const STATE: &str = "skymesh/vehicle/1/state";
const SWARM: &str = "skymesh/swarm/state";

/// Kills a child process on drop (a failed test leaves nothing running).
struct Reaped(Option<Child>);

impl Reaped {
    fn child(&mut self) -> &mut Child {
        self.0.as_mut().unwrap()
    }

    /// SIGTERM, then waits for the exit (bounded so a hung process fails the test).
    fn terminate(&mut self, what: &str) -> std::process::ExitStatus {
        let child = self.0.as_mut().unwrap();
        kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM).unwrap();
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                self.0 = None;
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "{what} did not exit after SIGTERM"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn skymesh(domain: &str, dir: &Path, log: &str) -> Command {
    let mut cmd = Command::new(binary("skymesh"));
    let file = |suffix: &str| std::fs::File::create(dir.join(format!("{log}.{suffix}"))).unwrap();
    cmd.env("SKYMESH_DOMAIN", domain)
        .env(
            "SKYMESH_IPC_CONFIG",
            repo_root().join("deploy/iceoryx2.toml"),
        )
        .stdin(Stdio::null())
        .stdout(file("stdout"))
        .stderr(file("stderr"));
    cmd
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

/// Records the mesh's vehicle topics and swarm state while vehicle 1 takes off;
/// returns the recording's path (in `dir`).
fn record_a_takeoff(dir: &Path) -> PathBuf {
    let mut mesh = Mesh::start(MeshOptions {
        swarm: true,
        ..Default::default()
    })
    .unwrap();
    // Something listens at the pose broadcast's destination: the gateway watches
    // the swarm state, so the swarm queue publishes it at its full rate.
    let _pose_sink = UdpSocket::bind(("127.0.0.1", mesh.pose_port)).unwrap();
    for s in ["autopilot-link", "swarm-queue", "groundcontrol-gateway"] {
        mesh.wait_running(s, STARTUP).unwrap();
    }
    let path = dir.join("takeoff.mcap");
    let mut recorder = Reaped(Some(
        skymesh(&mesh.domain, dir, "record")
            .args(["record", "-o"])
            .arg(&path)
            // A glob (every vehicle topic, found on the bus) and an exact name.
            .args(["skymesh/vehicle/*/*", SWARM])
            .spawn()
            .unwrap(),
    ));
    let log = dir.join("record.stderr");
    // The recorder names each topic it records: wait for the glob's.
    let deadline = Instant::now() + STARTUP;
    while !(read(&log).contains(&format!("recording {STATE} "))
        && read(&log).contains(&format!("recording {SWARM} ")))
    {
        assert!(
            recorder.child().try_wait().unwrap().is_none(),
            "recorder exited: {}",
            read(&log)
        );
        assert!(Instant::now() < deadline, "recorder: {}", read(&log));
        std::thread::sleep(Duration::from_millis(50));
    }
    let started = Instant::now();

    let rt = runtime();
    rt.block_on(async {
        let mut operator = Ground::new(&mesh, "e2e-record");
        operator.take_off(10.0).await;
        // Keep flight authority while the take-off flies (a grab a second), until
        // the vehicle is above 5 m and the recording is RECORD_FOR long.
        let deadline = Instant::now() + FLIGHT;
        let mut top = 0.0f32;
        while top <= 5.0 || started.elapsed() < RECORD_FOR {
            assert!(Instant::now() < deadline, "no climb above 5 m: top {top} m");
            if let Some(s) = operator
                .state
                .recv_timeout(Duration::from_secs(1))
                .await
                .unwrap()
            {
                top = top.max(s.alt_rel_m);
            }
            operator.keep_authority();
        }
        println!("climbed to {top:.2} m while recording");
    });
    let status = recorder.terminate("skymesh record");
    let log = read(&log);
    assert!(
        status.success(),
        "skymesh record after SIGTERM: {status}\n{log}"
    );
    println!("{}", log.trim());
    drop(mesh);
    path
}

/// Every message of the recording, read with the `mcap` crate: (topic, JSON).
fn read_in_rust(path: &Path) -> Vec<(String, Value)> {
    let bytes = std::fs::read(path).unwrap();
    // Finished and indexed: a summary with statistics, channels, chunk indexes.
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("the recording has a summary section");
    assert!(!summary.chunk_indexes.is_empty(), "no chunk index");
    let stats = summary.stats.expect("statistics record");
    let mut schemas = BTreeMap::new();
    for ch in summary.channels.values() {
        let schema = ch.schema.as_ref().expect("every channel has a schema");
        assert_eq!(schema.encoding, "jsonschema", "{}", ch.topic);
        assert_eq!(ch.message_encoding, "json", "{}", ch.topic);
        schemas.insert(ch.topic.clone(), schema.name.clone());
    }
    assert_eq!(
        schemas.get(STATE).map(String::as_str),
        Some("skymesh.VehicleState.v2")
    );
    assert_eq!(
        schemas.get(SWARM).map(String::as_str),
        Some("skymesh.SwarmState.v1")
    );
    for topic in ["status", "command", "command_ack", "authority"] {
        assert!(
            schemas.contains_key(&format!("skymesh/vehicle/1/{topic}")),
            "{topic} not recorded: {schemas:?}"
        );
    }
    let mut out = Vec::new();
    let mut last_log_time = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert!(m.log_time >= last_log_time, "log times go back");
        last_log_time = m.log_time;
        out.push((
            m.channel.topic.clone(),
            serde_json::from_slice(&m.data).unwrap(),
        ));
    }
    assert_eq!(out.len() as u64, stats.message_count);
    out
}

fn of<'a>(msgs: &'a [(String, Value)], topic: &str) -> Vec<&'a Value> {
    msgs.iter()
        .filter(|(t, _)| t == topic)
        .map(|(_, v)| v)
        .collect()
}

fn floats(values: &[&Value], field: impl Fn(&Value) -> &Value) -> Vec<f64> {
    values.iter().map(|v| field(v).as_f64().unwrap()).collect()
}

/// The Python reader: validates every message against its channel's JSON schema
/// and prints what the Rust side compares.
const PY_READER: &str = r##"
import json, sys
from mcap.reader import make_reader

def types_of(s):
    t = s.get("type")
    return t if isinstance(t, list) else ([t] if t else [])

def check(v, s, root, where):
    if "$ref" in s:
        ref = s["$ref"]
        assert ref.startswith("#/$defs/"), ref
        s = root["$defs"][ref[len("#/$defs/"):]]
    if "anyOf" in s:
        errors = []
        for alt in s["anyOf"]:
            try:
                check(v, alt, root, where)
                break
            except AssertionError as e:
                errors.append(str(e))
        else:
            raise AssertionError(f"{where}: no alternative fits {v!r}: {errors}")
    ts = types_of(s)
    if ts:
        ok = {
            "object": isinstance(v, dict), "array": isinstance(v, list),
            "string": isinstance(v, str), "boolean": isinstance(v, bool),
            "integer": isinstance(v, int) and not isinstance(v, bool),
            "number": isinstance(v, (int, float)) and not isinstance(v, bool),
            "null": v is None,
        }
        assert any(ok[t] for t in ts), f"{where}: {v!r} is not {ts}"
    if "enum" in s:
        assert v in s["enum"], f"{where}: {v!r} not in {s['enum']}"
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        if "minimum" in s: assert v >= s["minimum"], f"{where}: {v} < {s['minimum']}"
        if "maximum" in s: assert v <= s["maximum"], f"{where}: {v} > {s['maximum']}"
    if isinstance(v, dict) and "properties" in s:
        props = s["properties"]
        assert set(v) == set(props), f"{where}: fields {sorted(v)} != schema {sorted(props)}"
        for k in s.get("required", []):
            assert k in v, f"{where}: {k} missing"
        for k, x in v.items():
            check(x, props[k], root, f"{where}.{k}")
    if isinstance(v, list):
        if "minItems" in s: assert len(v) >= s["minItems"], where
        if "maxItems" in s: assert len(v) <= s["maxItems"], where
        if isinstance(s.get("items"), dict):
            for i, x in enumerate(v):
                check(x, s["items"], root, f"{where}[{i}]")

counts, alt, modes, swarm_z = {}, [], [], []
schemas = {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages():
        assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
        if schema.id not in schemas:
            schemas[schema.id] = json.loads(schema.data)
        root = schemas[schema.id]
        assert root.get("title") == schema.name, (root.get("title"), schema.name)
        v = json.loads(message.data)
        check(v, root, root, channel.topic)
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
        if channel.topic == "skymesh/vehicle/1/state":
            alt.append(v["alt_rel_m"])
        elif channel.topic == "skymesh/vehicle/1/status":
            modes.append(v["mode"])
        elif channel.topic == "skymesh/swarm/state":
            swarm_z.append(v["drones"][0]["tracking"][2])
print(json.dumps({"counts": counts, "alt_rel_m": alt, "modes": modes, "swarm_z": swarm_z}))
"##;

fn python_has_mcap() -> bool {
    Command::new("python3")
        .args(["-c", "import mcap.reader"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Reads the recording with the Python `mcap` package and compares with the Rust
/// reading; skipped (one line) when python3 lacks it, unless
/// `SKYMESH_REQUIRE_PY_MCAP=1`.
fn read_in_python(dir: &Path, path: &Path, msgs: &[(String, Value)]) {
    if !python_has_mcap() {
        assert!(
            std::env::var("SKYMESH_REQUIRE_PY_MCAP").as_deref() != Ok("1"),
            "SKYMESH_REQUIRE_PY_MCAP=1 but python3 cannot import mcap (pip install mcap)"
        );
        println!("SKIPPED the Python reading: python3 has no `mcap` package (pip install mcap; SKYMESH_REQUIRE_PY_MCAP=1 makes this fail)");
        return;
    }
    let script = dir.join("read_mcap.py");
    std::fs::write(&script, PY_READER).unwrap();
    let out = Command::new("python3")
        .arg(&script)
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "the Python reader failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let py: Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut counts = BTreeMap::new();
    for (topic, _) in msgs {
        *counts.entry(topic.clone()).or_insert(0u64) += 1;
    }
    let py_counts: BTreeMap<String, u64> = serde_json::from_value(py["counts"].clone()).unwrap();
    assert_eq!(py_counts, counts);
    let state = of(msgs, STATE);
    let py_alt: Vec<f64> = serde_json::from_value(py["alt_rel_m"].clone()).unwrap();
    assert_eq!(py_alt, floats(&state, |v| &v["alt_rel_m"]));
    let py_modes: Vec<String> = serde_json::from_value(py["modes"].clone()).unwrap();
    let modes: Vec<String> = of(msgs, "skymesh/vehicle/1/status")
        .iter()
        .map(|v| v["mode"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(py_modes, modes);
    let py_z: Vec<f64> = serde_json::from_value(py["swarm_z"].clone()).unwrap();
    assert_eq!(
        py_z,
        floats(&of(msgs, SWARM), |v| &v["drones"][0]["tracking"][2])
    );
    println!(
        "the Python mcap reader agrees: {} messages, every one valid against its schema",
        msgs.len()
    );
}

/// A mesh of the GroundControl gateway alone (no vehicle-sim, autopilot-link or
/// swarm queue), its pose broadcast sent to `pose_port`.
fn start_gateway_mesh(dir: &Path, domain: &str, pose_port: u16) -> Reaped {
    let bins = bin_dir();
    std::fs::write(
        dir.join("groundcontrol-gateway.toml"),
        format!(
            "listen = \"127.0.0.1:{}\"\nprivileged = [\"127.0.0.1\"]\n\
             broadcast_destinations = [\"127.0.0.1:{pose_port}\"]\n\
             broadcast_bind = \"127.0.0.1:0\"\n",
            free_port()
        ),
    )
    .unwrap();
    std::fs::write(
        dir.join("skymesh.toml"),
        format!(
            "[supervisor]\nmetrics = \"127.0.0.1:0\"\nipc_config = \"{}\"\n\n\
             [[service]]\nname = \"groundcontrol-gateway\"\n\
             binary = \"{}/skymesh-groundcontrol-gateway\"\n\
             config = \"groundcontrol-gateway.toml\"\n",
            repo_root().join("deploy/iceoryx2.toml").display(),
            bins.display()
        ),
    )
    .unwrap();
    let mut up = skymesh(domain, dir, "supervisor");
    up.arg("up")
        .arg("--config")
        .arg(dir.join("skymesh.toml"))
        .arg("--status-file")
        .arg(dir.join("metrics.addr"))
        .arg("--no-table")
        .env_remove("NOTIFY_SOCKET");
    let mut mesh = Reaped(Some(up.spawn().unwrap()));
    // Running: `skymesh status` exits 0 once every service runs.
    let deadline = Instant::now() + STARTUP;
    loop {
        assert!(
            mesh.child().try_wait().unwrap().is_none(),
            "gateway mesh exited: {}",
            read(&dir.join("supervisor.stderr"))
        );
        let addr = read(&dir.join("metrics.addr"));
        if !addr.trim().is_empty() {
            let ok = Command::new(binary("skymesh"))
                .args(["status", "--metrics", addr.trim()])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success());
            if ok {
                return mesh;
            }
        }
        assert!(
            Instant::now() < deadline,
            "gateway not running: {}",
            read(&dir.join("supervisor.stderr"))
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Removes the replay mesh's iceoryx2 files.
struct DomainFiles(String);

impl Drop for DomainFiles {
    fn drop(&mut self) {
        if let Ok(d) = Domain::load(&self.0, Some(&repo_root().join("deploy/iceoryx2.toml"))) {
            d.cleanup_dead_nodes();
            if d.live_nodes().is_empty() {
                d.remove_leftover_files();
            }
        }
    }
}

#[test]
fn a_recorded_takeoff_reads_back_and_replays_into_the_pose_broadcast() {
    let dir = tempfile::Builder::new()
        .prefix("skymesh-record-")
        .tempdir()
        .unwrap();
    let d = dir.path();
    let path = record_a_takeoff(d);
    let size = std::fs::metadata(&path).unwrap().len();

    // The Rust reading: what was flown.
    let msgs = read_in_rust(&path);
    let state = of(&msgs, STATE);
    let alt = floats(&state, |v| &v["alt_rel_m"]);
    println!(
        "recording: {} messages, {size} bytes, {} states of vehicle 1",
        msgs.len(),
        state.len()
    );
    assert!(alt.len() > 20, "{} states", alt.len());
    let top = alt.iter().copied().fold(f64::MIN, f64::max);
    assert!(
        alt[0] < 1.0 && top > 5.0,
        "altitude does not rise: {} → {top}",
        alt[0]
    );
    let status = of(&msgs, "skymesh/vehicle/1/status");
    assert!(
        status
            .iter()
            .any(|s| s["mode"] == "guided" && s["armed"] == 1),
        "never armed in guided"
    );
    assert!(
        of(&msgs, "skymesh/vehicle/1/command")
            .iter()
            .any(|c| c["kind"] == "takeoff" && c["source"] == "operator" && c["f"][0] == 10.0),
        "the take-off command is not in the recording"
    );
    assert!(
        of(&msgs, "skymesh/vehicle/1/command_ack")
            .iter()
            .any(|a| a["result"] == "accepted"),
        "no accepted command ack"
    );
    let swarm = of(&msgs, SWARM);
    let swarm_z = floats(&swarm, |v| &v["drones"][0]["tracking"][2]);
    assert!(swarm_z.len() > 10, "{} swarm states", swarm_z.len());
    let swarm_top = swarm_z.iter().copied().fold(f64::MIN, f64::max);
    assert!(
        swarm_top > 5.0,
        "swarm tracking z never above 5 m: {swarm_top}"
    );

    // The second implementation.
    read_in_python(d, &path, &msgs);

    // Replay into a mesh of the GroundControl gateway alone.
    let replay_dir = d.join("replay");
    std::fs::create_dir_all(&replay_dir).unwrap();
    let domain = format!("e2erec{}", std::process::id());
    let _files = DomainFiles(domain.clone());
    let pose_port = free_udp_port();
    let poses = UdpSocket::bind(("127.0.0.1", pose_port)).unwrap();
    poses
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut gateway = start_gateway_mesh(&replay_dir, &domain, pose_port);
    let mut replay = Reaped(Some(
        skymesh(&domain, &replay_dir, "replay")
            .arg("replay")
            .arg(&path)
            .args(["--rate", "2"])
            .spawn()
            .unwrap(),
    ));
    // Every pose of drone 1 broadcast while the replay runs (and a little after).
    let recorded: HashSet<[u32; 3]> = swarm
        .iter()
        .map(|v| {
            let t = &v["drones"][0]["tracking"];
            [0, 1, 2].map(|i| (t[i].as_f64().unwrap() as f32).to_bits())
        })
        .collect();
    let mut seen_z = Vec::new();
    let mut buf = vec![0u8; 65_536];
    let deadline = Instant::now() + FLIGHT;
    let mut replay_done = None;
    loop {
        if replay_done.is_none() {
            if let Some(status) = replay.child().try_wait().unwrap() {
                replay_done = Some((status, Instant::now()));
                replay.0 = None;
            }
        }
        if let Some((_, at)) = replay_done {
            if at.elapsed() > Duration::from_secs(1) {
                break;
            }
        }
        assert!(Instant::now() < deadline, "replay did not end");
        let Ok(n) = poses.recv(&mut buf) else {
            continue;
        };
        for p in gc_proto::decode_pose_datagram(&buf[..n]).unwrap() {
            if p.id == 1 {
                assert!(
                    recorded.contains(&p.tracking.map(f32::to_bits)),
                    "a broadcast pose {:?} is no recorded position",
                    p.tracking
                );
                seen_z.push(p.tracking[2]);
            }
        }
    }
    let (status, _) = replay_done.unwrap();
    let replay_log = read(&replay_dir.join("replay.stderr"));
    assert!(status.success(), "skymesh replay: {status}\n{replay_log}");
    println!("{}", replay_log.trim());
    let gw_status = gateway.terminate("the gateway mesh");
    assert!(gw_status.success(), "gateway mesh: {gw_status}");
    assert!(
        seen_z.len() > 10,
        "{} poses of drone 1 broadcast",
        seen_z.len()
    );
    let first = seen_z[0];
    let top = seen_z.iter().copied().fold(f32::MIN, f32::max);
    println!(
        "pose broadcast during the replay: {} poses of drone 1, z {first:.2} → top {top:.2} m (recorded top {swarm_top:.2} m)",
        seen_z.len()
    );
    assert!(first < 1.0, "the replayed trajectory starts at {first} m");
    assert!(
        top > 5.0,
        "the replayed trajectory never climbs above 5 m: {top}"
    );
}
