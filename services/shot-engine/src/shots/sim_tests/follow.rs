use nalgebra::{Vector2, Vector3};

use super::*;
use crate::shots::follow::{Follow, FollowMode, DEFAULT_STALE_AFTER_S};

/// A deterministic xorshift for jitter.
struct Noise(u64);

impl Noise {
    /// Uniform in [-1, 1).
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The phone: walks east at 3 m/s for 25 s from `start`, then turns south.
fn walker(start: Vector3<f64>, t: f64) -> Vector3<f64> {
    let leg = 25.0;
    if t < leg {
        start + Vector3::new(0.0, 3.0 * t, 0.0)
    } else {
        start + Vector3::new(-3.0 * (t - leg), 3.0 * leg, 0.0)
    }
}

/// Called every tick: time, vehicle, true phone position, guidance, the shot.
type Check<'a> = dyn FnMut(f64, &PointMass, &Vector3<f64>, &Guidance, &Follow) + 'a;

/// Run a follow for `secs` from `t0`, the phone at `phone(t)` with `jitter` metres
/// of uniform noise horizontally; calls `check(t, vehicle, phone, guidance, follow)`
/// each tick.
#[allow(clippy::too_many_arguments)]
fn run(
    m: &mut PointMass,
    follow: &mut Follow,
    phone: &dyn Fn(f64) -> Vector3<f64>,
    jitter: f64,
    cruise: f32,
    t0: f64,
    secs: f64,
    check: &mut Check<'_>,
) {
    let mut noise = Noise(0x2545_f491_4f6c_dd1d);
    for i in 0..ticks(secs) {
        let t = t0 + i as f64 * f64::from(DT);
        let truth = phone(t);
        let fix = truth + Vector3::new(noise.next() * jitter, noise.next() * jitter, 0.0);
        follow.update_target(m.to_geo(fix), t);
        let g = follow.step(&m.view(), t, DT, cruise, &LIMITS);
        m.fly(&g);
        check(t, m, &truth, &g, follow);
    }
}

fn horizontal(v: Vector3<f64>) -> Vector2<f64> {
    Vector2::new(v.x, v.y)
}

#[test]
fn hold_angle_keeps_the_offset_to_a_walking_target() {
    let start = Vector3::new(15.0, 0.0, 0.0);
    for dynamics in DYNAMICS {
        for jitter in [0.0, 2.0] {
            let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
            let mut follow = Follow::new(&m.view());
            let (mut worst_settled, mut worst_turn, mut worst_alt) = (0.0_f64, 0.0_f64, 0.0_f64);
            run(
                &mut m,
                &mut follow,
                &|t| walker(start, t),
                jitter,
                0.0,
                0.0,
                50.0,
                &mut |t, m, phone, g, f| {
                    // The offset is taken once the filter has settled on the target.
                    let Some([n, e]) = f.offset_m() else {
                        assert!(t < 1.0, "no offset after {t} s");
                        return;
                    };
                    let held = Vector2::new(f64::from(n), f64::from(e));
                    assert!(
                        (held - Vector2::new(-15.0, -2.1)).norm() < 1.5 + jitter,
                        "{held:?}"
                    );
                    let err = (horizontal(m.pos - phone) - held).norm();
                    worst_alt = worst_alt.max((m.pos.z + 10.0).abs());
                    // Settled on each leg: 8 s after the start and after the turn.
                    if (8.0..25.0).contains(&t) || t >= 33.0 {
                        worst_settled = worst_settled.max(err);
                    }
                    if t >= 8.0 {
                        worst_turn = worst_turn.max(err);
                    }
                    assert!(g.roi.is_some());
                },
            );
            let limit = if jitter > 0.0 { 2.5 } else { 1.0 };
            assert!(
                worst_settled < limit,
                "{dynamics:?} ±{jitter}: {worst_settled}"
            );
            // An abrupt 90° turn at 3 m/s is a 4.2 m/s change of velocity: at 2.5 m/s²
            // even a perfectly informed vehicle falls 3.6 m behind.
            assert!(
                worst_turn < 6.5,
                "{dynamics:?} ±{jitter}: {worst_turn} in the turn"
            );
            assert!(worst_alt < 0.2, "{worst_alt}");
            let v = follow.target_velocity_ned();
            assert!(
                (f64::from(v[0]) + 3.0).abs() < 0.5 && f64::from(v[1]).abs() < 0.5,
                "{v:?}"
            );
        }
    }
}

#[test]
fn hold_angle_with_cruise_orbits_the_moving_target() {
    let start = Vector3::new(20.0, 0.0, 0.0);
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
        let mut follow = Follow::new(&m.view());
        let mut worst = 0.0_f64;
        let mut first = None;
        let mut last = Vector2::zeros();
        run(
            &mut m,
            &mut follow,
            &|t| walker(start, t),
            0.0,
            1.0,
            0.0,
            50.0,
            &mut |t, m, phone, _, _| {
                let rel = horizontal(m.pos - phone);
                if (8.0..25.0).contains(&t) || t >= 33.0 {
                    worst = worst.max((rel.norm() - 20.0).abs());
                }
                if t >= 8.0 {
                    first.get_or_insert(rel);
                    last = rel;
                }
            },
        );
        assert!(worst < 1.5, "{dynamics:?}: distance off by {worst}");
        // 1 m/s on a 20 m circle for 42 s turns 2.1 rad counter-clockwise.
        let first = first.unwrap_or_default();
        let turned = (first.x * last.y - first.y * last.x).atan2(first.dot(&last));
        assert!((turned + 2.1).abs() < 0.2, "{dynamics:?}: turned {turned}");
    }
}

#[test]
fn free_look_translates_and_leaves_the_camera_to_the_pilot() {
    let start = Vector3::new(0.0, -12.0, 0.0);
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[3]);
    let mut follow = Follow::new(&m.view());
    follow.set_mode(FollowMode::FreeLook, &m.view());
    let mut worst = 0.0_f64;
    // Cruise does not orbit in free look.
    run(
        &mut m,
        &mut follow,
        &|t| walker(start, t),
        0.0,
        3.0,
        0.0,
        25.0,
        &mut |t, m, phone, g, f| {
            assert_eq!((g.roi, g.yaw_deg, g.gimbal_pitch_deg), (None, None, None));
            if t > 8.0 {
                let [n, e] = f.offset_m().unwrap_or_default();
                let offset = Vector2::new(f64::from(n), f64::from(e));
                assert!(
                    (offset - Vector2::new(0.0, 10.0)).norm() < 1.5,
                    "{offset:?}"
                );
                worst = worst.max((horizontal(m.pos - phone) - offset).norm());
            }
        },
    );
    assert!(worst < 1.0, "{worst}");
}

#[test]
fn look_at_keeps_the_vehicle_put() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
        let mut follow = Follow::new(&m.view());
        follow.set_mode(FollowMode::LookAt, &m.view());
        assert_eq!(follow.mode(), FollowMode::LookAt);
        let start = Vector3::new(10.0, 0.0, 0.0);
        let home = m.pos;
        run(
            &mut m,
            &mut follow,
            &|t| walker(start, t),
            2.0,
            4.0,
            0.0,
            40.0,
            &mut |_, m, phone, g, _| {
                assert!(
                    (m.pos - home).norm() < 0.05,
                    "moved {}",
                    (m.pos - home).norm()
                );
                let roi = g
                    .roi
                    .map(|r| m.ned(&r))
                    .unwrap_or_else(|| panic!("camera on the target"));
                assert!(ground(&roi, phone) < 2.0, "{}", ground(&roi, phone));
            },
        );
    }
}

#[test]
fn leash_trails_within_the_leash_and_slack_does_not_move_the_vehicle() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
        let mut follow = Follow::new(&m.view());
        follow.set_mode(FollowMode::Leash, &m.view());
        // The phone starts 10 m north, first walks towards the vehicle (slack), then
        // away east and south.
        let phone = |t: f64| {
            if t < 3.0 {
                Vector3::new(10.0 - t, 0.0, 0.0)
            } else {
                walker(Vector3::new(7.0, 0.0, 0.0), t - 3.0)
            }
        };
        let home = m.pos;
        let mut worst = 0.0_f64;
        run(
            &mut m,
            &mut follow,
            &phone,
            0.0,
            0.0,
            0.0,
            3.0,
            &mut |_, m, _, _, _| {
                assert!(
                    (m.pos - home).norm() < 0.05,
                    "slack leash moved the vehicle"
                );
            },
        );
        run(
            &mut m,
            &mut follow,
            &phone,
            2.0,
            0.0,
            3.0,
            50.0,
            &mut |_, m, phone, g, _| {
                worst = worst.max(ground(&m.pos, phone));
                assert!(g.roi.is_some());
            },
        );
        assert!(worst < 10.0 + 3.0, "{dynamics:?}: trailed {worst}");
        assert!(ground(&m.pos, &phone(53.0)) > 9.0, "keeps the leash length");
    }
}

#[test]
fn jitter_does_not_shake_the_vehicle() {
    for dynamics in DYNAMICS {
        let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), dynamics);
        let mut follow = Follow::new(&m.view());
        let phone = |_| Vector3::new(0.0, 15.0, 0.0);
        let mut fastest = 0.0_f64;
        // `fly` checks every setpoint step is within max_accel·dt.
        run(
            &mut m,
            &mut follow,
            &phone,
            2.0,
            0.0,
            0.0,
            30.0,
            &mut |t, m, _, _, _| {
                if t > 3.0 {
                    fastest = fastest.max(m.vel.norm());
                }
            },
        );
        assert!(fastest < 1.3, "{dynamics:?}: {fastest}");
        let target = follow.target().map(|p| m.ned(&p)).unwrap_or_default();
        assert!(ground(&target, &phone(0.0)) < 1.0, "{target:?}");
    }
}

#[test]
fn no_or_stale_target_hovers_without_roi() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[0]);
    m.vel = Vector3::new(3.0, 0.0, 0.0);
    let mut follow = Follow::new(&m.view());
    assert_eq!(follow.target(), None);
    assert_eq!(follow.target_age_s(1.0), None);
    let mut t = 0.0;
    for _ in 0..ticks(3.0) {
        let g = follow.step(&m.view(), t, DT, 2.0, &LIMITS);
        assert_eq!(g.roi, None);
        m.fly(&g);
        t += f64::from(DT);
    }
    assert!(m.vel.norm() < 1e-6, "hovering {:?}", m.vel);
    follow.update_target(m.to_geo(Vector3::new(10.0, 0.0, 0.0)), t);
    // An older fix is ignored.
    follow.update_target(m.to_geo(Vector3::new(50.0, 0.0, 0.0)), t - 1.0);
    let target = follow.target().map(|p| m.ned(&p)).unwrap_or_default();
    assert!((target.x - 10.0).abs() < 1e-6);
    assert!(follow.step(&m.view(), t, DT, 0.0, &LIMITS).roi.is_some());
    let later = t + DEFAULT_STALE_AFTER_S + 0.1;
    assert!(
        (follow.target_age_s(later).unwrap_or_default() - DEFAULT_STALE_AFTER_S - 0.1).abs() < 1e-9
    );
    assert_eq!(follow.step(&m.view(), later, DT, 0.0, &LIMITS).roi, None);
    follow.set_stale_after_s(10.0);
    assert!(follow
        .step(&m.view(), later, DT, 0.0, &LIMITS)
        .roi
        .is_some());
}

#[test]
fn a_target_right_below_starts_the_follow_at_the_minimum_distance() {
    let mut m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[1]);
    let mut follow = Follow::new(&m.view());
    run(
        &mut m,
        &mut follow,
        &|_| Vector3::zeros(),
        0.0,
        0.0,
        0.0,
        10.0,
        &mut |_, _, _, g, _| {
            assert!(g.velocity_ned_mps.iter().all(|x| x.is_finite()));
        },
    );
    assert!((horizontal(m.pos).norm() - 2.0).abs() < 0.1, "{:?}", m.pos);
}

#[test]
fn the_filter_estimates_velocity_and_restarts_after_a_loss() {
    let m = PointMass::new(Vector3::new(0.0, 0.0, -10.0), DYNAMICS[0]);
    let mut follow = Follow::new(&m.view());
    // 5 s of a phone walking north at 2 m/s, fixes at 10 Hz.
    for i in 0..=50 {
        let t = f64::from(i) * 0.1;
        follow.update_target(m.to_geo(Vector3::new(2.0 * t, 5.0, 0.0)), t);
    }
    let v = follow.target_velocity_ned();
    assert!((v[0] - 2.0).abs() < 0.1 && v[1].abs() < 0.1, "{v:?}");
    // Predicted to the latest step.
    follow.step(&m.view(), 5.5, DT, 0.0, &LIMITS);
    let at = follow.target().map(|p| m.ned(&p)).unwrap_or_default();
    assert!((at.x - 11.0).abs() < 0.3, "{at:?}");
    assert!(follow
        .target_at(f64::NAN)
        .is_some_and(|p| p.lat_deg.is_finite()));
    // Lost for longer than the stale limit, then seen far away: a fresh start, no
    // velocity made up from the jump.
    follow.update_target(
        m.to_geo(Vector3::new(100.0, 5.0, 0.0)),
        5.0 + DEFAULT_STALE_AFTER_S + 1.0,
    );
    assert_eq!(follow.target_velocity_ned(), [0.0; 3]);
    let at = follow.target().map(|p| m.ned(&p)).unwrap_or_default();
    assert!((at.x - 100.0).abs() < 1e-6);
    // Nonsense fixes are ignored.
    follow.update_target(
        GeoPoint {
            lat_deg: f64::NAN,
            ..HOME
        },
        10.0,
    );
    follow.update_target(m.to_geo(Vector3::zeros()), f64::INFINITY);
    let at = follow.target().map(|p| m.ned(&p)).unwrap_or_default();
    assert!((at.x - 100.0).abs() < 1e-6);
}
