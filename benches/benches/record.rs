//! `skymesh record`'s cost per sample: JSON encoding plus the MCAP write (chunked,
//! uncompressed, indexed) of ten seconds of one vehicle's topics at the rates a
//! flying vehicle publishes them (`VehicleState` 50 Hz; status, authority and
//! payload 1 Hz; a command and its ack every two seconds), into a file.
//!
//! Reported twice from the same work: samples/s and bytes/s of MCAP output.
//!
//! `cargo bench -p skymesh-benches --bench record`

use std::hint::black_box;
use std::io::BufWriter;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use skymesh_ipc_types::{
    AckResult, AuthorityState, Command, CommandAck, CommandSource, FixedStr, FlightMode, GpsFix,
    PayloadState, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_record::topics::Kind;
use skymesh_record::{encode, wall_offset_ns, Encoded, McapSink};

const SECONDS: u64 = 10;

/// Ten seconds of vehicle 1's topics, encoded, in publish order.
fn flight(channels: &[u16; 6]) -> Vec<Encoded> {
    let offset = wall_offset_ns();
    let mut out = Vec::new();
    let mut t = 1_000_000_000u64;
    for i in 0..SECONDS * 50 {
        t += 20_000_000;
        let mut s = VehicleState {
            vehicle_id: 1,
            position_valid: 1,
            attitude_valid: 1,
            lat_deg: -35.363261 + i as f64 * 1e-7,
            lon_deg: 149.165230,
            alt_msl_m: 584.0 + i as f32 * 0.02,
            alt_rel_m: i as f32 * 0.02,
            alt_ellipsoid_m: f32::NAN,
            geoid_undulation_m: f32::NAN,
            vel_ned_mps: [0.5, 0.1, -1.0],
            heading_deg: 12.5,
            attitude_q: [0.99, 0.01, 0.02, 0.1],
            roll_rad: 0.01,
            pitch_rad: -0.02,
            yaw_rad: 0.2,
            body_rates_radps: [0.001, -0.002, 0.003],
            position_stamp_ns: t - 5_000_000,
            time_boot_ms: (t / 1_000_000) as u32,
            ..Default::default()
        };
        s.header.seq = i + 1;
        s.header.stamp_ns = t;
        out.push(encode(&s, channels[0], t + 100_000, offset).unwrap());
        if i % 50 == 0 {
            let mut st = VehicleStatus {
                vehicle_id: 1,
                mode: FlightMode::Guided.to_wire(),
                armed: 1,
                gps_fix: GpsFix::Fix3d.to_wire(),
                satellites: 14,
                link_up: 1,
                battery_remaining_pct: 87,
                battery_voltage_v: 16.2,
                status_text: FixedStr::new("Takeoff complete"),
                ..Default::default()
            };
            st.header.stamp_ns = t;
            out.push(encode(&st, channels[1], t + 100_000, offset).unwrap());
            let mut a = AuthorityState {
                vehicle_id: 1,
                flight_holder: CommandSource::Operator.to_wire(),
                ..Default::default()
            };
            a.header.stamp_ns = t;
            out.push(encode(&a, channels[2], t + 100_000, offset).unwrap());
            let mut p = PayloadState {
                vehicle_id: 1,
                gimbal_valid: 1,
                gimbal_pitch_deg: -30.0,
                ..Default::default()
            };
            p.header.stamp_ns = t;
            out.push(encode(&p, channels[3], t + 100_000, offset).unwrap());
        }
        if i % 100 == 0 {
            let mut c = VehicleCommand::new(
                1,
                CommandSource::Operator,
                i as u32,
                &Command::GrabFlightAuthority,
            )
            .unwrap();
            c.header.stamp_ns = t;
            out.push(encode(&c, channels[4], t + 100_000, offset).unwrap());
            let mut ack = CommandAck {
                vehicle_id: 1,
                result: AckResult::Accepted.to_wire(),
                command_id: i as u32,
                ..Default::default()
            };
            ack.header.stamp_ns = t;
            out.push(encode(&ack, channels[5], t + 100_000, offset).unwrap());
        }
    }
    out
}

const TOPICS: [(Kind, &str); 6] = [
    (Kind::VehicleState, "skymesh/vehicle/1/state"),
    (Kind::VehicleStatus, "skymesh/vehicle/1/status"),
    (Kind::AuthorityState, "skymesh/vehicle/1/authority"),
    (Kind::PayloadState, "skymesh/vehicle/1/payload"),
    (Kind::VehicleCommand, "skymesh/vehicle/1/command"),
    (Kind::CommandAck, "skymesh/vehicle/1/command_ack"),
];

/// Encodes the samples (JSON) and writes a whole recording of them; returns its size.
fn record_once(samples: &[VehicleState], rest: &[Encoded], path: &std::path::Path) -> u64 {
    let file = std::fs::File::create(path).unwrap();
    let mut sink = McapSink::new(BufWriter::new(file)).unwrap();
    let mut channels = [0u16; 6];
    for (c, (kind, topic)) in channels.iter_mut().zip(TOPICS) {
        *c = sink.add_channel(kind, topic).unwrap();
    }
    let offset = wall_offset_ns();
    for s in samples {
        let m = encode(s, channels[0], s.header.stamp_ns, offset).unwrap();
        sink.write(black_box(&m)).unwrap();
    }
    for m in rest {
        sink.write(m).unwrap();
    }
    let (_, w) = sink.finish().unwrap();
    drop(w);
    std::fs::metadata(path).unwrap().len()
}

fn record(c: &mut Criterion) {
    let recorded = flight(&[1, 2, 3, 4, 5, 6]);
    // The states are encoded inside the measurement (the recorder's JSON work); the
    // 1 Hz and rarer samples are written pre-encoded, a few percent of the total.
    let states: Vec<VehicleState> = recorded
        .iter()
        .filter(|m| m.channel == 1)
        .map(|m| serde_json::from_slice(&m.data).unwrap())
        .collect();
    let rest: Vec<Encoded> = recorded.into_iter().filter(|m| m.channel != 1).collect();
    let samples = (states.len() + rest.len()) as u64;
    let dir = std::env::temp_dir().join(format!("skymesh-record-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bench.mcap");
    let bytes = record_once(&states, &rest, &path);
    println!(
        "record: {samples} samples of vehicle 1's topics ({SECONDS} s of flight) → {bytes} bytes of MCAP, {:.0} bytes a sample",
        bytes as f64 / samples as f64
    );
    let mut group = c.benchmark_group("record");
    group.throughput(Throughput::Elements(samples));
    group.bench_function("vehicle_topics_samples", |b| {
        b.iter(|| record_once(&states, &rest, &path))
    });
    group.throughput(Throughput::Bytes(bytes));
    group.bench_function("vehicle_topics_bytes", |b| {
        b.iter(|| record_once(&states, &rest, &path))
    });
    group.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, record);
criterion_main!(benches);
