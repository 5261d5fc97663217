//! Pose broadcast benchmark: prints numbers, asserts nothing.
//!
//! The cost of building one pose datagram (every drone of a `SwarmState` → 84-byte
//! GroundControl records) at 10, 100 and 250 drones, with the gateway's own
//! `build_datagram` into a reused buffer, and in the same run a baseline: a plain
//! copy of the same number of bytes into the same kind of buffer (what the
//! datagram would cost if the records were already laid out). Median of 7 runs.
//!
//! `cargo bench -p skymesh-groundcontrol-gateway --bench broadcast`

use std::hint::black_box;
use std::time::Instant;

use gc_proto::POSE_RECORD_LEN;
use skymesh_groundcontrol_gateway::broadcast::{build_datagram, MAX_DATAGRAM};
use skymesh_ipc_types::{SwarmDrone, SwarmState};

fn state(n: usize) -> Box<SwarmState> {
    let mut s: Box<SwarmState> = Box::default();
    s.count = n as u16;
    s.time_s = 123.456;
    for (i, d) in s.drones.iter_mut().take(n).enumerate() {
        let f = i as f32;
        *d = SwarmDrone {
            drone: i as u16,
            vehicle_id: (i % 250) as u8 + 1,
            drone_state: 10,
            flags: 0x103,
            tracking: [f, f * 0.5, 10.0],
            tracking_yaw_deg: f,
            quaternion: [0.0, 0.0, 0.38, 0.92],
            target: [f + 1.0, f * 0.5, 10.0],
            target_yaw_deg: f,
            color: [0.1, 0.2, 0.3],
            ..SwarmDrone::default()
        };
    }
    s
}

fn ns_per_call(iterations: u32, mut f: impl FnMut(u32)) -> f64 {
    let mut runs: Vec<f64> = (0..7)
        .map(|_| {
            let t = Instant::now();
            for i in 0..iterations {
                f(i);
            }
            t.elapsed().as_nanos() as f64 / f64::from(iterations)
        })
        .collect();
    runs.sort_by(f64::total_cmp);
    runs[runs.len() / 2]
}

fn main() {
    println!("pose datagram build (median of 7 runs, ns per datagram)");
    println!(
        "{:>7} {:>9} {:>14} {:>14} {:>7} {:>16}",
        "drones", "bytes", "build_datagram", "memcpy", "ratio", "µs per s at 30 Hz"
    );
    for n in [10usize, 100, 250] {
        let s = state(n);
        let mut buf: Vec<u8> = Vec::with_capacity(MAX_DATAGRAM);
        let iterations = (2_000_000 / n) as u32;
        let build = ns_per_call(iterations, |i| {
            build_datagram(black_box(&s), 2, i, &mut buf);
            black_box(&buf);
        });
        assert_eq!(buf.len(), n * POSE_RECORD_LEN);
        let source = buf.clone();
        let mut copy: Vec<u8> = Vec::with_capacity(MAX_DATAGRAM);
        let memcpy = ns_per_call(iterations, |_| {
            copy.clear();
            copy.extend_from_slice(black_box(&source));
            black_box(&copy);
        });
        println!(
            "{:>7} {:>9} {:>14.0} {:>14.0} {:>6.1}x {:>16.1}",
            n,
            n * POSE_RECORD_LEN,
            build,
            memcpy,
            build / memcpy,
            build * 30.0 / 1000.0
        );
    }
}
