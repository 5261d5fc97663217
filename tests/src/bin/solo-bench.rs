//! Solo app packet in → first resulting MAVLink setpoint out, through the real mesh.
//!
//! Runs vehicle-sim, autopilot-link, solo-gateway and shot-engine under the
//! supervisor, with a tap between autopilot-link and vehicle-sim that timestamps every
//! `SET_POSITION_TARGET_*` frame. The vehicle hovers at 10 m; each round enters orbit
//! over TCP 5507, then measures:
//!
//! - `roi`: SOLO_MESSAGE_LOCATION (the orbit's ROI) → the first setpoint on the wire
//!   (includes the engine's GUIDED switch, authority grab and ROI command);
//! - `speed`: SOLO_SHOT_OPTIONS (cruise speed change) while orbiting → the first
//!   setpoint whose velocity reflects it (faster than every setpoint of the 500 ms
//!   before); `speed>.05`: → the first one faster than 0.05 m/s (the acceleration
//!   limit, 2 m/s², gets there 25 ms of steps after the change);
//!
//! and a baseline in the same run: the same TLV packet over loopback TCP to a thread
//! that decodes it and writes a MAVLink setpoint over a second loopback TCP socket to
//! the same tap (what a single-process translator would cost).
//!
//! `cargo run --release -p skymesh-e2e --bin solo-bench -- --rounds 30 [--realtime 20] [--vision]`
//!
//! `--realtime P` / `--vision`: the control path real-time on CPU 1 as shipped
//! (solo-gateway and shot-engine at P, autopilot-link at P + 10), the camera and
//! the vision pipeline in the mesh (`bench::ControlPath`).

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use mavlink::dialects::ardupilotmega::{MavMessage, SET_POSITION_TARGET_LOCAL_NED_DATA};
use mavlink::MavHeader;
use mavlink_frame::{FrameParser, RawFrame};
use skymesh_e2e::bench::{arg, bench_thread_realtime, percentile, start_tapped_mesh, ControlPath};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{topics, VehicleState};
use solo_proto::{shots, Location, SoloMessage};

/// One setpoint seen on the wire: when, and its NED velocity.
#[derive(Debug, Clone, Copy)]
struct Seen {
    at: Instant,
    /// MAVLink message id: 84/86 setpoints, 11 SET_MODE, 75/76 COMMAND_INT/LONG.
    msgid: u32,
    vel: [f32; 3],
}

fn is_setpoint(s: &Seen) -> bool {
    s.msgid == 84 || s.msgid == 86
}

/// Reports every frame `parser` has whole: SET_POSITION_TARGET_* with their velocity,
/// SET_MODE and COMMAND_* without (autopilot-link's own frame parser, CRC checked).
fn scan_frames(parser: &mut FrameParser, now: Instant, out: &mpsc::Sender<Seen>) {
    while let Some(frame) = parser.next_frame() {
        let msgid = frame.message_id();
        // SET_MODE (11), COMMAND_INT (75), COMMAND_LONG (76): the time is enough.
        let vel = if matches!(msgid, 11 | 75 | 76) {
            [0.0; 3]
        } else {
            match frame.decode() {
                Ok(MavMessage::SET_POSITION_TARGET_LOCAL_NED(m)) => [m.vx, m.vy, m.vz],
                Ok(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(m)) => [m.vx, m.vy, m.vz],
                _ => continue,
            }
        };
        let _ = out.send(Seen {
            at: now,
            msgid,
            vel,
        });
    }
}

/// Reads TLV frames from the app connection into a channel.
fn app_reader(mut stream: TcpStream, out: mpsc::Sender<SoloMessage>) {
    std::thread::spawn(move || {
        let mut header = [0u8; 8];
        loop {
            if stream.read_exact(&mut header).is_err() {
                return;
            }
            let ty = u32::from_le_bytes(header[..4].try_into().expect("4 bytes"));
            let len = u32::from_le_bytes(header[4..].try_into().expect("4 bytes")) as usize;
            let mut value = vec![0u8; len.min(1 << 16)];
            if stream.read_exact(&mut value).is_err() {
                return;
            }
            if let Ok(m) = SoloMessage::decode(ty, &value) {
                let _ = out.send(m);
            }
        }
    });
}

fn expect_app(
    rx: &mpsc::Receiver<SoloMessage>,
    what: &str,
    f: impl Fn(&SoloMessage) -> bool,
) -> Result<()> {
    let deadline = Instant::now() + Duration::from_secs(10);
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        if let Ok(m) = rx.recv_timeout(left) {
            if f(&m) {
                return Ok(());
            }
        }
    }
    bail!("no {what} from the shot engine")
}

/// Waits for the first setpoint after `t0` that satisfies `f`; returns its latency.
fn first_setpoint(
    rx: &mpsc::Receiver<Seen>,
    t0: Instant,
    f: impl Fn(&Seen) -> bool,
) -> Result<Duration> {
    let deadline = t0 + Duration::from_secs(10);
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(s) if s.at >= t0 && f(&s) => return Ok(s.at - t0),
            Ok(_) => {}
            Err(_) => break,
        }
    }
    bail!("no setpoint within 10 s")
}

/// A setpoint carries a speed change once it is this much faster than every
/// setpoint of the 500 ms before (the smallest event step changes it by
/// `max_accel` × 1 ms = 2 mm/s).
const SPEED_EPS_MPS: f32 = 0.001;

/// Waits for the first setpoints after `t0` satisfying `f` and `g`; their latencies.
fn first_two(
    rx: &mpsc::Receiver<Seen>,
    t0: Instant,
    f: impl Fn(&Seen) -> bool,
    g: impl Fn(&Seen) -> bool,
) -> Result<(Duration, Duration)> {
    let deadline = t0 + Duration::from_secs(10);
    let (mut a, mut b) = (None, None);
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(s) if s.at >= t0 => {
                if a.is_none() && f(&s) {
                    a = Some(s.at - t0);
                }
                if b.is_none() && g(&s) {
                    b = Some(s.at - t0);
                }
                if let (Some(a), Some(b)) = (a, b) {
                    return Ok((a, b));
                }
            }
            Ok(_) => {}
            Err(_) => break,
        }
    }
    bail!("no setpoint within 10 s")
}

fn drain<T>(rx: &mpsc::Receiver<T>) {
    while rx.try_recv().is_ok() {}
}

/// Operator: GUIDED, arm, take off to 10 m, then give authority back.
fn take_off(mesh: &Mesh) -> Result<()> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?
        .block_on(skymesh_e2e::bench::take_off(mesh, 10.0))
}

/// The baseline: the same TLV over loopback TCP, decoded by a thread that writes one
/// MAVLink SET_POSITION_TARGET_LOCAL_NED over a second loopback socket to a reader
/// that scans it exactly as the tap does.
fn baseline(rounds: usize) -> Result<Vec<f64>> {
    let app_side = TcpListener::bind("127.0.0.1:0")?;
    let wire_side = TcpListener::bind("127.0.0.1:0")?;
    let app_addr = app_side.local_addr()?;
    let wire_addr = wire_side.local_addr()?;
    let (seen_tx, seen_rx) = mpsc::channel();
    std::thread::spawn(move || {
        let Ok((mut wire_in, _)) = wire_side.accept() else {
            return;
        };
        let mut parser = FrameParser::new();
        let mut buf = [0u8; 4096];
        while let Ok(n) = wire_in.read(&mut buf) {
            if n == 0 {
                break;
            }
            let now = Instant::now();
            parser.push(&buf[..n]);
            scan_frames(&mut parser, now, &seen_tx);
        }
    });
    std::thread::spawn(move || {
        let Ok((mut app_in, _)) = app_side.accept() else {
            return;
        };
        let Ok(mut wire_out) = TcpStream::connect(wire_addr) else {
            return;
        };
        let _ = wire_out.set_nodelay(true);
        let mut header = [0u8; 8];
        let mut seq = 0u8;
        while app_in.read_exact(&mut header).is_ok() {
            let ty = u32::from_le_bytes(header[..4].try_into().expect("4 bytes"));
            let len = u32::from_le_bytes(header[4..].try_into().expect("4 bytes")) as usize;
            let mut value = vec![0u8; len];
            if app_in.read_exact(&mut value).is_err() {
                return;
            }
            if SoloMessage::decode(ty, &value).is_err() {
                continue;
            }
            // What a translator would write: one SET_POSITION_TARGET_LOCAL_NED.
            let header = MavHeader {
                system_id: 255,
                component_id: 190,
                sequence: seq,
            };
            let msg = MavMessage::SET_POSITION_TARGET_LOCAL_NED(
                SET_POSITION_TARGET_LOCAL_NED_DATA::default(),
            );
            seq = seq.wrapping_add(1);
            if wire_out
                .write_all(RawFrame::encode(header, &msg).as_bytes())
                .is_err()
            {
                return;
            }
        }
    });
    let mut app = TcpStream::connect(app_addr)?;
    app.set_nodelay(true)?;
    let packet = SoloMessage::Location(Location {
        lat_deg: 35.0,
        lon_deg: 149.0,
        alt_m: 0.0,
    })
    .to_bytes();
    let mut out = Vec::with_capacity(rounds);
    for _ in 0..rounds {
        std::thread::sleep(Duration::from_millis(20));
        let t0 = Instant::now();
        app.write_all(&packet)?;
        out.push(first_setpoint(&seen_rx, t0, is_setpoint)?.as_secs_f64() * 1e3);
    }
    Ok(out)
}

fn report(name: &str, mut ms: Vec<f64>, base_p50: f64) {
    ms.sort_by(f64::total_cmp);
    let p50 = percentile(&ms, 0.5);
    println!(
        "{name:<9} n={:<4} p50={p50:8.3} ms  p99={:8.3} ms  p999={:8.3} ms  max={:8.3} ms  p50/baseline={:.0}x",
        ms.len(),
        percentile(&ms, 0.99),
        percentile(&ms, 0.999),
        percentile(&ms, 1.0),
        p50 / base_p50
    );
}

fn main() -> Result<()> {
    let rounds = arg("--rounds", 20) as usize;
    let control = ControlPath::from_args(&[
        ("solo-gateway", false),
        ("shot-engine", false),
        ("autopilot-link", true),
    ])?;
    println!("solo-bench: {}", control.describe);
    let (opts, services) = control.mesh(
        MeshOptions {
            solo: true,
            attitude_hz: 25.0,
            ..Default::default()
        },
        &[
            "vehicle-sim",
            "autopilot-link",
            "solo-gateway",
            "shot-engine",
        ],
    );
    let (seen_tx, seen_rx) = mpsc::channel();
    let mut mesh = start_tapped_mesh(opts, &services, move |parser, now| {
        scan_frames(parser, now, &seen_tx)
    })?;
    // The app's writes are this thread's: from here on it runs as the bench's
    // threads do (the supervisor, already started, keeps normal scheduling).
    bench_thread_realtime();
    take_off(&mesh)?;

    let app = TcpStream::connect(("127.0.0.1", mesh.solo_port))?;
    app.set_nodelay(true)?;
    let (app_tx, app_rx) = mpsc::channel();
    app_reader(app.try_clone()?, app_tx);
    let mut app_w = app;
    let here = {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        rt.block_on(async {
            let bus = mesh.bus("solo-bench-pos")?;
            let mut state = bus.subscriber::<VehicleState>(&topics::vehicle_state(1))?;
            state
                .recv_timeout(Duration::from_secs(5))
                .await?
                .context("no vehicle state")
        })?
    };
    // ROI 30 m north of the hover point, on the ground.
    let roi = Location {
        lat_deg: here.lat_deg + 30.0 / 111_320.0,
        lon_deg: here.lon_deg,
        alt_m: 0.0,
    };

    let (mut roi_ms, mut speed_ms, mut command_ms) = (Vec::new(), Vec::new(), Vec::new());
    let mut moving_ms = Vec::new();
    for round in 0..rounds {
        app_w.write_all(&SoloMessage::SetCurrentShot(shots::ORBIT).to_bytes())?;
        expect_app(
            &app_rx,
            "GET_CURRENT_SHOT orbit",
            |m| matches!(m, SoloMessage::GetCurrentShot(s) if *s == shots::ORBIT),
        )?;
        // Spread the packets over the engine's 40 ms loop phase (a fixed pause would
        // lock onto one phase and hide the spread).
        let jitter = |k: usize| Duration::from_micros(((round * 7 + k) * 4_999 % 40_000) as u64);
        std::thread::sleep(Duration::from_millis(200) + jitter(0));
        drain(&seen_rx);
        let t0 = Instant::now();
        app_w.write_all(&SoloMessage::Location(roi).to_bytes())?;
        // The engine reacts to the packet at once: GUIDED, ROI (MAVLink commands) and,
        // with its event step, the first setpoint.
        command_ms.push(first_setpoint(&seen_rx, t0, |s| !is_setpoint(s))?.as_secs_f64() * 1e3);
        roi_ms.push(first_setpoint(&seen_rx, t0, is_setpoint)?.as_secs_f64() * 1e3);

        // Orbiting at 0 m/s: change the cruise speed and wait for a moving setpoint.
        std::thread::sleep(Duration::from_millis(500) + jitter(3));
        let speed = if round % 2 == 0 { 3.0 } else { -3.0 };
        // The setpoints' horizontal speed before the change (radial corrections
        // only): a setpoint carries the change once it is faster than all of them.
        let floor = seen_rx
            .try_iter()
            .filter(is_setpoint)
            .map(|s| s.vel[0].hypot(s.vel[1]))
            .fold(0.0f32, f32::max);
        let t0 = Instant::now();
        app_w.write_all(
            &SoloMessage::ShotOptions {
                cruise_speed: speed,
            }
            .to_bytes(),
        )?;
        let (changed, moving) = first_two(
            &seen_rx,
            t0,
            |s| is_setpoint(s) && s.vel[0].hypot(s.vel[1]) > floor + SPEED_EPS_MPS,
            |s| is_setpoint(s) && s.vel[0].hypot(s.vel[1]) > 0.05,
        )?;
        speed_ms.push(changed.as_secs_f64() * 1e3);
        moving_ms.push(moving.as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(300));
        app_w.write_all(&SoloMessage::SetCurrentShot(shots::NONE).to_bytes())?;
        expect_app(
            &app_rx,
            "GET_CURRENT_SHOT -1",
            |m| matches!(m, SoloMessage::GetCurrentShot(s) if *s == shots::NONE),
        )?;
        std::thread::sleep(Duration::from_millis(700));
    }
    let mut base = baseline(rounds.max(50))?;
    base.sort_by(f64::total_cmp);
    let base_p50 = percentile(&base, 0.5);
    println!(
        "solo-bench: {rounds} rounds (app packet in over TCP 5507 → first MAVLink setpoint out)"
    );
    report("baseline", base, base_p50);
    report("command", command_ms, base_p50);
    report("roi", roi_ms, base_p50);
    report("speed", speed_ms, base_p50);
    report("speed>.05", moving_ms, base_p50);
    mesh.stop(Duration::from_secs(10))?;
    Ok(())
}
