//! [`CommandAck`], the answer to each command, with its result and refusal reason.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

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

/// The answer to one [`VehicleCommand`](super::VehicleCommand), published by `autopilot-link`.
///
/// Topic: [`crate::topics::vehicle_command_ack`]. Matched to its command by
/// `(source, command_id)`.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.CommandAck.v2")]
#[repr(C)]
pub struct CommandAck {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// [`CommandSource`](super::CommandSource) of the command answered.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandSource>")
    )]
    pub source: u8,
    /// [`CommandKind`](super::CommandKind) of the command answered (raw: may be an unknown
    /// value that was refused).
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::CommandKind>")
    )]
    pub kind: u8,
    /// [`AckResult`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::AckResult>")
    )]
    pub result: u8,
    /// `command_id` of the command answered.
    pub command_id: u32,
    /// [`RefusalReason`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::RefusalReason>")
    )]
    pub reason: u16,
    /// The MAVLink `MAV_RESULT` when the autopilot answered, 255 otherwise.
    pub mav_result: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
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

crate::impl_sample!(CommandAck);
