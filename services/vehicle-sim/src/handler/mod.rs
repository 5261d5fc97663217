//! MAVLink message in → vehicle change + replies out, the way ArduCopter
//! answers. Pure: no I/O, no clock; the engine applies the stream requests to
//! the sender's link and sends the replies back on it.

// REQUEST_DATA_STREAM is deprecated in MAVLink but ArduPilot still honours it.
#![allow(deprecated)]

mod actuators;
mod camera;
mod command;
mod gimbal;
mod gopro;
mod setpoint;

use mavlink::dialects::ardupilotmega::{
    GoproRequestStatus, MavDataStream, MavMessage, MavModeFlag, MavResult,
};
use mavlink::Message;
use tracing::{debug, info};

use crate::config::{COMPONENT_ID, GIMBAL_COMPONENT_ID};
use crate::model::Vehicle;
use crate::streams::IntervalRequest;
use mavlink_frame::Inbound;

pub use command::Cmd;

/// SET_MODE is acknowledged with its message id in the command field, as
/// ArduPilot does (`MAVLINK_MSG_ID_SET_MODE`).
const SET_MODE_ACK_COMMAND: u16 = 11;

/// A reply for the link the request came from.
#[derive(Debug, Clone, PartialEq)]
// Nearly every value is the large variant (a MavMessage, ~280 bytes); boxing
// it would add an allocation per frame and save nothing.
#[allow(clippy::large_enum_variant)]
pub enum Outgoing {
    /// A dialect message from the autopilot (component 1).
    Message(MavMessage),
    /// A dialect message from another component of the vehicle, e.g. the
    /// gimbal's GoPro bridge ([`GIMBAL_COMPONENT_ID`]).
    FromComponent {
        /// Sending component id.
        component: u8,
        /// The message.
        msg: MavMessage,
    },
    /// A COMMAND_ACK for a command number the dialect cannot represent.
    CommandAckRaw {
        /// The raw command number.
        command: u16,
        /// The result.
        result: MavResult,
    },
}

impl Outgoing {
    /// The component the frame is sent from.
    pub fn component(&self) -> u8 {
        match self {
            Outgoing::FromComponent { component, .. } => *component,
            _ => COMPONENT_ID,
        }
    }

    /// A message from the gimbal (the GoPro bridge).
    pub fn from_gimbal(msg: MavMessage) -> Self {
        Outgoing::FromComponent {
            component: GIMBAL_COMPONENT_ID,
            msg,
        }
    }
}

/// Which GoPro request was answered, for statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoProRequest {
    /// GOPRO_SET_REQUEST.
    Set,
    /// GOPRO_GET_REQUEST.
    Get,
}

/// A change to the sender link's telemetry schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StreamRequest {
    /// MAV_CMD_SET_MESSAGE_INTERVAL for one message id.
    Interval {
        /// Message id (one the simulator produces).
        id: u32,
        /// The new interval.
        request: IntervalRequest,
    },
    /// REQUEST_DATA_STREAM for an ArduCopter stream group.
    DataStream {
        /// The group.
        stream: MavDataStream,
        /// Rate, Hz.
        rate_hz: u16,
        /// Start (true) or stop.
        start: bool,
    },
}

/// Everything a message caused, besides the change to the vehicle.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Response {
    /// Replies for the sender's link, in order.
    pub replies: Vec<Outgoing>,
    /// Schedule changes for the sender's link.
    pub streams: Vec<StreamRequest>,
    /// The COMMAND_ACK result, if one was sent (for statistics).
    pub ack: Option<MavResult>,
    /// The GoPro request answered and its status, if any (for statistics).
    pub gopro: Option<(GoProRequest, GoproRequestStatus)>,
}

impl Response {
    fn ack_raw(&mut self, command: u16, result: MavResult) {
        self.replies
            .push(Outgoing::CommandAckRaw { command, result });
        self.ack = Some(result);
    }
}

/// Answers MAVLink for one simulated vehicle.
#[derive(Debug, Clone)]
pub struct Handler {
    system_id: u8,
}

impl Handler {
    /// A handler for the vehicle with MAVLink system id `system_id`.
    pub fn new(system_id: u8) -> Self {
        Self { system_id }
    }

    /// Messages addressed elsewhere are ignored (ArduPilot would route them).
    fn for_us(&self, target_system: u8, target_component: Option<u8>) -> bool {
        (target_system == 0 || target_system == self.system_id)
            && target_component.is_none_or(|c| c == 0 || c == COMPONENT_ID)
    }

    /// GoPro requests are for the gimbal (component 154, or 0 = every
    /// component) of this system (or 0, broadcast).
    fn for_gimbal(&self, target_system: u8, target_component: u8) -> bool {
        (target_system == 0 || target_system == self.system_id)
            && (target_component == 0 || target_component == GIMBAL_COMPONENT_ID)
    }

    /// Handle one inbound frame.
    pub fn handle(&self, v: &mut Vehicle, inbound: &Inbound) -> Response {
        let mut resp = Response::default();
        match inbound {
            Inbound::UnknownCommand {
                header,
                command,
                target_system,
                target_component,
            } => {
                if self.for_us(*target_system, Some(*target_component)) {
                    info!(
                        command,
                        from_system = header.system_id,
                        "command not in the dialect; unsupported"
                    );
                    resp.ack_raw(*command, MavResult::MAV_RESULT_UNSUPPORTED);
                }
            }
            Inbound::Message { header, msg, .. } => {
                let from = header.system_id;
                self.handle_message(v, msg, from, &mut resp);
            }
        }
        resp
    }

    fn handle_message(&self, v: &mut Vehicle, msg: &MavMessage, from: u32, resp: &mut Response) {
        match msg {
            MavMessage::COMMAND_LONG(d) => {
                if self.for_us(d.target_system, Some(d.target_component)) {
                    command::execute(v, self.system_id, &Cmd::from_long(d), resp);
                }
            }
            MavMessage::COMMAND_INT(d) => {
                if self.for_us(d.target_system, Some(d.target_component)) {
                    command::execute(v, self.system_id, &Cmd::from_int(d), resp);
                }
            }
            MavMessage::SET_MODE(d) => {
                if self.for_us(d.target_system, None) {
                    let result = set_mode(v, d.base_mode, d.custom_mode);
                    info!(from, custom_mode = d.custom_mode, ?result, "SET_MODE");
                    resp.ack_raw(SET_MODE_ACK_COMMAND, result);
                }
            }
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => {
                if self.for_us(d.target_system, Some(d.target_component)) {
                    let t = setpoint::local_ned(v, d);
                    setpoint::apply(v, t, "SET_POSITION_TARGET_LOCAL_NED");
                }
            }
            MavMessage::SET_POSITION_TARGET_GLOBAL_INT(d) => {
                if self.for_us(d.target_system, Some(d.target_component)) {
                    let t = setpoint::global_int(v, d);
                    setpoint::apply(v, t, "SET_POSITION_TARGET_GLOBAL_INT");
                }
            }
            MavMessage::REQUEST_DATA_STREAM(d) => {
                if self.for_us(d.target_system, Some(d.target_component)) {
                    debug!(from, stream = ?d.req_stream_id, rate = d.req_message_rate,
                        start = d.start_stop, "REQUEST_DATA_STREAM");
                    resp.streams.push(StreamRequest::DataStream {
                        stream: d.req_stream_id,
                        rate_hz: d.req_message_rate,
                        start: d.start_stop != 0,
                    });
                }
            }
            MavMessage::GOPRO_SET_REQUEST(d) => {
                if self.for_gimbal(d.target_system, d.target_component) {
                    gopro::set_request(v, d, from, resp);
                }
            }
            MavMessage::GOPRO_GET_REQUEST(d) => {
                if self.for_gimbal(d.target_system, d.target_component) {
                    gopro::get_request(v, d, from, resp);
                }
            }
            // Ground stations' heartbeats and everything else need no answer.
            MavMessage::HEARTBEAT(_) => {}
            other => debug!(from, message = other.message_name(), "ignored"),
        }
    }
}

/// ArduPilot `_set_mode_common`: only custom modes are accepted.
fn set_mode(v: &mut Vehicle, base_mode: MavModeFlag, custom_mode: u32) -> MavResult {
    if !base_mode.contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) {
        return MavResult::MAV_RESULT_DENIED;
    }
    match v.set_mode_number(custom_mode) {
        Ok(()) => MavResult::MAV_RESULT_ACCEPTED,
        Err(_) => MavResult::MAV_RESULT_FAILED,
    }
}

#[cfg(test)]
mod tests;
