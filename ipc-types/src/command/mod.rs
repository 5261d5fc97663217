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

mod ack;
mod kind;
mod typed;
mod wire;

pub use ack::{AckResult, CommandAck, RefusalReason};
pub use kind::{AuthorityDomain, CameraModeKind, CommandKind, CommandSource, FocusMode, ZoomMode};
pub use typed::{Command, CommandError};
pub use wire::VehicleCommand;

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
