//! DO_SET_HOME handler tests: where home goes, when it is refused, what is
//! announced, and that RTL and arming follow the new home.

use mavlink::dialects::ardupilotmega::HOME_POSITION_DATA;
use mavlink::MessageData;

use super::*;
use crate::model::{Event, GeoPoint};
use crate::telemetry;

const OK: MavResult = MavResult::MAV_RESULT_ACCEPTED;

/// Metres per degree of latitude near the origin (WGS-84 at 35.4° S; to a metre in
/// the f32 latitude test below).
const M_PER_DEG: f64 = 110_947.0;

/// A point `north_m` north of the origin (the initial home) at `alt_msl_m`, in the
/// model's own frame (WGS-84; it was ArduPilot's 111 318.8 m per degree sphere).
fn north_of_origin(v: &Vehicle, north_m: f64, alt_msl_m: f64) -> GeoPoint {
    GeoPoint {
        alt_msl_m,
        ..v.frame().to_geo(&nalgebra::Vector3::new(north_m, 0.0, 0.0))
    }
}

fn set_home_int(h: &Handler, v: &mut Vehicle, p1: f32, at: GeoPoint, frame: MavFrame) -> Response {
    h.handle(
        v,
        &msg(MavMessage::COMMAND_INT(COMMAND_INT_DATA {
            param1: p1,
            x: at.lat_e7(),
            y: at.lon_e7(),
            z: at.alt_msl_m as f32,
            command: MavCmd::MAV_CMD_DO_SET_HOME,
            target_system: 1,
            target_component: 1,
            frame,
            ..COMMAND_INT_DATA::DEFAULT
        })),
    )
}

fn home_changed(v: &mut Vehicle) -> bool {
    v.take_events().contains(&Event::HomeChanged)
}

#[test]
fn command_int_moves_home_to_the_given_msl_location_and_announces_it() {
    let (h, mut v) = setup();
    v.take_events();
    let ground = v.frame().origin().alt_msl_m;
    let target = north_of_origin(&v, 50.0, ground + 6.0);
    let r = set_home_int(&h, &mut v, 0.0, target, MavFrame::MAV_FRAME_GLOBAL);
    assert_eq!(r.ack, Some(OK));
    let home = v.home_geo().expect("home");
    assert_eq!(
        (home.lat_e7(), home.lon_e7()),
        (target.lat_e7(), target.lon_e7())
    );
    assert!((home.alt_msl_m - target.alt_msl_m).abs() < 1e-3);
    let ned = v.home_ned().expect("home");
    assert!((ned.x - 50.0).abs() < 0.01 && ned.y.abs() < 0.01, "{ned:?}");
    // The engine broadcasts HOME_POSITION for this event at once.
    assert!(home_changed(&mut v));
    let Some(MavMessage::HOME_POSITION(hp)) = telemetry::build(HOME_POSITION_DATA::ID, &v, 1)
    else {
        panic!("HOME_POSITION")
    };
    assert_eq!(hp.latitude, target.lat_e7());
    assert_eq!(hp.altitude, ((ground + 6.0) * 1000.0).round() as i32);
    // Relative altitude is measured from home: on the ground, 6 m below it.
    assert!(
        (v.relative_alt() + 6.0).abs() < 1e-6,
        "{}",
        v.relative_alt()
    );
}

#[test]
fn command_long_here_and_zero_location_use_the_current_position() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 10.0);
    // Somewhere else first, then "here" with param1 = 1 (the location is ignored).
    let elsewhere = north_of_origin(&v, 30.0, 590.0);
    let r = set_home_int(&h, &mut v, 0.0, elsewhere, MavFrame::MAV_FRAME_GLOBAL);
    assert_eq!(r.ack, Some(OK));
    let here = v.position_ned();
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_HOME,
            [1., 0., 0., 0., elsewhere.lat_deg as f32, 0., 0.]
        ),
        OK
    );
    assert!((v.home_ned().expect("home") - here).norm() < 0.01);
    assert!(
        v.relative_alt().abs() < 0.01,
        "home is where the vehicle is"
    );
    // COMMAND_LONG, degrees, MSL: 20 m north at 600 m.
    let o = v.frame().origin();
    let lat = (o.lat_deg + 20.0 / M_PER_DEG) as f32;
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_HOME,
            [0., 0., 0., 0., lat, o.lon_deg as f32, 600.]
        ),
        OK
    );
    let home = v.home_geo().expect("home");
    // An f32 latitude is good to about a metre.
    assert!(((home.lat_deg - o.lat_deg) * M_PER_DEG - 20.0).abs() < 2.0);
    assert!((home.alt_msl_m - 600.0).abs() < 1e-3);
    // Latitude and longitude both 0: ArduPilot's "here".
    let here = v.position_ned();
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_HOME,
            [0., 0., 0., 0., 0., 0., 100.]
        ),
        OK
    );
    assert!((v.home_ned().expect("home") - here).norm() < 0.01);
}

#[test]
fn home_is_refused_without_a_position_far_away_or_in_a_bad_frame() {
    // No EKF position yet: retry later.
    let mut v = Vehicle::new(VehicleParams {
        ekf_ready_after_s: 30.0,
        ..VehicleParams::default()
    });
    let h = Handler::new(1);
    let target = north_of_origin(&v, 50.0, 584.0);
    let r = set_home_int(&h, &mut v, 0.0, target, MavFrame::MAV_FRAME_GLOBAL);
    assert_eq!(r.ack, Some(MavResult::MAV_RESULT_TEMPORARILY_REJECTED));
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_HOME,
            [1., 0., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert!(v.home_ned().is_none());

    let (h, mut v) = setup();
    v.take_events();
    let before = v.home_ned();
    // Over 50 km from the EKF origin.
    let far = north_of_origin(&v, 60_000.0, 584.0);
    let r = set_home_int(&h, &mut v, 0.0, far, MavFrame::MAV_FRAME_GLOBAL);
    assert_eq!(r.ack, Some(MavResult::MAV_RESULT_FAILED));
    // No such latitude; a frame that is not global.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_HOME,
            [0., 0., 0., 0., 91., 149., 584.]
        ),
        MavResult::MAV_RESULT_DENIED
    );
    let r = set_home_int(&h, &mut v, 0.0, target, MavFrame::MAV_FRAME_LOCAL_NED);
    assert_eq!(r.ack, Some(MavResult::MAV_RESULT_DENIED));
    assert_eq!(v.home_ned(), before, "home unchanged");
    assert!(!home_changed(&mut v), "nothing announced");
}

#[test]
fn rtl_returns_to_the_new_home_and_arming_leaves_a_set_home_alone() {
    let (h, mut v) = setup();
    // Set on the ground, then armed elsewhere: home stays (DO_SET_HOME locks it).
    let ground = v.frame().origin().alt_msl_m;
    let target = north_of_origin(&v, 50.0, ground);
    let r = set_home_int(&h, &mut v, 0.0, target, MavFrame::MAV_FRAME_GLOBAL);
    assert_eq!(r.ack, Some(OK));
    airborne(&h, &mut v, 10.0);
    let home = v.home_ned().expect("home");
    assert!((home.x - 50.0).abs() < 0.01, "arming kept it: {home:?}");
    assert!(
        (v.relative_alt() - 10.0).abs() < 0.1,
        "home is at ground level"
    );
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH, [0.; 7]),
        OK
    );
    // Climb, 50 m, loiter, land.
    run(&mut v, 90.0);
    let p = v.position_ned();
    assert!(
        (p.x - 50.0).abs() < 1.0 && p.y.abs() < 1.0,
        "landed at the new home: {p:?}"
    );
    assert!(v.landed() && !v.armed());
}
