use nalgebra::Vector3;

use super::*;
use crate::shots::multipoint::{Multipoint, MultipointError, PlaybackEvent};
use crate::shots::spline::{Keypoint, SplinePath};

/// Three keypoints in an L: 30 m north, then 30 m east, 10 m up; the camera turns
/// from north to east to south and pitches down.
fn l_path(m: &PointMass) -> SplinePath {
    let kp = |n: f64, e: f64, pitch_deg: f32, yaw_deg: f32| Keypoint {
        position: m.to_geo(Vector3::new(n, e, -10.0)),
        pitch_deg,
        yaw_deg,
    };
    SplinePath::new(
        &[
            kp(0.0, 0.0, 0.0, 0.0),
            kp(30.0, 0.0, -30.0, 90.0),
            kp(30.0, 30.0, -60.0, 180.0),
        ],
        &LIMITS,
    )
    .expect("valid path")
}

/// What a flight saw.
#[derive(Debug, Default)]
struct Flight {
    events: Vec<PlaybackEvent>,
    /// Worst vehicle speed / curvature limit at its projection.
    worst_ratio: f64,
    /// Farthest from the path, metres.
    max_cross: f64,
    max_speed: f64,
    secs: f64,
}

/// Step until `done` (or `secs`), collecting events and checks.
fn fly(
    m: &mut PointMass,
    mp: &mut Multipoint,
    secs: f64,
    on_path: bool,
    done: impl Fn(&Multipoint, &[PlaybackEvent]) -> bool,
) -> Flight {
    let mut f = Flight::default();
    for i in 0..ticks(secs) {
        let g = mp.step(&m.view(), DT, &LIMITS);
        m.fly(&g);
        f.events.extend(mp.take_events());
        let path = mp.path();
        let p = path.frame().to_ned(&m.geo());
        let s = path.spline().closest_s(&p, None);
        if on_path {
            f.max_cross = f.max_cross.max((path.spline().position(s) - p).norm());
            f.worst_ratio = f.worst_ratio.max(m.vel.norm() / path.curvature_limit(s));
        }
        f.max_speed = f.max_speed.max(m.vel.norm());
        f.secs = (i + 1) as f64 * f64::from(DT);
        if done(mp, &f.events) {
            break;
        }
    }
    f
}

fn attach(m: &mut PointMass, mp: &mut Multipoint, index: usize) -> Flight {
    mp.attach(index).expect("keypoint exists");
    let f = fly(m, mp, 60.0, false, |mp, _| mp.attached());
    assert!(mp.attached(), "not attached after {} s", f.secs);
    assert_eq!(f.events, vec![PlaybackEvent::Attached { index }]);
    f
}

/// Seek and fly until stopped.
fn seek(m: &mut PointMass, mp: &mut Multipoint, u: f32, cruise_state: i32) -> Flight {
    mp.seek(u, cruise_state).expect("attached");
    let f = fly(m, mp, 90.0, true, |mp, ev| {
        !mp.moving() && ev.contains(&PlaybackEvent::Stopped)
    });
    assert!(!mp.moving(), "still moving after {} s", f.secs);
    f
}

#[test]
fn attach_seek_to_half_and_back_along_the_l() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(-8.0, 5.0, -14.0), dynamics);
        let mut mp = Multipoint::new(l_path(&m));
        attach(&mut m, &mut mp, 0);
        let start = m.ned(&mp.path().position_at_u(0.0));
        assert!((m.pos - start).norm() < 1.0);
        assert!(mp.u() < 0.01 && mp.cruise_state() == 0, "{}", mp.u());

        let f = seek(&mut m, &mut mp, 0.5, 1);
        let half = m.ned(&mp.path().position_at_u(0.5));
        let miss = (m.pos - half).norm();
        eprintln!("{dynamics:?}: miss {miss:.3} m, worst v/limit {:.3}, cross {:.3} m, max speed {:.2}, {:.1} s", f.worst_ratio, f.max_cross, f.max_speed, f.secs);
        assert!(miss < 1.0, "{dynamics:?}: stopped {miss} m from u = 0.5");
        assert!(
            f.worst_ratio <= 1.1,
            "{dynamics:?}: {} × the curvature limit",
            f.worst_ratio
        );
        assert!(
            f.max_cross < 1.0,
            "{dynamics:?}: {} m off the path",
            f.max_cross
        );
        assert!(
            f.max_speed > 3.0,
            "{dynamics:?}: cruised at {}",
            f.max_speed
        );
        assert_eq!(f.events.first(), Some(&PlaybackEvent::Started));
        assert!(
            f.events
                .contains(&PlaybackEvent::PassedKeypoint { index: 1 }),
            "{:?}",
            f.events
        );
        assert_eq!(f.events.last(), Some(&PlaybackEvent::Stopped));
        assert!((mp.u() - 0.5).abs() < 0.02, "{}", mp.u());
        assert_eq!(mp.cruise_state(), 0);

        let f = seek(&mut m, &mut mp, 0.0, -1);
        let miss = (m.pos - start).norm();
        eprintln!(
            "  back: miss {miss:.3} m, worst v/limit {:.3}, cross {:.3} m, {:.1} s",
            f.worst_ratio, f.max_cross, f.secs
        );
        assert!(miss < 1.0, "{dynamics:?}: back {miss} m from u = 0");
        assert!(f.worst_ratio <= 1.1, "{dynamics:?}: {}", f.worst_ratio);
        assert!(
            f.events
                .contains(&PlaybackEvent::PassedKeypoint { index: 0 }),
            "{:?}",
            f.events
        );
        assert!(mp.u() < 0.02);

        // Through the corner without stopping: slowed by the curvature limit.
        let f = seek(&mut m, &mut mp, 1.0, 1);
        let end = m.ned(&mp.path().position_at_u(1.0));
        eprintln!(
            "  through: miss {:.3} m, worst v/limit {:.3}, cross {:.3} m, {:.1} s",
            (m.pos - end).norm(),
            f.worst_ratio,
            f.max_cross,
            f.secs
        );
        assert!((m.pos - end).norm() < 1.0, "{dynamics:?}");
        assert!(f.worst_ratio <= 1.1, "{dynamics:?}: {}", f.worst_ratio);
        assert!(
            f.max_cross < 1.0,
            "{dynamics:?}: {} m off the path",
            f.max_cross
        );
        assert_eq!(
            f.events,
            vec![
                PlaybackEvent::Started,
                PlaybackEvent::PassedKeypoint { index: 1 },
                PlaybackEvent::PassedKeypoint { index: 2 },
                PlaybackEvent::Stopped
            ]
        );
    }
}

#[test]
fn pause_brakes_and_holds_on_the_path_then_resumes() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
        let mut mp = Multipoint::new(l_path(&m));
        attach(&mut m, &mut mp, 0);
        mp.seek(1.0, 1).expect("attached");
        let f = fly(&mut m, &mut mp, 4.0, true, |_, _| false);
        assert!(
            m.vel.norm() > 3.0,
            "{dynamics:?}: cruising at {}",
            m.vel.norm()
        );
        assert_eq!(f.events, vec![PlaybackEvent::Started]);
        assert_eq!(mp.cruise_state(), 1);
        mp.pause();
        assert_eq!(mp.cruise_state(), 0, "braking for a pause reports paused");
        let f = fly(&mut m, &mut mp, 10.0, true, |mp, _| !mp.moving());
        assert_eq!(f.events, vec![PlaybackEvent::Stopped], "{dynamics:?}");
        let braked = fly(&mut m, &mut mp, 3.0, true, |_, _| false);
        let held = m.pos;
        let u_held = mp.u();
        let f = fly(&mut m, &mut mp, 10.0, true, |_, _| false);
        assert!(braked.events.is_empty() && f.events.is_empty());
        assert!(
            (m.pos - held).norm() < 0.1,
            "{dynamics:?}: drifted {}",
            (m.pos - held).norm()
        );
        assert!(f.max_cross < 0.3, "{dynamics:?}: {}", f.max_cross);
        assert!(u_held > 0.1 && u_held < 0.5, "{u_held}");
        // Resume to the end.
        let f = seek(&mut m, &mut mp, 1.0, 1);
        assert_eq!(f.events.first(), Some(&PlaybackEvent::Started));
        assert!((m.pos - m.ned(&mp.path().position_at_u(1.0))).norm() < 1.0);
    }
}

#[test]
fn cruise_state_picks_the_end_a_scrub_or_a_pause() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[1]);
    let mut mp = Multipoint::new(l_path(&m));
    attach(&mut m, &mut mp, 0);
    // Paused with the target where the vehicle is: nothing moves.
    mp.seek(mp.u(), 0).expect("attached");
    let f = fly(&mut m, &mut mp, 3.0, true, |_, _| false);
    assert!(f.events.is_empty() && f.max_speed < 0.1, "{f:?}");
    // Paused but somewhere else: a scrub there.
    let f = seek(&mut m, &mut mp, 0.25, 0);
    assert!((mp.u() - 0.25).abs() < 0.02, "{}", mp.u());
    assert_eq!(f.events.first(), Some(&PlaybackEvent::Started));
    // Cruising right with a target behind: to the end, as the reference does.
    seek(&mut m, &mut mp, 0.1, 1);
    assert!(mp.u() > 0.98, "{}", mp.u());
    // Cruising left with a target not behind: to the start.
    let f = seek(&mut m, &mut mp, 1.0, -1);
    assert!(mp.u() < 0.02, "{}", mp.u());
    assert!(f
        .events
        .contains(&PlaybackEvent::PassedKeypoint { index: 1 }));
}

#[test]
fn requests_out_of_turn_are_refused() {
    let mut m = PointMass::new(Vector3::new(5.0, 5.0, -10.0), DYNAMICS[1]);
    let mut mp = Multipoint::new(l_path(&m));
    assert_eq!(mp.seek(0.5, 1), Err(MultipointError::NotAttached));
    assert_eq!(
        mp.attach(3),
        Err(MultipointError::NoSuchKeypoint { index: 3, count: 3 })
    );
    // Idle: brakes and holds, camera left alone.
    let held = m.pos;
    for _ in 0..ticks(3.0) {
        let g = mp.step(&m.view(), DT, &LIMITS);
        assert_eq!((g.yaw_deg, g.gimbal_pitch_deg, g.roi), (None, None, None));
        m.fly(&g);
    }
    assert!((m.pos - held).norm() < 0.05);
    assert!(mp.take_events().is_empty());
    // Attaching: not yet seekable.
    mp.attach(2).expect("exists");
    assert_eq!(mp.attaching(), Some(2));
    assert_eq!(mp.seek(0.5, 1), Err(MultipointError::NotAttached));
    attach(&mut m, &mut mp, 2);
    assert!((mp.u() - 1.0).abs() < 0.01);
    assert!(matches!(
        mp.seek(f32::NAN, 1),
        Err(MultipointError::BadPosition { .. })
    ));
    assert!(matches!(
        mp.seek(1.5, 1),
        Err(MultipointError::BadPosition { .. })
    ));
}

#[test]
fn camera_follows_the_keypoints_unless_free() {
    let mut m = PointMass::new(Vector3::new(-5.0, 0.0, -10.0), DYNAMICS[1]);
    let mut mp = Multipoint::new(l_path(&m));
    mp.attach(1).expect("exists");
    // Attaching: the camera turns to the keypoint's attitude.
    let g = mp.step(&m.view(), DT, &LIMITS);
    assert_eq!((g.gimbal_pitch_deg, g.yaw_deg), (Some(-30.0), Some(90.0)));
    m.fly(&g);
    attach(&mut m, &mut mp, 1);
    mp.seek(0.75, 1).expect("attached");
    for _ in 0..ticks(20.0) {
        let g = mp.step(&m.view(), DT, &LIMITS);
        let (pitch, yaw) = mp.path().camera_at(f64::from(mp.u()));
        let (gp, gy) = (
            g.gimbal_pitch_deg.unwrap_or(f32::NAN),
            g.yaw_deg.unwrap_or(f32::NAN),
        );
        assert!(
            (gp - pitch).abs() < 1e-3 && (gy - yaw).abs() < 1e-3,
            "{g:?} vs {pitch} {yaw}"
        );
        m.fly(&g);
    }
    let (pitch, yaw) = mp.path().camera_at(0.75);
    assert!(
        (pitch + 45.0).abs() < 1.0 && (yaw - 135.0).abs() < 2.0,
        "{pitch} {yaw}"
    );
    mp.set_camera_free(true);
    assert!(mp.camera_free());
    let g = mp.step(&m.view(), DT, &LIMITS);
    assert_eq!((g.gimbal_pitch_deg, g.yaw_deg, g.roi), (None, None, None));
}

#[test]
fn desired_time_sets_the_cruise_speed() {
    let m0 = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[1]);
    let path = l_path(&m0);
    let d = Multipoint::new(path.clone()).durations();
    assert!(d.min_time_s > 0.0 && d.max_time_s > d.min_time_s, "{d:?}");
    let desired = 2.0 * f64::from(d.min_time_s);
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[1]);
    let mut mp = Multipoint::new(path);
    attach(&mut m, &mut mp, 0);
    mp.set_desired_time(desired);
    assert!(mp.cruise_speed_mps() < mp.path().max_speed_mps());
    let f = seek(&mut m, &mut mp, 1.0, 1);
    eprintln!(
        "desired {desired:.1} s, flew {:.1} s at {:.2} m/s",
        f.secs,
        mp.cruise_speed_mps()
    );
    assert!(
        (f.secs - desired).abs() < 0.15 * desired,
        "{} s for {desired} s",
        f.secs
    );
    assert!(f.max_speed <= mp.cruise_speed_mps() * 1.05);
    // Nonsense: the fastest; a cruise speed is clamped to the path.
    mp.set_desired_time(f64::NAN);
    assert_eq!(mp.cruise_speed_mps(), mp.path().max_speed_mps());
    mp.set_cruise_speed(50.0);
    assert_eq!(mp.cruise_speed_mps(), mp.path().max_speed_mps());
    mp.set_cruise_speed(0.01);
    assert_eq!(mp.cruise_speed_mps(), 0.5);
    mp.set_min_cruise_speed(0.2);
    assert!(
        (f64::from(mp.durations().max_time_s) - f64::from(d.max_time_s) * 2.5).abs()
            < 0.05 * f64::from(d.max_time_s) * 2.5
    );
}
