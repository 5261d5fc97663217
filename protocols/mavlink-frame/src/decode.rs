//! Frames to dialect messages and back, for an endpoint that answers MAVLink (a
//! simulated autopilot, a test ground station): MAVLink 1 and 2 in, MAVLink 2 out.
//!
//! The dialect decodes a COMMAND_LONG/COMMAND_INT only if it knows the command
//! number; for the rest [`FrameDecoder`] still extracts the command so the
//! receiver can answer MAV_RESULT_UNSUPPORTED, which needs
//! [`encode_command_ack_raw`] because the typed COMMAND_ACK cannot carry an
//! unknown command either.

use mavlink::dialects::ardupilotmega::{MavMessage, MavResult, COMMAND_ACK_DATA};
use mavlink::error::ParserError;
use mavlink::{calculate_crc, MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, MessageData};

use crate::parser::{BadFrame, FrameParser};
use crate::raw::{message_info, RawFrame, COMMAND_LONG_ID, STX_V2};

/// A decoded inbound frame.
#[derive(Debug, Clone, PartialEq)]
// Nearly every value is the large variant (a MavMessage, ~280 bytes); boxing
// it would add an allocation per frame and save nothing.
#[allow(clippy::large_enum_variant)]
pub enum Inbound {
    /// A message of the ardupilotmega dialect.
    Message {
        /// Sender and sequence.
        header: MavHeader,
        /// MAVLink 1 or 2 framing.
        version: MavlinkVersion,
        /// The message.
        msg: MavMessage,
    },
    /// A COMMAND_LONG/COMMAND_INT whose command number the dialect lacks.
    UnknownCommand {
        /// Sender and sequence.
        header: MavHeader,
        /// The raw MAV_CMD number.
        command: u16,
        /// Addressed system.
        target_system: u8,
        /// Addressed component.
        target_component: u8,
    },
}

impl Inbound {
    /// Decodes one checked frame; a payload that does not decode is
    /// [`BadFrame::Payload`].
    pub fn from_frame(frame: &RawFrame) -> Result<Inbound, BadFrame> {
        let header = frame.header();
        match frame.decode() {
            Ok(msg) => Ok(Inbound::Message {
                header,
                version: frame.version(),
                msg,
            }),
            Err(ParserError::InvalidEnum {
                enum_type: "MavCmd",
                ..
            }) if frame.command().is_some() => Ok(unknown_command(header, frame)),
            Err(e) => Err(BadFrame::Payload {
                id: frame.message_id(),
                reason: e.to_string(),
            }),
        }
    }
}

/// COMMAND_LONG and COMMAND_INT carry their targets at the same offsets.
fn unknown_command(header: MavHeader, frame: &RawFrame) -> Inbound {
    let info = message_info(COMMAND_LONG_ID);
    let byte = |offset: Option<usize>| offset.map_or(0, |o| frame.payload_byte(o));
    Inbound::UnknownCommand {
        header,
        command: frame.command().unwrap_or(0),
        target_system: byte(info.and_then(|i| i.target_system)),
        target_component: byte(info.and_then(|i| i.target_component)),
    }
}

/// Incremental MAVLink 1/2 decoder for an endpoint: a [`FrameParser`] that
/// rejects unknown message ids, plus payload decoding.
#[derive(Debug)]
pub struct FrameDecoder {
    parser: FrameParser,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        FrameDecoder {
            parser: FrameParser::dialect_only(),
        }
    }

    /// Appends received bytes (see [`FrameParser::push`]).
    pub fn push(&mut self, bytes: &[u8]) {
        self.parser.push(bytes);
    }

    /// Bytes buffered but not yet decoded.
    pub fn buffered(&self) -> usize {
        self.parser.pending()
    }

    /// Drops a trailing partial frame and returns how many bytes it had.
    pub fn end_datagram(&mut self) -> usize {
        self.parser.end_datagram()
    }

    /// The next frame, an error for input that had to be discarded, or `None`
    /// when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Result<Inbound, BadFrame>> {
        Some(
            self.parser
                .next_checked()?
                .and_then(|frame| Inbound::from_frame(&frame)),
        )
    }
}

/// Appends `msg` as a MAVLink 2 frame.
pub fn encode(header: MavHeader, msg: &MavMessage, out: &mut Vec<u8>) {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(header, msg);
    out.extend_from_slice(raw.raw_bytes());
}

/// Appends a MAVLink 2 COMMAND_ACK for a raw command number (one the dialect's
/// `MavCmd` cannot represent), addressed to everyone.
pub fn encode_command_ack_raw(
    header: MavHeader,
    command: u16,
    result: MavResult,
    out: &mut Vec<u8>,
) {
    let [lo, hi] = command.to_le_bytes();
    let id = COMMAND_ACK_DATA::ID.to_le_bytes();
    let start = out.len();
    out.extend_from_slice(&[
        STX_V2,
        3, // payload: command u16, result u8
        0,
        0,
        header.sequence,
        header.system_id as u8,
        header.component_id,
        id[0],
        id[1],
        id[2],
        lo,
        hi,
        result as u8,
    ]);
    let crc = calculate_crc(&out[start + 1..], COMMAND_ACK_DATA::EXTRA_CRC);
    out.extend_from_slice(&crc.to_le_bytes());
}

#[cfg(test)]
mod tests;
