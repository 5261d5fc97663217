//! Actuator handler tests: DO_MOTOR_TEST, SET_CAMERA_ZOOM, DO_SET_SERVO and what
//! SERVO_OUTPUT_RAW reports.

use mavlink::dialects::ardupilotmega::SERVO_OUTPUT_RAW_DATA;
use mavlink::MessageData;

use super::*;
use crate::model::Event;
use crate::telemetry;

const OK: MavResult = MavResult::MAV_RESULT_ACCEPTED;
const DENIED: MavResult = MavResult::MAV_RESULT_DENIED;
const UNSUPPORTED: MavResult = MavResult::MAV_RESULT_UNSUPPORTED;

/// DO_MOTOR_TEST: motor, throttle type, throttle, timeout, motor count.
fn motor_test(h: &Handler, v: &mut Vehicle, p: [f32; 5]) -> MavResult {
    let [motor, kind, throttle, timeout, count] = p;
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_DO_MOTOR_TEST,
        [motor, kind, throttle, timeout, count, 0., 0.],
    )
}

/// SET_CAMERA_ZOOM: zoom type, value, camera.
fn zoom(h: &Handler, v: &mut Vehicle, kind: f32, value: f32, camera: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
        [kind, value, camera, 0., 0., 0., 0.],
    )
}

fn servo(h: &Handler, v: &mut Vehicle, channel: f32, pwm: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_DO_SET_SERVO,
        [channel, pwm, 0., 0., 0., 0., 0.],
    )
}

/// The STATUSTEXTs queued since the last call.
fn texts(v: &mut Vehicle) -> Vec<String> {
    v.take_events()
        .into_iter()
        .filter_map(|e| match e {
            Event::Text { text, .. } => Some(text),
            _ => None,
        })
        .collect()
}

/// SERVO_OUTPUT_RAW as streamed, outputs 1..=16.
fn outputs(v: &Vehicle) -> [u16; 16] {
    let Some(Outgoing::Message(MavMessage::SERVO_OUTPUT_RAW(b))) =
        telemetry::build_outgoing(SERVO_OUTPUT_RAW_DATA::ID, v, 1)
    else {
        panic!("no SERVO_OUTPUT_RAW")
    };
    assert_eq!(b.port, 0);
    [
        b.servo1_raw,
        b.servo2_raw,
        b.servo3_raw,
        b.servo4_raw,
        b.servo5_raw,
        b.servo6_raw,
        b.servo7_raw,
        b.servo8_raw,
        b.servo9_raw,
        b.servo10_raw,
        b.servo11_raw,
        b.servo12_raw,
        b.servo13_raw,
        b.servo14_raw,
        b.servo15_raw,
        b.servo16_raw,
    ]
}

/// A fresh vehicle on the ground with its start-up texts taken.
fn ground() -> (Handler, Vehicle) {
    let (h, mut v) = setup();
    texts(&mut v);
    (h, v)
}

fn motors(v: &Vehicle) -> [u16; 4] {
    let o = outputs(v);
    [o[0], o[1], o[2], o[3]]
}

#[test]
fn motor_test_is_denied_in_the_air_and_while_armed() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    texts(&mut v);
    let before = motors(&v);
    assert_eq!(motor_test(&h, &mut v, [1., 0., 20., 2., 0.]), DENIED);
    assert_eq!(texts(&mut v), ["Motor Test: vehicle not landed"]);
    assert_eq!(motors(&v), before, "the flight outputs are untouched");
    assert!(!v.motor_testing());

    // Landed but armed: disarm first.
    let (h, mut v) = setup();
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1., 4., 0., 0., 0., 0., 0.],
    );
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1., 0., 0., 0., 0., 0., 0.],
    );
    assert!(v.armed() && v.landed());
    texts(&mut v);
    assert_eq!(motor_test(&h, &mut v, [1., 0., 20., 2., 0.]), DENIED);
    assert_eq!(texts(&mut v), ["Motor Test: vehicle armed, disarm first"]);
}

#[test]
fn a_motor_test_spins_one_motor_on_the_ground_and_stops_after_its_timeout() {
    let (h, mut v) = setup();
    run(&mut v, 0.5);
    texts(&mut v);
    let home = v.position_ned();
    assert_eq!(motors(&v), [1000; 4], "disarmed");
    assert_eq!(motor_test(&h, &mut v, [2., 0., 30., 2., 0.]), OK);
    assert_eq!(texts(&mut v), ["starting motor test"]);
    assert_eq!(motors(&v), [1000, 1300, 1000, 1000], "1000 + 10 × percent");
    // It does not arm the vehicle, and arming waits for its end, forced or not.
    for force in [0., 21196.] {
        assert_eq!(
            cmd(
                &h,
                &mut v,
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1., force, 0., 0., 0., 0., 0.]
            ),
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
    }
    assert_eq!(texts(&mut v), ["PreArm: Motor Testing"; 2]);
    let MavMessage::HEARTBEAT(hb) = telemetry::heartbeat(&v) else {
        panic!("not a heartbeat")
    };
    assert!(!hb
        .base_mode
        .contains(mavlink::dialects::ardupilotmega::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED));
    run(&mut v, 1.9);
    assert_eq!(motors(&v), [1000, 1300, 1000, 1000], "still spinning");
    run(&mut v, 0.15);
    assert_eq!(motors(&v), [1000; 4], "stopped after 2 s");
    assert!(!v.motor_testing());
    assert_eq!(texts(&mut v), ["finished motor test"]);
    assert_eq!(v.position_ned(), home, "nothing moved");
    assert!(!v.armed() && v.landed());
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1., 0., 0., 0., 0., 0., 0.]
        ),
        OK,
        "arming after the test"
    );
}

#[test]
fn a_new_motor_test_replaces_the_running_one() {
    let (h, mut v) = ground();
    assert_eq!(motor_test(&h, &mut v, [1., 0., 50., 2., 0.]), OK);
    run(&mut v, 1.5);
    // PWM throttle type: the output itself, for its own timeout from now.
    assert_eq!(motor_test(&h, &mut v, [3., 1., 1200., 1., 1.]), OK);
    assert_eq!(texts(&mut v), ["starting motor test"], "one start only");
    assert_eq!(motors(&v), [1000, 1000, 1200, 1000]);
    run(&mut v, 0.9);
    assert_eq!(motors(&v), [1000, 1000, 1200, 1000]);
    run(&mut v, 0.15);
    assert_eq!(motors(&v), [1000; 4]);
    assert!(!v.motor_testing());
}

#[test]
fn several_motors_are_tested_in_turn_with_a_pause_between() {
    let (h, mut v) = setup();
    // Motors 3 and 4, 1 s each, half a timeout apart (as ArduCopter).
    assert_eq!(motor_test(&h, &mut v, [3., 0., 10., 1., 2.]), OK);
    run(&mut v, 0.5);
    assert_eq!(motors(&v), [1000, 1000, 1100, 1000]);
    run(&mut v, 0.75);
    assert_eq!(motors(&v), [1000; 4], "the pause");
    assert!(v.motor_testing());
    run(&mut v, 0.5);
    assert_eq!(motors(&v), [1000, 1000, 1000, 1100]);
    run(&mut v, 0.8);
    assert!(!v.motor_testing(), "done after 2.5 s");
}

#[test]
fn motor_test_parameters_are_checked() {
    let (h, mut v) = ground();
    for (p, result) in [
        ([0., 0., 20., 2., 0.], DENIED),
        ([5., 0., 20., 2., 0.], DENIED),
        ([1.5, 0., 20., 2., 0.], DENIED),
        ([f32::NAN, 0., 20., 2., 0.], DENIED),
        ([2., 0., 20., 2., 4.], DENIED),
        ([1., 0., 101., 2., 0.], DENIED),
        ([1., 0., -1., 2., 0.], DENIED),
        ([1., 0., f32::NAN, 2., 0.], DENIED),
        ([1., 1., 700., 2., 0.], DENIED),
        ([1., 1., 2300., 2., 0.], DENIED),
        ([1., 0., 20., 0., 0.], DENIED),
        ([1., 0., 20., -1., 0.], DENIED),
        ([1., 0., 20., f32::INFINITY, 0.], DENIED),
        // Pilot pass-through and compass calibration: no RC, no compass.
        ([1., 2., 20., 2., 0.], UNSUPPORTED),
        ([1., 3., 20., 2., 0.], UNSUPPORTED),
        ([1., 9., 20., 2., 0.], UNSUPPORTED),
    ] {
        assert_eq!(motor_test(&h, &mut v, p), result, "{p:?}");
        assert!(!v.motor_testing(), "{p:?}");
    }
    let refusals = texts(&mut v);
    assert_eq!(refusals[0], "Motor Test: invalid motor 0");
    assert_eq!(refusals[4], "Motor Test: invalid motor count 4");
    assert!(refusals.iter().all(|t| t.len() <= 50), "{refusals:?}");
    // Longer than ArduCopter's 600 s: cut to it.
    assert_eq!(motor_test(&h, &mut v, [4., 0., 5., 1000., 0.]), OK);
    run(&mut v, 599.0);
    assert_eq!(motors(&v)[3], 1050);
    run(&mut v, 1.1);
    assert!(!v.motor_testing());
}

#[test]
fn camera_zoom_steps_zooms_continuously_and_goes_to_a_level() {
    let (h, mut v) = setup();
    let level = |v: &Vehicle| v.payload().zoom.level_pct();
    assert_eq!(level(&v), 0.0, "widest at start");
    assert_eq!(zoom(&h, &mut v, 2., 50., 1.), OK);
    assert_eq!(level(&v), 50.0);
    // Steps of 1 %, stopping at the ends.
    assert_eq!(zoom(&h, &mut v, 0., 5., 0.), OK);
    assert_eq!(level(&v), 55.0);
    assert_eq!(zoom(&h, &mut v, 0., -100., 0.), OK);
    assert_eq!(level(&v), 0.0);
    // Continuous: 20 %/s at full rate until stopped.
    assert_eq!(zoom(&h, &mut v, 1., 1., 0.), OK);
    run(&mut v, 1.0);
    assert!((level(&v) - 20.0).abs() < 1e-6, "{}", level(&v));
    assert_eq!(zoom(&h, &mut v, 1., 0., 0.), OK);
    run(&mut v, 1.0);
    assert!((level(&v) - 20.0).abs() < 1e-6, "stopped");
    // ... or until an end; beyond ±1 is clipped.
    assert_eq!(zoom(&h, &mut v, 1., -3., 0.), OK);
    assert_eq!(v.payload().zoom.rate(), -1.0);
    run(&mut v, 1.5);
    assert_eq!((level(&v), v.payload().zoom.rate()), (0.0, 0.0));
    // A level or a step ends a continuous zoom.
    assert_eq!(zoom(&h, &mut v, 1., 0.5, 0.), OK);
    run(&mut v, 1.0);
    assert!((level(&v) - 10.0).abs() < 1e-6, "half rate");
    assert_eq!(zoom(&h, &mut v, 2., 80., 0.), OK);
    run(&mut v, 1.0);
    assert_eq!(level(&v), 80.0);
}

#[test]
fn camera_zoom_refusals() {
    let (h, mut v) = setup();
    assert_eq!(zoom(&h, &mut v, 2., 30., 0.), OK);
    for (kind, value, camera, result) in [
        (2., 100.5, 0., DENIED),
        (2., -1., 0., DENIED),
        (2., f32::NAN, 0., DENIED),
        (0., 101., 0., DENIED),
        (0., f32::INFINITY, 0., DENIED),
        (1., f32::NAN, 0., DENIED),
        // No such camera: the simulator has one, id 1.
        (2., 50., 2., DENIED),
        // Not a CAMERA_ZOOM_TYPE.
        (7., 50., 0., DENIED),
        (1.5, 50., 0., DENIED),
        // Focal length and field of view: the simulated camera has no optics.
        (3., 50., 0., UNSUPPORTED),
        (4., 50., 0., UNSUPPORTED),
    ] {
        assert_eq!(
            zoom(&h, &mut v, kind, value, camera),
            result,
            "{kind} {value} {camera}"
        );
    }
    assert_eq!(v.payload().zoom.level_pct(), 30.0, "nothing changed");
}

#[test]
fn servo_output_raw_reports_the_motors_and_the_servos_set() {
    let (h, mut v) = setup();
    assert_eq!(
        outputs(&v),
        [1000, 1000, 1000, 1000, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    );
    assert_eq!(servo(&h, &mut v, 5., 1500.), OK);
    assert_eq!(servo(&h, &mut v, 9., 1900.), OK);
    assert_eq!(servo(&h, &mut v, 16., 1100.), OK);
    assert_eq!(servo(&h, &mut v, 17., 1300.), OK, "beyond port 0");
    texts(&mut v);
    // The motor outputs are not servos (ArduPilot: FAILED, with a reason).
    assert_eq!(servo(&h, &mut v, 3., 1500.), MavResult::MAV_RESULT_FAILED);
    assert_eq!(
        texts(&mut v),
        ["ServoRelayEvent: Channel 3 is already in use"]
    );
    let o = outputs(&v);
    assert_eq!(
        o,
        [1000, 1000, 1000, 1000, 1500, 0, 0, 0, 1900, 0, 0, 0, 0, 0, 0, 1100]
    );
    // Armed on the ground the motors idle at MOT_SPIN_ARM; in a hover they carry
    // the hover throttle.
    airborne(&h, &mut v, 5.0);
    let hover = motors(&v);
    assert!(hover.iter().all(|m| (1350..=1450).contains(m)), "{hover:?}");
    assert_eq!(outputs(&v)[8], 1900, "servos stay as set");
    let (h, mut v) = setup();
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1., 4., 0., 0., 0., 0., 0.],
    );
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        [1., 0., 0., 0., 0., 0., 0.],
    );
    assert_eq!(motors(&v), [1100; 4]);
}

#[test]
fn servo_output_raw_can_be_requested_and_streamed() {
    let (h, mut v) = setup();
    let id = SERVO_OUTPUT_RAW_DATA::ID as f32;
    let r = h.handle(
        &mut v,
        &long(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [id, 0., 0., 0., 0., 0., 0.],
        ),
    );
    assert!(matches!(
        &r.replies[..],
        [
            Outgoing::Message(MavMessage::COMMAND_ACK(_)),
            Outgoing::Message(MavMessage::SERVO_OUTPUT_RAW(_))
        ]
    ));
    let r = h.handle(
        &mut v,
        &long(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [id, 100_000., 0., 0., 0., 0., 0.],
        ),
    );
    assert_eq!(r.ack, Some(OK));
    assert!(matches!(
        r.streams[..],
        [StreamRequest::Interval { id: 36, request: IntervalRequest::Every(d) }]
            if d == std::time::Duration::from_millis(100)
    ));
}
