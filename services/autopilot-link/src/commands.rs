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

use mavlink::dialects::ardupilotmega::{
    GoproCommand, MavCmd, MavFrame, MavMessage, MavModeFlag, PositionTargetTypemask,
    COMMAND_INT_DATA, COMMAND_LONG_DATA, GOPRO_SET_REQUEST_DATA,
    SET_POSITION_TARGET_GLOBAL_INT_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use skymesh_ipc_types::{Command, FlightMode, RefusalReason, VehicleCommand};

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

/// What one [`Command`] becomes on the wire: the acknowledged command (sent first)
/// and/or a setpoint that nothing acknowledges.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub command: Option<MavCommand>,
    pub setpoint: Option<MavMessage>,
}

/// What the mapping needs to know about the vehicle and the link.
#[derive(Debug, Clone, Copy)]
pub struct PlanContext {
    pub target: Target,
    /// The autopilot's current mode (decides how `Brake` is done).
    pub mode: FlightMode,
    /// Sequence number for `CameraCapture` (prevents a double capture on retransmit).
    pub capture_seq: u32,
}

/// `GIMBAL_MANAGER_FLAGS_YAW_IN_VEHICLE_FRAME` as a DO_GIMBAL_MANAGER_PITCHYAW param5:
/// yaw angles and rates relative to the nose.
const GIMBAL_YAW_IN_VEHICLE_FRAME: f32 = 32.0;

fn long(t: Target, command: MavCmd, p: [f32; 7]) -> MavCommand {
    MavCommand::Long(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: t.system,
        target_component: t.component,
        confirmation: 0,
    })
}

fn set_mode(t: Target, custom_mode: u32) -> MavCommand {
    let flag = f32::from(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits());
    long(
        t,
        MavCmd::MAV_CMD_DO_SET_MODE,
        [flag, custom_mode as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
}

fn deg_e7(deg: f64) -> i32 {
    // Validated to ±180°, so the product fits in i32.
    (deg * 1e7).round() as i32
}

/// Ignore-everything-but mask for SET_POSITION_TARGET_*.
fn mask_except(use_bits: PositionTargetTypemask) -> PositionTargetTypemask {
    let all = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
    all - use_bits
}

const POSITION_BITS: PositionTargetTypemask =
    PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
        .union(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE)
        .union(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE);
const VELOCITY_BITS: PositionTargetTypemask =
    PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
        .union(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE)
        .union(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE);

fn velocity_setpoint(t: Target, vel: [f32; 3], yaw_rate_dps: Option<f32>) -> MavMessage {
    let mut used = VELOCITY_BITS;
    if yaw_rate_dps.is_some() {
        used |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
    }
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        vx: vel[0],
        vy: vel[1],
        vz: vel[2],
        yaw_rate: yaw_rate_dps.unwrap_or(0.0).to_radians(),
        type_mask: mask_except(used),
        target_system: t.system,
        target_component: t.component,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..Default::default()
    })
}

/// Maps a validated command. `Err` names what cannot be expressed in MAVLink.
pub fn plan(command: &Command, ctx: &PlanContext) -> Result<Plan, &'static str> {
    let t = ctx.target;
    let only = |c: MavCommand| Plan {
        command: Some(c),
        setpoint: None,
    };
    let force = |f: bool| if f { FORCE_MAGIC } else { 0.0 };
    Ok(match *command {
        Command::Arm { force: f } => only(long(
            t,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, force(f), 0.0, 0.0, 0.0, 0.0, 0.0],
        )),
        Command::Disarm { force: f } => only(long(
            t,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [0.0, force(f), 0.0, 0.0, 0.0, 0.0, 0.0],
        )),
        Command::MotorKill { emergency } => only(long(
            t,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [0.0, force(emergency), 0.0, 0.0, 0.0, 0.0, 0.0],
        )),
        Command::GrabFlightAuthority
        | Command::ReleaseFlightAuthority
        | Command::GrabPayloadAuthority
        | Command::ReleasePayloadAuthority
        | Command::ReleaseEmergency
        | Command::ClearEmergency => {
            return Err("authority requests have no MAVLink form; the arbiter decides them")
        }
        Command::SetMode(mode) => {
            let custom = mode
                .to_copter_custom_mode()
                .ok_or("this flight mode has no ArduCopter mode number")?;
            only(set_mode(t, custom))
        }
        Command::Takeoff { alt_rel_m } => only(long(
            t,
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, alt_rel_m],
        )),
        Command::Land => only(long(t, MavCmd::MAV_CMD_NAV_LAND, [0.0; 7])),
        Command::ReturnToLaunch => only(long(t, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH, [0.0; 7])),
        Command::GoTo {
            lat_deg,
            lon_deg,
            alt_rel_m,
            yaw_deg,
            speed_mps,
        } => {
            let mut used = POSITION_BITS;
            if yaw_deg.is_some() {
                used |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE;
            }
            // GLOBAL_RELATIVE_ALT_INT is deprecated in favour of GLOBAL_RELATIVE_ALT,
            // but it is what every ArduPilot release accepts for this message.
            #[allow(deprecated)]
            let frame = MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT;
            let setpoint =
                MavMessage::SET_POSITION_TARGET_GLOBAL_INT(SET_POSITION_TARGET_GLOBAL_INT_DATA {
                    lat_int: deg_e7(lat_deg),
                    lon_int: deg_e7(lon_deg),
                    alt: alt_rel_m,
                    yaw: yaw_deg.unwrap_or(0.0).to_radians(),
                    type_mask: mask_except(used),
                    target_system: t.system,
                    target_component: t.component,
                    coordinate_frame: frame,
                    ..Default::default()
                });
            Plan {
                command: speed_mps.map(|s| {
                    long(
                        t,
                        MavCmd::MAV_CMD_DO_CHANGE_SPEED,
                        [1.0, s, -1.0, 0.0, 0.0, 0.0, 0.0],
                    )
                }),
                setpoint: Some(setpoint),
            }
        }
        Command::VelocityNed {
            vel_ned_mps,
            yaw_rate_dps,
        } => Plan {
            command: None,
            setpoint: Some(velocity_setpoint(t, vel_ned_mps, yaw_rate_dps)),
        },
        Command::SetYaw {
            yaw_deg,
            rate_dps,
            relative,
        } => {
            let (angle, direction, rel) = if relative {
                (yaw_deg.abs(), if yaw_deg < 0.0 { -1.0 } else { 1.0 }, 1.0)
            } else {
                // Absolute: 0..360, shortest way round.
                (yaw_deg.rem_euclid(360.0), 0.0, 0.0)
            };
            only(long(
                t,
                MavCmd::MAV_CMD_CONDITION_YAW,
                [angle, rate_dps, direction, rel, 0.0, 0.0, 0.0],
            ))
        }
        Command::SetRoi {
            lat_deg,
            lon_deg,
            alt_rel_m,
        } => only(MavCommand::Int(COMMAND_INT_DATA {
            x: deg_e7(lat_deg),
            y: deg_e7(lon_deg),
            z: alt_rel_m,
            command: MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
            target_system: t.system,
            target_component: t.component,
            frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
            ..Default::default()
        })),
        Command::ClearRoi => only(long(t, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7])),
        Command::SetHome {
            lat_deg,
            lon_deg,
            alt_msl_m,
        } => {
            // ArduPilot takes x = y = 0 as "use the current location"; that is not
            // what was asked for.
            if deg_e7(lat_deg) == 0 && deg_e7(lon_deg) == 0 {
                return Err("lat = lon = 0 is 'here' to ArduPilot");
            }
            only(MavCommand::Int(COMMAND_INT_DATA {
                // param1 = 0: use the given location, not the current one.
                param1: 0.0,
                x: deg_e7(lat_deg),
                y: deg_e7(lon_deg),
                z: alt_msl_m,
                command: MavCmd::MAV_CMD_DO_SET_HOME,
                target_system: t.system,
                target_component: t.component,
                frame: MavFrame::MAV_FRAME_GLOBAL,
                ..Default::default()
            }))
        }
        Command::Gimbal { pitch_deg, yaw_deg } => only(long(
            t,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [
                pitch_deg,
                yaw_deg,
                f32::NAN,
                f32::NAN,
                GIMBAL_YAW_IN_VEHICLE_FRAME,
                0.0,
                0.0,
            ],
        )),
        Command::CameraCapture => only(long(
            t,
            MavCmd::MAV_CMD_IMAGE_START_CAPTURE,
            [0.0, 0.0, 1.0, ctx.capture_seq as f32, 0.0, 0.0, 0.0],
        )),
        Command::RecordStart => only(long(t, MavCmd::MAV_CMD_VIDEO_START_CAPTURE, [0.0; 7])),
        Command::RecordStop => only(long(t, MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE, [0.0; 7])),
        Command::Servo { channel, pwm_us } => only(long(
            t,
            MavCmd::MAV_CMD_DO_SET_SERVO,
            [
                f32::from(channel),
                f32::from(pwm_us),
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        )),
        Command::MotorTest {
            motor,
            throttle_pct,
            duration_s,
        } => only(long(
            t,
            MavCmd::MAV_CMD_DO_MOTOR_TEST,
            [
                f32::from(motor),
                // MOTOR_TEST_THROTTLE_PERCENT
                0.0,
                throttle_pct,
                duration_s,
                // one motor
                1.0,
                // MOTOR_TEST_ORDER_BOARD: `motor` is the output number
                2.0,
                0.0,
            ],
        )),
        Command::CameraZoom {
            camera,
            mode,
            value,
        } => only(long(
            t,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [
                f32::from(mode.to_wire()),
                value,
                f32::from(camera),
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        )),
        Command::CameraMode { camera, mode } => only(long(
            t,
            MavCmd::MAV_CMD_SET_CAMERA_MODE,
            [
                f32::from(camera),
                f32::from(mode.to_wire()),
                f32::NAN,
                f32::NAN,
                0.0,
                0.0,
                f32::NAN,
            ],
        )),
        Command::CameraCaptureStop { camera } => only(long(
            t,
            MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE,
            [
                f32::from(camera),
                f32::NAN,
                f32::NAN,
                f32::NAN,
                0.0,
                0.0,
                f32::NAN,
            ],
        )),
        Command::GimbalRate {
            pitch_rate_dps,
            yaw_rate_dps,
        } => only(long(
            t,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            // No angle (NaN): the gimbal turns at the rates until told otherwise.
            [
                f32::NAN,
                f32::NAN,
                pitch_rate_dps,
                yaw_rate_dps,
                GIMBAL_YAW_IN_VEHICLE_FRAME,
                0.0,
                0.0,
            ],
        )),
        Command::CameraFocus {
            camera,
            mode,
            value,
        } => only(long(
            t,
            MavCmd::MAV_CMD_SET_CAMERA_FOCUS,
            [
                f32::from(mode.to_wire()),
                if mode.is_auto() { 0.0 } else { value },
                f32::from(camera),
                f32::NAN,
                0.0,
                0.0,
                0.0,
            ],
        )),
        Command::GoProSet { command, value } => {
            let cmd_id = gopro_command(command)
                .ok_or("GoPro command ids above 16 have no MAVLink GOPRO_COMMAND")?;
            only(MavCommand::GoPro(GOPRO_SET_REQUEST_DATA {
                target_system: t.system,
                target_component: GIMBAL_COMPONENT,
                cmd_id,
                value,
            }))
        }
        Command::EmergencyStop => {
            return Err("an emergency stop is driven by the stop tracker, not planned")
        }
        Command::Brake if ctx.mode == FlightMode::Guided => Plan {
            command: None,
            setpoint: Some(zero_velocity(t)),
        },
        Command::Brake => only(brake_mode(t, 0)?),
    })
}

/// COMMAND_LONG DO_SET_MODE BRAKE; `confirmation` counts the repeats (0 first).
pub fn brake_mode(t: Target, confirmation: u8) -> Result<MavCommand, &'static str> {
    let brake = FlightMode::Brake
        .to_copter_custom_mode()
        .ok_or("BRAKE has no ArduCopter mode number")?;
    let mut cmd = set_mode(t, brake);
    if let MavCommand::Long(c) = &mut cmd {
        c.confirmation = confirmation;
    }
    Ok(cmd)
}

/// A zero-velocity SET_POSITION_TARGET_LOCAL_NED: hold here (GUIDED).
pub fn zero_velocity(t: Target) -> MavMessage {
    velocity_setpoint(t, [0.0; 3], None)
}

/// Why a command sample was not admitted.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub reason: RefusalReason,
    pub detail: String,
}

/// Command intake: checks a sample before anything else looks at it.
///
/// Order: addressed to this vehicle, decodes to a valid [`Command`] (finite, in
/// range, known kind and source), link up.
pub fn admit(sample: &VehicleCommand, vehicle_id: u8, link_up: bool) -> Result<Command, Refusal> {
    if sample.vehicle_id != vehicle_id {
        return Err(Refusal {
            reason: RefusalReason::WrongVehicle,
            detail: format!(
                "for vehicle {}, this is vehicle {vehicle_id}",
                sample.vehicle_id
            ),
        });
    }
    let invalid = |e: skymesh_ipc_types::CommandError| Refusal {
        reason: e.reason(),
        detail: e.to_string(),
    };
    sample.source().map_err(invalid)?;
    let command = sample.command().map_err(invalid)?;
    if !link_up {
        return Err(Refusal {
            reason: RefusalReason::LinkDown,
            detail: "no autopilot heartbeat".to_string(),
        });
    }
    Ok(command)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acks::Origin;
    use skymesh_ipc_types::{CameraModeKind, CommandKind, CommandSource, FocusMode, ZoomMode};

    const T: Target = Target {
        system: 1,
        component: 1,
    };

    fn ctx(mode: FlightMode) -> PlanContext {
        PlanContext {
            target: T,
            mode,
            capture_seq: 7,
        }
    }

    fn long_of(p: &Plan) -> &COMMAND_LONG_DATA {
        match &p.command {
            Some(MavCommand::Long(c)) => c,
            other => panic!("expected COMMAND_LONG, got {other:?}"),
        }
    }

    fn plan_of(c: Command) -> Plan {
        plan(&c, &ctx(FlightMode::Loiter)).unwrap()
    }

    #[test]
    fn arming_commands_map_to_component_arm_disarm() {
        for (cmd, p1, p2) in [
            (Command::Arm { force: false }, 1.0, 0.0),
            (Command::Arm { force: true }, 1.0, FORCE_MAGIC),
            (Command::Disarm { force: false }, 0.0, 0.0),
            (Command::Disarm { force: true }, 0.0, FORCE_MAGIC),
            (Command::MotorKill { emergency: true }, 0.0, FORCE_MAGIC),
            (Command::MotorKill { emergency: false }, 0.0, 0.0),
        ] {
            let p = plan_of(cmd);
            let c = long_of(&p);
            assert_eq!(c.command, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, "{cmd:?}");
            assert_eq!((c.param1, c.param2), (p1, p2), "{cmd:?}");
            assert_eq!((c.target_system, c.target_component), (1, 1));
            assert_eq!(c.confirmation, 0);
            assert!(p.setpoint.is_none());
        }
    }

    #[test]
    fn modes_takeoff_and_navigation_commands() {
        let p = plan_of(Command::SetMode(FlightMode::Guided));
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
        assert_eq!((c.param1, c.param2), (1.0, 4.0));
        let p = plan_of(Command::Takeoff { alt_rel_m: 10.0 });
        assert_eq!(long_of(&p).command, MavCmd::MAV_CMD_NAV_TAKEOFF);
        assert_eq!(long_of(&p).param7, 10.0);
        assert_eq!(
            long_of(&plan_of(Command::Land)).command,
            MavCmd::MAV_CMD_NAV_LAND
        );
        assert_eq!(
            long_of(&plan_of(Command::ReturnToLaunch)).command,
            MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH
        );
        assert!(plan(
            &Command::SetMode(FlightMode::Unknown),
            &ctx(FlightMode::Loiter)
        )
        .is_err());
    }

    #[test]
    fn go_to_is_a_global_position_setpoint_with_optional_yaw_and_speed() {
        let p = plan_of(Command::GoTo {
            lat_deg: -35.363261,
            lon_deg: 149.16523,
            alt_rel_m: 20.0,
            yaw_deg: None,
            speed_mps: None,
        });
        assert!(p.command.is_none());
        let Some(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(s)) = &p.setpoint else {
            panic!("{p:?}")
        };
        assert_eq!(
            (s.lat_int, s.lon_int, s.alt),
            (-353_632_610, 1_491_652_300, 20.0)
        );
        #[allow(deprecated)]
        let frame = MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT;
        assert_eq!(s.coordinate_frame, frame);
        assert_eq!(s.type_mask.bits(), 0b1101_1111_1000, "position only");
        assert_eq!((s.target_system, s.target_component), (1, 1));

        let p = plan_of(Command::GoTo {
            lat_deg: 1.0,
            lon_deg: 2.0,
            alt_rel_m: 5.0,
            yaw_deg: Some(90.0),
            speed_mps: Some(3.0),
        });
        let Some(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(s)) = &p.setpoint else {
            panic!("{p:?}")
        };
        assert_eq!(s.type_mask.bits(), 0b1001_1111_1000, "position and yaw");
        assert!((s.yaw - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_CHANGE_SPEED);
        assert_eq!((c.param1, c.param2), (1.0, 3.0));
    }

    #[test]
    fn velocity_is_a_local_ned_setpoint_with_optional_yaw_rate() {
        let p = plan_of(Command::VelocityNed {
            vel_ned_mps: [1.0, -2.0, 0.5],
            yaw_rate_dps: None,
        });
        assert!(p.command.is_none());
        let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(s)) = &p.setpoint else {
            panic!("{p:?}")
        };
        assert_eq!((s.vx, s.vy, s.vz), (1.0, -2.0, 0.5));
        assert_eq!(s.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(s.type_mask.bits(), 0b1101_1100_0111, "velocity only");
        let p = plan_of(Command::VelocityNed {
            vel_ned_mps: [0.0; 3],
            yaw_rate_dps: Some(-90.0),
        });
        let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(s)) = &p.setpoint else {
            panic!("{p:?}")
        };
        assert_eq!(
            s.type_mask.bits(),
            0b0101_1100_0111,
            "velocity and yaw rate"
        );
        assert!((s.yaw_rate + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    }

    #[test]
    fn yaw_roi_gimbal_camera_and_servo() {
        let c = plan_of(Command::SetYaw {
            yaw_deg: -30.0,
            rate_dps: 20.0,
            relative: true,
        });
        let c = long_of(&c);
        assert_eq!(c.command, MavCmd::MAV_CMD_CONDITION_YAW);
        assert_eq!(
            [c.param1, c.param2, c.param3, c.param4],
            [30.0, 20.0, -1.0, 1.0]
        );
        let c = plan_of(Command::SetYaw {
            yaw_deg: -30.0,
            rate_dps: 0.0,
            relative: false,
        });
        let c = long_of(&c);
        assert_eq!(
            [c.param1, c.param2, c.param3, c.param4],
            [330.0, 0.0, 0.0, 0.0]
        );

        let p = plan_of(Command::SetRoi {
            lat_deg: 1.5,
            lon_deg: -2.5,
            alt_rel_m: 3.0,
        });
        let Some(MavCommand::Int(c)) = &p.command else {
            panic!("{p:?}")
        };
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_ROI_LOCATION);
        assert_eq!((c.x, c.y, c.z), (15_000_000, -25_000_000, 3.0));
        assert_eq!(c.frame, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT);
        assert_eq!(
            long_of(&plan_of(Command::ClearRoi)).command,
            MavCmd::MAV_CMD_DO_SET_ROI_NONE
        );

        let g = plan_of(Command::Gimbal {
            pitch_deg: -45.0,
            yaw_deg: 10.0,
        });
        let g = long_of(&g);
        assert_eq!(g.command, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW);
        assert_eq!((g.param1, g.param2, g.param5), (-45.0, 10.0, 32.0));
        assert!(g.param3.is_nan() && g.param4.is_nan());

        let cam = plan_of(Command::CameraCapture);
        let cam = long_of(&cam);
        assert_eq!(cam.command, MavCmd::MAV_CMD_IMAGE_START_CAPTURE);
        assert_eq!((cam.param3, cam.param4), (1.0, 7.0));
        assert_eq!(
            long_of(&plan_of(Command::RecordStart)).command,
            MavCmd::MAV_CMD_VIDEO_START_CAPTURE
        );
        assert_eq!(
            long_of(&plan_of(Command::RecordStop)).command,
            MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE
        );
        let s = plan_of(Command::Servo {
            channel: 9,
            pwm_us: 1900,
        });
        let s = long_of(&s);
        assert_eq!(s.command, MavCmd::MAV_CMD_DO_SET_SERVO);
        assert_eq!((s.param1, s.param2), (9.0, 1900.0));
    }

    #[test]
    fn set_home_is_a_command_int_in_the_global_frame_with_msl_altitude() {
        let p = plan_of(Command::SetHome {
            lat_deg: -35.363261,
            lon_deg: 149.16523,
            alt_msl_m: 584.5,
        });
        assert!(p.setpoint.is_none());
        let Some(MavCommand::Int(c)) = &p.command else {
            panic!("{p:?}")
        };
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_HOME);
        assert_eq!(c.frame, MavFrame::MAV_FRAME_GLOBAL);
        assert_eq!(c.param1, 0.0, "the given location, not the current one");
        assert_eq!((c.x, c.y, c.z), (-353_632_610, 1_491_652_300, 584.5));
        assert_eq!((c.target_system, c.target_component), (1, 1));
        let cmd = p.command.unwrap();
        assert_eq!(
            cmd.key(),
            AnswerKey::CommandAck(MavCmd::MAV_CMD_DO_SET_HOME as u32)
        );
        assert!(cmd.retransmits());
        assert!(matches!(cmd.message(), MavMessage::COMMAND_INT(_)));
        // (0, 0) would set home to wherever the vehicle is.
        let err = plan(
            &Command::SetHome {
                lat_deg: 0.0,
                lon_deg: 0.0,
                alt_msl_m: 10.0,
            },
            &ctx(FlightMode::Loiter),
        )
        .unwrap_err();
        assert!(err.contains("'here'"), "{err}");
    }

    #[test]
    fn brake_holds_guided_with_zero_velocity_and_switches_to_brake_otherwise() {
        let p = plan(&Command::Brake, &ctx(FlightMode::Guided)).unwrap();
        assert!(p.command.is_none());
        let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(s)) = &p.setpoint else {
            panic!("{p:?}")
        };
        assert_eq!((s.vx, s.vy, s.vz), (0.0, 0.0, 0.0));
        for mode in [FlightMode::Auto, FlightMode::Rtl, FlightMode::Unknown] {
            let p = plan(&Command::Brake, &ctx(mode)).unwrap();
            let c = long_of(&p);
            assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
            assert_eq!(c.param2, 17.0);
        }
        // The stop tracker's frames: BRAKE counting its repeats, and the zero setpoint.
        let MavCommand::Long(c) = brake_mode(T, 2).unwrap() else {
            panic!("COMMAND_LONG")
        };
        assert_eq!(
            (c.command, c.param2, c.confirmation),
            (MavCmd::MAV_CMD_DO_SET_MODE, 17.0, 2)
        );
        assert_eq!(
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(match zero_velocity(T) {
                MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) => s,
                other => panic!("{other:?}"),
            }),
            plan(&Command::Brake, &ctx(FlightMode::Guided))
                .unwrap()
                .setpoint
                .unwrap()
        );
        assert!(plan(&Command::EmergencyStop, &ctx(FlightMode::Guided)).is_err());
    }

    #[test]
    fn gopro_set_is_a_gopro_set_request_to_the_gimbal() {
        let p = plan_of(Command::GoProSet {
            command: 1,
            value: [1, 0, 0, 0],
        });
        assert!(p.setpoint.is_none());
        let Some(MavCommand::GoPro(r)) = &p.command else {
            panic!("{p:?}")
        };
        assert_eq!((r.target_system, r.target_component), (1, GIMBAL_COMPONENT));
        assert_eq!(r.cmd_id, GoproCommand::GOPRO_COMMAND_CAPTURE_MODE);
        assert_eq!(r.value, [1, 0, 0, 0]);
        let cmd = p.command.unwrap();
        assert_eq!(cmd.key(), AnswerKey::GoPro(1));
        assert!(!cmd.retransmits());
        assert!(matches!(cmd.message(), MavMessage::GOPRO_SET_REQUEST(_)));
        // Every id the dialect knows maps to itself.
        for id in 0..=16 {
            assert_eq!(gopro_command(id).map(|c| c as u8), Some(id));
        }
        // ipc-types refuses ids above the dialect's last GOPRO_COMMAND; the mapping
        // still refuses them should a wire struct carry one.
        assert_eq!(skymesh_ipc_types::command::limits::MAX_GOPRO_COMMAND, 16);
        assert!(gopro_command(17).is_none());
        let arm = plan_of(Command::Arm { force: false }).command.unwrap();
        assert_eq!(arm.key(), AnswerKey::CommandAck(400));
        assert!(arm.retransmits());
    }

    #[test]
    fn motor_test_and_camera_zoom_map_to_do_motor_test_and_set_camera_zoom() {
        let p = plan_of(Command::MotorTest {
            motor: 3,
            throttle_pct: 12.5,
            duration_s: 2.0,
        });
        assert!(p.setpoint.is_none());
        let c = long_of(&p);
        assert_eq!((c.target_system, c.target_component), (1, 1));
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_MOTOR_TEST);
        // Motor 3, MOTOR_TEST_THROTTLE_PERCENT, 12.5 %, 2 s, one motor.
        assert_eq!(
            [c.param1, c.param2, c.param3, c.param4, c.param5],
            [3.0, 0.0, 12.5, 2.0, 1.0]
        );
        assert_eq!(
            p.command.unwrap().key(),
            AnswerKey::CommandAck(MavCmd::MAV_CMD_DO_MOTOR_TEST as u32)
        );

        for (mode, value, p1) in [
            (ZoomMode::Step, -3.0, 0.0),
            (ZoomMode::Continuous, 1.0, 1.0),
            (ZoomMode::Range, 55.5, 2.0),
        ] {
            let p = plan_of(Command::CameraZoom {
                camera: 2,
                mode,
                value,
            });
            let c = long_of(&p);
            assert_eq!(c.command, MavCmd::MAV_CMD_SET_CAMERA_ZOOM);
            // param1 CAMERA_ZOOM_TYPE, param2 the value, param3 the camera id.
            assert_eq!([c.param1, c.param2, c.param3], [p1, value, 2.0], "{mode}");
            assert_eq!([c.param4, c.param5, c.param6, c.param7], [0.0; 4]);
        }
    }

    #[test]
    fn camera_mode_and_capture_stop_carry_the_camera_id_in_param1() {
        for (mode, p2) in [
            (CameraModeKind::Image, 0.0),
            (CameraModeKind::Video, 1.0),
            (CameraModeKind::ImageSurvey, 2.0),
        ] {
            let p = plan_of(Command::CameraMode { camera: 3, mode });
            assert!(p.setpoint.is_none());
            let c = long_of(&p);
            assert_eq!((c.target_system, c.target_component), (1, 1));
            assert_eq!(c.command, MavCmd::MAV_CMD_SET_CAMERA_MODE);
            assert_eq!((c.param1, c.param2), (3.0, p2), "{mode}");
            assert!(c.param3.is_nan() && c.param4.is_nan() && c.param7.is_nan());
            assert_eq!((c.param5, c.param6), (0.0, 0.0));
        }
        let p = plan_of(Command::CameraCaptureStop { camera: 0 });
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE);
        assert_eq!(c.param1, 0.0, "every camera");
        assert!(c.param2.is_nan() && c.param3.is_nan() && c.param4.is_nan());
        assert_eq!(
            p.command.unwrap().key(),
            AnswerKey::CommandAck(MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE as u32)
        );
        let c = plan_of(Command::CameraCaptureStop { camera: 200 });
        assert_eq!(long_of(&c).param1, 200.0);
    }

    #[test]
    fn gimbal_rate_is_pitchyaw_with_unset_angles_and_the_rates() {
        let p = plan_of(Command::GimbalRate {
            pitch_rate_dps: -15.0,
            yaw_rate_dps: 30.0,
        });
        let g = long_of(&p);
        assert_eq!(g.command, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW);
        assert!(g.param1.is_nan() && g.param2.is_nan(), "no angle");
        assert_eq!(
            [g.param3, g.param4, g.param5, g.param6, g.param7],
            [-15.0, 30.0, 32.0, 0.0, 0.0]
        );
        // Same MAV_CMD as an angle command: a rate supersedes a pending angle.
        let angle = plan_of(Command::Gimbal {
            pitch_deg: 0.0,
            yaw_deg: 0.0,
        });
        assert_eq!(p.command.unwrap().key(), angle.command.unwrap().key());
    }

    #[test]
    fn camera_focus_maps_type_value_and_camera() {
        for (mode, value, p1, p2) in [
            (FocusMode::Step, 1.0, 0.0, 1.0),
            (FocusMode::Continuous, -1.0, 1.0, -1.0),
            (FocusMode::Range, 42.5, 2.0, 42.5),
            (FocusMode::Meters, 12.0, 3.0, 12.0),
            (FocusMode::Auto, 99.0, 4.0, 0.0),
            (FocusMode::AutoSingle, 0.0, 5.0, 0.0),
            (FocusMode::AutoContinuous, -3.0, 6.0, 0.0),
        ] {
            let p = plan_of(Command::CameraFocus {
                camera: 2,
                mode,
                value,
            });
            let c = long_of(&p);
            assert_eq!(c.command, MavCmd::MAV_CMD_SET_CAMERA_FOCUS);
            // param1 SET_FOCUS_TYPE, param2 the value (0 when ignored), param3 camera.
            assert_eq!([c.param1, c.param2, c.param3], [p1, p2, 2.0], "{mode}");
            assert!(c.param4.is_nan());
        }
    }

    #[test]
    fn new_payload_commands_pass_intake_from_the_wire() {
        for cmd in [
            Command::CameraMode {
                camera: 0,
                mode: CameraModeKind::Video,
            },
            Command::CameraCaptureStop { camera: 1 },
            Command::GimbalRate {
                pitch_rate_dps: 0.0,
                yaw_rate_dps: 0.0,
            },
            Command::CameraFocus {
                camera: 0,
                mode: FocusMode::Auto,
                value: 0.0,
            },
        ] {
            assert_eq!(admit(&sample(&cmd, 3), 1, true), Ok(cmd));
        }
        let mut bad = sample(
            &Command::GimbalRate {
                pitch_rate_dps: 1.0,
                yaw_rate_dps: 1.0,
            },
            4,
        );
        bad.f[0] = 400.0;
        let r = admit(&bad, 1, true).unwrap_err();
        assert_eq!(r.reason, RefusalReason::InvalidParameter);
        assert!(r.detail.contains("pitch_rate_dps"), "{}", r.detail);
    }

    fn sample(kind_cmd: &Command, id: u32) -> VehicleCommand {
        let mut s = VehicleCommand::new(1, CommandSource::Operator, id, kind_cmd).unwrap();
        s.header.seq = u64::from(id) + 100;
        s
    }

    #[test]
    fn intake_checks_vehicle_validity_and_link_in_that_order() {
        let good = sample(&Command::Land, 1);
        assert_eq!(admit(&good, 1, true), Ok(Command::Land));
        let r = admit(&good, 2, true).unwrap_err();
        assert_eq!(r.reason, RefusalReason::WrongVehicle);
        assert_eq!(
            admit(&good, 1, false).unwrap_err().reason,
            RefusalReason::LinkDown
        );
        let mut nan = sample(&Command::Takeoff { alt_rel_m: 5.0 }, 2);
        nan.f[0] = f32::NAN;
        let r = admit(&nan, 1, false).unwrap_err();
        assert_eq!(r.reason, RefusalReason::InvalidParameter);
        assert!(r.detail.contains("alt_rel_m"), "{}", r.detail);
        let mut bad_source = good;
        bad_source.source = 99;
        assert_eq!(
            admit(&bad_source, 1, true).unwrap_err().reason,
            RefusalReason::InvalidParameter
        );
        let o = Origin::of(&good);
        assert_eq!(
            (o.kind, o.command_id, o.command_seq),
            (CommandKind::Land.to_wire(), 1, 101)
        );
    }
}
