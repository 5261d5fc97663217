//! Actuator commands: MAV_CMD_DO_SET_SERVO, MAV_CMD_DO_MOTOR_TEST and
//! MAV_CMD_SET_CAMERA_ZOOM. Their outputs go out in SERVO_OUTPUT_RAW
//! ([`crate::telemetry::servo_output_raw`]); the zoom level stays in the model.
//!
//! | command | accepted | refused |
//! |---|---|---|
//! | DO_SET_SERVO p1 channel, p2 µs | channel 5..=32 (1..=4 drive the motors) | FAILED, as ArduPilot (motor channel: STATUSTEXT "ServoRelayEvent: Channel N is already in use") |
//! | DO_MOTOR_TEST p1 motor 1..=4, p2 throttle type, p3 throttle, p4 timeout s, p5 motor count (0 = 1), p6 order (ignored, as ArduCopter) | landed and disarmed; type 0 percent 0..=100 or type 1 PWM 800..=2200 µs; timeout > 0 (cut to 600 s) | DENIED with a STATUSTEXT ("Motor Test: vehicle not landed", ...; ArduCopter answers FAILED, the simulator tells refusals apart as it does for arming); types 2 (pilot) and 3 (compass calibration) UNSUPPORTED: no RC, no compass |
//! | SET_CAMERA_ZOOM p1 zoom type, p2 value, p3 camera (0 all, 1 the one camera) | type 0 step: ±steps of 1 % (up to 100); 1 continuous: −1..=1 × 20 %/s until 0 or an end (beyond ±1 clipped, as MAVLink says); 2 range: 0..=100 % | DENIED for a value out of range, an unknown camera or a type MAVLink does not define; types 3 (focal length) and 4 (field of view) UNSUPPORTED: the simulated camera has no optics |

use mavlink::dialects::ardupilotmega::{MavResult, MavSeverity};
use tracing::info;

use super::command::Cmd;
use crate::model::{motors, MotorTestRequest, TestThrottle, Vehicle};

/// Servo channels ArduPilot has outputs for.
const MAX_SERVO_CHANNEL: f32 = 32.0;

/// The simulator's one camera (SET_CAMERA_ZOOM param3; 0 addresses every camera).
pub const CAMERA_ID: f32 = 1.0;

/// MAV_CMD_DO_SET_SERVO: record the output of a channel that is not a motor's.
pub(super) fn set_servo(v: &mut Vehicle, channel: f32, pwm: f32) -> MavResult {
    if !((1.0..=MAX_SERVO_CHANNEL).contains(&channel) && (0.0..=f32::from(u16::MAX)).contains(&pwm))
    {
        return MavResult::MAV_RESULT_FAILED;
    }
    let channel = channel as u8;
    if channel <= motors::MOTORS {
        v.say(
            MavSeverity::MAV_SEVERITY_INFO,
            &format!("ServoRelayEvent: Channel {channel} is already in use"),
        );
        return MavResult::MAV_RESULT_FAILED;
    }
    v.payload_mut().servos.insert(channel, pwm as u16);
    MavResult::MAV_RESULT_ACCEPTED
}

/// MAV_CMD_DO_MOTOR_TEST.
pub(super) fn motor_test(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    let [motor, kind, value, timeout] = cmd.p.map(f64::from);
    let throttle = match kind {
        0.0 => TestThrottle::Percent(value),
        1.0 => TestThrottle::Pwm(value),
        _ => {
            info!(
                throttle_type = kind,
                "motor test throttle type not simulated"
            );
            return MavResult::MAV_RESULT_UNSUPPORTED;
        }
    };
    let req = MotorTestRequest {
        motor,
        throttle,
        timeout_s: timeout,
        count: cmd.p5,
    };
    match v.motor_test(req) {
        Ok(()) => {
            info!(motor, ?throttle, timeout, "motor test");
            MavResult::MAV_RESULT_ACCEPTED
        }
        Err(why) => {
            info!(?why, "motor test refused");
            MavResult::MAV_RESULT_DENIED
        }
    }
}

/// MAV_CMD_SET_CAMERA_ZOOM.
pub(super) fn camera_zoom(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    use MavResult::*;
    let [kind, value, camera, _] = cmd.p;
    if !(camera == 0.0 || camera == CAMERA_ID) {
        return MAV_RESULT_DENIED;
    }
    let value = f64::from(value);
    let zoom = &mut v.payload_mut().zoom;
    let result = match kind {
        0.0 => zoom.step_by(value),
        1.0 => zoom.continuous(value),
        2.0 => zoom.set_level(value),
        3.0 | 4.0 => return MAV_RESULT_UNSUPPORTED,
        _ => return MAV_RESULT_DENIED,
    };
    match result {
        Ok(()) => MAV_RESULT_ACCEPTED,
        Err(why) => {
            info!(?why, "zoom refused");
            MAV_RESULT_DENIED
        }
    }
}
