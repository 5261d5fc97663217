use nalgebra::Vector3;

use super::*;
use crate::shots::zipline::Zipline;

/// The view with the camera where the test wants it.
fn camera(m: &PointMass, yaw: f32, pitch: f32) -> VehicleView {
    VehicleView {
        camera_yaw_deg: yaw,
        camera_pitch_deg: pitch,
        ..m.view()
    }
}

/// Distance of `p` from the line through `o` along `u` (unit), and how far along.
fn line_error(o: &Vector3<f64>, u: &Vector3<f64>, p: &Vector3<f64>) -> (f64, f64) {
    let along = (p - o).dot(u);
    ((p - o - u * along).norm(), along)
}

/// Fly `secs`: (max cross-track error after `settle` s, along at the end).
fn fly(
    m: &mut PointMass,
    z: &mut Zipline,
    o: &Vector3<f64>,
    u: &Vector3<f64>,
    cruise: f32,
    secs: f64,
    settle: f64,
) -> (f64, f64) {
    let mut worst = 0.0_f64;
    let mut along = 0.0;
    for i in 0..ticks(secs) {
        let g = z.step(&m.view(), DT, cruise, &LIMITS);
        m.fly(&g);
        let (c, a) = line_error(o, u, &m.pos);
        if i >= ticks(settle) {
            worst = worst.max(c);
        }
        along = a;
    }
    (worst, along)
}

#[test]
fn zipline_flies_the_camera_line_both_ways_and_holds_it() {
    let o = Vector3::new(0.0, 0.0, -10.0);
    let yaw = 30.0_f64;
    let u = Vector3::new(yaw.to_radians().cos(), yaw.to_radians().sin(), 0.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(o, dynamics);
        let mut z = Zipline::new(&camera(&m, 30.0, -45.0), false);
        let (cross, along) = fly(&mut m, &mut z, &o, &u, 4.0, 15.0, 0.0);
        assert!(cross < 0.2, "{dynamics:?}: {cross} m off the line");
        // About 4 m/s for most of 15 s, and still going: no end to the line.
        assert!(along > 50.0, "{dynamics:?}: {along}");
        assert!((m.vel.norm() - 4.0).abs() < 0.05, "{:?}", m.vel);
        assert!((f64::from(z.along_m()) - along).abs() < 1.0);
        // Back the other way, past the origin.
        let (cross, along) = fly(&mut m, &mut z, &o, &u, -5.0, 30.0, 0.0);
        assert!(cross < 0.2, "{dynamics:?}: {cross}");
        assert!(along < -50.0, "{dynamics:?}: {along}");
        assert!(
            (m.pos.z + 10.0).abs() < 0.1,
            "2-D: altitude held {}",
            m.pos.z
        );
    }
}

#[test]
fn a_3d_zipline_follows_the_camera_pitch_within_the_climb_limit() {
    let o = Vector3::new(0.0, 0.0, -40.0);
    let (yaw, pitch) = (90.0_f64.to_radians(), (-30.0_f64).to_radians());
    let u = Vector3::new(
        pitch.cos() * yaw.cos(),
        pitch.cos() * yaw.sin(),
        -pitch.sin(),
    );
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(o, dynamics);
        let mut z = Zipline::new(&camera(&m, 90.0, -30.0), true);
        let (cross, along) = fly(&mut m, &mut z, &o, &u, 5.0, 10.0, 0.0);
        assert!(cross < 0.2, "{dynamics:?}: {cross}");
        assert!(along > 30.0);
        assert!(m.pos.z > -40.0 + 15.0, "descended: {}", m.pos.z);
        // 5 m/s along a 30° slope: 4.33 horizontal, 2.5 down (the climb limit).
        assert!((m.vel.norm() - 5.0).abs() < 0.05, "{:?}", m.vel);
    }
}

#[test]
fn zipline_pulls_a_drifting_vehicle_back_and_pause_holds() {
    let o = Vector3::new(0.0, 0.0, -10.0);
    let u = Vector3::new(1.0, 0.0, 0.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(o, dynamics);
        // Laid while the vehicle slides sideways at 3 m/s.
        m.vel = Vector3::new(0.0, 3.0, 0.0);
        let mut z = Zipline::new(&camera(&m, 0.0, 0.0), false);
        let (cross, _) = fly(&mut m, &mut z, &o, &u, 3.0, 20.0, 8.0);
        assert!(cross < 0.1, "{dynamics:?}: {cross}");
        // Pause: brakes, then stays put.
        fly(&mut m, &mut z, &o, &u, 0.0, 5.0, 0.0);
        let held = m.pos;
        let (cross, _) = fly(&mut m, &mut z, &o, &u, 0.0, 10.0, 0.0);
        assert!((m.pos - held).norm() < 0.1, "{dynamics:?}");
        assert!(cross < 0.1);
        assert!(m.vel.norm() < 0.05);
    }
}

#[test]
fn a_new_line_turns_the_flight_without_a_jump() {
    let o = Vector3::new(0.0, 0.0, -10.0);
    let mut m = PointMass::new(o, DYNAMICS[3]);
    let mut z = Zipline::new(&camera(&m, 0.0, 0.0), false);
    let north = Vector3::new(1.0, 0.0, 0.0);
    fly(&mut m, &mut z, &o, &north, 5.0, 8.0, 0.0);
    // The pilot aims east and presses A: a new line from here, flown east. `fly`
    // checks every setpoint change stays within the acceleration limit.
    let start = m.ned(&m.view().position);
    z.relay(&camera(&m, 90.0, 0.0));
    let east = Vector3::new(0.0, 1.0, 0.0);
    let (cross, along) = fly(&mut m, &mut z, &start, &east, 5.0, 20.0, 8.0);
    assert!(cross < 0.2, "{cross}");
    assert!(along > 50.0);
}
