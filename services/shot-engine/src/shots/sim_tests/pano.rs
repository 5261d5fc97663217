use nalgebra::Vector3;

use super::*;
use crate::shots::geo::wrap_180;
use crate::shots::pano::{
    cylinder_stations, sphere_stations, Pano, PanoKind, PanoOptions, PanoPhase, PanoStation,
    ARRIVED_DEG, SPHERE_ROWS, TURN_TIMEOUT_S, VIDEO_PAN_MAX_LEAD_DEG,
};

/// A gimbal and nose that slew toward what they are asked at `rate` deg/s.
#[derive(Debug, Clone, Copy)]
struct Camera {
    yaw: f64,
    pitch: f64,
    rate: f64,
}

impl Camera {
    fn follow(&mut self, g: &Guidance) {
        let max = self.rate * f64::from(DT);
        if let Some(y) = g.yaw_deg {
            let d = wrap_180(f64::from(y) - self.yaw);
            self.yaw = (self.yaw + d.clamp(-max, max)).rem_euclid(360.0);
        }
        if let Some(p) = g.gimbal_pitch_deg {
            let d = f64::from(p) - self.pitch;
            self.pitch += d.clamp(-max, max);
        }
    }

    fn view(&self, m: &PointMass) -> VehicleView {
        VehicleView {
            camera_yaw_deg: self.yaw as f32,
            camera_pitch_deg: self.pitch as f32,
            heading_deg: self.yaw as f32,
            ..m.view()
        }
    }
}

const OPTIONS: PanoOptions = PanoOptions {
    cylinder_fov_deg: 360.0,
    lens_fov_deg: 69.5,
    yaw_rate_dps: 20.0,
};

/// What a run saw: the camera (yaw, pitch) at each trigger, the station counters,
/// and the largest drift from where it began.
type Seen = (Vec<(f64, f64)>, Vec<(u8, u8)>, f64);

/// Run a started pano until it finishes (or `secs`).
fn run(m: &mut PointMass, cam: &mut Camera, pano: &mut Pano, t0: f64, secs: f64) -> Seen {
    let start = m.pos;
    let mut shots = Vec::new();
    let mut counters = Vec::new();
    let mut drift = 0.0_f64;
    for i in 0..ticks(secs) {
        let now = t0 + i as f64 * f64::from(DT);
        let s = pano.step(&cam.view(m), DT, now, &LIMITS);
        assert_eq!(s.guidance.roi, None);
        if s.trigger {
            shots.push((cam.yaw, cam.pitch));
        }
        counters.push(s.station);
        m.fly(&s.guidance);
        cam.follow(&s.guidance);
        drift = drift.max((m.pos - start).norm());
        if s.phase == PanoPhase::Finished {
            break;
        }
    }
    (shots, counters, drift)
}

/// Every station photographed exactly once, on the station, in order.
fn check_shots(stations: &[PanoStation], shots: &[(f64, f64)]) {
    assert_eq!(shots.len(), stations.len(), "{shots:?}");
    for (s, (yaw, pitch)) in stations.iter().zip(shots) {
        assert!(
            (pitch - f64::from(s.pitch_deg)).abs() <= f64::from(ARRIVED_DEG),
            "{s:?}: pitch {pitch}"
        );
        if s.pitch_deg > -89.0 {
            assert!(
                wrap_180(yaw - f64::from(s.yaw_deg)).abs() <= f64::from(ARRIVED_DEG),
                "{s:?}: yaw {yaw}"
            );
        }
    }
}

#[test]
fn cylinder_and_sphere_photograph_every_station_once_holding_position() {
    for (kind, options) in [
        (PanoKind::Cylinder, OPTIONS),
        (
            PanoKind::Cylinder,
            PanoOptions {
                cylinder_fov_deg: 180.0,
                ..OPTIONS
            },
        ),
        (PanoKind::Sphere, OPTIONS),
    ] {
        for dynamics in DYNAMICS {
            let mut m = PointMass::new(Vector3::new(0.0, 0.0, -20.0), dynamics);
            let mut cam = Camera {
                yaw: 100.0,
                pitch: -10.0,
                rate: 60.0,
            };
            let mut pano = Pano::new(kind, &cam.view(&m), options);
            assert_eq!(pano.phase(), PanoPhase::Setup);
            // Setup: holding, camera free, nothing taken.
            let (shots, _, _) = run(&mut m, &mut cam, &mut pano, 0.0, 2.0);
            assert!(shots.is_empty());
            pano.start(&cam.view(&m), 2.0);
            assert_eq!(pano.phase(), PanoPhase::Run);
            let stations = pano.stations().to_vec();
            let (shots, counters, drift) = run(&mut m, &mut cam, &mut pano, 2.0, 120.0);
            assert_eq!(pano.phase(), PanoPhase::Finished, "{kind:?} {dynamics:?}");
            check_shots(&stations, &shots);
            assert!(drift < 0.05, "{kind:?} {dynamics:?}: drifted {drift}");
            let total = u8::try_from(stations.len()).unwrap_or(0);
            assert_eq!(counters.first(), Some(&(0, total)));
            assert_eq!(counters.last(), Some(&(total, total)));
            assert!(counters.windows(2).all(|w| w[1].0 >= w[0].0));
            // Finished: nothing more.
            let (shots, _, _) = run(&mut m, &mut cam, &mut pano, 200.0, 2.0);
            assert!(shots.is_empty());
        }
    }
}

#[test]
fn pano_brakes_a_moving_vehicle_and_holds_where_it_stopped() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -20.0), DYNAMICS[1]);
    m.vel = Vector3::new(4.0, 0.0, 0.0);
    let mut cam = Camera {
        yaw: 0.0,
        pitch: 0.0,
        rate: 60.0,
    };
    let mut pano = Pano::new(PanoKind::Cylinder, &cam.view(&m), OPTIONS);
    run(&mut m, &mut cam, &mut pano, 0.0, 6.0);
    assert!(m.vel.norm() < 0.05);
    let held = pano.hold_point().map(|p| m.ned(&p));
    assert!(held.is_some_and(|h| (h - m.pos).norm() < 0.1), "{held:?}");
    pano.start(&cam.view(&m), 6.0);
    let (shots, _, drift) = run(&mut m, &mut cam, &mut pano, 6.0, 120.0);
    assert_eq!(shots.len(), pano.stations().len());
    assert!(drift < 0.1, "{drift}");
}

#[test]
fn a_camera_that_never_turns_still_finishes_by_timeout() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -20.0), DYNAMICS[0]);
    let mut cam = Camera {
        yaw: 0.0,
        pitch: 0.0,
        rate: 0.0,
    };
    let mut pano = Pano::new(PanoKind::Sphere, &cam.view(&m), OPTIONS);
    pano.start(&cam.view(&m), 0.0);
    let n = pano.stations().len();
    let (shots, _, _) = run(
        &mut m,
        &mut cam,
        &mut pano,
        0.0,
        (TURN_TIMEOUT_S + 3.0) * 20.0,
    );
    assert_eq!(pano.phase(), PanoPhase::Finished);
    assert_eq!(shots.len(), n);
}

#[test]
fn video_pan_turns_at_its_rate_pauses_and_never_runs_away() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -20.0), DYNAMICS[0]);
    let mut cam = Camera {
        yaw: 350.0,
        pitch: -15.0,
        rate: 90.0,
    };
    let mut pano = Pano::new(PanoKind::VideoPan, &cam.view(&m), OPTIONS);
    pano.start(&cam.view(&m), 0.0);
    assert!(pano.stations().is_empty());
    // 10 s at 20°/s: 200° clockwise, camera pitch left to the pilot.
    let mut turned = 0.0;
    let mut last = cam.yaw;
    for i in 0..ticks(10.0) {
        let s = pano.step(&cam.view(&m), DT, f64::from(i as f32 * DT), &LIMITS);
        assert!(!s.trigger);
        assert_eq!(s.station, (0, 0));
        assert_eq!(s.guidance.gimbal_pitch_deg, None);
        assert_eq!(s.phase, PanoPhase::Run);
        m.fly(&s.guidance);
        cam.follow(&s.guidance);
        turned += wrap_180(cam.yaw - last);
        last = cam.yaw;
    }
    assert!((turned - 200.0).abs() < 2.0, "{turned}");
    // Paused (rate 0): stays.
    pano.set_options(PanoOptions {
        yaw_rate_dps: 0.0,
        ..OPTIONS
    });
    for _ in 0..ticks(1.0) {
        let s = pano.step(&cam.view(&m), DT, 10.0, &LIMITS);
        cam.follow(&s.guidance);
    }
    let paused = cam.yaw;
    for _ in 0..ticks(3.0) {
        let s = pano.step(&cam.view(&m), DT, 10.0, &LIMITS);
        cam.follow(&s.guidance);
    }
    assert!(wrap_180(cam.yaw - paused).abs() < 0.01);
    // Asked for more than allowed, with a camera that cannot turn: the target stays
    // within the lead of the camera, counter-clockwise.
    pano.set_options(PanoOptions {
        yaw_rate_dps: -500.0,
        ..OPTIONS
    });
    assert_eq!(pano.yaw_rate_dps(), -60.0);
    for _ in 0..ticks(5.0) {
        let s = pano.step(&cam.view(&m), DT, 20.0, &LIMITS);
        let lead = wrap_180(f64::from(s.guidance.yaw_deg.unwrap_or(f32::NAN)) - cam.yaw);
        assert!(
            (-f64::from(VIDEO_PAN_MAX_LEAD_DEG) - 1e-3..=0.0).contains(&lead),
            "{lead}"
        );
    }
}

#[test]
fn station_layouts() {
    // Full circle, 69.5° lens at 30 % overlap: ≤ 48.65° apart → 8 photos, 45° apart.
    let full = cylinder_stations(10.0, -5.0, 360.0, 69.5);
    assert_eq!(full.len(), 8);
    for (i, s) in full.iter().enumerate() {
        let want = (10.0 + 45.0 * i as f64).rem_euclid(360.0);
        assert!((f64::from(s.yaw_deg) - want).abs() < 1e-3, "{s:?}");
        assert_eq!(s.pitch_deg, -5.0);
    }
    // 180° with a 60° lens: centres span ±60°, ≤ 42° apart → 4 photos, 40° apart.
    let half = cylinder_stations(0.0, 0.0, 180.0, 60.0);
    let yaws: Vec<f32> = half.iter().map(|s| s.yaw_deg).collect();
    for (y, want) in yaws.iter().zip([300.0, 340.0, 20.0, 60.0]) {
        assert!((y - want).abs() < 1e-3, "{yaws:?}");
    }
    // Out of range and nonsense are clamped: 40° → 91°; NaN → 360°; bad lens → default.
    assert_eq!(cylinder_stations(0.0, 0.0, 40.0, 60.0).len(), 2);
    assert_eq!(cylinder_stations(0.0, 0.0, f32::NAN, 69.5).len(), 8);
    assert_eq!(cylinder_stations(0.0, 0.0, 360.0, -1.0).len(), 8);
    // The sphere: the documented rows.
    let sphere = sphere_stations(90.0);
    let want: usize = SPHERE_ROWS.iter().map(|r| usize::from(r.1)).sum();
    assert_eq!(sphere.len(), want);
    assert_eq!(sphere.len(), 17);
    assert_eq!(sphere[0].yaw_deg, 90.0);
    assert_eq!(sphere[16].pitch_deg, -90.0);
    assert_eq!(PanoKind::from_wire(1), Some(PanoKind::Sphere));
    assert_eq!(PanoKind::from_wire(3), None);
    assert_eq!(PanoKind::VideoPan.to_wire(), 2);
}

#[test]
fn options_change_only_in_setup_except_the_pan_rate() {
    let m = PointMass::new(Vector3::new(0.0, 0.0, -20.0), DYNAMICS[0]);
    let v = m.view();
    let mut pano = Pano::new(PanoKind::Cylinder, &v, OPTIONS);
    let narrow = PanoOptions {
        cylinder_fov_deg: 120.0,
        lens_fov_deg: 60.0,
        yaw_rate_dps: 5.0,
    };
    pano.set_options(narrow);
    assert_eq!(pano.options(), narrow);
    pano.start(&v, 0.0);
    let n = pano.stations().len();
    pano.set_options(OPTIONS);
    assert_eq!(pano.options().cylinder_fov_deg, 120.0);
    assert_eq!(pano.options().yaw_rate_dps, 20.0);
    assert_eq!(pano.stations().len(), n);
    // A second start is ignored.
    pano.start(&v, 1.0);
    assert_eq!(pano.stations().len(), n);
}
