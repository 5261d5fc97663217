//! Vehicle commands and their acknowledgements.
//!
//! Every flight, camera and payload instruction from any gateway or engine is a
//! [`VehicleCommand`] sample on `skymesh/vehicle/{id}/command`; `autopilot-link` is the
//! only subscriber that acts on it and answers each one with a [`CommandAck`].
//!
//! The wire struct is plain data; code builds and reads it through the typed
//! [`Command`] enum. Both directions validate: non-finite or out-of-range numbers and
//! unknown kinds are refused with a [`CommandError`], so a corrupt or hostile sample
//! never becomes a MAVLink message.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::vehicle::FlightMode;
use crate::wire_enum;

wire_enum! {
    /// Who sent a command. Flight authority priorities are decided by the arbiter.
    pub enum CommandSource: u8 {
        /// Failsafes, geofence, emergency stop.
        Safety = 0 => "safety",
        ManualRc = 1 => "manual_rc",
        DjiDrc = 2 => "dji_drc",
        ShotEngine = 3 => "shot_engine",
        SwarmQueue = 4 => "swarm_queue",
        Imc = 5 => "imc",
        Vision = 6 => "vision",
        /// Local operator tools (`skymesh` CLI) and tests.
        Operator = 7 => "operator",
    }
}

wire_enum! {
    /// What a [`VehicleCommand`] asks for; selects how its parameters are read.
    pub enum CommandKind: u8 {
        Arm = 1 => "arm",
        Disarm = 2 => "disarm",
        SetMode = 3 => "set_mode",
        Takeoff = 4 => "takeoff",
        Land = 5 => "land",
        ReturnToLaunch = 6 => "return_to_launch",
        GoTo = 7 => "go_to",
        VelocityNed = 8 => "velocity_ned",
        SetYaw = 9 => "set_yaw",
        SetRoi = 10 => "set_roi",
        ClearRoi = 11 => "clear_roi",
        Gimbal = 12 => "gimbal",
        CameraCapture = 13 => "camera_capture",
        RecordStart = 14 => "record_start",
        RecordStop = 15 => "record_stop",
        Servo = 16 => "servo",
        Brake = 17 => "brake",
        EmergencyStop = 18 => "emergency_stop",
        GrabFlightAuthority = 19 => "grab_flight_authority",
        ReleaseFlightAuthority = 20 => "release_flight_authority",
        GrabPayloadAuthority = 21 => "grab_payload_authority",
        ReleasePayloadAuthority = 22 => "release_payload_authority",
        MotorKill = 23 => "motor_kill",
        GoProSet = 24 => "gopro_set",
        SetHome = 25 => "set_home",
        MotorTest = 26 => "motor_test",
        CameraZoom = 27 => "camera_zoom",
        CameraMode = 28 => "camera_mode",
        CameraCaptureStop = 29 => "camera_capture_stop",
        GimbalRate = 30 => "gimbal_rate",
        CameraFocus = 31 => "camera_focus",
        ReleaseEmergency = 32 => "release_emergency",
        ClearEmergency = 33 => "clear_emergency",
    }
}

wire_enum! {
    /// How [`Command::CameraZoom`]'s value is read, numbered as MAVLink CAMERA_ZOOM_TYPE.
    pub enum ZoomMode: u8 {
        /// `value` zoom steps in (+) or out (−).
        Step = 0 => "step",
        /// Keep zooming in (+1), out (−1), or stop (0).
        Continuous = 1 => "continuous",
        /// Zoom to `value` percent of the camera's range (0 = widest).
        Range = 2 => "range",
    }
}

wire_enum! {
    /// What [`Command::CameraMode`] switches a camera to, numbered as MAVLink CAMERA_MODE.
    pub enum CameraModeKind: u8 {
        /// Still photos.
        Image = 0 => "image",
        /// Video recording.
        Video = 1 => "video",
        /// Still photos with the camera's survey settings.
        ImageSurvey = 2 => "image_survey",
    }
}

wire_enum! {
    /// How [`Command::CameraFocus`]'s value is read, numbered as MAVLink SET_FOCUS_TYPE.
    pub enum FocusMode: u8 {
        /// One focus step in (−1) or out towards infinity (+1); 0 does nothing.
        Step = 0 => "step",
        /// Keep focusing in (−1), out (+1), or stop (0).
        Continuous = 1 => "continuous",
        /// Focus to `value` percent of the camera's focus range (0..=100).
        Range = 2 => "range",
        /// Focus at `value` metres (≥ 0).
        Meters = 3 => "meters",
        /// Automatic focus; `value` is ignored.
        Auto = 4 => "auto",
        /// Focus once automatically (AF-S); `value` is ignored.
        AutoSingle = 5 => "auto_single",
        /// Keep focusing automatically (AF-C); `value` is ignored.
        AutoContinuous = 6 => "auto_continuous",
    }
}

impl FocusMode {
    /// The automatic modes, whose value is ignored.
    pub const fn is_auto(self) -> bool {
        matches!(
            self,
            FocusMode::Auto | FocusMode::AutoSingle | FocusMode::AutoContinuous
        )
    }
}

wire_enum! {
    /// Outcome of a command.
    pub enum AckResult: u8 {
        Accepted = 0 => "accepted",
        Refused = 1 => "refused",
        /// Accepted by the autopilot and still running (long commands).
        InProgress = 2 => "in_progress",
        /// Accepted after the arbiter reduced it (e.g. a velocity limited by the geofence).
        Limited = 3 => "limited",
    }
}

wire_enum! {
    /// Why a command was refused (`None` when accepted).
    pub enum RefusalReason: u16 {
        None = 0 => "none",
        /// The autopilot did not answer within the command timeout.
        Timeout = 1 => "timeout",
        /// The autopilot answered MAV_RESULT_DENIED.
        Denied = 2 => "denied",
        /// The autopilot answered MAV_RESULT_UNSUPPORTED, or skymesh cannot map it.
        Unsupported = 3 => "unsupported",
        /// The autopilot answered MAV_RESULT_FAILED.
        Failed = 4 => "failed",
        /// The autopilot answered MAV_RESULT_TEMPORARILY_REJECTED.
        TemporarilyRejected = 5 => "temporarily_rejected",
        /// A parameter was not finite or out of range, or the kind is unknown.
        InvalidParameter = 6 => "invalid_parameter",
        /// No autopilot heartbeat: nothing can be executed.
        LinkDown = 7 => "link_down",
        /// Another source holds authority.
        NoAuthority = 8 => "no_authority",
        /// The target lies outside the geofence envelope.
        Geofence = 9 => "geofence",
        /// The sample was older than its maximum age when it arrived.
        Stale = 10 => "stale",
        /// Addressed to another vehicle.
        WrongVehicle = 11 => "wrong_vehicle",
        /// The vehicle is not in a state that allows it (e.g. not GUIDED for a setpoint).
        WrongState = 12 => "wrong_state",
        /// Superseded by a newer command before the autopilot answered.
        Cancelled = 13 => "cancelled",
        /// An emergency stop holds the vehicle; only the safety source may command it.
        Emergency = 14 => "emergency",
        /// Not allowed while the vehicle is in the air: a motor kill not flagged as an
        /// emergency, a motor test, or a servo channel not configured for use in flight.
        InAir = 15 => "in_air",
        /// The source lost authority to a higher-priority source.
        Preempted = 16 => "preempted",
        /// The autopilot is flying its own failsafe (RTL, LAND, SmartRTL): only a
        /// pilot on the sticks (manual RC) may change its mode or brake it.
        AutopilotFailsafe = 17 => "autopilot_failsafe",
    }
}

impl CommandSource {
    /// Flight-authority priority, higher wins. Safety > manual RC > local operator >
    /// DJI DRC > shot engine > swarm queue > IMC > vision. The operator (the
    /// `skymesh` CLI and ground tools on the companion computer) ranks just below a
    /// pilot on the sticks, above every automated source.
    pub const fn priority(self) -> u8 {
        match self {
            CommandSource::Safety => 100,
            CommandSource::ManualRc => 90,
            CommandSource::Operator => 80,
            CommandSource::DjiDrc => 70,
            CommandSource::ShotEngine => 60,
            CommandSource::SwarmQueue => 50,
            CommandSource::Imc => 40,
            CommandSource::Vision => 30,
        }
    }
}

/// Which authority a command needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AuthorityDomain {
    /// Anything that moves the aircraft or changes its flight state.
    Flight,
    /// Camera, gimbal and payload outputs (DJI separates these from flight).
    Payload,
}

impl CommandKind {
    /// The authority a command of this kind needs; `None` for the authority
    /// requests themselves and for the emergency stop (always allowed, it only brakes).
    pub const fn authority(self) -> Option<AuthorityDomain> {
        match self {
            CommandKind::Gimbal
            | CommandKind::CameraCapture
            | CommandKind::RecordStart
            | CommandKind::RecordStop
            | CommandKind::Servo
            | CommandKind::CameraZoom
            | CommandKind::CameraMode
            | CommandKind::CameraCaptureStop
            | CommandKind::GimbalRate
            | CommandKind::CameraFocus
            | CommandKind::GoProSet
            | CommandKind::GrabPayloadAuthority
            | CommandKind::ReleasePayloadAuthority => Some(AuthorityDomain::Payload),
            CommandKind::EmergencyStop
            | CommandKind::ReleaseEmergency
            | CommandKind::ClearEmergency => None,
            _ => Some(AuthorityDomain::Flight),
        }
    }

    /// Setpoints are a stream: each carries a maximum age and the arbiter brakes when
    /// the stream stops.
    pub const fn is_setpoint(self) -> bool {
        matches!(self, CommandKind::VelocityNed)
    }

    /// Grab/release requests.
    pub const fn is_authority_request(self) -> bool {
        matches!(
            self,
            CommandKind::GrabFlightAuthority
                | CommandKind::ReleaseFlightAuthority
                | CommandKind::GrabPayloadAuthority
                | CommandKind::ReleasePayloadAuthority
        )
    }
}

/// Flag bits of [`VehicleCommand::flags`].
pub mod flags {
    /// Arm/disarm bypassing the autopilot's checks (ArduPilot magic 21196).
    pub const FORCE: u8 = 0x01;
    /// `GoTo`: `f[1]` holds a yaw to face.
    pub const HAS_YAW: u8 = 0x02;
    /// `GoTo`: `f[2]` holds a ground speed.
    pub const HAS_SPEED: u8 = 0x04;
    /// `SetYaw`: the angle is relative to the current heading.
    pub const RELATIVE: u8 = 0x08;
    /// `VelocityNed`: `f[3]` holds a yaw rate.
    pub const HAS_YAW_RATE: u8 = 0x10;
    /// `MotorKill`: an emergency kill, executed even in the air.
    pub const EMERGENCY: u8 = 0x20;
}

/// Sanity limits applied at conversion; the arbiter's envelope is stricter.
pub mod limits {
    pub const MAX_ALT_M: f32 = 10_000.0;
    pub const MIN_ALT_M: f32 = -1_000.0;
    pub const MAX_TAKEOFF_ALT_M: f32 = 1_000.0;
    pub const MAX_SPEED_MPS: f32 = 50.0;
    pub const MAX_YAW_RATE_DPS: f32 = 720.0;
    pub const MAX_GIMBAL_DEG: f32 = 360.0;
    pub const PWM_US: core::ops::RangeInclusive<u16> = 500..=2500;
    pub const SERVO_CHANNELS: core::ops::RangeInclusive<u8> = 1..=32;
    /// Highest MAVLink GOPRO_COMMAND id (GOPRO_COMMAND_CHARGING).
    pub const MAX_GOPRO_COMMAND: u8 = 16;
    /// Motor numbers of a motor test (ArduPilot numbers motors from 1).
    pub const MOTORS: core::ops::RangeInclusive<u8> = 1..=12;
    /// Longest motor test.
    pub const MAX_MOTOR_TEST_S: f32 = 10.0;
    /// Most zoom steps in one command.
    pub const MAX_ZOOM_STEPS: f32 = 100.0;
    /// Fastest commanded gimbal rate, deg/s, either axis.
    pub const MAX_GIMBAL_RATE_DPS: f32 = 360.0;
    /// Farthest focus distance a command may name (metres; beyond is infinity).
    pub const MAX_FOCUS_M: f32 = 100_000.0;
}

/// A typed command. Build a [`VehicleCommand`] from it with [`VehicleCommand::new`].
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
    /// The refusal reason to put in the [`CommandAck`].
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
#[type_name("skymesh.VehicleCommand.v2")]
#[repr(C)]
pub struct VehicleCommand {
    pub header: SampleHeader,
    /// MAVLink system id of the target vehicle.
    pub vehicle_id: u8,
    /// [`CommandSource`] as stored on the wire.
    pub source: u8,
    /// [`CommandKind`] as stored on the wire.
    pub kind: u8,
    /// See [`flags`].
    pub flags: u8,
    /// Chosen by the sender, echoed in the [`CommandAck`].
    pub command_id: u32,
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub f: [f32; 8],
    pub i: [i32; 2],
    /// Maximum age at arrival for setpoints, ms; 0 = the arbiter's default for the source.
    pub max_age_ms: u32,
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

/// The answer to one [`VehicleCommand`], published by `autopilot-link`.
///
/// Topic: [`crate::topics::vehicle_command_ack`]. Matched to its command by
/// `(source, command_id)`.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.CommandAck.v2")]
#[repr(C)]
pub struct CommandAck {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// [`CommandSource`] of the command answered.
    pub source: u8,
    /// [`CommandKind`] of the command answered (raw: may be an unknown value that was refused).
    pub kind: u8,
    /// [`AckResult`] as stored on the wire.
    pub result: u8,
    /// `command_id` of the command answered.
    pub command_id: u32,
    /// [`RefusalReason`] as stored on the wire.
    pub reason: u16,
    /// The MAVLink `MAV_RESULT` when the autopilot answered, 255 otherwise.
    pub mav_result: u8,
    pub reserved: u8,
    /// Sequence number of the command sample answered.
    pub command_seq: u32,
    /// Human-readable detail for logs and operators.
    pub detail: FixedStr<48>,
}
crate::assert_layout!(CommandAck, size = 88, align = 8);

impl CommandAck {
    /// Sentinel for `mav_result` when the autopilot never answered.
    pub const NO_MAV_RESULT: u8 = 255;

    pub fn result(&self) -> Option<AckResult> {
        AckResult::try_from(self.result).ok()
    }

    pub fn reason(&self) -> Option<RefusalReason> {
        RefusalReason::try_from(self.reason).ok()
    }

    /// Accepted as sent, or accepted after the arbiter limited it.
    pub fn is_accepted(&self) -> bool {
        self.result == AckResult::Accepted.to_wire() || self.result == AckResult::Limited.to_wire()
    }
}

crate::impl_sample!(VehicleCommand, CommandAck);

#[cfg(test)]
mod tests {
    use super::*;

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
    fn payload_additions_are_payload_commands_with_stable_numbers() {
        for (kind, wire, label) in [
            (CommandKind::CameraMode, 28, "camera_mode"),
            (CommandKind::CameraCaptureStop, 29, "camera_capture_stop"),
            (CommandKind::GimbalRate, 30, "gimbal_rate"),
            (CommandKind::CameraFocus, 31, "camera_focus"),
        ] {
            assert_eq!(kind.to_wire(), wire);
            assert_eq!(kind.to_string(), label);
            assert_eq!(kind.authority(), Some(AuthorityDomain::Payload), "{kind}");
            assert!(!kind.is_setpoint() && !kind.is_authority_request());
        }
        // The numbering is MAVLink's CAMERA_MODE and SET_FOCUS_TYPE.
        assert_eq!(
            CameraModeKind::ALL
                .iter()
                .map(|m| (m.to_wire(), m.as_str()))
                .collect::<Vec<_>>(),
            [(0, "image"), (1, "video"), (2, "image_survey")]
        );
        assert_eq!(
            FocusMode::ALL
                .iter()
                .map(|m| (m.to_wire(), m.as_str()))
                .collect::<Vec<_>>(),
            [
                (0, "step"),
                (1, "continuous"),
                (2, "range"),
                (3, "meters"),
                (4, "auto"),
                (5, "auto_single"),
                (6, "auto_continuous")
            ]
        );
        assert!(FocusMode::AutoSingle.is_auto() && !FocusMode::Meters.is_auto());
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
