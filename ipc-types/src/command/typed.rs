//! The typed [`Command`] and its validation: every parameter finite and in range.

use super::limits;
use super::{CameraModeKind, CommandKind, FocusMode, RefusalReason, ZoomMode};
use crate::vehicle::FlightMode;

/// A typed command. Build a [`VehicleCommand`](super::VehicleCommand) from it with
/// [`VehicleCommand::new`](super::VehicleCommand::new).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    Arm {
        force: bool,
    },
    Disarm {
        force: bool,
    },
    SetMode(FlightMode),
    /// Climb to `alt_rel_m` above home (vehicle must be GUIDED and armed).
    Takeoff {
        alt_rel_m: f32,
    },
    Land,
    ReturnToLaunch,
    /// Fly to a position (GUIDED), optionally facing `yaw_deg` at `speed_mps`.
    GoTo {
        lat_deg: f64,
        lon_deg: f64,
        alt_rel_m: f32,
        yaw_deg: Option<f32>,
        speed_mps: Option<f32>,
    },
    /// Velocity setpoint in NED, m/s, with an optional yaw rate (deg/s).
    VelocityNed {
        vel_ned_mps: [f32; 3],
        yaw_rate_dps: Option<f32>,
    },
    /// Face `yaw_deg` (absolute 0..360, or relative ±) turning at `rate_dps` (0 = default).
    SetYaw {
        yaw_deg: f32,
        rate_dps: f32,
        relative: bool,
    },
    SetRoi {
        lat_deg: f64,
        lon_deg: f64,
        alt_rel_m: f32,
    },
    ClearRoi,
    Gimbal {
        pitch_deg: f32,
        yaw_deg: f32,
    },
    CameraCapture,
    RecordStart,
    RecordStop,
    Servo {
        channel: u8,
        pwm_us: u16,
    },
    /// Stop and hold position now.
    Brake,
    /// Brake and hover now; the safety source takes flight authority and keeps it
    /// while any source that engaged the stop has not released it
    /// ([`Command::ReleaseEmergency`]) or until an explicit
    /// [`Command::ClearEmergency`]. Does not stop the motors.
    EmergencyStop,
    /// The sender withdraws the emergency stop(s) it engaged. The stop ends when the
    /// last engager has withdrawn; another source's stop is never lifted by this.
    ReleaseEmergency,
    /// Ends the emergency stop whoever engaged it. Only the operator and safety
    /// sources may send it; the audit names the sender.
    ClearEmergency,
    /// Take flight authority (granted if no higher-priority source holds it).
    GrabFlightAuthority,
    /// Give flight authority back.
    ReleaseFlightAuthority,
    /// Take payload (camera, gimbal, servo) authority.
    GrabPayloadAuthority,
    /// Give payload authority back.
    ReleasePayloadAuthority,
    /// Stop the motors. Refused while in the air unless `emergency` (a falling
    /// aircraft is better than a fly-away, but only when someone says so).
    MotorKill {
        emergency: bool,
    },
    /// A GoPro setting through the gimbal's GoPro bridge (MAVLink `GOPRO_SET_REQUEST`):
    /// `command` is a MAVLink GOPRO_COMMAND (0..=16), `value` its four value bytes.
    GoProSet {
        command: u8,
        value: [u8; 4],
    },
    /// Move home (where RTL returns and what relative altitudes are measured from)
    /// to this point; the altitude is above mean sea level. A flight command: it
    /// changes where the vehicle goes on RTL.
    SetHome {
        lat_deg: f64,
        lon_deg: f64,
        alt_msl_m: f32,
    },
    /// Spin one motor on the ground (MAVLink `MAV_CMD_DO_MOTOR_TEST`, throttle in
    /// percent). Never executed in the air: the arbiter refuses it `in_air`.
    MotorTest {
        motor: u8,
        throttle_pct: f32,
        duration_s: f32,
    },
    /// Zoom camera `camera` (0 = every camera): MAVLink `MAV_CMD_SET_CAMERA_ZOOM` for a
    /// real camera, the virtual cameras' zoom for the vision pipeline.
    CameraZoom {
        camera: u8,
        mode: ZoomMode,
        value: f32,
    },
    /// Switch camera `camera` (0 = every camera) to photo, video or survey mode
    /// (MAVLink `MAV_CMD_SET_CAMERA_MODE`).
    CameraMode {
        camera: u8,
        mode: CameraModeKind,
    },
    /// Stop an interval or continuous photo sequence of camera `camera` (0 = every
    /// camera; MAVLink `MAV_CMD_IMAGE_STOP_CAPTURE`).
    CameraCaptureStop {
        camera: u8,
    },
    /// Turn the gimbal at these rates (deg/s, pitch up and yaw right positive,
    /// |rate| ≤ 360) until the next gimbal command or a rate of 0; the gimbal stops
    /// at its limits. MAVLink `MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW` with the angles unset.
    GimbalRate {
        pitch_rate_dps: f32,
        yaw_rate_dps: f32,
    },
    /// Focus camera `camera` (0 = every camera; MAVLink `MAV_CMD_SET_CAMERA_FOCUS`):
    /// see [`FocusMode`] for how `value` is read.
    CameraFocus {
        camera: u8,
        mode: FocusMode,
        value: f32,
    },
}

/// Why a command could not be converted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    #[error("command kind {0} is unknown")]
    UnknownKind(u8),
    #[error("command source {0} is unknown")]
    UnknownSource(u8),
    #[error("parameter {name} is not a finite number")]
    NotFinite { name: &'static str },
    #[error("parameter {name} = {value} is outside {min}..={max}")]
    OutOfRange {
        name: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("flight mode {0} cannot be commanded")]
    BadMode(u8),
}

impl CommandError {
    /// The refusal reason to put in the [`CommandAck`](super::CommandAck).
    pub fn reason(&self) -> RefusalReason {
        RefusalReason::InvalidParameter
    }
}

fn check(name: &'static str, value: f64, min: f64, max: f64) -> Result<(), CommandError> {
    if !value.is_finite() {
        return Err(CommandError::NotFinite { name });
    }
    if value < min || value > max {
        return Err(CommandError::OutOfRange {
            name,
            value,
            min,
            max,
        });
    }
    Ok(())
}

fn check_position(lat: f64, lon: f64, alt: f32) -> Result<(), CommandError> {
    check("lat_deg", lat, -90.0, 90.0)?;
    check("lon_deg", lon, -180.0, 180.0)?;
    check(
        "alt_rel_m",
        alt.into(),
        limits::MIN_ALT_M.into(),
        limits::MAX_ALT_M.into(),
    )
}

impl Command {
    pub fn kind(&self) -> CommandKind {
        match self {
            Command::Arm { .. } => CommandKind::Arm,
            Command::Disarm { .. } => CommandKind::Disarm,
            Command::SetMode(_) => CommandKind::SetMode,
            Command::Takeoff { .. } => CommandKind::Takeoff,
            Command::Land => CommandKind::Land,
            Command::ReturnToLaunch => CommandKind::ReturnToLaunch,
            Command::GoTo { .. } => CommandKind::GoTo,
            Command::VelocityNed { .. } => CommandKind::VelocityNed,
            Command::SetYaw { .. } => CommandKind::SetYaw,
            Command::SetRoi { .. } => CommandKind::SetRoi,
            Command::ClearRoi => CommandKind::ClearRoi,
            Command::Gimbal { .. } => CommandKind::Gimbal,
            Command::CameraCapture => CommandKind::CameraCapture,
            Command::RecordStart => CommandKind::RecordStart,
            Command::RecordStop => CommandKind::RecordStop,
            Command::Servo { .. } => CommandKind::Servo,
            Command::Brake => CommandKind::Brake,
            Command::EmergencyStop => CommandKind::EmergencyStop,
            Command::ReleaseEmergency => CommandKind::ReleaseEmergency,
            Command::ClearEmergency => CommandKind::ClearEmergency,
            Command::GrabFlightAuthority => CommandKind::GrabFlightAuthority,
            Command::ReleaseFlightAuthority => CommandKind::ReleaseFlightAuthority,
            Command::GrabPayloadAuthority => CommandKind::GrabPayloadAuthority,
            Command::ReleasePayloadAuthority => CommandKind::ReleasePayloadAuthority,
            Command::MotorKill { .. } => CommandKind::MotorKill,
            Command::GoProSet { .. } => CommandKind::GoProSet,
            Command::SetHome { .. } => CommandKind::SetHome,
            Command::MotorTest { .. } => CommandKind::MotorTest,
            Command::CameraZoom { .. } => CommandKind::CameraZoom,
            Command::CameraMode { .. } => CommandKind::CameraMode,
            Command::CameraCaptureStop { .. } => CommandKind::CameraCaptureStop,
            Command::GimbalRate { .. } => CommandKind::GimbalRate,
            Command::CameraFocus { .. } => CommandKind::CameraFocus,
        }
    }

    /// Refuses non-finite and out-of-range parameters.
    pub fn validate(&self) -> Result<(), CommandError> {
        use limits::*;
        match *self {
            Command::SetMode(mode) => {
                if mode.to_copter_custom_mode().is_none() {
                    return Err(CommandError::BadMode(mode.to_wire()));
                }
            }
            Command::Takeoff { alt_rel_m } => {
                check("alt_rel_m", alt_rel_m.into(), 0.5, MAX_TAKEOFF_ALT_M.into())?
            }
            Command::GoTo {
                lat_deg,
                lon_deg,
                alt_rel_m,
                yaw_deg,
                speed_mps,
            } => {
                check_position(lat_deg, lon_deg, alt_rel_m)?;
                if let Some(y) = yaw_deg {
                    check("yaw_deg", y.into(), -360.0, 360.0)?;
                }
                if let Some(s) = speed_mps {
                    check("speed_mps", s.into(), 0.0, MAX_SPEED_MPS.into())?;
                }
            }
            Command::VelocityNed {
                vel_ned_mps,
                yaw_rate_dps,
            } => {
                for (name, v) in ["vn", "ve", "vd"].into_iter().zip(vel_ned_mps) {
                    check(
                        name,
                        v.into(),
                        (-MAX_SPEED_MPS).into(),
                        MAX_SPEED_MPS.into(),
                    )?;
                }
                if let Some(r) = yaw_rate_dps {
                    check(
                        "yaw_rate_dps",
                        r.into(),
                        (-MAX_YAW_RATE_DPS).into(),
                        MAX_YAW_RATE_DPS.into(),
                    )?;
                }
            }
            Command::SetYaw {
                yaw_deg, rate_dps, ..
            } => {
                check("yaw_deg", yaw_deg.into(), -360.0, 360.0)?;
                check("rate_dps", rate_dps.into(), 0.0, MAX_YAW_RATE_DPS.into())?;
            }
            Command::SetRoi {
                lat_deg,
                lon_deg,
                alt_rel_m,
            } => check_position(lat_deg, lon_deg, alt_rel_m)?,
            Command::SetHome {
                lat_deg,
                lon_deg,
                alt_msl_m,
            } => {
                check("lat_deg", lat_deg, -90.0, 90.0)?;
                check("lon_deg", lon_deg, -180.0, 180.0)?;
                check(
                    "alt_msl_m",
                    alt_msl_m.into(),
                    MIN_ALT_M.into(),
                    MAX_ALT_M.into(),
                )?;
            }
            Command::Gimbal { pitch_deg, yaw_deg } => {
                check("pitch_deg", pitch_deg.into(), -180.0, 180.0)?;
                check(
                    "yaw_deg",
                    yaw_deg.into(),
                    (-MAX_GIMBAL_DEG).into(),
                    MAX_GIMBAL_DEG.into(),
                )?;
            }
            Command::Servo { channel, pwm_us } => {
                check(
                    "channel",
                    channel.into(),
                    (*SERVO_CHANNELS.start()).into(),
                    (*SERVO_CHANNELS.end()).into(),
                )?;
                check(
                    "pwm_us",
                    pwm_us.into(),
                    (*PWM_US.start()).into(),
                    (*PWM_US.end()).into(),
                )?;
            }
            Command::GoProSet { command, .. } => check(
                "gopro_command",
                command.into(),
                0.0,
                limits::MAX_GOPRO_COMMAND.into(),
            )?,
            Command::MotorTest {
                motor,
                throttle_pct,
                duration_s,
            } => {
                check(
                    "motor",
                    motor.into(),
                    (*MOTORS.start()).into(),
                    (*MOTORS.end()).into(),
                )?;
                check("throttle_pct", throttle_pct.into(), 0.0, 100.0)?;
                check(
                    "duration_s",
                    duration_s.into(),
                    0.0,
                    MAX_MOTOR_TEST_S.into(),
                )?;
            }
            Command::CameraZoom { mode, value, .. } => match mode {
                ZoomMode::Step => check(
                    "zoom_steps",
                    value.into(),
                    (-MAX_ZOOM_STEPS).into(),
                    MAX_ZOOM_STEPS.into(),
                )?,
                ZoomMode::Continuous => check("zoom_direction", value.into(), -1.0, 1.0)?,
                ZoomMode::Range => check("zoom_pct", value.into(), 0.0, 100.0)?,
            },
            Command::GimbalRate {
                pitch_rate_dps,
                yaw_rate_dps,
            } => {
                for (name, r) in [
                    ("pitch_rate_dps", pitch_rate_dps),
                    ("yaw_rate_dps", yaw_rate_dps),
                ] {
                    check(
                        name,
                        r.into(),
                        (-MAX_GIMBAL_RATE_DPS).into(),
                        MAX_GIMBAL_RATE_DPS.into(),
                    )?;
                }
            }
            Command::CameraFocus { mode, value, .. } => match mode {
                FocusMode::Step => check("focus_steps", value.into(), -1.0, 1.0)?,
                FocusMode::Continuous => check("focus_direction", value.into(), -1.0, 1.0)?,
                FocusMode::Range => check("focus_pct", value.into(), 0.0, 100.0)?,
                FocusMode::Meters => check("focus_m", value.into(), 0.0, MAX_FOCUS_M.into())?,
                // Ignored, but still a number: nothing non-finite travels.
                FocusMode::Auto | FocusMode::AutoSingle | FocusMode::AutoContinuous => {
                    if !value.is_finite() {
                        return Err(CommandError::NotFinite {
                            name: "focus_value",
                        });
                    }
                }
            },
            Command::Arm { .. }
            | Command::Disarm { .. }
            | Command::Land
            | Command::ReturnToLaunch
            | Command::ClearRoi
            | Command::CameraCapture
            | Command::RecordStart
            | Command::RecordStop
            | Command::Brake
            | Command::EmergencyStop
            | Command::ReleaseEmergency
            | Command::ClearEmergency
            | Command::GrabFlightAuthority
            | Command::ReleaseFlightAuthority
            | Command::GrabPayloadAuthority
            | Command::ReleasePayloadAuthority
            | Command::MotorKill { .. }
            | Command::CameraMode { .. }
            | Command::CameraCaptureStop { .. } => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{CommandSource, VehicleCommand};

    #[test]
    fn gimbal_rate_and_focus_ranges_are_checked_both_ways() {
        let rate = |p, y| Command::GimbalRate {
            pitch_rate_dps: p,
            yaw_rate_dps: y,
        };
        let focus = |mode, value| Command::CameraFocus {
            camera: 0,
            mode,
            value,
        };
        for good in [
            rate(360.0, -360.0),
            rate(0.0, 0.0),
            focus(FocusMode::Step, -1.0),
            focus(FocusMode::Continuous, 0.0),
            focus(FocusMode::Range, 100.0),
            focus(FocusMode::Meters, 0.0),
            focus(FocusMode::Auto, 12345.0),
            focus(FocusMode::AutoContinuous, -7.0),
        ] {
            assert!(good.validate().is_ok(), "{good:?} refused");
        }
        for (bad, name) in [
            (rate(360.5, 0.0), "pitch_rate_dps"),
            (rate(0.0, -361.0), "yaw_rate_dps"),
            (focus(FocusMode::Step, 2.0), "focus_steps"),
            (focus(FocusMode::Continuous, -1.5), "focus_direction"),
            (focus(FocusMode::Range, 100.5), "focus_pct"),
            (focus(FocusMode::Range, -0.5), "focus_pct"),
            (focus(FocusMode::Meters, -1.0), "focus_m"),
        ] {
            match bad.validate() {
                Err(CommandError::OutOfRange { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
        for bad in [f32::NAN, f32::INFINITY] {
            assert!(matches!(
                rate(bad, 0.0).validate(),
                Err(CommandError::NotFinite { .. })
            ));
            assert_eq!(
                focus(FocusMode::AutoSingle, bad).validate(),
                Err(CommandError::NotFinite {
                    name: "focus_value"
                })
            );
        }
        // Hostile wire samples: bad enums, negative or too large camera ids, NaN rates.
        let good_focus =
            VehicleCommand::new(1, CommandSource::DjiDrc, 1, &focus(FocusMode::Meters, 3.0))
                .unwrap();
        let mut w = good_focus;
        w.i[1] = 7;
        assert!(matches!(
            w.command(),
            Err(CommandError::OutOfRange {
                name: "focus_mode",
                ..
            })
        ));
        let mut w = good_focus;
        w.i[0] = 256;
        assert!(w.command().is_err(), "camera id above 255 read back");
        let mut w = VehicleCommand::new(
            1,
            CommandSource::DjiDrc,
            1,
            &Command::CameraMode {
                camera: 0,
                mode: CameraModeKind::Image,
            },
        )
        .unwrap();
        w.i[1] = 3;
        assert!(matches!(
            w.command(),
            Err(CommandError::OutOfRange {
                name: "camera_mode",
                ..
            })
        ));
        let mut w = VehicleCommand::new(
            1,
            CommandSource::DjiDrc,
            1,
            &Command::CameraCaptureStop { camera: 0 },
        )
        .unwrap();
        w.i[0] = -1;
        assert!(w.command().is_err(), "negative camera id read back");
        let mut w = VehicleCommand::new(1, CommandSource::DjiDrc, 1, &rate(1.0, 1.0)).unwrap();
        w.f[1] = f32::NAN;
        assert_eq!(
            w.command(),
            Err(CommandError::NotFinite {
                name: "yaw_rate_dps"
            })
        );
    }

    #[test]
    fn motor_test_and_zoom_ranges_are_checked() {
        let bad = [
            Command::MotorTest {
                motor: 0,
                throttle_pct: 10.0,
                duration_s: 1.0,
            },
            Command::MotorTest {
                motor: 1,
                throttle_pct: 101.0,
                duration_s: 1.0,
            },
            Command::MotorTest {
                motor: 1,
                throttle_pct: 10.0,
                duration_s: f32::NAN,
            },
            Command::CameraZoom {
                camera: 0,
                mode: ZoomMode::Range,
                value: 120.0,
            },
            Command::CameraZoom {
                camera: 0,
                mode: ZoomMode::Continuous,
                value: 2.0,
            },
        ];
        for c in bad {
            assert!(c.validate().is_err(), "{c:?} accepted");
        }
        let mut wire = VehicleCommand::new(
            1,
            CommandSource::Imc,
            1,
            &Command::CameraZoom {
                camera: 0,
                mode: ZoomMode::Step,
                value: 3.0,
            },
        )
        .unwrap();
        wire.i[1] = 9;
        assert!(wire.command().is_err(), "unknown zoom mode read back");
    }
}
