//! Who sent a command, what kind it is and which authority it needs, and the modes
//! that select how a camera command's value is read.

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

wire_enum! {
    /// What a [`VehicleCommand`](super::VehicleCommand) asks for; selects how its
    /// parameters are read.
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

wire_enum! {
    /// How [`Command::CameraZoom`](super::Command::CameraZoom)'s value is read, numbered
    /// as MAVLink CAMERA_ZOOM_TYPE.
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
    /// What [`Command::CameraMode`](super::Command::CameraMode) switches a camera to,
    /// numbered as MAVLink CAMERA_MODE.
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
    /// How [`Command::CameraFocus`](super::Command::CameraFocus)'s value is read,
    /// numbered as MAVLink SET_FOCUS_TYPE.
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
