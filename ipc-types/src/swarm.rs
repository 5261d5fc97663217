//! Swarm commands and state: `groundcontrol-gateway` ↔ `swarm-queue`.
//!
//! The gateway cuts GroundControl's 32-byte records, checks privilege, merges the
//! `EXT_PARAM_1`/`EXT_PARAM_2` records that precede a command into it, validates the
//! parameters with [`SwarmCommand::validate`], and publishes one [`SwarmCommand`] per
//! drone on [`crate::topics::swarm_command`]. The queue answers on
//! [`crate::topics::swarm_reply`] (command finished, timed out or refused; the idle
//! answers of `CHECK_ALL_IDLE`) and publishes every drone's state in one
//! [`SwarmState`] on [`crate::topics::swarm_state`], from which the gateway builds the
//! pose broadcast.
//!
//! Positions are metres in the site frame (x east, y north, z up) around the
//! swarm-queue's configured site origin; yaw is counter-clockwise degrees from x
//! (GroundControl's convention). [`SwarmCommandKind`] is numbered as GroundControl's
//! `NetCmdType`, so the gateway maps record types one to one.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

/// Most drones one swarm-queue serves (and one [`SwarmState`] carries).
pub const SWARM_MAX_DRONES: usize = 256;
/// Longest `CMD_EXT_TEXT` (GroundControl carries 20 characters).
pub const SWARM_TEXT_CAPACITY: usize = 24;
/// Largest coordinate accepted in the site frame, metres.
pub const SWARM_MAX_SITE_M: f32 = 10_000.0;
/// Fastest waypoint speed accepted, m/s.
pub const SWARM_MAX_SPEED_MPS: f32 = 20.0;
/// Longest pause / colour fade accepted, seconds.
pub const SWARM_MAX_DURATION_S: f32 = 3_600.0;

wire_enum! {
    /// A swarm command, numbered as GroundControl's `NetCmdType`.
    pub enum SwarmCommandKind: u8 {
        CtrlMode = 0x10 => "ctrl_mode",
        ColorMode = 0x11 => "color_mode",
        ManualColorMode = 0x12 => "manual_color_mode",
        ResetHomePosition = 0x20 => "reset_home_position",
        ResetHomePositionToAnim = 0x21 => "reset_home_position_to_anim",
        ResetAnimPosition = 0x30 => "reset_anim_position",
        ResetAnimPositionToDrone = 0x31 => "reset_anim_position_to_drone",
        EmergencyMode = 0x40 => "emergency_mode",
        EnableSafetyPilot = 0x41 => "enable_safety_pilot",
        WakeUp = 0x42 => "wake_up",
        MotorsCmd = 0x43 => "motors_cmd",
        SetActive = 0x50 => "set_active",
        SetManualTarget = 0x51 => "set_manual_target",
        SetGroup = 0x52 => "set_group",
        SetAnimPlaybackTime = 0x60 => "set_anim_playback_time",
        SetAnimPlaybackSpeed = 0x61 => "set_anim_playback_speed",
        SetAnimColorIntensity = 0x62 => "set_anim_color_intensity",
        SetCalibrationOffset = 0x70 => "set_calibration_offset",
        SetGeofence = 0x80 => "set_geofence",
        SetGeofencePosition = 0x81 => "set_geofence_position",
        ReconfigureGeofence = 0x82 => "reconfigure_geofence",
        SetClockTimeout = 0x90 => "set_clock_timeout",
        ExtGoExternal = 0xA0 => "ext_go_external",
        ExtGoHome = 0xA1 => "ext_go_home",
        ExtGoHomeAtPosition = 0xA2 => "ext_go_home_at_position",
        ExtPause = 0xA3 => "ext_pause",
        ExtColor = 0xA4 => "ext_color",
        ExtColorGradient = 0xA5 => "ext_color_gradient",
        ExtWaypoint = 0xA6 => "ext_waypoint",
        ExtWaypointFollow = 0xA7 => "ext_waypoint_follow",
        ExtPlaybackAnim = 0xA8 => "ext_playback_anim",
        ExtAnimCancelLoop = 0xA9 => "ext_anim_cancel_loop",
        ExtAnimAdjPlaybackSpeed = 0xAA => "ext_anim_adj_playback_speed",
        ExtHalt = 0xAB => "ext_halt",
        ExtCheckAllIdle = 0xAC => "ext_check_all_idle",
        ExtHaltAndSaveCurCmd = 0xAD => "ext_halt_and_save_cur_cmd",
        ExtPushSavedCmd = 0xAE => "ext_push_saved_cmd",
        ExtSetBoundingBox = 0xAF => "ext_set_bounding_box",
        ExtSetActive = 0xB0 => "ext_set_active",
        ExtResetTrackingToFrame = 0xB1 => "ext_reset_tracking_to_frame",
        ExtVideo = 0xB2 => "ext_video",
        ExtText = 0xB3 => "ext_text",
        ResetTrackingToSetup = 0xB4 => "reset_tracking_to_setup",
        ResetHomeToSetup = 0xB5 => "reset_home_to_setup",
        ExtSetHomePositionCoordinate = 0xB6 => "ext_set_home_position_coordinate",
        ExtVehicleCmd = 0xB7 => "ext_vehiclecmd",
        ExtVideoCmd = 0xB8 => "ext_video_cmd",
        ExtTimecode = 0xD0 => "ext_timecode",
        ExtTimecodeActive = 0xD1 => "ext_timecode_active",
        ExtWaypointFollowColor = 0xD2 => "ext_waypoint_follow_color",
    }
}

impl SwarmCommandKind {
    /// `CMD_EXT_*` commands: any client may send them. Everything else needs a
    /// privileged client.
    pub fn is_ext(self) -> bool {
        self.as_str().starts_with("ext_")
    }
}

wire_enum! {
    /// What a [`SwarmReply`] says.
    pub enum SwarmResult: u8 {
        /// The command finished (GroundControl `ACK_CMD_SUCCESS`).
        Success = 0 => "success",
        /// The command did not finish in its time (GroundControl `ACK_CMD_TIMEOUT`).
        Timeout = 1 => "timeout",
        /// Refused without effect (unknown drone, invalid parameters, not meaningful
        /// for a MAVLink drone, refused by the arbiter); `reason` says why.
        Refused = 2 => "refused",
        /// Answer to `CHECK_ALL_IDLE`: `value` = 1 idle, 0 busy.
        IdleState = 3 => "idle_state",
        /// Accepted into the drone's queue or applied at once (no GroundControl record;
        /// for logs and tools).
        Accepted = 4 => "accepted",
    }
}

wire_enum! {
    /// GroundControl's `DroneState`, derived from the vehicle's phase.
    pub enum DroneState: u8 {
        None = 0 => "none",
        Puppet = 1 => "puppet",
        ResetGeofence = 2 => "reset_geofence",
        SetGeofence = 3 => "set_geofence",
        GuessState = 4 => "guess_state",
        OnGround = 5 => "on_ground",
        TakeoffWait = 6 => "takeoff_wait",
        TakeoffMotorsOn = 7 => "takeoff_motors_on",
        TakeoffLowLevel = 8 => "takeoff_low_level",
        Takeoff = 9 => "takeoff",
        FollowTarget = 10 => "follow_target",
        LandingInitiate = 11 => "landing_initiate",
        LandingWait = 12 => "landing_wait",
        LandingPrepare = 13 => "landing_prepare",
        LandingFast = 14 => "landing_fast",
        LandingSlow = 15 => "landing_slow",
        LandingMotorsOff = 16 => "landing_motors_off",
    }
}

/// Every drone (`drone` value of a [`SwarmCommand`] addressed to all).
pub const ALL_DRONES: u16 = u16::MAX;

/// One command for one drone (or [`ALL_DRONES`]), as GroundControl sent it.
///
/// Parameter slots: `f[0..4]` the record's four floats, `f[4..8]` the floats of the
/// preceding `EXT_PARAM_1`, `f[8..12]` of `EXT_PARAM_2` (flags [`swarm_flags`] say
/// which were present); `d` the record's two doubles or two i64 (as bits, for the
/// commands that carry them); `int1`/`int2` the record's integers; `text` for
/// `CMD_EXT_TEXT`.
///
/// | kind | parameters |
/// |---|---|
/// | `ExtWaypoint`, `ExtWaypointFollow`, `SetManualTarget` | `f[0..3]` x, y, z (site m), `f[3]` speed m/s (0 = default); `int1` yaw in degrees × 100 |
/// | `ExtWaypointFollowColor` | as `ExtWaypointFollow`, `f[4..7]` rgb from `EXT_PARAM_1` |
/// | `ExtPause` | `f[0]` seconds |
/// | `ExtColor` | `f[4..7]` rgb 0..1 (`EXT_PARAM_1`), `f[0]` fade seconds |
/// | `ExtColorGradient` | `f[4..7]` from rgb, `f[8..11]` to rgb, `f[0]` seconds |
/// | `ExtPlaybackAnim` | `int1`/`int2` first/last frame, `f[0]` loop (0/1), `f[1]` speed, `f[2]` use choreography (0/1), `f[3]` use colour (0/1) |
/// | `ExtAnimAdjPlaybackSpeed`, `SetAnimPlaybackSpeed` | `f[0]` speed factor |
/// | `SetAnimPlaybackTime` | `f[0]` seconds into the animation |
/// | `SetAnimColorIntensity` | `f[0]` 0..1 |
/// | `ExtSetActive`, `SetActive` | `int1` 0/1 |
/// | `ExtSetHomePositionCoordinate` | `f[0..3]` x, y, z, `f[3]` yaw (CCW degrees) |
/// | `ExtSetBoundingBox` | `f[4..7]` min x, y, z (`EXT_PARAM_1`), `f[0..3]` max x, y, z |
/// | `ExtText` | `text` (≤ 20 characters) |
/// | `ExtVehicleCmd` | `int1` 1 relative / 2 absolute rotation / 4 void (as the public Unity client sends), `f[0]` rotation degrees (CCW) |
/// | `ExtResetTrackingToFrame` | `int1` frame |
/// | `ExtVideo`, `ExtVideoCmd`, `ExtTimecode`, `ExtTimecodeActive` | `int1`, `int2`, `f`, `d` recorded as sent |
/// | `MotorsCmd`, `EmergencyMode`, `EnableSafetyPilot`, `WakeUp`, `CtrlMode`, `ColorMode`, `ManualColorMode`, `SetGroup`, `SetClockTimeout` | `int1` (mode / on-off / group / ms) |
/// | `SetCalibrationOffset`, `SetGeofencePosition` | `f[0..3]` x, y, z |
/// | `SetGeofence`, `ReconfigureGeofence` | `f[4..7]` min (`EXT_PARAM_1`), `f[0..3]` max |
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.SwarmCommand.v1")]
#[repr(C)]
pub struct SwarmCommand {
    pub header: SampleHeader,
    /// Chosen by the gateway, echoed in replies.
    pub request_id: u32,
    /// The gateway's id of the client connection (replies go back to it).
    pub client: u16,
    /// GroundControl drone id (`context`), or [`ALL_DRONES`].
    pub drone: u16,
    /// [`SwarmCommandKind`] as stored on the wire.
    pub kind: u8,
    /// See [`swarm_flags`].
    pub flags: u8,
    pub reserved: [u8; 2],
    pub int1: i32,
    pub int2: i32,
    pub f: [f32; 12],
    pub reserved2: u32,
    /// The record's two doubles or two i64 (bit pattern), where the kind carries them.
    pub d: [u64; 2],
    pub text: FixedStr<SWARM_TEXT_CAPACITY>,
}
crate::assert_layout!(
    SwarmCommand,
    size = 24 + 12 + 8 + 48 + 4 + 16 + 24,
    align = 8
);

/// Flag bits of [`SwarmCommand::flags`].
pub mod swarm_flags {
    /// `f[4..8]` came from an `EXT_PARAM_1` record.
    pub const HAS_EXT1: u8 = 0x01;
    /// `f[8..12]` came from an `EXT_PARAM_2` record.
    pub const HAS_EXT2: u8 = 0x02;
    /// Sent by a privileged client.
    pub const PRIVILEGED: u8 = 0x04;
}

/// Why a [`SwarmCommand`]'s parameters are not acceptable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SwarmCommandError {
    #[error("command type {0:#04x} is unknown")]
    UnknownKind(u8),
    #[error("{kind}: {name} = {value} is not finite or outside {min}..={max}")]
    OutOfRange {
        kind: &'static str,
        name: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("{kind}: needs the {which} parameter record first")]
    MissingExtParam {
        kind: &'static str,
        which: &'static str,
    },
    #[error("{kind}: text is not valid UTF-8")]
    BadText { kind: &'static str },
}

impl SwarmCommand {
    pub fn kind(&self) -> Result<SwarmCommandKind, SwarmCommandError> {
        SwarmCommandKind::try_from(self.kind).map_err(|_| SwarmCommandError::UnknownKind(self.kind))
    }

    pub fn has(&self, flag: u8) -> bool {
        self.flags & flag != 0
    }

    /// Site-frame position in `f[0..3]`.
    pub fn position(&self) -> [f32; 3] {
        [self.f[0], self.f[1], self.f[2]]
    }

    /// RGB in `f[4..7]` (from `EXT_PARAM_1`).
    pub fn rgb1(&self) -> [f32; 3] {
        [self.f[4], self.f[5], self.f[6]]
    }

    /// RGB in `f[8..11]` (from `EXT_PARAM_2`).
    pub fn rgb2(&self) -> [f32; 3] {
        [self.f[8], self.f[9], self.f[10]]
    }

    /// Refuses NaN/∞, out-of-range values and missing parameter records, by kind.
    /// The gateway checks before publishing; the queue checks again on receipt.
    pub fn validate(&self) -> Result<(), SwarmCommandError> {
        use SwarmCommandKind as K;
        let kind = self.kind()?;
        let k = kind.as_str();
        let check = |name: &'static str, v: f32, min: f32, max: f32| {
            if v.is_finite() && (min..=max).contains(&v) {
                Ok(())
            } else {
                Err(SwarmCommandError::OutOfRange {
                    kind: k,
                    name,
                    value: v.into(),
                    min: min.into(),
                    max: max.into(),
                })
            }
        };
        let check_int = |name: &'static str, v: i32, min: i32, max: i32| {
            if (min..=max).contains(&v) {
                Ok(())
            } else {
                Err(SwarmCommandError::OutOfRange {
                    kind: k,
                    name,
                    value: v.into(),
                    min: min.into(),
                    max: max.into(),
                })
            }
        };
        let need = |flag: u8, which: &'static str| {
            if self.has(flag) {
                Ok(())
            } else {
                Err(SwarmCommandError::MissingExtParam { kind: k, which })
            }
        };
        let site = |base: usize| -> Result<(), SwarmCommandError> {
            for (i, name) in ["x", "y", "z"].into_iter().enumerate() {
                check(name, self.f[base + i], -SWARM_MAX_SITE_M, SWARM_MAX_SITE_M)?;
            }
            Ok(())
        };
        let rgb = |base: usize| -> Result<(), SwarmCommandError> {
            for (i, name) in ["r", "g", "b"].into_iter().enumerate() {
                check(name, self.f[base + i], 0.0, 1.0)?;
            }
            Ok(())
        };
        let flag01 = |name: &'static str, v: f32| check(name, v, 0.0, 1.0);
        match kind {
            K::ExtWaypoint | K::ExtWaypointFollow | K::SetManualTarget => {
                site(0)?;
                check("speed", self.f[3], 0.0, SWARM_MAX_SPEED_MPS)?;
                check_int("yaw_cdeg", self.int1, -36_000, 36_000)?;
            }
            K::ExtWaypointFollowColor => {
                site(0)?;
                check("speed", self.f[3], 0.0, SWARM_MAX_SPEED_MPS)?;
                check_int("yaw_cdeg", self.int1, -36_000, 36_000)?;
                need(swarm_flags::HAS_EXT1, "EXT_PARAM_1")?;
                rgb(4)?;
            }
            K::ExtPause => check("seconds", self.f[0], 0.0, SWARM_MAX_DURATION_S)?,
            K::ExtColor => {
                need(swarm_flags::HAS_EXT1, "EXT_PARAM_1")?;
                rgb(4)?;
                check("seconds", self.f[0], 0.0, SWARM_MAX_DURATION_S)?;
            }
            K::ExtColorGradient => {
                need(swarm_flags::HAS_EXT1, "EXT_PARAM_1")?;
                need(swarm_flags::HAS_EXT2, "EXT_PARAM_2")?;
                rgb(4)?;
                rgb(8)?;
                check("seconds", self.f[0], 0.0, SWARM_MAX_DURATION_S)?;
            }
            K::ExtPlaybackAnim => {
                check_int("first_frame", self.int1, 0, i32::MAX)?;
                check_int("last_frame", self.int2, -1, i32::MAX)?;
                flag01("loop", self.f[0])?;
                check("speed", self.f[1], 0.01, 100.0)?;
                flag01("use_choreography", self.f[2])?;
                flag01("use_color", self.f[3])?;
            }
            K::ExtAnimAdjPlaybackSpeed | K::SetAnimPlaybackSpeed => {
                check("speed", self.f[0], 0.01, 100.0)?
            }
            K::SetAnimPlaybackTime => check("seconds", self.f[0], 0.0, 86_400.0)?,
            K::SetAnimColorIntensity => flag01("intensity", self.f[0])?,
            K::ExtSetActive | K::SetActive | K::MotorsCmd | K::EnableSafetyPilot => {
                check_int("value", self.int1, 0, 1)?
            }
            K::ExtSetHomePositionCoordinate => {
                site(0)?;
                check("yaw", self.f[3], -360.0, 360.0)?;
            }
            K::ExtSetBoundingBox | K::SetGeofence | K::ReconfigureGeofence => {
                need(swarm_flags::HAS_EXT1, "EXT_PARAM_1")?;
                site(0)?;
                site(4)?;
                for (i, name) in ["x", "y", "z"].into_iter().enumerate() {
                    if self.f[4 + i] > self.f[i] {
                        return Err(SwarmCommandError::OutOfRange {
                            kind: k,
                            name,
                            value: self.f[4 + i].into(),
                            min: f64::from(-SWARM_MAX_SITE_M),
                            max: self.f[i].into(),
                        });
                    }
                }
            }
            K::ExtText => {
                if self.text.try_as_str().is_none() {
                    return Err(SwarmCommandError::BadText { kind: k });
                }
            }
            K::ExtVehicleCmd => {
                if !matches!(self.int1, 1 | 2 | 4) {
                    return Err(SwarmCommandError::OutOfRange {
                        kind: k,
                        name: "vehicle_cmd",
                        value: self.int1.into(),
                        min: 1.0,
                        max: 4.0,
                    });
                }
                check("rotation", self.f[0], -3_600.0, 3_600.0)?;
            }
            K::ExtResetTrackingToFrame => check_int("frame", self.int1, 0, i32::MAX)?,
            K::SetCalibrationOffset | K::SetGeofencePosition => site(0)?,
            K::SetClockTimeout => check_int("timeout_ms", self.int1, 0, 3_600_000)?,
            K::CtrlMode
            | K::ColorMode
            | K::ManualColorMode
            | K::SetGroup
            | K::EmergencyMode
            | K::WakeUp
            | K::ResetHomePosition
            | K::ResetHomePositionToAnim
            | K::ResetAnimPosition
            | K::ResetAnimPositionToDrone
            | K::ResetTrackingToSetup
            | K::ResetHomeToSetup
            | K::ExtGoExternal
            | K::ExtGoHome
            | K::ExtGoHomeAtPosition
            | K::ExtAnimCancelLoop
            | K::ExtHalt
            | K::ExtCheckAllIdle
            | K::ExtHaltAndSaveCurCmd
            | K::ExtPushSavedCmd
            | K::ExtVideo
            | K::ExtVideoCmd
            | K::ExtTimecode
            | K::ExtTimecodeActive => {}
        }
        Ok(())
    }
}

/// The queue's answer about one command and one drone.
///
/// Topic: [`crate::topics::swarm_reply`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.SwarmReply.v1")]
#[repr(C)]
pub struct SwarmReply {
    pub header: SampleHeader,
    pub request_id: u32,
    /// The client of the command (from [`SwarmCommand::client`]).
    pub client: u16,
    pub drone: u16,
    /// [`SwarmCommandKind`] answered (raw: may be an unknown value that was refused).
    pub kind: u8,
    /// [`SwarmResult`] as stored on the wire.
    pub result: u8,
    pub reserved: [u8; 2],
    /// `IdleState`: 1 idle, 0 busy.
    pub value: i32,
    /// Why, for `Refused` and `Timeout`.
    pub reason: FixedStr<48>,
}
crate::assert_layout!(SwarmReply, size = 24 + 16 + 48, align = 8);

impl SwarmReply {
    pub fn result(&self) -> Result<SwarmResult, crate::UnknownValue> {
        SwarmResult::try_from(self.result)
    }
}

/// Flag bits of [`SwarmDrone::flags`] (the low two bits are GroundControl's pose flags).
pub mod drone_flags {
    /// Ready for commands: no current command and an empty queue.
    pub const IDLE: u32 = 0x01;
    /// Enabled (`SET_ACTIVE`).
    pub const ACTIVE: u32 = 0x02;
    /// Vehicle state is fresh (position received within the last second).
    pub const POSE_VALID: u32 = 0x100;
    /// A command is saved by `HALT_AND_SAVE_CUR_CMD`.
    pub const HAS_SAVED: u32 = 0x200;
    /// In emergency mode (braking with safety authority).
    pub const EMERGENCY: u32 = 0x400;
    /// The autopilot link of this drone is down.
    pub const LINK_DOWN: u32 = 0x800;
}

/// One drone in a [`SwarmState`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[repr(C)]
pub struct SwarmDrone {
    /// GroundControl drone id.
    pub drone: u16,
    /// MAVLink system id of the vehicle.
    pub vehicle_id: u8,
    /// [`DroneState`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::DroneState>")
    )]
    pub drone_state: u8,
    /// See [`drone_flags`].
    pub flags: u32,
    /// [`SwarmCommandKind`] of the current command, 0 if none.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::SwarmCommandKind>")
    )]
    pub current: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: u8,
    /// Commands waiting behind the current one.
    pub queue_depth: u16,
    /// Animation frame being played (0 if none).
    pub anim_frame: u32,
    /// Tracked position, site frame, metres.
    pub tracking: [f32; 3],
    /// Tracked yaw, CCW degrees from x (east).
    pub tracking_yaw_deg: f32,
    /// Attitude quaternion x, y, z, w in the site frame (x east, y north, z up).
    pub quaternion: [f32; 4],
    /// Target of the current command (the tracked pose when there is none).
    pub target: [f32; 3],
    pub target_yaw_deg: f32,
    /// LED colour 0..1.
    pub color: [f32; 3],
    /// Rotation of a rotating base relative to the body (`VEHICLECMD`), degrees.
    pub relative_rotation_deg: f32,
}
crate::assert_layout!(SwarmDrone, size = 80, align = 4);

/// Every drone the queue serves, at the queue's tick rate.
///
/// Topic: [`crate::topics::swarm_state`] (latest value).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.SwarmState.v1")]
#[repr(C)]
pub struct SwarmState {
    pub header: SampleHeader,
    /// Drones in `drones` (the first `count` entries).
    pub count: u16,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: [u8; 6],
    /// Seconds since the swarm-queue started (the broadcast's timestamp).
    pub time_s: f64,
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::big_array"),
        schemars(with = "crate::json::BigArray<SwarmDrone, SWARM_MAX_DRONES>")
    )]
    pub drones: [SwarmDrone; SWARM_MAX_DRONES],
}
crate::assert_layout!(
    SwarmState,
    size = 24 + 16 + 80 * SWARM_MAX_DRONES,
    align = 8
);

impl Default for SwarmState {
    fn default() -> Self {
        SwarmState {
            header: SampleHeader::default(),
            count: 0,
            reserved: [0; 6],
            time_s: 0.0,
            drones: [SwarmDrone::default(); SWARM_MAX_DRONES],
        }
    }
}

impl SwarmState {
    /// The valid entries (count clamped: the sample came from another process).
    pub fn drones(&self) -> &[SwarmDrone] {
        &self.drones[..usize::from(self.count).min(SWARM_MAX_DRONES)]
    }
}

/// A reader's word that it needs [`SwarmState`] at the queue's tick rate: the pose
/// broadcast says so while somebody may listen to the poses (a destination that
/// does not refuse), and renews it every second. The queue keeps each
/// publisher's (header `service`, `instance`) newest word for
/// [`SWARM_WATCH_LEASE_NS`]; while no word says `watching` and it has nothing to
/// fly, it ticks once a second. A word that starts watching makes it tick at once,
/// so a state published after the word comes within a tick's work.
///
/// Topic: [`crate::topics::swarm_watch`] (latest value per publisher).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.SwarmWatch.v1")]
#[repr(C)]
pub struct SwarmWatch {
    pub header: SampleHeader,
    /// 1: the state is read at the queue's tick rate; 0: not any more.
    pub watching: u8,
    pub reserved: [u8; 7],
}
crate::assert_layout!(SwarmWatch, size = 24 + 8, align = 8);

/// How long a [`SwarmWatch`] that says `watching` holds without being renewed
/// (its publisher renews it every second; one that died stops counting after this).
pub const SWARM_WATCH_LEASE_NS: u64 = 3_000_000_000;

crate::impl_sample!(SwarmCommand, SwarmReply, SwarmState, SwarmWatch);

#[cfg(test)]
mod tests {
    use super::*;

    fn cmd(kind: SwarmCommandKind) -> SwarmCommand {
        SwarmCommand {
            kind: kind.to_wire(),
            ..Default::default()
        }
    }

    #[test]
    fn ext_commands_are_the_unprivileged_ones() {
        assert!(SwarmCommandKind::ExtWaypoint.is_ext());
        assert!(SwarmCommandKind::ExtWaypointFollowColor.is_ext());
        assert!(!SwarmCommandKind::EmergencyMode.is_ext());
        assert!(!SwarmCommandKind::ResetTrackingToSetup.is_ext());
        assert_eq!(SwarmCommandKind::ExtVehicleCmd.to_wire(), 0xB7);
    }

    #[test]
    fn waypoints_are_range_checked() {
        let mut c = cmd(SwarmCommandKind::ExtWaypoint);
        c.f[..4].copy_from_slice(&[1.0, 2.0, 3.0, 1.5]);
        assert!(c.validate().is_ok());
        c.f[1] = f32::NAN;
        assert!(c.validate().is_err());
        c.f[1] = 2.0;
        c.f[3] = 100.0;
        assert!(c.validate().is_err());
        c.kind = 0xEE;
        assert_eq!(c.validate(), Err(SwarmCommandError::UnknownKind(0xEE)));
    }

    #[test]
    fn colour_needs_its_parameter_record() {
        let mut c = cmd(SwarmCommandKind::ExtColor);
        c.f[4..7].copy_from_slice(&[1.0, 0.5, 0.0]);
        assert!(matches!(
            c.validate(),
            Err(SwarmCommandError::MissingExtParam { .. })
        ));
        c.flags |= swarm_flags::HAS_EXT1;
        assert!(c.validate().is_ok());
        c.f[5] = 1.5;
        assert!(c.validate().is_err());
    }

    #[test]
    fn bounding_box_min_must_not_exceed_max() {
        let mut c = cmd(SwarmCommandKind::ExtSetBoundingBox);
        c.flags = swarm_flags::HAS_EXT1;
        c.f[..3].copy_from_slice(&[10.0, 10.0, 5.0]);
        c.f[4..7].copy_from_slice(&[-10.0, -10.0, 0.0]);
        assert!(c.validate().is_ok());
        c.f[6] = 6.0;
        assert!(c.validate().is_err());
    }

    #[test]
    fn state_count_is_clamped() {
        let mut s = SwarmState {
            count: 3,
            ..Default::default()
        };
        assert_eq!(s.drones().len(), 3);
        s.count = u16::MAX;
        assert_eq!(s.drones().len(), SWARM_MAX_DRONES);
    }
}
