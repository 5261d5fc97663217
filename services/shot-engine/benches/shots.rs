//! One step of each shot's geometry, timed: what a 25 Hz tick costs the engine.
//!
//! A plain timing loop (no criterion: the workspace does not carry it, and these
//! numbers only need to show the geometry is far below the 40 ms tick). Prints
//! nanoseconds per step; asserts nothing about time.
//!
//! `cargo bench -p skymesh-shot-engine --bench shots`

use std::hint::black_box;
use std::time::Instant;

use skymesh_shot_engine::shots::{
    offset, projected_roi, CableCam, CablePoint, Follow, GeoPoint, Limits, Orbit, Selfie,
    VehicleView,
};

const STEPS: u32 = 200_000;
const DT: f32 = 0.04;

const LIMITS: Limits = Limits {
    max_speed_mps: 5.0,
    max_accel_mps2: 2.5,
    max_climb_mps: 2.5,
    position_gain: 1.0,
};

const HOME: GeoPoint = GeoPoint {
    lat_deg: -35.363_261,
    lon_deg: 149.165_230,
    alt_rel_m: 20.0,
};

fn view(i: u32) -> VehicleView {
    // Walk the vehicle a little so no step is the same.
    let p = offset(&HOME, f64::from(i % 360), 30.0 + f64::from(i % 7) * 0.1);
    VehicleView {
        position: p,
        vel_ned_mps: [1.0, 2.0, 0.0],
        heading_deg: (i % 360) as f32,
        camera_pitch_deg: -70.0,
        camera_yaw_deg: (i % 360) as f32,
    }
}

fn time(name: &str, mut step: impl FnMut(u32)) {
    for i in 0..STEPS / 10 {
        step(i);
    }
    let start = Instant::now();
    for i in 0..STEPS {
        step(i);
    }
    let ns = start.elapsed().as_nanos() as f64 / f64::from(STEPS);
    println!("{name:<16} {ns:>8.0} ns/step");
}

fn main() {
    let roi = GeoPoint {
        alt_rel_m: 0.0,
        ..HOME
    };
    let mut orbit = Orbit::new(roi, &view(0));
    time("orbit", |i| {
        black_box(orbit.step(&view(i), DT, 4.0, &LIMITS));
    });

    let mut follow = Follow::new(&view(0));
    time("follow", |i| {
        let now = f64::from(i) * f64::from(DT);
        follow.update_target(offset(&HOME, 90.0, f64::from(i % 100) * 0.1), now);
        black_box(follow.step(&view(i), now, DT, 1.0, &LIMITS));
    });

    let a = CablePoint {
        position: HOME,
        yaw_deg: 350.0,
        pitch_deg: 0.0,
    };
    let b = CablePoint {
        position: offset(&HOME, 45.0, 80.0),
        yaw_deg: 10.0,
        pitch_deg: -30.0,
    };
    let mut cable = CableCam::new(a, b);
    time("cable", |i| {
        black_box(cable.step(&view(i), DT, 4.0, &LIMITS));
    });

    let mut selfie = Selfie::new(HOME, offset(&HOME, 180.0, 40.0), roi);
    time("selfie", |i| {
        black_box(selfie.step(&view(i), DT, 4.0, &LIMITS));
    });

    time("projected_roi", |i| {
        black_box(projected_roi(&view(i)));
    });
}
