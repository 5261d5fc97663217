//! [`VehicleCommand`], the command as it travels on the bus: laid out from a typed
//! [`Command`] and read back with the same checks.

use iceoryx2::prelude::ZeroCopySend;

use super::{
    flags, limits, CameraModeKind, Command, CommandError, CommandKind, CommandSource, FocusMode,
    ZoomMode,
};
use crate::header::SampleHeader;
use crate::vehicle::FlightMode;

/// A command for one vehicle, as it travels on the bus.
///
/// Parameter slots by kind: `GoTo`/`SetRoi`: lat/lon, `f[0]` alt_rel, `f[1]` yaw,
/// `f[2]` speed; `VelocityNed`: `f[0..3]` vn/ve/vd, `f[3]` yaw rate; `Takeoff`: `f[0]`;
/// `SetYaw`: `f[0]` yaw, `f[1]` rate; `Gimbal`: `f[0]` pitch, `f[1]` yaw; `SetMode`:
/// `i[0]` [`FlightMode`]; `Servo`: `i[0]` channel, `i[1]` pwm; `GoProSet`: `i[0]`
/// command, `i[1]` the four value bytes little-endian; `SetHome`: lat/lon, `f[0]`
/// altitude above mean sea level; `MotorTest`: `i[0]` motor, `f[0]` throttle %, `f[1]`
/// duration; `CameraZoom`: `i[0]` camera, `i[1]` [`ZoomMode`], `f[0]` value;
/// `CameraMode`: `i[0]` camera, `i[1]` [`CameraModeKind`]; `CameraCaptureStop`: `i[0]`
/// camera; `GimbalRate`: `f[0]` pitch rate, `f[1]` yaw rate; `CameraFocus`: `i[0]`
/// camera, `i[1]` [`FocusMode`], `f[0]` value.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.VehicleCommand.v2")]
#[repr(C)]
pub struct VehicleCommand {
    pub header: SampleHeader,
    /// MAVLink system id of the target vehicle.
    pub vehicle_id: u8,
    /// [`CommandSource`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub source: u8,
    /// [`CommandKind`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandKind>")
    )]
    pub kind: u8,
    /// See [`flags`].
    pub flags: u8,
    /// Chosen by the sender, echoed in the [`CommandAck`](super::CommandAck).
    pub command_id: u32,
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub f: [f32; 8],
    pub i: [i32; 2],
    /// Maximum age at arrival for setpoints, ms; 0 = the arbiter's default for the source.
    pub max_age_ms: u32,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: u32,
}
crate::assert_layout!(VehicleCommand, size = 96, align = 8);

impl VehicleCommand {
    /// Validates `command` and lays it out for the wire.
    pub fn new(
        vehicle_id: u8,
        source: CommandSource,
        command_id: u32,
        command: &Command,
    ) -> Result<Self, CommandError> {
        command.validate()?;
        let mut c = VehicleCommand {
            vehicle_id,
            source: source.to_wire(),
            kind: command.kind().to_wire(),
            command_id,
            ..Default::default()
        };
        match *command {
            Command::Arm { force } | Command::Disarm { force } => {
                if force {
                    c.flags |= flags::FORCE;
                }
            }
            Command::SetMode(mode) => c.i[0] = mode.to_wire().into(),
            Command::Takeoff { alt_rel_m } => c.f[0] = alt_rel_m,
            Command::GoTo {
                lat_deg,
                lon_deg,
                alt_rel_m,
                yaw_deg,
                speed_mps,
            } => {
                c.lat_deg = lat_deg;
                c.lon_deg = lon_deg;
                c.f[0] = alt_rel_m;
                if let Some(y) = yaw_deg {
                    c.flags |= flags::HAS_YAW;
                    c.f[1] = y;
                }
                if let Some(s) = speed_mps {
                    c.flags |= flags::HAS_SPEED;
                    c.f[2] = s;
                }
            }
            Command::VelocityNed {
                vel_ned_mps,
                yaw_rate_dps,
            } => {
                c.f[..3].copy_from_slice(&vel_ned_mps);
                if let Some(r) = yaw_rate_dps {
                    c.flags |= flags::HAS_YAW_RATE;
                    c.f[3] = r;
                }
            }
            Command::SetYaw {
                yaw_deg,
                rate_dps,
                relative,
            } => {
                c.f[0] = yaw_deg;
                c.f[1] = rate_dps;
                if relative {
                    c.flags |= flags::RELATIVE;
                }
            }
            Command::SetRoi {
                lat_deg,
                lon_deg,
                alt_rel_m,
            } => {
                c.lat_deg = lat_deg;
                c.lon_deg = lon_deg;
                c.f[0] = alt_rel_m;
            }
            Command::SetHome {
                lat_deg,
                lon_deg,
                alt_msl_m,
            } => {
                c.lat_deg = lat_deg;
                c.lon_deg = lon_deg;
                c.f[0] = alt_msl_m;
            }
            Command::Gimbal { pitch_deg, yaw_deg } => {
                c.f[0] = pitch_deg;
                c.f[1] = yaw_deg;
            }
            Command::Servo { channel, pwm_us } => {
                c.i[0] = channel.into();
                c.i[1] = pwm_us.into();
            }
            Command::Land
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
            | Command::ReleasePayloadAuthority => {}
            Command::MotorKill { emergency } => {
                if emergency {
                    c.flags |= flags::EMERGENCY;
                }
            }
            Command::GoProSet { command, value } => {
                c.i[0] = command.into();
                c.i[1] = i32::from_le_bytes(value);
            }
            Command::MotorTest {
                motor,
                throttle_pct,
                duration_s,
            } => {
                c.i[0] = motor.into();
                c.f[0] = throttle_pct;
                c.f[1] = duration_s;
            }
            Command::CameraZoom {
                camera,
                mode,
                value,
            } => {
                c.i[0] = camera.into();
                c.i[1] = mode.to_wire().into();
                c.f[0] = value;
            }
            Command::CameraMode { camera, mode } => {
                c.i[0] = camera.into();
                c.i[1] = mode.to_wire().into();
            }
            Command::CameraCaptureStop { camera } => c.i[0] = camera.into(),
            Command::GimbalRate {
                pitch_rate_dps,
                yaw_rate_dps,
            } => {
                c.f[0] = pitch_rate_dps;
                c.f[1] = yaw_rate_dps;
            }
            Command::CameraFocus {
                camera,
                mode,
                value,
            } => {
                c.i[0] = camera.into();
                c.i[1] = mode.to_wire().into();
                c.f[0] = value;
            }
        }
        Ok(c)
    }

    pub fn source(&self) -> Result<CommandSource, CommandError> {
        CommandSource::try_from(self.source).map_err(|_| CommandError::UnknownSource(self.source))
    }

    pub fn kind(&self) -> Result<CommandKind, CommandError> {
        CommandKind::try_from(self.kind).map_err(|_| CommandError::UnknownKind(self.kind))
    }

    /// Reads the typed command back, refusing anything a valid sender could not have written.
    pub fn command(&self) -> Result<Command, CommandError> {
        let has = |bit: u8| self.flags & bit != 0;
        let int_param = |idx: usize, name: &'static str, max: i64| -> Result<i64, CommandError> {
            let v = i64::from(self.i[idx]);
            if !(0..=max).contains(&v) {
                return Err(CommandError::OutOfRange {
                    name,
                    value: v as f64,
                    min: 0.0,
                    max: max as f64,
                });
            }
            Ok(v)
        };
        let cmd = match self.kind()? {
            CommandKind::Arm => Command::Arm {
                force: has(flags::FORCE),
            },
            CommandKind::Disarm => Command::Disarm {
                force: has(flags::FORCE),
            },
            CommandKind::SetMode => {
                let raw = int_param(0, "mode", u8::MAX.into())? as u8;
                Command::SetMode(FlightMode::try_from(raw).map_err(|_| CommandError::BadMode(raw))?)
            }
            CommandKind::Takeoff => Command::Takeoff {
                alt_rel_m: self.f[0],
            },
            CommandKind::Land => Command::Land,
            CommandKind::ReturnToLaunch => Command::ReturnToLaunch,
            CommandKind::GoTo => Command::GoTo {
                lat_deg: self.lat_deg,
                lon_deg: self.lon_deg,
                alt_rel_m: self.f[0],
                yaw_deg: has(flags::HAS_YAW).then_some(self.f[1]),
                speed_mps: has(flags::HAS_SPEED).then_some(self.f[2]),
            },
            CommandKind::VelocityNed => Command::VelocityNed {
                vel_ned_mps: [self.f[0], self.f[1], self.f[2]],
                yaw_rate_dps: has(flags::HAS_YAW_RATE).then_some(self.f[3]),
            },
            CommandKind::SetYaw => Command::SetYaw {
                yaw_deg: self.f[0],
                rate_dps: self.f[1],
                relative: has(flags::RELATIVE),
            },
            CommandKind::SetRoi => Command::SetRoi {
                lat_deg: self.lat_deg,
                lon_deg: self.lon_deg,
                alt_rel_m: self.f[0],
            },
            CommandKind::ClearRoi => Command::ClearRoi,
            CommandKind::Gimbal => Command::Gimbal {
                pitch_deg: self.f[0],
                yaw_deg: self.f[1],
            },
            CommandKind::CameraCapture => Command::CameraCapture,
            CommandKind::RecordStart => Command::RecordStart,
            CommandKind::RecordStop => Command::RecordStop,
            CommandKind::Servo => Command::Servo {
                channel: int_param(0, "channel", u8::MAX.into())? as u8,
                pwm_us: int_param(1, "pwm_us", u16::MAX.into())? as u16,
            },
            CommandKind::Brake => Command::Brake,
            CommandKind::EmergencyStop => Command::EmergencyStop,
            CommandKind::ReleaseEmergency => Command::ReleaseEmergency,
            CommandKind::ClearEmergency => Command::ClearEmergency,
            CommandKind::GrabFlightAuthority => Command::GrabFlightAuthority,
            CommandKind::ReleaseFlightAuthority => Command::ReleaseFlightAuthority,
            CommandKind::GrabPayloadAuthority => Command::GrabPayloadAuthority,
            CommandKind::ReleasePayloadAuthority => Command::ReleasePayloadAuthority,
            CommandKind::MotorKill => Command::MotorKill {
                emergency: has(flags::EMERGENCY),
            },
            CommandKind::GoProSet => Command::GoProSet {
                command: int_param(0, "gopro_command", limits::MAX_GOPRO_COMMAND.into())? as u8,
                value: self.i[1].to_le_bytes(),
            },
            CommandKind::SetHome => Command::SetHome {
                lat_deg: self.lat_deg,
                lon_deg: self.lon_deg,
                alt_msl_m: self.f[0],
            },
            CommandKind::MotorTest => Command::MotorTest {
                motor: int_param(0, "motor", u8::MAX.into())? as u8,
                throttle_pct: self.f[0],
                duration_s: self.f[1],
            },
            CommandKind::CameraZoom => {
                let raw = int_param(1, "zoom_mode", u8::MAX.into())? as u8;
                Command::CameraZoom {
                    camera: int_param(0, "camera", u8::MAX.into())? as u8,
                    mode: ZoomMode::try_from(raw).map_err(|_| CommandError::OutOfRange {
                        name: "zoom_mode",
                        value: raw.into(),
                        min: 0.0,
                        max: 2.0,
                    })?,
                    value: self.f[0],
                }
            }
            CommandKind::CameraMode => {
                let raw = int_param(1, "camera_mode", u8::MAX.into())? as u8;
                Command::CameraMode {
                    camera: int_param(0, "camera", u8::MAX.into())? as u8,
                    mode: CameraModeKind::try_from(raw).map_err(|_| CommandError::OutOfRange {
                        name: "camera_mode",
                        value: raw.into(),
                        min: 0.0,
                        max: 2.0,
                    })?,
                }
            }
            CommandKind::CameraCaptureStop => Command::CameraCaptureStop {
                camera: int_param(0, "camera", u8::MAX.into())? as u8,
            },
            CommandKind::GimbalRate => Command::GimbalRate {
                pitch_rate_dps: self.f[0],
                yaw_rate_dps: self.f[1],
            },
            CommandKind::CameraFocus => {
                let raw = int_param(1, "focus_mode", u8::MAX.into())? as u8;
                Command::CameraFocus {
                    camera: int_param(0, "camera", u8::MAX.into())? as u8,
                    mode: FocusMode::try_from(raw).map_err(|_| CommandError::OutOfRange {
                        name: "focus_mode",
                        value: raw.into(),
                        min: 0.0,
                        max: 6.0,
                    })?,
                    value: self.f[0],
                }
            }
        };
        cmd.validate()?;
        Ok(cmd)
    }
}

crate::impl_sample!(VehicleCommand);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::AuthorityDomain;

    fn all_examples() -> Vec<Command> {
        vec![
            Command::Arm { force: true },
            Command::Disarm { force: false },
            Command::SetMode(FlightMode::Guided),
            Command::Takeoff { alt_rel_m: 10.0 },
            Command::Land,
            Command::ReturnToLaunch,
            Command::GoTo {
                lat_deg: -35.0,
                lon_deg: 149.0,
                alt_rel_m: 20.0,
                yaw_deg: Some(90.0),
                speed_mps: None,
            },
            Command::VelocityNed {
                vel_ned_mps: [1.0, -2.0, 0.5],
                yaw_rate_dps: Some(10.0),
            },
            Command::SetYaw {
                yaw_deg: -30.0,
                rate_dps: 20.0,
                relative: true,
            },
            Command::SetRoi {
                lat_deg: 1.0,
                lon_deg: 2.0,
                alt_rel_m: 0.0,
            },
            Command::ClearRoi,
            Command::Gimbal {
                pitch_deg: -45.0,
                yaw_deg: 10.0,
            },
            Command::CameraCapture,
            Command::RecordStart,
            Command::RecordStop,
            Command::Servo {
                channel: 9,
                pwm_us: 1900,
            },
            Command::GoProSet {
                command: 2,
                value: [1, 0, 0, 0xff],
            },
            Command::Brake,
            Command::EmergencyStop,
            Command::ReleaseEmergency,
            Command::ClearEmergency,
            Command::GrabFlightAuthority,
            Command::ReleaseFlightAuthority,
            Command::GrabPayloadAuthority,
            Command::ReleasePayloadAuthority,
            Command::MotorKill { emergency: true },
            Command::SetHome {
                lat_deg: -35.3632,
                lon_deg: 149.1652,
                alt_msl_m: 584.0,
            },
            Command::MotorTest {
                motor: 3,
                throttle_pct: 12.5,
                duration_s: 2.0,
            },
            Command::CameraZoom {
                camera: 1,
                mode: ZoomMode::Continuous,
                value: -1.0,
            },
            Command::CameraMode {
                camera: 0,
                mode: CameraModeKind::ImageSurvey,
            },
            Command::CameraCaptureStop { camera: 255 },
            Command::GimbalRate {
                pitch_rate_dps: -360.0,
                yaw_rate_dps: 12.5,
            },
            Command::CameraFocus {
                camera: 2,
                mode: FocusMode::Meters,
                value: 35.5,
            },
        ]
    }

    #[test]
    fn payload_additions_lay_out_as_documented() {
        let w = |c: &Command| VehicleCommand::new(1, CommandSource::DjiDrc, 1, c).unwrap();
        let m = w(&Command::CameraMode {
            camera: 3,
            mode: CameraModeKind::Video,
        });
        assert_eq!((m.kind, m.i), (28, [3, 1]));
        let s = w(&Command::CameraCaptureStop { camera: 7 });
        assert_eq!((s.kind, s.i[0]), (29, 7));
        let r = w(&Command::GimbalRate {
            pitch_rate_dps: -10.0,
            yaw_rate_dps: 20.0,
        });
        assert_eq!((r.kind, r.f[0], r.f[1]), (30, -10.0, 20.0));
        let f = w(&Command::CameraFocus {
            camera: 1,
            mode: FocusMode::Range,
            value: 40.0,
        });
        assert_eq!((f.kind, f.i, f.f[0]), (31, [1, 2], 40.0));
    }

    #[test]
    fn every_command_round_trips_through_the_wire_struct() {
        let examples = all_examples();
        assert_eq!(
            examples.len(),
            CommandKind::ALL.len(),
            "an example per kind"
        );
        for (n, cmd) in examples.into_iter().enumerate() {
            let wire = VehicleCommand::new(3, CommandSource::ShotEngine, n as u32, &cmd).unwrap();
            assert_eq!(wire.command().unwrap(), cmd);
            assert_eq!(wire.source().unwrap(), CommandSource::ShotEngine);
            assert_eq!(wire.command_id, n as u32);
        }
    }

    #[test]
    fn non_finite_numbers_are_refused_both_ways() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let cmd = Command::VelocityNed {
                vel_ned_mps: [bad, 0.0, 0.0],
                yaw_rate_dps: None,
            };
            assert_eq!(
                VehicleCommand::new(1, CommandSource::Vision, 1, &cmd),
                Err(CommandError::NotFinite { name: "vn" })
            );
            // A hostile or corrupt sample written without the constructor:
            let mut wire = VehicleCommand::new(
                1,
                CommandSource::Vision,
                1,
                &Command::Takeoff { alt_rel_m: 5.0 },
            )
            .unwrap();
            wire.f[0] = bad;
            assert!(matches!(
                wire.command(),
                Err(CommandError::NotFinite { .. })
            ));
        }
        let mut wire = VehicleCommand::new(
            1,
            CommandSource::Operator,
            1,
            &Command::GoTo {
                lat_deg: 0.0,
                lon_deg: 0.0,
                alt_rel_m: 1.0,
                yaw_deg: None,
                speed_mps: None,
            },
        )
        .unwrap();
        wire.lat_deg = f64::NAN;
        assert_eq!(
            wire.command(),
            Err(CommandError::NotFinite { name: "lat_deg" })
        );
    }

    #[test]
    fn out_of_range_and_unknown_values_are_refused() {
        assert!(matches!(
            VehicleCommand::new(
                1,
                CommandSource::Operator,
                1,
                &Command::Takeoff { alt_rel_m: 5000.0 }
            ),
            Err(CommandError::OutOfRange { .. })
        ));
        assert!(matches!(
            VehicleCommand::new(
                1,
                CommandSource::Operator,
                1,
                &Command::Servo {
                    channel: 0,
                    pwm_us: 1500
                }
            ),
            Err(CommandError::OutOfRange { .. })
        ));
        assert_eq!(
            VehicleCommand::new(
                1,
                CommandSource::Operator,
                1,
                &Command::SetMode(FlightMode::Unknown)
            ),
            Err(CommandError::BadMode(0))
        );
        let mut wire = VehicleCommand::new(1, CommandSource::Operator, 1, &Command::Land).unwrap();
        wire.kind = 200;
        assert_eq!(wire.command(), Err(CommandError::UnknownKind(200)));
        wire.source = 99;
        assert_eq!(wire.source(), Err(CommandError::UnknownSource(99)));
        let mut wire = VehicleCommand::new(
            1,
            CommandSource::Operator,
            1,
            &Command::SetMode(FlightMode::Loiter),
        )
        .unwrap();
        wire.i[0] = -1;
        assert!(matches!(
            wire.command(),
            Err(CommandError::OutOfRange { .. })
        ));
    }

    #[test]
    fn set_home_is_a_flight_command_with_checked_position_and_msl_altitude() {
        assert_eq!(
            CommandKind::SetHome.authority(),
            Some(AuthorityDomain::Flight)
        );
        assert!(!CommandKind::SetHome.is_setpoint());
        let home = |lat_deg, lon_deg, alt_msl_m| Command::SetHome {
            lat_deg,
            lon_deg,
            alt_msl_m,
        };
        let wire =
            VehicleCommand::new(1, CommandSource::ShotEngine, 4, &home(1.5, -2.5, -20.0)).unwrap();
        assert_eq!((wire.lat_deg, wire.lon_deg, wire.f[0]), (1.5, -2.5, -20.0));
        assert_eq!(wire.kind, 25);
        for (bad, name) in [
            (home(90.5, 0.0, 0.0), "lat_deg"),
            (home(0.0, -180.5, 0.0), "lon_deg"),
            (home(0.0, 0.0, 10_001.0), "alt_msl_m"),
            (home(0.0, 0.0, -1_001.0), "alt_msl_m"),
        ] {
            match VehicleCommand::new(1, CommandSource::ShotEngine, 1, &bad) {
                Err(CommandError::OutOfRange { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
        let mut wire = wire;
        wire.f[0] = f32::NAN;
        assert_eq!(
            wire.command(),
            Err(CommandError::NotFinite { name: "alt_msl_m" })
        );
    }

    proptest::proptest! {
        /// Whatever bytes another process writes, reading never panics and whatever
        /// it accepts is finite and in range.
        #[test]
        fn arbitrary_wire_commands_never_panic(
            kind in 0u8..=255, flags in 0u8..=255, lat in proptest::num::f64::ANY,
            lon in proptest::num::f64::ANY, f in proptest::array::uniform8(proptest::num::f32::ANY),
            i in proptest::array::uniform2(proptest::num::i32::ANY),
        ) {
            let wire = VehicleCommand { kind, flags, lat_deg: lat, lon_deg: lon, f, i, ..Default::default() };
            if let Ok(cmd) = wire.command() {
                proptest::prop_assert!(cmd.validate().is_ok());
                let again = VehicleCommand::new(0, CommandSource::Operator, 0, &cmd).unwrap();
                proptest::prop_assert_eq!(again.command().unwrap(), cmd);
            }
        }
    }
}
