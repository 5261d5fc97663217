//! vehicle-sim ATTITUDE → `VehicleState` at a bus subscriber, through the real mesh.
//!
//! Runs vehicle-sim and autopilot-link under the supervisor, with a tap between them
//! that timestamps every chunk vehicle-sim writes towards autopilot-link as it reads
//! it (then forwards it at once, then parses it). Each ATTITUDE frame in it is
//! matched, by its `time_boot_ms`, to the `VehicleState` autopilot-link publishes for
//! it (`skymesh/vehicle/1/state`, one per ATTITUDE), received by a subscriber in
//! this process: tap read → TCP → autopilot-link (parse, fuse, publish) → iceoryx2 →
//! subscriber wakes.
//!
//! Baseline, same run, same frames: the tap also sends each ATTITUDE frame's bytes
//! over one loopback UDP hop to a thread that parses them with the mavlink crate
//! (the floor for any MAVLink consumer one hop away), timed from the same read.
//! Both paths see every frame, so they are interleaved by construction (and share
//! the machine: on a 2-core VM they compete for it).
//!
//! `cargo run --release -p skymesh-e2e --bin telemetry-bench -- --samples 3000`

use std::collections::HashMap;
use std::net::UdpSocket;
use std::sync::mpsc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::MavlinkReader;
use mavlink_frame::FrameParser;
use skymesh_e2e::bench::{arg, percentile, start_tapped_mesh_both};
use skymesh_e2e::MeshOptions;
use skymesh_ipc_types::{topics, VehicleState};

/// ATTITUDE's MAVLink message id.
const ATTITUDE: u32 = 30;
/// Matched samples left out of the numbers (link start-up, stream requests).
const WARMUP: usize = 100;

/// A timestamped `time_boot_ms`, from one of the three observers.
#[derive(Debug, Clone, Copy)]
enum Ev {
    /// The tap read the frame from vehicle-sim.
    Tap(u32, Instant),
    /// The baseline thread parsed it.
    Base(u32, Instant),
}

#[derive(Debug, Default, Clone, Copy)]
struct Slot {
    tap: Option<Instant>,
    base: Option<Instant>,
    bus: Option<Instant>,
    done_base: bool,
    done_bus: bool,
}

/// For every ATTITUDE in the chunk: report the tap time, and send the frame's bytes
/// to the baseline consumer.
fn scan_attitude(parser: &mut FrameParser, now: Instant, udp: &UdpSocket, out: &mpsc::Sender<Ev>) {
    while let Some(frame) = parser.next_frame() {
        if frame.message_id() != ATTITUDE || frame.component_id() != 1 {
            continue;
        }
        let _ = udp.send(frame.as_bytes());
        if let Ok(MavMessage::ATTITUDE(a)) = frame.decode() {
            let _ = out.send(Ev::Tap(a.time_boot_ms, now));
        }
    }
}

/// The baseline consumer: one UDP datagram per frame, parsed by the mavlink crate.
fn baseline_consumer(sock: UdpSocket, out: mpsc::Sender<Ev>) {
    std::thread::spawn(move || {
        let mut buf = [0u8; 512];
        while let Ok(n) = sock.recv(&mut buf) {
            let mut reader = MavlinkReader::new(&buf[..n]);
            if let Ok((_, MavMessage::ATTITUDE(a))) = reader.read_any_message::<MavMessage>() {
                let now = Instant::now();
                let _ = out.send(Ev::Base(a.time_boot_ms, now));
            }
        }
    });
}

fn report(name: &str, mut ms: Vec<f64>, base_p50: f64) -> f64 {
    ms.sort_by(f64::total_cmp);
    let p50 = percentile(&ms, 0.5);
    println!(
        "{name:<9} n={:<5} p50={p50:7.3} ms  p99={:7.3} ms  p999={:7.3} ms  max={:7.3} ms  p50/baseline={:.1}x",
        ms.len(),
        percentile(&ms, 0.99),
        percentile(&ms, 0.999),
        percentile(&ms, 1.0),
        p50 / base_p50
    );
    p50
}

fn main() -> Result<()> {
    let samples = arg("--samples", 3000) as usize;
    let hz = arg("--hz", 50) as f64;

    let base_rx_sock = UdpSocket::bind("127.0.0.1:0")?;
    let base_tx_sock = UdpSocket::bind("127.0.0.1:0")?;
    base_tx_sock.connect(base_rx_sock.local_addr()?)?;
    let base_tx_sock = Arc::new(base_tx_sock);
    let (ev_tx, ev_rx) = mpsc::channel();
    baseline_consumer(base_rx_sock, ev_tx.clone());

    let tap_tx = ev_tx.clone();
    let mut mesh = start_tapped_mesh_both(
        MeshOptions {
            attitude_hz: hz,
            // Measured on the ground: at `hz` there too, not at the ground rate.
            autopilot_link_extra: "ground_attitude_hz = 0".to_string(),
            ..Default::default()
        },
        &["vehicle-sim", "autopilot-link"],
        |_: &mut FrameParser, _| {},
        move |parser, now| scan_attitude(parser, now, &base_tx_sock, &tap_tx),
    )?;

    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let (mesh_ms, base_ms) = rt.block_on(async {
        let bus = mesh.bus("telemetry-bench")?;
        let mut state = bus.subscriber::<VehicleState>(&topics::vehicle_state(1))?;
        let mut slots: HashMap<u32, Slot> = HashMap::new();
        let (mut mesh_ms, mut base_ms) = (Vec::new(), Vec::new());
        let mut matched = 0usize;
        let deadline = Instant::now() + Duration::from_secs(170);
        while mesh_ms.len() < samples || base_ms.len() < samples {
            if Instant::now() > deadline {
                bail!(
                    "only {} mesh / {} baseline samples in 170 s",
                    mesh_ms.len(),
                    base_ms.len()
                );
            }
            let s = state.recv_timeout(Duration::from_secs(5)).await?;
            let bus_at = Instant::now();
            if let Some(s) = s {
                slots.entry(s.time_boot_ms).or_default().bus = Some(bus_at);
            }
            for ev in ev_rx.try_iter() {
                match ev {
                    Ev::Tap(t, at) => slots.entry(t).or_default().tap = Some(at),
                    Ev::Base(t, at) => slots.entry(t).or_default().base = Some(at),
                }
            }
            slots.retain(|_, slot| {
                if let Some(tap) = slot.tap {
                    if let (false, Some(bus)) = (slot.done_bus, slot.bus) {
                        slot.done_bus = true;
                        matched += 1;
                        if matched > WARMUP {
                            mesh_ms.push((bus - tap).as_secs_f64() * 1e3);
                        }
                    }
                    if let (false, Some(base)) = (slot.done_base, slot.base) {
                        slot.done_base = true;
                        if matched > WARMUP {
                            base_ms.push((base - tap).as_secs_f64() * 1e3);
                        }
                    }
                }
                // Keep a slot until both paths are in (or it is clearly lost).
                !(slot.done_bus && slot.done_base)
                    && slot
                        .tap
                        .or(slot.bus)
                        .or(slot.base)
                        .is_some_and(|t| bus_at.duration_since(t) < Duration::from_secs(2))
            });
        }
        anyhow::Ok((mesh_ms, base_ms))
    })?;
    println!(
        "telemetry-bench: ATTITUDE at {hz} Hz, vehicle-sim → tap → autopilot-link → VehicleState at a bus subscriber; {WARMUP} warm-up samples left out"
    );
    let mut base_sorted = base_ms.clone();
    base_sorted.sort_by(f64::total_cmp);
    let base_p50 = percentile(&base_sorted, 0.5);
    report("baseline", base_ms, base_p50);
    report("mesh", mesh_ms, base_p50);
    mesh.stop(Duration::from_secs(10))?;
    Ok(())
}
