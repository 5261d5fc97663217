//! Actuators in the air ([`super::in_air`]): motor tests, servos, camera zoom.

use super::tests::{executed, flying, refusal, sample, settings, S};
use super::*;
use skymesh_ipc_types::{AckResult, ZoomMode};
use CommandSource::*;

fn motor_test() -> Command {
    Command::MotorTest {
        motor: 2,
        throttle_pct: 15.0,
        duration_s: 3.0,
    }
}

fn servo(channel: u8) -> Command {
    Command::Servo {
        channel,
        pwm_us: 1900,
    }
}

/// Armed, on the ground at home (what the arbiter sees after arming).
fn armed_on_ground() -> VehicleView {
    let mut v = flying(0.0, 0.0, [0.0, 0.0, 0.1]);
    if let Some(k) = &mut v.position {
        k.alt_rel_m = 0.2;
    }
    v
}

#[test]
fn motor_tests_are_refused_in_the_air_from_every_source_and_run_on_the_ground() {
    let mut a = Arbiter::new(settings());
    let air = flying(0.0, 0.0, [0.0; 3]);
    for source in [Safety, ManualRc, Operator, Imc] {
        let d = a.decide(S, &sample(source, motor_test(), S), &air);
        assert_eq!(
            refusal(&d),
            (
                RefusalReason::InAir,
                "in the air: motor test of motor 2 refused, motor tests run only on the ground"
            ),
            "{source}"
        );
        assert!(d.effects.is_empty(), "{source}: a refusal grabs nothing");
    }
    assert_eq!(a.authority().state(1).flight(), None);
    // Armed with no position counts as flying.
    let unknown = VehicleView {
        armed: true,
        ..VehicleView::default()
    };
    let d = a.decide(S, &sample(Imc, motor_test(), S), &unknown);
    assert_eq!(refusal(&d).0, RefusalReason::InAir);
    // On the ground, disarmed or armed: executed unchanged, with flight authority.
    for ground in [VehicleView::default(), armed_on_ground()] {
        let d = a.decide(2 * S, &sample(Imc, motor_test(), 2 * S), &ground);
        assert_eq!(executed(&d), motor_test());
    }
    assert_eq!(a.authority().state(1).flight(), Some(Imc));
}

#[test]
fn servos_in_the_air_are_refused_unless_their_channel_is_allowed() {
    let mut s = settings();
    assert!(s.servo_channels_in_flight.is_empty(), "none by default");
    let mut a = Arbiter::new(s.clone());
    let air = flying(0.0, 0.0, [2.0, 0.0, 0.0]);
    let d = a.decide(S, &sample(Imc, servo(9), S), &air);
    assert_eq!(
        refusal(&d),
        (
            RefusalReason::InAir,
            "in the air: servo channel 9 is not in servo_channels_in_flight"
        )
    );
    assert_eq!(a.authority().state(1).payload(), None);
    // On the ground every channel is driven.
    for ground in [VehicleView::default(), armed_on_ground()] {
        let d = a.decide(S, &sample(Imc, servo(9), S), &ground);
        assert_eq!(executed(&d), servo(9));
    }

    s.servo_channels_in_flight = vec![9, 12];
    let mut a = Arbiter::new(s);
    let d = a.decide(S, &sample(Imc, servo(9), S), &air);
    assert_eq!(executed(&d), servo(9), "an allowed channel in flight");
    assert_eq!(a.authority().state(1).payload(), Some(Imc));
    assert_eq!(
        a.authority().state(1).flight(),
        None,
        "a servo needs payload authority only"
    );
    let d = a.decide(S, &sample(Imc, servo(10), S), &air);
    assert_eq!(refusal(&d).0, RefusalReason::InAir);
    // Safety gets no exception for servos either.
    let d = a.decide(S, &sample(Safety, servo(10), S), &air);
    assert_eq!(refusal(&d).0, RefusalReason::InAir);
}

#[test]
fn authority_is_decided_before_the_in_air_rule() {
    let mut a = Arbiter::new(settings());
    let air = flying(0.0, 0.0, [0.0; 3]);
    a.decide(S, &sample(Operator, Command::GrabPayloadAuthority, S), &air);
    let d = a.decide(S, &sample(Imc, servo(9), S), &air);
    assert_eq!(
        refusal(&d),
        (
            RefusalReason::NoAuthority,
            "payload authority held by operator"
        )
    );
}

#[test]
fn camera_zoom_passes_unchanged_with_payload_authority_in_the_air() {
    let mut a = Arbiter::new(settings());
    let air = flying(0.0, 0.0, [3.0, 0.0, 0.0]);
    for (mode, value) in [
        (ZoomMode::Continuous, 1.0),
        (ZoomMode::Continuous, 0.0),
        (ZoomMode::Step, -5.0),
        (ZoomMode::Range, 42.5),
    ] {
        let zoom = Command::CameraZoom {
            camera: 1,
            mode,
            value,
        };
        let d = a.decide(S, &sample(Imc, zoom, S), &air);
        assert_eq!(d.result(), AckResult::Accepted, "{mode}");
        assert_eq!(executed(&d), zoom);
    }
    let st = a.authority().state(1);
    assert_eq!((st.payload(), st.flight()), (Some(Imc), None));
    let zoom = Command::CameraZoom {
        camera: 0,
        mode: ZoomMode::Range,
        value: 0.0,
    };
    let d = a.decide(S, &sample(Vision, zoom, S), &air);
    assert_eq!(refusal(&d).0, RefusalReason::NoAuthority);
}
