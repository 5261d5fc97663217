//! MAVLink framing over byte buffers, as pure functions: MAVLink 1 and 2 in,
//! MAVLink 2 out.
//!
//! The decoder takes bytes in whatever chunks the socket delivers, yields one
//! frame at a time, and resynchronises after garbage: a candidate that fails
//! (unknown message, bad flags, bad checksum) is dropped one byte at a time so a
//! real frame hidden inside it is still found. Candidates with an unknown
//! message id are rejected as soon as the header is in, so a stray marker in
//! garbage rarely holds back the frames behind it. Nothing is allocated from a
//! declared length: a frame is at most 280 bytes.
//!
//! The dialect decodes a COMMAND_LONG/COMMAND_INT only if it knows the command
//! number; for the rest the decoder still extracts the command so the handler
//! can answer MAV_RESULT_UNSUPPORTED, which needs a hand-encoded COMMAND_ACK
//! because the typed one cannot carry an unknown command either.
//!
//! The dialect is built without MAVLink 2 extension fields, so
//! GIMBAL_DEVICE_ATTITUDE_STATUS, whose `delta_yaw`, `delta_yaw_velocity` and
//! `gimbal_device_id` are extensions, is encoded here by hand
//! ([`encode_gimbal_device_attitude_status`]), as is SERVO_OUTPUT_RAW with its
//! extensions `servo9_raw..servo16_raw` ([`encode_servo_output_raw`]); receivers
//! without the extensions read the base fields and ignore the rest, as MAVLink 2
//! requires.

use mavlink::dialects::ardupilotmega::{
    MavMessage, MavResult, COMMAND_ACK_DATA, COMMAND_INT_DATA, COMMAND_LONG_DATA,
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, SERVO_OUTPUT_RAW_DATA,
};
use mavlink::error::ParserError;
use mavlink::{
    calculate_crc, MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message, MessageData,
};

const STX_V1: u8 = 0xFE;
const STX_V2: u8 = 0xFD;
/// STX + len + seq + sys + comp + msgid.
const HEADER_V1: usize = 6;
/// STX + len + incompat + compat + seq + sys + comp + msgid(3).
const HEADER_V2: usize = 10;
const CHECKSUM_LEN: usize = 2;
const SIGNATURE_LEN: usize = 13;
const IFLAG_SIGNED: u8 = 0x01;

/// Once this much undecoded input is buffered the caller is not draining the
/// decoder; `push` discards the oldest bytes (a frame is ≤ 280 bytes).
pub const MAX_BUFFERED: usize = 64 * 1024;

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

/// Input the decoder had to throw away.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadFrame {
    /// Bytes before the next frame marker.
    #[error("{len} bytes of garbage before a frame marker")]
    Garbage {
        /// Discarded bytes.
        len: usize,
    },
    /// A MAVLink 2 header with incompatibility flags we cannot handle.
    #[error("unsupported MAVLink 2 incompatibility flags {flags:#04x}")]
    IncompatFlags {
        /// The flags byte.
        flags: u8,
    },
    /// A message id outside the ardupilotmega dialect.
    #[error("unknown message id {id}")]
    UnknownMessage {
        /// Message id.
        id: u32,
    },
    /// The checksum did not match.
    #[error("checksum mismatch on message id {id}")]
    Checksum {
        /// Message id.
        id: u32,
    },
    /// A well-framed message whose payload does not decode (e.g. a bad enum value).
    #[error("message id {id} does not decode: {reason}")]
    Payload {
        /// Message id.
        id: u32,
        /// Parser message.
        reason: String,
    },
}

/// Incremental MAVLink 1/2 frame decoder.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    /// Bytes before `start` are consumed; compacted on the next `push`.
    start: usize,
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Append received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.drain(..self.start);
        self.start = 0;
        self.buf.extend_from_slice(bytes);
        if self.buf.len() > MAX_BUFFERED {
            let excess = self.buf.len() - MAX_BUFFERED;
            self.buf.drain(..excess);
        }
    }

    /// Bytes buffered but not yet decoded.
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.start
    }

    /// The next frame, an error for input that had to be discarded, or `None`
    /// when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Result<Inbound, BadFrame>> {
        let data = &self.buf[self.start..];
        if data.is_empty() {
            return None;
        }
        match data.iter().position(|&b| b == STX_V1 || b == STX_V2) {
            Some(0) => {}
            Some(len) => {
                self.start += len;
                return Some(Err(BadFrame::Garbage { len }));
            }
            None => {
                let len = data.len();
                self.start += len;
                return Some(Err(BadFrame::Garbage { len }));
            }
        }
        let (version, header_len) = if data[0] == STX_V2 {
            (MavlinkVersion::V2, HEADER_V2)
        } else {
            (MavlinkVersion::V1, HEADER_V1)
        };
        if data.len() < header_len {
            return None;
        }
        let payload_len = usize::from(data[1]);
        let (msg_id, signature_len) = match version {
            MavlinkVersion::V1 => (u32::from(data[5]), 0),
            MavlinkVersion::V2 => {
                let flags = data[2];
                if flags & !IFLAG_SIGNED != 0 {
                    return Some(Err(self.reject(BadFrame::IncompatFlags { flags })));
                }
                let id = u32::from_le_bytes([data[7], data[8], data[9], 0]);
                let sig = if flags & IFLAG_SIGNED != 0 {
                    SIGNATURE_LEN
                } else {
                    0
                };
                (id, sig)
            }
        };
        if MavMessage::default_message_from_id(msg_id).is_none() {
            return Some(Err(self.reject(BadFrame::UnknownMessage { id: msg_id })));
        }
        let crc_at = header_len + payload_len;
        let total = crc_at + CHECKSUM_LEN + signature_len;
        if data.len() < total {
            return None;
        }
        let expected = u16::from_le_bytes([data[crc_at], data[crc_at + 1]]);
        if calculate_crc(&data[1..crc_at], MavMessage::extra_crc(msg_id)) != expected {
            return Some(Err(self.reject(BadFrame::Checksum { id: msg_id })));
        }

        let (seq, sys, comp) = match version {
            MavlinkVersion::V1 => (data[2], data[3], data[4]),
            MavlinkVersion::V2 => (data[4], data[5], data[6]),
        };
        let header = MavHeader {
            system_id: u32::from(sys),
            component_id: comp,
            sequence: seq,
        };
        let payload = &data[header_len..crc_at];
        let result = match MavMessage::parse(version, msg_id, payload) {
            Ok(msg) => Ok(Inbound::Message {
                header,
                version,
                msg,
            }),
            Err(ParserError::InvalidEnum {
                enum_type: "MavCmd",
                ..
            }) if is_command(msg_id) => Ok(unknown_command(header, payload)),
            Err(e) => Err(BadFrame::Payload {
                id: msg_id,
                reason: e.to_string(),
            }),
        };
        // The checksum matched, so the whole frame is consumed either way.
        self.start += total;
        Some(result)
    }

    /// Drop the candidate's marker byte and resync from the next byte.
    fn reject(&mut self, why: BadFrame) -> BadFrame {
        self.start += 1;
        why
    }
}

fn is_command(msg_id: u32) -> bool {
    msg_id == COMMAND_LONG_DATA::ID || msg_id == COMMAND_INT_DATA::ID
}

/// COMMAND_LONG and COMMAND_INT both carry `command: u16` at payload offset 28,
/// then target system and component (MAVLink wire order sorts fields by size).
fn unknown_command(header: MavHeader, payload: &[u8]) -> Inbound {
    // MAVLink 2 truncates trailing zero bytes; restore them.
    let byte = |i: usize| payload.get(i).copied().unwrap_or(0);
    Inbound::UnknownCommand {
        header,
        command: u16::from_le_bytes([byte(28), byte(29)]),
        target_system: byte(30),
        target_component: byte(31),
    }
}

/// Append `msg` as a MAVLink 2 frame.
pub fn encode(header: MavHeader, msg: &MavMessage, out: &mut Vec<u8>) {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(header, msg);
    out.extend_from_slice(raw.raw_bytes());
}

/// Append a MAVLink 2 COMMAND_ACK for a raw command number (one the dialect's
/// `MavCmd` cannot represent).
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

/// GIMBAL_DEVICE_ATTITUDE_STATUS with its MAVLink 2 extension fields.
#[derive(Debug, Clone, PartialEq)]
pub struct GimbalDeviceAttitudeStatus {
    /// The base fields (all the dialect knows).
    pub base: GIMBAL_DEVICE_ATTITUDE_STATUS_DATA,
    /// Extension: yaw relating the vehicle and earth frames (the vehicle's
    /// heading), radians; NaN if unknown.
    pub delta_yaw: f32,
    /// Extension: the vehicle's yaw rate, rad/s; NaN if unknown.
    pub delta_yaw_velocity: f32,
    /// Extension: gimbal device id (1..=6) when the device shares the
    /// manager's component id, as an autopilot-driven mount does; 0 otherwise.
    pub gimbal_device_id: u8,
}

/// Bytes of GIMBAL_DEVICE_ATTITUDE_STATUS's extension fields on the wire.
pub const GIMBAL_STATUS_EXTENSION_LEN: usize = 9;

/// Append a MAVLink 2 GIMBAL_DEVICE_ATTITUDE_STATUS frame including its
/// extension fields (after the base payload, in declaration order).
pub fn encode_gimbal_device_attitude_status(
    header: MavHeader,
    status: &GimbalDeviceAttitudeStatus,
    out: &mut Vec<u8>,
) {
    type D = GIMBAL_DEVICE_ATTITUDE_STATUS_DATA;
    let mut payload = [0u8; D::ENCODED_LEN + GIMBAL_STATUS_EXTENSION_LEN];
    // `ser` may report a zero-truncated length; the zeros are in `payload` anyway.
    status
        .base
        .ser(MavlinkVersion::V2, &mut payload[..D::ENCODED_LEN]);
    let ext = &mut payload[D::ENCODED_LEN..];
    ext[0..4].copy_from_slice(&status.delta_yaw.to_le_bytes());
    ext[4..8].copy_from_slice(&status.delta_yaw_velocity.to_le_bytes());
    ext[8] = status.gimbal_device_id;
    frame_v2(header, D::ID, D::EXTRA_CRC, &payload, out);
}

/// SERVO_OUTPUT_RAW with its MAVLink 2 extension fields.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoOutputRaw {
    /// The base fields: time, servo outputs 1..=8, port.
    pub base: SERVO_OUTPUT_RAW_DATA,
    /// Extensions: servo outputs 9..=16, µs (0 = unused).
    pub servo9_16: [u16; 8],
}

/// Bytes of SERVO_OUTPUT_RAW's extension fields on the wire.
pub const SERVO_OUTPUT_EXTENSION_LEN: usize = 16;

/// Append a MAVLink 2 SERVO_OUTPUT_RAW frame including `servo9_raw..servo16_raw`
/// (after the base payload, in declaration order).
pub fn encode_servo_output_raw(header: MavHeader, servos: &ServoOutputRaw, out: &mut Vec<u8>) {
    type D = SERVO_OUTPUT_RAW_DATA;
    let mut payload = [0u8; D::ENCODED_LEN + SERVO_OUTPUT_EXTENSION_LEN];
    servos
        .base
        .ser(MavlinkVersion::V2, &mut payload[..D::ENCODED_LEN]);
    for (chunk, pwm) in payload[D::ENCODED_LEN..]
        .chunks_exact_mut(2)
        .zip(servos.servo9_16)
    {
        chunk.copy_from_slice(&pwm.to_le_bytes());
    }
    frame_v2(header, D::ID, D::EXTRA_CRC, &payload, out);
}

/// Append a MAVLink 2 frame around `payload`, with trailing zero bytes
/// truncated (at least one byte is kept), as MAVLink 2 senders do.
fn frame_v2(header: MavHeader, msg_id: u32, extra_crc: u8, payload: &[u8], out: &mut Vec<u8>) {
    let len = payload
        .iter()
        .rposition(|&b| b != 0)
        .map_or(1, |last| last + 1)
        .min(payload.len());
    let id = msg_id.to_le_bytes();
    let start = out.len();
    out.extend_from_slice(&[
        STX_V2,
        len as u8,
        0,
        0,
        header.sequence,
        header.system_id as u8,
        header.component_id,
        id[0],
        id[1],
        id[2],
    ]);
    out.extend_from_slice(&payload[..len]);
    let crc = calculate_crc(&out[start + 1..], extra_crc);
    out.extend_from_slice(&crc.to_le_bytes());
}

#[cfg(test)]
mod tests;
