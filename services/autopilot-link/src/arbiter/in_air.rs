//! What may not run while the vehicle is in the air (refusal `InAir`).
//!
//! The in-air notion is the arbiter's (`VehicleView::in_air`): armed and (position
//! unknown, above `in_air_alt_m`, or faster than `in_air_speed_mps`). The rules:
//!
//! | command | in the air |
//! |---|---|
//! | `MotorKill { emergency: false }` | refused: only an emergency kill stops the motors in flight |
//! | `Disarm { force: true }` | refused: a forced disarm skips the autopilot's landed check, so in flight it is a motor kill; it has no emergency flag, so it is always refused (a deliberate kill in flight is `MotorKill { emergency: true }`). A plain `Disarm` passes: the autopilot refuses it unless landed |
//! | `MotorTest` | refused for every source, safety included: a motor test spins one motor at a fixed throttle, which is never meaningful in flight (ArduCopter itself only runs it landed) |
//! | `Servo { channel, .. }` | refused unless `channel` is in `servo_channels_in_flight` (`[arbiter]` config; empty by default): a servo output in flight may be a control surface, a gripper or a parachute, so only channels the operator declared harmless (a payload release, a light) are driven by remote tools such as the IMC gateway |
//!
//! Everything else, `CameraZoom` and the other payload commands included, passes
//! unchanged.

use skymesh_ipc_types::Command;

/// Why `command` may not run in the air; `None` when it may. `servo_channels` are
/// the servo channels allowed in flight (sorted or not).
pub fn refusal(command: &Command, servo_channels: &[u8]) -> Option<String> {
    match *command {
        Command::MotorKill { emergency: false } => {
            Some("in the air: only an emergency kill stops the motors".to_string())
        }
        Command::Disarm { force: true } => {
            Some("in the air: a forced disarm is a motor kill".to_string())
        }
        Command::MotorTest { motor, .. } => Some(format!(
            "in the air: motor test of motor {motor} refused, motor tests run only on the ground"
        )),
        Command::Servo { channel, .. } if !servo_channels.contains(&channel) => Some(format!(
            "in the air: servo channel {channel} is not in servo_channels_in_flight"
        )),
        _ => None,
    }
}
