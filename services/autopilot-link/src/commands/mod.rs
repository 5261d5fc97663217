//! Vehicle commands → MAVLink: intake checks and the mapping. Pure, no I/O.
//!
//! Commands go to the autopilot (target component 1), GoPro requests to the gimbal
//! (component 154, `MAV_COMP_ID_GIMBAL`, which bridges the GoPro on the Solo gimbal).
//! Mapping:
//!
//! | `Command` | MAVLink | answered by |
//! |---|---|---|
//! | `Arm { force }` | COMMAND_LONG `COMPONENT_ARM_DISARM` p1 = 1, p2 = 21196 if forced | COMMAND_ACK |
//! | `Disarm { force }` | COMMAND_LONG `COMPONENT_ARM_DISARM` p1 = 0, p2 = 21196 if forced | COMMAND_ACK |
//! | `SetMode(m)` | COMMAND_LONG `DO_SET_MODE` p1 = `MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`, p2 = ArduCopter custom mode | COMMAND_ACK |
//! | `Takeoff { alt }` | COMMAND_LONG `NAV_TAKEOFF` p7 = alt above home (GUIDED, armed) | COMMAND_ACK |
//! | `Land` | COMMAND_LONG `NAV_LAND` (here) | COMMAND_ACK |
//! | `ReturnToLaunch` | COMMAND_LONG `NAV_RETURN_TO_LAUNCH` | COMMAND_ACK |
//! | `GoTo` | SET_POSITION_TARGET_GLOBAL_INT, frame `GLOBAL_RELATIVE_ALT_INT`, position (+ yaw if given) | accepted when written |
//! | `GoTo` with speed | COMMAND_LONG `DO_CHANGE_SPEED` p1 = 1 (ground), p2 = speed, then the setpoint above | the speed command's COMMAND_ACK |
//! | `VelocityNed` | SET_POSITION_TARGET_LOCAL_NED, frame `LOCAL_NED`, velocity (+ yaw rate if given) | accepted when written |
//! | `SetYaw` | COMMAND_LONG `CONDITION_YAW` p1 = angle, p2 = rate, p3 = direction, p4 = relative | COMMAND_ACK |
//! | `SetRoi` | COMMAND_INT `DO_SET_ROI_LOCATION`, frame `GLOBAL_RELATIVE_ALT` | COMMAND_ACK |
//! | `ClearRoi` | COMMAND_LONG `DO_SET_ROI_NONE` | COMMAND_ACK |
//! | `SetHome { lat, lon, alt_msl }` | COMMAND_INT `DO_SET_HOME`, frame `GLOBAL` (altitude above MSL), p1 = 0 (use the given location), x/y = lat/lon × 1e7, z = alt; lat = lon = 0 is refused `unsupported` (ArduPilot reads it as "here") | COMMAND_ACK; the autopilot then announces the new home (HOME_POSITION → `VehicleStatus` home) |
//! | `Gimbal` | COMMAND_LONG `DO_GIMBAL_MANAGER_PITCHYAW` p1 = pitch, p2 = yaw (vehicle frame), rates NaN | COMMAND_ACK |
//! | `CameraCapture` | COMMAND_LONG `IMAGE_START_CAPTURE` p3 = 1 image, p4 = capture sequence | COMMAND_ACK |
//! | `RecordStart` / `RecordStop` | COMMAND_LONG `VIDEO_START_CAPTURE` / `VIDEO_STOP_CAPTURE` | COMMAND_ACK |
//! | `Servo` | COMMAND_LONG `DO_SET_SERVO` p1 = channel, p2 = PWM µs | COMMAND_ACK |
//! | `MotorTest { motor, throttle_pct, duration_s }` | COMMAND_LONG `DO_MOTOR_TEST` p1 = motor, p2 = 0 (`MOTOR_TEST_THROTTLE_PERCENT`), p3 = throttle %, p4 = duration s, p5 = 1 motor | COMMAND_ACK (ArduCopter: only landed) |
//! | `CameraZoom { camera, mode, value }` | COMMAND_LONG `SET_CAMERA_ZOOM` p1 = `CAMERA_ZOOM_TYPE` (0 step, 1 continuous, 2 range), p2 = value, p3 = camera id (0 = all) | COMMAND_ACK |
//! | `CameraMode { camera, mode }` | COMMAND_LONG `SET_CAMERA_MODE` p1 = camera id (0 = all), p2 = `CAMERA_MODE` (0 image, 1 video, 2 image survey), p3, p4, p7 NaN (reserved) | COMMAND_ACK |
//! | `CameraCaptureStop { camera }` | COMMAND_LONG `IMAGE_STOP_CAPTURE` p1 = camera id (0 = all), p2–p4, p7 NaN (reserved) | COMMAND_ACK |
//! | `GimbalRate { pitch_rate_dps, yaw_rate_dps }` | COMMAND_LONG `DO_GIMBAL_MANAGER_PITCHYAW` p1 = p2 = NaN (no angle), p3 = pitch rate, p4 = yaw rate (deg/s), p5 = vehicle-frame yaw flag, p7 = 0 (all gimbals); turns until the next gimbal command, a rate of 0 stops it | COMMAND_ACK |
//! | `CameraFocus { camera, mode, value }` | COMMAND_LONG `SET_CAMERA_FOCUS` p1 = `SET_FOCUS_TYPE` (0 step, 1 continuous, 2 range, 3 metres, 4 auto, 5 auto single, 6 auto continuous), p2 = value (0 for the auto types, which ignore it), p3 = camera id (0 = all), p4 NaN (reserved) | COMMAND_ACK (ArduPilot denies step and metres) |
//! | `Brake` in GUIDED | SET_POSITION_TARGET_LOCAL_NED zero velocity (stays GUIDED, so setpoints resume at once) | accepted when written |
//! | `Brake` otherwise | COMMAND_LONG `DO_SET_MODE` BRAKE (17) | COMMAND_ACK |
//! | `EmergencyStop` | not planned here: driven by the service's stop tracker (`service/stop.rs`): COMMAND_LONG `DO_SET_MODE` BRAKE repeated until a HEARTBEAT reports BRAKE, and zero-velocity setpoints at 10 Hz until the measured speed is < 0.3 m/s; in RTL/LAND/SmartRTL nothing is sent (the failsafe descent is held) | `accepted` when BRAKE is reported or the speed confirms the stop (in RTL/LAND/SmartRTL at once, "failsafe descent held"), else refused `failed` after `stop_confirm_timeout_s` |
//! | `ReleaseEmergency` / `ClearEmergency` | no MAVLink: decided by the arbiter | — |
//! | `MotorKill { emergency: false }` | COMMAND_LONG `COMPONENT_ARM_DISARM` p1 = 0: ArduPilot refuses it in the air | COMMAND_ACK |
//! | `MotorKill { emergency: true }` | COMMAND_LONG `COMPONENT_ARM_DISARM` p1 = 0, p2 = 21196: motors stop even in flight | COMMAND_ACK |
//! | `GoProSet { command, value }` | GOPRO_SET_REQUEST to (vehicle, 154), `cmd_id` = command, `value` as given; a command id the dialect has no GOPRO_COMMAND for (17..=31) is refused `unsupported` | GOPRO_SET_RESPONSE with that `cmd_id` from the vehicle's system: SUCCESS → accepted, FAILED → refused `failed`; none within `command_timeout` → refused `timeout` (never retransmitted) |
//! | authority grab/release | no MAVLink: decided by the arbiter | — |
//!
//! `Gimbal` has no `DO_MOUNT_CONTROL` fallback: a gimbal without gimbal protocol v2
//! answers UNSUPPORTED, which is reported as a refusal.
//!
//! `SetHome` needs flight authority (it changes where RTL flies) but has no envelope
//! check: the arbiter neither refuses a home outside a keep-in fence nor limits it,
//! and it does not end a velocity stream (the vehicle does not move). The fence
//! still governs every position target, RTL's flight included where the autopilot's
//! own fence applies; a home outside the fence only means RTL ends there.
//!
//! ## Actuators (IMC and other remote tools)
//!
//! Remote tools drive actuators through the bus commands above; the IMC gateway maps
//! its messages as follows (the value conversions are the gateway's):
//!
//! | IMC message | `Command` | MAVLink | authority |
//! |---|---|---|---|
//! | SetServoPosition, SetControlSurfaceDeflection, SetPWM | `Servo { channel, pwm_us }` | `DO_SET_SERVO` | payload |
//! | SetThrusterActuation | `MotorTest { motor, throttle_pct, duration_s }` | `DO_MOTOR_TEST` | flight |
//! | CameraZoom | `CameraZoom { camera, mode, value }` | `SET_CAMERA_ZOOM` | payload |
//!
//! The DJI Cloud API gateway's payload methods add `CameraMode`, `CameraCaptureStop`,
//! `GimbalRate` and `CameraFocus` (payload authority, never restricted in the air).
//!
//! In the air (the arbiter's notion: armed and high, fast or of unknown position)
//! the arbiter refuses every `MotorTest` (`in_air`, whatever the source) and every
//! `Servo` whose channel is not listed in `[arbiter] servo_channels_in_flight`
//! (empty by default); on the ground both pass. `CameraZoom` is never restricted.
//! ArduCopter itself refuses a motor test unless landed and a `DO_SET_SERVO` on a
//! channel its motors use.
//!
//! Answers are tracked in [`crate::acks`].
//!
//! | file | holds |
//! |---|---|
//! | `mod.rs` | the addressed requests ([`MavCommand`], [`Target`]) |
//! | `plan.rs` | the mapping [`plan`] and the stop's messages |
//! | `intake.rs` | the checks a sample passes first ([`admit`]) |

mod intake;
mod plan;
#[cfg(test)]
mod tests;

use mavlink::dialects::ardupilotmega::{
    GoproCommand, MavMessage, COMMAND_INT_DATA, COMMAND_LONG_DATA, GOPRO_SET_REQUEST_DATA,
};

pub use intake::{admit, Refusal};
pub use plan::{brake_mode, plan, zero_velocity, Plan, PlanContext};

/// ArduPilot's magic `param2` of COMPONENT_ARM_DISARM that bypasses arming checks
/// (arm) or the landed check (disarm).
pub const FORCE_MAGIC: f32 = 21196.0;

/// Who a MAVLink command is addressed to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Target {
    pub system: u8,
    pub component: u8,
}

/// MAVLink component id of the gimbal (`MAV_COMP_ID_GIMBAL`), which answers GoPro
/// requests on the Solo gimbal.
pub const GIMBAL_COMPONENT: u8 = 154;

/// A MAVLink request that is answered: COMMAND_LONG / COMMAND_INT by COMMAND_ACK,
/// GOPRO_SET_REQUEST by GOPRO_SET_RESPONSE.
#[derive(Debug, Clone, PartialEq)]
pub enum MavCommand {
    Long(COMMAND_LONG_DATA),
    Int(COMMAND_INT_DATA),
    GoPro(GOPRO_SET_REQUEST_DATA),
}

/// What identifies the answer to a [`MavCommand`]: at most one of each is outstanding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnswerKey {
    /// A COMMAND_ACK for this MAV_CMD.
    CommandAck(u32),
    /// A GOPRO_SET_RESPONSE for this GOPRO_COMMAND.
    GoPro(u8),
}

impl std::fmt::Display for AnswerKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AnswerKey::CommandAck(cmd) => write!(f, "MAV_CMD {cmd}"),
            AnswerKey::GoPro(cmd) => write!(f, "GOPRO_COMMAND {cmd}"),
        }
    }
}

impl MavCommand {
    /// What its answer carries: the MAV_CMD of a COMMAND_ACK or the `cmd_id` of a
    /// GOPRO_SET_RESPONSE.
    pub fn key(&self) -> AnswerKey {
        match self {
            MavCommand::Long(c) => AnswerKey::CommandAck(c.command as u32),
            MavCommand::Int(c) => AnswerKey::CommandAck(c.command as u32),
            MavCommand::GoPro(r) => AnswerKey::GoPro(r.cmd_id as u8),
        }
    }

    pub fn message(&self) -> MavMessage {
        match self {
            MavCommand::Long(c) => MavMessage::COMMAND_LONG(c.clone()),
            MavCommand::Int(c) => MavMessage::COMMAND_INT(c.clone()),
            MavCommand::GoPro(r) => MavMessage::GOPRO_SET_REQUEST(r.clone()),
        }
    }

    /// Whether an unanswered request is sent again. A GoPro request is not: the
    /// gimbal has no `confirmation` to tell a repeat from a new request, and the
    /// GoPro bridge is slow enough that a late answer would meet a second request.
    pub fn retransmits(&self) -> bool {
        !matches!(self, MavCommand::GoPro(_))
    }

    /// Prepares a retransmission: COMMAND_LONG counts it in `confirmation`.
    pub(crate) fn bump_confirmation(&mut self) {
        if let MavCommand::Long(c) = self {
            c.confirmation = c.confirmation.saturating_add(1);
        }
    }
}

/// The dialect's GOPRO_COMMAND for a wire value (0..=16; 17..=31 are reserved).
pub fn gopro_command(id: u8) -> Option<GoproCommand> {
    use GoproCommand::*;
    Some(match id {
        0 => GOPRO_COMMAND_POWER,
        1 => GOPRO_COMMAND_CAPTURE_MODE,
        2 => GOPRO_COMMAND_SHUTTER,
        3 => GOPRO_COMMAND_BATTERY,
        4 => GOPRO_COMMAND_MODEL,
        5 => GOPRO_COMMAND_VIDEO_SETTINGS,
        6 => GOPRO_COMMAND_LOW_LIGHT,
        7 => GOPRO_COMMAND_PHOTO_RESOLUTION,
        8 => GOPRO_COMMAND_PHOTO_BURST_RATE,
        9 => GOPRO_COMMAND_PROTUNE,
        10 => GOPRO_COMMAND_PROTUNE_WHITE_BALANCE,
        11 => GOPRO_COMMAND_PROTUNE_COLOUR,
        12 => GOPRO_COMMAND_PROTUNE_GAIN,
        13 => GOPRO_COMMAND_PROTUNE_SHARPNESS,
        14 => GOPRO_COMMAND_PROTUNE_EXPOSURE,
        15 => GOPRO_COMMAND_TIME,
        16 => GOPRO_COMMAND_CHARGING,
        _ => return None,
    })
}
