//! [`NetCmdType`]: the record types of the state server, numbered as GroundControl's
//! `NetCmdType` (the spec's list plus the ids FACTS.md found in the reference
//! client: `CMD_EXT_VIDEO_CMD` 0xB8, `CMD_EXT_TIMECODE` 0xD0,
//! `CMD_EXT_TIMECODE_ACTIVE` 0xD1, `CMD_EXT_WAYPOINT_FOLLOW_COLOR` 0xD2).

/// Which union member the record's last 16 bytes are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ParamKind {
    /// Four f32 (`NetCmdRecordFloat`): every type not listed below, and unknown types.
    Floats,
    /// Two f64 (`NetCmdRecordDouble`): `PING_REQUEST`, `PING_RESPONSE`.
    Doubles,
    /// Two i64 (`NetCmdRecordLong`): `EXT_PARAM_ACK`, `CMD_EXT_TEXT`.
    Longs,
}

macro_rules! net_cmd_types {
    ($($(#[$meta:meta])* $variant:ident = $value:literal => $wire_name:literal),+ $(,)?) => {
        /// A record type of the state server. [`crate::Record::kind`] stays a raw `i32`
        /// so unknown types can be carried, counted and refused.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[repr(i32)]
        pub enum NetCmdType {
            $($(#[$meta])* $variant = $value),+
        }

        impl NetCmdType {
            /// Every type, in id order.
            pub const ALL: &'static [NetCmdType] = &[$(NetCmdType::$variant),+];

            /// The type with this id, if the protocol has one.
            pub const fn from_i32(id: i32) -> Option<NetCmdType> {
                match id {
                    $($value => Some(NetCmdType::$variant),)+
                    _ => None,
                }
            }

            /// GroundControl's name (`CMD_EXT_WAYPOINT`).
            pub const fn name(self) -> &'static str {
                match self {
                    $(NetCmdType::$variant => $wire_name),+
                }
            }
        }
    };
}

net_cmd_types! {
    PingRequest = 0x00 => "PING_REQUEST",
    PingResponse = 0x01 => "PING_RESPONSE",
    DataBlob = 0x02 => "DATA_BLOB",
    ServerInfo = 0x03 => "SERVER_INFO",
    ClientInfo = 0x04 => "CLIENT_INFO",
    AckCmdTimeout = 0x05 => "ACK_CMD_TIMEOUT",
    AckCmdSuccess = 0x06 => "ACK_CMD_SUCCESS",
    CmdCtrlMode = 0x10 => "CMD_CTRL_MODE",
    CmdColorMode = 0x11 => "CMD_COLOR_MODE",
    CmdManualColorMode = 0x12 => "CMD_MANUAL_COLOR_MODE",
    CmdResetHomePosition = 0x20 => "CMD_RESET_HOME_POSITION",
    CmdResetHomePositionToAnim = 0x21 => "CMD_RESET_HOME_POSITION_TO_ANIM",
    CmdResetAnimPosition = 0x30 => "CMD_RESET_ANIM_POSITION",
    CmdResetAnimPositionToDrone = 0x31 => "CMD_RESET_ANIM_POSITION_TO_DRONE",
    CmdEmergencyMode = 0x40 => "CMD_EMERGENCY_MODE",
    CmdEnableSafetyPilot = 0x41 => "CMD_ENABLE_SAFETY_PILOT",
    CmdWakeUp = 0x42 => "CMD_WAKE_UP",
    CmdMotorsCmd = 0x43 => "CMD_MOTORS_CMD",
    CmdSetActive = 0x50 => "CMD_SET_ACTIVE",
    CmdSetManualTarget = 0x51 => "CMD_SET_MANUAL_TARGET",
    CmdSetGroup = 0x52 => "CMD_SET_GROUP",
    CmdSetAnimPlaybackTime = 0x60 => "CMD_SET_ANIM_PLAYBACK_TIME",
    CmdSetAnimPlaybackSpeed = 0x61 => "CMD_SET_ANIM_PLAYBACK_SPEED",
    CmdSetAnimColorIntensity = 0x62 => "CMD_SET_ANIM_COLOR_INTENSITY",
    CmdSetCalibrationOffset = 0x70 => "CMD_SET_CALIBRATION_OFFSET",
    CmdSetGeofence = 0x80 => "CMD_SET_GEOFENCE",
    CmdSetGeofencePosition = 0x81 => "CMD_SET_GEOFENCE_POSITION",
    CmdReconfigureGeofence = 0x82 => "CMD_RECONFIGURE_GEOFENCE",
    CmdSetClockTimeout = 0x90 => "CMD_SET_CLOCK_TIMEOUT",
    CmdExtGoExternal = 0xA0 => "CMD_EXT_GO_EXTERNAL",
    CmdExtGoHome = 0xA1 => "CMD_EXT_GO_HOME",
    CmdExtGoHomeAtPosition = 0xA2 => "CMD_EXT_GO_HOME_AT_POSITION",
    CmdExtPause = 0xA3 => "CMD_EXT_PAUSE",
    CmdExtColor = 0xA4 => "CMD_EXT_COLOR",
    CmdExtColorGradient = 0xA5 => "CMD_EXT_COLOR_GRADIENT",
    CmdExtWaypoint = 0xA6 => "CMD_EXT_WAYPOINT",
    CmdExtWaypointFollow = 0xA7 => "CMD_EXT_WAYPOINT_FOLLOW",
    CmdExtPlaybackAnim = 0xA8 => "CMD_EXT_PLAYBACK_ANIM",
    CmdExtAnimCancelLoop = 0xA9 => "CMD_EXT_ANIM_CANCEL_LOOP",
    CmdExtAnimAdjPlaybackSpeed = 0xAA => "CMD_EXT_ANIM_ADJ_PLAYBACK_SPEED",
    CmdExtHalt = 0xAB => "CMD_EXT_HALT",
    CmdExtCheckAllIdle = 0xAC => "CMD_EXT_CHECK_ALL_IDLE",
    CmdExtHaltAndSaveCurCmd = 0xAD => "CMD_EXT_HALT_AND_SAVE_CUR_CMD",
    CmdExtPushSavedCmd = 0xAE => "CMD_EXT_PUSH_SAVED_CMD",
    CmdExtSetBoundingBox = 0xAF => "CMD_EXT_SET_BOUNDING_BOX",
    CmdExtSetActive = 0xB0 => "CMD_EXT_SET_ACTIVE",
    CmdExtResetTrackingToFrame = 0xB1 => "CMD_EXT_RESET_TRACKING_TO_FRAME",
    CmdExtVideo = 0xB2 => "CMD_EXT_VIDEO",
    CmdExtText = 0xB3 => "CMD_EXT_TEXT",
    CmdResetTrackingToSetup = 0xB4 => "CMD_RESET_TRACKING_TO_SETUP",
    CmdResetHomeToSetup = 0xB5 => "CMD_RESET_HOME_TO_SETUP",
    CmdExtSetHomePositionCoordinate = 0xB6 => "CMD_EXT_SET_HOME_POSITION_COORDINATE",
    CmdExtVehicleCmd = 0xB7 => "CMD_EXT_VEHICLECMD",
    CmdExtVideoCmd = 0xB8 => "CMD_EXT_VIDEO_CMD",
    ExtParam1 = 0xC0 => "EXT_PARAM_1",
    ExtParam2 = 0xC1 => "EXT_PARAM_2",
    ExtParamAck = 0xC2 => "EXT_PARAM_ACK",
    CmdExtTimecode = 0xD0 => "CMD_EXT_TIMECODE",
    CmdExtTimecodeActive = 0xD1 => "CMD_EXT_TIMECODE_ACTIVE",
    CmdExtWaypointFollowColor = 0xD2 => "CMD_EXT_WAYPOINT_FOLLOW_COLOR",
}

impl NetCmdType {
    /// The id on the wire.
    pub const fn id(self) -> i32 {
        self as i32
    }

    /// The union member of this type's last 16 bytes (FACTS: PING uses doubles,
    /// EXT_PARAM_ACK and CMD_EXT_TEXT use i64, everything else f32).
    pub const fn param_kind(self) -> ParamKind {
        match self {
            NetCmdType::PingRequest | NetCmdType::PingResponse => ParamKind::Doubles,
            NetCmdType::ExtParamAck | NetCmdType::CmdExtText => ParamKind::Longs,
            _ => ParamKind::Floats,
        }
    }

    /// The parameter layout of the raw type id `id` (unknown ids: floats).
    pub const fn param_kind_of(id: i32) -> ParamKind {
        match NetCmdType::from_i32(id) {
            Some(t) => t.param_kind(),
            None => ParamKind::Floats,
        }
    }

    /// A command to a drone: `CMD_*` (privileged) and `CMD_EXT_*` (any client).
    pub const fn is_command(self) -> bool {
        (self as i32) >= 0x10 && !self.is_ext_param()
    }

    /// `CMD_EXT_*`: any client may send it; every other command needs a privileged
    /// client. (`CMD_RESET_TRACKING_TO_SETUP` and `CMD_RESET_HOME_TO_SETUP` sit among
    /// the ext ids but are privileged: their names say so.)
    pub fn is_ext_command(self) -> bool {
        self.name().starts_with("CMD_EXT_")
    }

    /// `EXT_PARAM_1`, `EXT_PARAM_2`, `EXT_PARAM_ACK`: parameters of the next command.
    pub const fn is_ext_param(self) -> bool {
        matches!(
            self,
            NetCmdType::ExtParam1 | NetCmdType::ExtParam2 | NetCmdType::ExtParamAck
        )
    }

    /// Types only the server sends (`PING_RESPONSE`, `SERVER_INFO`, `ACK_CMD_*`).
    pub const fn is_server_to_client(self) -> bool {
        matches!(
            self,
            NetCmdType::PingResponse
                | NetCmdType::ServerInfo
                | NetCmdType::AckCmdTimeout
                | NetCmdType::AckCmdSuccess
        )
    }

    /// A lower-case name for metric labels (`cmd_ext_waypoint`).
    pub fn label(self) -> &'static str {
        LABELS[NetCmdType::ALL
            .iter()
            .position(|t| *t == self)
            .unwrap_or_default()]
    }
}

/// [`NetCmdType::label`]s, in [`NetCmdType::ALL`] order (checked by a test).
const LABELS: [&str; 60] = [
    "ping_request",
    "ping_response",
    "data_blob",
    "server_info",
    "client_info",
    "ack_cmd_timeout",
    "ack_cmd_success",
    "cmd_ctrl_mode",
    "cmd_color_mode",
    "cmd_manual_color_mode",
    "cmd_reset_home_position",
    "cmd_reset_home_position_to_anim",
    "cmd_reset_anim_position",
    "cmd_reset_anim_position_to_drone",
    "cmd_emergency_mode",
    "cmd_enable_safety_pilot",
    "cmd_wake_up",
    "cmd_motors_cmd",
    "cmd_set_active",
    "cmd_set_manual_target",
    "cmd_set_group",
    "cmd_set_anim_playback_time",
    "cmd_set_anim_playback_speed",
    "cmd_set_anim_color_intensity",
    "cmd_set_calibration_offset",
    "cmd_set_geofence",
    "cmd_set_geofence_position",
    "cmd_reconfigure_geofence",
    "cmd_set_clock_timeout",
    "cmd_ext_go_external",
    "cmd_ext_go_home",
    "cmd_ext_go_home_at_position",
    "cmd_ext_pause",
    "cmd_ext_color",
    "cmd_ext_color_gradient",
    "cmd_ext_waypoint",
    "cmd_ext_waypoint_follow",
    "cmd_ext_playback_anim",
    "cmd_ext_anim_cancel_loop",
    "cmd_ext_anim_adj_playback_speed",
    "cmd_ext_halt",
    "cmd_ext_check_all_idle",
    "cmd_ext_halt_and_save_cur_cmd",
    "cmd_ext_push_saved_cmd",
    "cmd_ext_set_bounding_box",
    "cmd_ext_set_active",
    "cmd_ext_reset_tracking_to_frame",
    "cmd_ext_video",
    "cmd_ext_text",
    "cmd_reset_tracking_to_setup",
    "cmd_reset_home_to_setup",
    "cmd_ext_set_home_position_coordinate",
    "cmd_ext_vehiclecmd",
    "cmd_ext_video_cmd",
    "ext_param_1",
    "ext_param_2",
    "ext_param_ack",
    "cmd_ext_timecode",
    "cmd_ext_timecode_active",
    "cmd_ext_waypoint_follow_color",
];

impl std::fmt::Display for NetCmdType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_names_and_labels_agree() {
        assert_eq!(NetCmdType::ALL.len(), LABELS.len());
        for (t, label) in NetCmdType::ALL.iter().zip(LABELS) {
            assert_eq!(NetCmdType::from_i32(t.id()), Some(*t));
            assert_eq!(t.name().to_ascii_lowercase(), label);
            assert_eq!(t.label(), label);
        }
        let mut ids: Vec<i32> = NetCmdType::ALL.iter().map(|t| t.id()).collect();
        let sorted = {
            let mut s = ids.clone();
            s.sort_unstable();
            s
        };
        assert_eq!(ids, sorted, "ALL is in id order");
        ids.dedup();
        assert_eq!(ids.len(), NetCmdType::ALL.len());
        for unknown in [-1, 0x07, 0x0F, 0x13, 0xB9, 0xC3, 0xD3, 0x100, i32::MIN] {
            assert_eq!(NetCmdType::from_i32(unknown), None, "{unknown:#x}");
        }
    }

    #[test]
    fn facts_extras_and_layouts() {
        assert_eq!(NetCmdType::CmdExtVideoCmd.id(), 0xB8);
        assert_eq!(NetCmdType::CmdExtTimecode.id(), 0xD0);
        assert_eq!(NetCmdType::CmdExtTimecodeActive.id(), 0xD1);
        assert_eq!(NetCmdType::CmdExtWaypointFollowColor.id(), 0xD2);
        assert_eq!(NetCmdType::PingRequest.param_kind(), ParamKind::Doubles);
        assert_eq!(NetCmdType::PingResponse.param_kind(), ParamKind::Doubles);
        assert_eq!(NetCmdType::ExtParamAck.param_kind(), ParamKind::Longs);
        assert_eq!(NetCmdType::CmdExtText.param_kind(), ParamKind::Longs);
        assert_eq!(NetCmdType::ExtParam1.param_kind(), ParamKind::Floats);
        assert_eq!(NetCmdType::param_kind_of(0x7777), ParamKind::Floats);
    }

    #[test]
    fn privilege_classes() {
        let ext: Vec<_> = NetCmdType::ALL
            .iter()
            .filter(|t| t.is_ext_command())
            .collect();
        assert!(ext.iter().all(|t| t.is_command()));
        assert!(NetCmdType::CmdExtWaypoint.is_ext_command());
        assert!(NetCmdType::CmdExtWaypointFollowColor.is_ext_command());
        assert!(!NetCmdType::CmdResetTrackingToSetup.is_ext_command());
        assert!(NetCmdType::CmdResetTrackingToSetup.is_command());
        assert!(!NetCmdType::ExtParam1.is_command());
        assert!(!NetCmdType::PingRequest.is_command());
        assert!(NetCmdType::CmdEmergencyMode.is_command());
        assert!(!NetCmdType::CmdEmergencyMode.is_ext_command());
        assert!(NetCmdType::AckCmdSuccess.is_server_to_client());
        assert!(!NetCmdType::PingRequest.is_server_to_client());
    }
}
