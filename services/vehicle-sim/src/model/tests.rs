//! Model tests: explicit dt, no clock.

use super::*;
use nalgebra::Vector3;

const DT: f64 = 0.01;

fn run(v: &mut Vehicle, secs: f64) {
    let steps = (secs / DT).round() as usize;
    for _ in 0..steps {
        v.step(DT);
    }
}

fn texts(v: &mut Vehicle) -> Vec<String> {
    v.take_events()
        .into_iter()
        .filter_map(|e| match e {
            Event::Text { text, .. } => Some(text),
            Event::HomeChanged | Event::GoProChanged => None,
        })
        .collect()
}

/// Armed in GUIDED, hovering at `alt` metres.
fn hovering(alt: f64) -> Vehicle {
    let mut v = Vehicle::new(VehicleParams::default());
    v.set_mode(FlightMode::Guided).expect("guided");
    v.arm(false).expect("arm");
    v.takeoff(alt).expect("takeoff");
    run(&mut v, 8.0 + alt / 2.5);
    assert!((v.relative_alt() - alt).abs() < 0.1, "{}", v.relative_alt());
    v.take_events();
    v
}

#[test]
fn starts_disarmed_on_the_ground_with_home_at_origin() {
    let mut v = Vehicle::new(VehicleParams::default());
    assert!(!v.armed() && v.landed() && v.ekf_ready());
    assert_eq!(v.mode(), FlightMode::Stabilize);
    assert_eq!(v.home_ned(), Some(Vector3::zeros()));
    let home = v.home_geo().expect("home");
    assert_eq!(home.lat_e7(), -353_632_610);
    assert!(v.take_events().contains(&Event::HomeChanged));
}

#[test]
fn arming_refused_in_land_with_reason() {
    let mut v = Vehicle::new(VehicleParams::default());
    v.set_mode(FlightMode::Land).expect("mode");
    v.take_events();
    assert_eq!(
        v.arm(false),
        Err(ArmRefusal::ModeNotArmable(FlightMode::Land))
    );
    assert_eq!(texts(&mut v), vec!["Arm: Mode not armable".to_owned()]);
    assert!(!v.armed());
    // Forced arming skips the checks.
    assert_eq!(v.arm(true), Ok(()));
    assert!(v.armed());
}

#[test]
fn arming_waits_for_gps_then_ekf() {
    let mut v = Vehicle::new(VehicleParams {
        ekf_ready_after_s: 30.0,
        ..VehicleParams::default()
    });
    v.set_mode(FlightMode::Guided).expect("mode");
    assert_eq!(v.arm(false), Err(ArmRefusal::NoGpsFix));
    assert!(v.home_ned().is_none());
    run(&mut v, 20.0);
    let refusal = v.arm(false).unwrap_err();
    assert_eq!(refusal, ArmRefusal::EkfNotReady);
    assert!(refusal.is_temporary());
    assert!(texts(&mut v).iter().any(|t| t.starts_with("PreArm: EKF")));
    run(&mut v, 10.5);
    assert!(v.ekf_ready() && v.home_ned().is_some());
    assert_eq!(v.arm(false), Ok(()));
}

#[test]
fn arming_refused_on_low_battery() {
    let mut v = Vehicle::new(VehicleParams {
        battery_initial_fraction: 0.1,
        ..VehicleParams::default()
    });
    let e = v.arm(false).unwrap_err();
    assert!(matches!(e, ArmRefusal::BatteryLow { .. }));
    assert!(!e.is_temporary());
}

#[test]
fn takeoff_climbs_to_target_within_limits_and_holds() {
    let mut v = Vehicle::new(VehicleParams::default());
    v.set_mode(FlightMode::Guided).expect("mode");
    assert_eq!(v.takeoff(10.0), Err(TakeoffRefusal::NotArmed));
    v.arm(false).expect("arm");
    assert_eq!(v.takeoff(-1.0), Err(TakeoffRefusal::BadAltitude(-1.0)));
    v.takeoff(10.0).expect("takeoff");
    let mut max_alt = 0.0_f64;
    for _ in 0..1000 {
        v.step(DT);
        assert!(v.velocity_ned().z >= -2.5 - 1e-9, "climb limit");
        max_alt = max_alt.max(v.relative_alt());
    }
    assert!(!v.landed());
    assert!(
        (v.relative_alt() - 10.0).abs() < 0.5,
        "{}",
        v.relative_alt()
    );
    assert!(max_alt < 10.05, "overshoot {max_alt}");
    run(&mut v, 20.0);
    assert!((v.relative_alt() - 10.0).abs() < 0.01);
    assert!(v.armed(), "hovering does not auto-disarm");
    assert_eq!(v.takeoff(20.0), Err(TakeoffRefusal::AlreadyFlying));
}

#[test]
fn takeoff_refused_outside_takeoff_modes() {
    let mut v = Vehicle::new(VehicleParams::default());
    v.arm(false).expect("arm in stabilize");
    assert_eq!(
        v.takeoff(5.0),
        Err(TakeoffRefusal::Mode(FlightMode::Stabilize))
    );
}

#[test]
fn velocity_setpoint_flies_then_times_out_and_stops() {
    let mut v = hovering(10.0);
    let start = v.position_ned();
    v.guided_target(GuidedTarget {
        vel: Some(Vector3::new(2.0, 0.0, 0.0)),
        ..GuidedTarget::default()
    })
    .expect("guided");
    run(&mut v, 2.5);
    assert!((v.velocity_ned().x - 2.0).abs() < 1e-6);
    // 3 s timeout, then 2 m/s brakes at 2.5 m/s² in under a second.
    run(&mut v, 1.5);
    assert!(v.velocity_ned().norm() < 1e-6, "{:?}", v.velocity_ned());
    let stopped = v.position_ned();
    run(&mut v, 2.0);
    assert!((v.position_ned() - stopped).norm() < 1e-6);
    let travelled = stopped.x - start.x;
    // ~0.4 s to accelerate, cruise, ~0.8 s to stop: about 5.2 m.
    assert!((4.5..6.0).contains(&travelled), "{travelled}");
    assert!((v.relative_alt() - 10.0).abs() < 0.01);
}

#[test]
fn position_target_reached_without_overshoot() {
    let mut v = hovering(10.0);
    let target = v.position_ned() + Vector3::new(30.0, 20.0, -5.0);
    v.guided_target(GuidedTarget {
        pos: Some(target),
        ..GuidedTarget::default()
    })
    .expect("guided");
    let dir = (target - v.position_ned()).normalize();
    let start = v.position_ned();
    let mut max_along = 0.0_f64;
    for _ in 0..3000 {
        v.step(DT);
        max_along = max_along.max((v.position_ned() - start).dot(&dir));
        let vxy = v.velocity_ned().xy().norm();
        assert!(vxy <= 5.0 + 1e-9);
    }
    assert!((v.position_ned() - target).norm() < 0.05);
    assert!(max_along <= (target - start).norm() + 0.05);
    // It turned to face the target on the way.
    let bearing = 20.0_f64.atan2(30.0);
    assert!((v.heading() - bearing).abs() < 0.02, "{}", v.heading());
}

#[test]
fn setpoints_ignored_outside_guided() {
    let mut v = hovering(5.0);
    v.set_mode(FlightMode::Loiter).expect("loiter");
    let e = v.guided_target(GuidedTarget {
        vel: Some(Vector3::new(1.0, 0.0, 0.0)),
        ..GuidedTarget::default()
    });
    assert_eq!(e, Err(NotGuided(FlightMode::Loiter)));
}

#[test]
fn land_descends_and_disarms() {
    let mut v = hovering(10.0);
    v.set_mode(FlightMode::Land).expect("land");
    let mut fastest_low = 0.0_f64;
    for _ in 0..4000 {
        v.step(DT);
        if v.relative_alt() < 5.0 {
            fastest_low = fastest_low.max(v.velocity_ned().z);
        }
    }
    assert!(!v.armed() && v.landed());
    assert!(fastest_low <= 0.5 + 1e-9, "{fastest_low}");
    assert!(texts(&mut v).contains(&"Disarming motors".to_owned()));
}

#[test]
fn rtl_climbs_returns_and_lands_at_home() {
    let mut v = hovering(10.0);
    v.guided_target(GuidedTarget {
        pos: Some(Vector3::new(40.0, -30.0, -10.0)),
        ..GuidedTarget::default()
    })
    .expect("guided");
    run(&mut v, 20.0);
    v.set_mode(FlightMode::Rtl).expect("rtl");
    let mut max_alt = 0.0_f64;
    for _ in 0..10_000 {
        v.step(DT);
        max_alt = max_alt.max(v.relative_alt());
        if !v.armed() {
            break;
        }
    }
    assert!(!v.armed() && v.landed());
    assert!((max_alt - 15.0).abs() < 0.1, "RTL_ALT: {max_alt}");
    assert!(v.position_ned().xy().norm() < 0.3, "{:?}", v.position_ned());
}

#[test]
fn rtl_from_higher_keeps_altitude() {
    let mut v = hovering(25.0);
    v.set_mode(FlightMode::Rtl).expect("rtl");
    run(&mut v, 1.0);
    assert!(v.relative_alt() > 24.5);
}

#[test]
fn landed_and_armed_auto_disarms_after_delay() {
    let mut v = Vehicle::new(VehicleParams::default());
    v.set_mode(FlightMode::Guided).expect("mode");
    v.arm(false).expect("arm");
    run(&mut v, 9.5);
    assert!(v.armed());
    run(&mut v, 1.0);
    assert!(!v.armed());
}

#[test]
fn disarm_in_flight_needs_force_and_then_it_falls() {
    let mut v = hovering(10.0);
    assert_eq!(v.disarm(false), Err(DisarmRefusal::Flying));
    v.disarm(true).expect("forced");
    run(&mut v, 3.0);
    assert!(v.landed() && v.relative_alt().abs() < 1e-9);
    assert!(texts(&mut v).iter().any(|t| t.starts_with("Crash")));
}

#[test]
fn battery_drains_faster_in_flight() {
    let mut ground = Vehicle::new(VehicleParams::default());
    run(&mut ground, 60.0);
    let mut air = hovering(10.0);
    let before = air.battery().consumed_mah();
    run(&mut air, 60.0);
    let hover_mah = air.battery().consumed_mah() - before;
    // 15 A for a minute is 250 mAh.
    assert!((hover_mah - 250.0).abs() < 5.0, "{hover_mah}");
    assert!(ground.battery().consumed_mah() < 10.0);
    assert!(air.battery().voltage() < ground.battery().voltage());
    assert!((air.throttle() - 0.4).abs() < 0.01);
}

#[test]
fn condition_yaw_relative_and_absolute() {
    let mut v = hovering(5.0);
    let h0 = v.heading();
    v.condition_yaw(90.0, 30.0, 1, true);
    run(&mut v, 2.0);
    assert!(v.attitude().rates.z > 0.4, "turning clockwise at 30°/s");
    run(&mut v, 2.0);
    let expect = geo::wrap_2pi(h0 + std::f64::consts::FRAC_PI_2);
    assert!((v.heading() - expect).abs() < 1e-6);
    v.condition_yaw(180.0, 0.0, 0, false);
    run(&mut v, 5.0);
    assert!((v.heading() - std::f64::consts::PI).abs() < 1e-6);
}

#[test]
fn roi_points_the_nose() {
    let mut v = hovering(5.0);
    v.set_roi(Some(Vector3::new(0.0, -50.0, 0.0)));
    run(&mut v, 5.0);
    assert!((v.heading() - 1.5 * std::f64::consts::PI).abs() < 0.01);
}

#[test]
fn accelerating_pitches_nose_down_and_hover_is_level() {
    let mut v = hovering(5.0);
    let a = v.attitude();
    assert!(a.roll.abs() < 1e-3 && a.pitch.abs() < 1e-3);
    v.condition_yaw(0.0, 0.0, 0, false);
    run(&mut v, 5.0);
    v.guided_target(GuidedTarget {
        vel: Some(Vector3::new(5.0, 0.0, 0.0)),
        yaw: Some(0.0),
        ..GuidedTarget::default()
    })
    .expect("guided");
    run(&mut v, 0.5);
    assert!(v.attitude().pitch < -0.2, "{}", v.attitude().pitch);
}

#[test]
fn circle_orbits_at_radius() {
    let mut v = hovering(10.0);
    let yaw = v.attitude().yaw;
    let center = v.position_ned() + Vector3::new(yaw.cos(), yaw.sin(), 0.0) * 10.0;
    v.set_mode(FlightMode::Circle).expect("circle");
    for _ in 0..2000 {
        v.step(DT);
        let r = (v.position_ned() - center).xy().norm();
        assert!((r - 10.0).abs() < 1.0, "radius {r}");
    }
}

#[test]
fn mode_changes_are_announced_and_unknown_modes_refused() {
    let mut v = Vehicle::new(VehicleParams::default());
    v.take_events();
    v.set_mode(FlightMode::Auto).expect("auto");
    let t = texts(&mut v);
    assert!(t.contains(&"Mode AUTO".to_owned()));
    assert!(t.iter().any(|s| s.contains("no mission")));
    assert_eq!(
        v.set_mode_number(21),
        Err(ModeRefusal::NotSimulated("SMART_RTL"))
    );
    assert_eq!(v.set_mode_number(99), Err(ModeRefusal::Unknown(99)));
    assert_eq!(v.mode(), FlightMode::Auto);
    assert_eq!(
        v.arm(false),
        Err(ArmRefusal::ModeNotArmable(FlightMode::Auto))
    );
}

#[test]
fn change_speed_applies_until_mode_change() {
    let mut v = hovering(10.0);
    v.set_speed(SpeedKind::Horizontal, 2.0);
    v.guided_target(GuidedTarget {
        pos: Some(v.position_ned() + Vector3::new(100.0, 0.0, 0.0)),
        ..GuidedTarget::default()
    })
    .expect("guided");
    run(&mut v, 10.0);
    assert!((v.velocity_ned().x - 2.0).abs() < 1e-6);
    v.set_mode(FlightMode::Loiter).expect("loiter");
    v.set_mode(FlightMode::Guided).expect("guided");
    v.guided_target(GuidedTarget {
        pos: Some(v.position_ned() + Vector3::new(100.0, 0.0, 0.0)),
        ..GuidedTarget::default()
    })
    .expect("guided");
    run(&mut v, 10.0);
    assert!((v.velocity_ned().x - 5.0).abs() < 1e-6);
}

#[test]
fn deterministic() {
    let a = hovering(7.0);
    let b = hovering(7.0);
    assert_eq!(a.position_ned(), b.position_ned());
    assert_eq!(a.battery(), b.battery());
}

#[test]
fn descending_to_a_ground_level_target_lands_and_auto_disarms() {
    let mut v = hovering(3.0);
    let mut ground = v.position_ned();
    ground.z = 0.0;
    v.guided_target(GuidedTarget {
        pos: Some(ground),
        ..GuidedTarget::default()
    })
    .expect("guided");
    run(&mut v, 10.0);
    assert!(v.landed() && v.armed());
    run(&mut v, 10.0);
    assert!(!v.armed(), "DISARM_DELAY after landing in GUIDED");
}
