//! The mapping of a [`Command`] to MAVLink (the table in [`super`]), and the
//! messages of the emergency stop (BRAKE mode, zero velocity).

use mavlink::dialects::ardupilotmega::{
    MavCmd, MavFrame, MavMessage, MavModeFlag, PositionTargetTypemask, COMMAND_INT_DATA,
    COMMAND_LONG_DATA, GOPRO_SET_REQUEST_DATA, SET_POSITION_TARGET_GLOBAL_INT_DATA,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use skymesh_ipc_types::{Command, FlightMode};

use super::{gopro_command, MavCommand, Target, FORCE_MAGIC, GIMBAL_COMPONENT};

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
