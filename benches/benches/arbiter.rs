//! The command arbiter's decision cost: `Arbiter::decide` per command (decode and
//! validate the sample, emergency, authority, freshness, limits, geofence, commit).
//!
//! The cases of the former hand-timed `services/autopilot-link/benches/arbiter.rs`:
//! a GoTo with a speed (target inside the fence, straight-path check), a VelocityNed
//! toward the keep-out that the limits leave alone, and a VelocityNed the limits
//! clamp (a `Limited` outcome with a formatted detail), each without a fence and
//! with a 32-vertex keep-in circle (r = 300 m) plus a 32-vertex keep-out circle
//! (r = 40 m, 100 m north). The vehicle is armed, GUIDED, inside the fence at 10 m,
//! moving north at 2 m/s.
//!
//! `cargo bench -p skymesh-benches --bench arbiter`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use skymesh_autopilot_link::arbiter::geofence::LocalFrame;
use skymesh_autopilot_link::arbiter::{Arbiter, Home, Kinematics, Outcome, VehicleView};
use skymesh_autopilot_link::RawConfig;
use skymesh_ipc_types::{
    Command, CommandSource, FenceKind, FlightMode, GeofenceSet, VehicleCommand,
};
use skymesh_runtime::ServiceConfig;

const HOME: (f64, f64) = (-35.363261, 149.165230);

/// A circle of 32 vertices, `radius_m` around a point `north_m` from home.
fn circle(frame: &LocalFrame, north_m: f64, radius_m: f64) -> Vec<[f64; 2]> {
    let unit = frame.to_local(HOME.0 + 1e-3, HOME.1 + 1e-3);
    (0..32)
        .map(|i| {
            let a = f64::from(i) * std::f64::consts::TAU / 32.0;
            let (n, e) = (north_m + radius_m * a.cos(), radius_m * a.sin());
            [HOME.0 + n / unit.x * 1e-3, HOME.1 + e / unit.y * 1e-3]
        })
        .collect()
}

fn decide(c: &mut Criterion) {
    let settings = RawConfig::default()
        .validate()
        .expect("the default configuration is valid")
        .arbiter;
    let frame = LocalFrame::new(HOME.0, HOME.1);
    let mut fence = GeofenceSet {
        vehicle_id: 1,
        enabled: 1,
        source: CommandSource::Operator.to_wire(),
        ..Default::default()
    };
    fence.push_polygon(FenceKind::KeepIn, &circle(&frame, 0.0, 300.0));
    fence.push_polygon(FenceKind::KeepOut, &circle(&frame, 100.0, 40.0));
    let view = VehicleView {
        armed: true,
        mode: FlightMode::Guided,
        position: Some(Kinematics {
            lat_deg: HOME.0,
            lon_deg: HOME.1,
            alt_rel_m: 10.0,
            vel_ned_mps: [2.0, 0.0, 0.0],
            age_s: 0.1,
        }),
        home: Some(Home {
            lat_deg: HOME.0,
            lon_deg: HOME.1,
            alt_msl_m: 584.0,
        }),
    };
    let east_150 = 150.0 / frame.to_local(HOME.0, HOME.1 + 1e-3).y * 1e-3;
    let cases = [
        (
            "goto_with_speed",
            Command::GoTo {
                lat_deg: HOME.0,
                lon_deg: HOME.1 + east_150,
                alt_rel_m: 20.0,
                yaw_deg: None,
                speed_mps: Some(8.0),
            },
        ),
        (
            "velocity_ned_5mps_not_limited",
            Command::VelocityNed {
                vel_ned_mps: [5.0, 0.0, 0.0],
                yaw_rate_dps: Some(10.0),
            },
        ),
        (
            "velocity_ned_25mps_clamped",
            Command::VelocityNed {
                vel_ned_mps: [25.0, 0.0, -1.0],
                yaw_rate_dps: None,
            },
        ),
    ];
    let mut group = c.benchmark_group("arbiter/decide");
    for (name, cmd) in cases {
        for (fence_name, fenced) in [("no_fence", false), ("keep_in_keep_out_32v", true)] {
            let mut arbiter = Arbiter::new(settings.clone());
            if fenced {
                arbiter.set_geofence(&fence, 1);
            }
            let mut sample = VehicleCommand::new(1, CommandSource::Operator, 1, &cmd)
                .expect("a valid command sample");
            let now = 10_000_000_000;
            sample.header.stamp_ns = now;
            let first = arbiter.decide(now, &sample, &view);
            assert!(
                !matches!(first.outcome, Outcome::Refused { .. }),
                "{name} ({fence_name}): {first:?}"
            );
            let mut id = 1u32;
            group.bench_function(BenchmarkId::new(name, fence_name), |b| {
                b.iter(|| {
                    id = id.wrapping_add(1);
                    sample.command_id = id;
                    black_box(arbiter.decide(black_box(now), black_box(&sample), black_box(&view)))
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, decide);
criterion_main!(benches);
