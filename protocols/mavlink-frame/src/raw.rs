//! One MAVLink frame exactly as it was on the wire, and what the dialect says
//! about its message id.
//!
//! [`RawFrame::target`] reads the target system/component of a frame at the byte
//! offsets of the dialect's message definition (learnt once from the `mavlink`
//! crate, see [`MessageInfo`]), so routing never needs to decode a payload and
//! works for payloads that hold enum values the dialect does not know.

use std::collections::HashMap;
use std::fmt;
use std::sync::LazyLock;

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message};

/// First byte of a MAVLink 2 frame.
pub const STX_V2: u8 = 0xFD;
/// First byte of a MAVLink 1 frame.
pub const STX_V1: u8 = 0xFE;
/// The largest MAVLink frame: 10 header + 255 payload + 2 checksum + 13 signature bytes.
pub const MAX_FRAME: usize = 280;
/// STX + len + incompat + compat + seq + sys + comp + msgid(3).
pub(crate) const V2_HEADER: usize = 10;
/// STX + len + seq + sys + comp + msgid.
pub(crate) const V1_HEADER: usize = 6;
pub(crate) const CHECKSUM_LEN: usize = 2;
/// Link id (1) + timestamp (6) + signature (6).
pub const SIGNATURE_LEN: usize = 13;
/// The only MAVLink 2 incompatibility flag: the frame is signed.
pub(crate) const IFLAG_SIGNED: u8 = 0x01;
/// `COMMAND_ACK`.
pub const COMMAND_ACK_ID: u32 = 77;
/// `COMMAND_LONG`.
pub const COMMAND_LONG_ID: u32 = 76;
/// `COMMAND_INT`.
pub const COMMAND_INT_ID: u32 = 75;
/// `COMMAND_LONG` and `COMMAND_INT` both carry the MAV_CMD as u16 at payload
/// offset 28 (MAVLink wire order sorts fields by size); the crate's typed messages
/// cannot hold a command number the dialect lacks, so it is read from the bytes.
const COMMAND_OFFSET: usize = 28;

/// What the framer and the router need to know about one message id of the dialect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageInfo {
    /// The CRC_EXTRA seed of the message's checksum.
    pub extra_crc: u8,
    /// Payload offset of `target_system`, if the message has one.
    pub target_system: Option<usize>,
    /// Payload offset of `target_component`, if the message has one.
    pub target_component: Option<usize>,
}

/// Every message id of the ardupilotmega dialect (all below 65536), built once.
///
/// Target offsets are found by serialising the message's default value twice, with
/// the target set to 0x00 and to 0xFF, and looking for the byte that differs: the
/// crate knows which fields are targets (extension fields included, e.g.
/// COMMAND_ACK's) but does not expose their offsets.
pub(crate) static MESSAGES: LazyLock<HashMap<u32, MessageInfo>> = LazyLock::new(|| {
    let offset_of = |a: &MavMessage, b: &MavMessage| -> Option<usize> {
        let (mut x, mut y) = ([0u8; 255], [0u8; 255]);
        a.ser(MavlinkVersion::V2, &mut x);
        b.ser(MavlinkVersion::V2, &mut y);
        x.iter().zip(y.iter()).position(|(p, q)| p != q)
    };
    let mut table = HashMap::new();
    for id in 0..=u32::from(u16::MAX) {
        let Some(msg) = MavMessage::default_message_from_id(id) else {
            continue;
        };
        let probe = |set: fn(&mut MavMessage) -> Option<&mut u8>| -> Option<usize> {
            let (mut lo, mut hi) = (msg.clone(), msg.clone());
            *set(&mut lo)? = 0x00;
            *set(&mut hi)? = 0xFF;
            offset_of(&lo, &hi)
        };
        let info = MessageInfo {
            extra_crc: MavMessage::extra_crc(id),
            target_system: probe(MavMessage::target_system_id_mut),
            target_component: probe(MavMessage::target_component_id_mut),
        };
        table.insert(id, info);
    }
    table
});

/// The dialect's definition of `message_id`, `None` for ids it does not know.
pub fn message_info(message_id: u32) -> Option<&'static MessageInfo> {
    MESSAGES.get(&message_id)
}

/// Whom a frame is addressed to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// No target fields (telemetry, unknown ids) or target system 0: everyone.
    Broadcast,
    /// Target system set, component 0 or absent: every component of that system.
    System(u8),
    /// Both set.
    Component(u8, u8),
}

/// One complete frame exactly as it was on the wire (never longer than [`MAX_FRAME`]).
#[derive(Clone, Copy)]
pub struct RawFrame {
    bytes: [u8; MAX_FRAME],
    len: u16,
}

impl fmt::Debug for RawFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RawFrame")
            .field("version", &self.version())
            .field("message_id", &self.message_id())
            .field("source", &(self.system_id(), self.component_id()))
            .field("len", &self.len)
            .finish()
    }
}

impl PartialEq for RawFrame {
    fn eq(&self, other: &Self) -> bool {
        self.as_bytes() == other.as_bytes()
    }
}

impl Eq for RawFrame {}

impl RawFrame {
    /// Wraps bytes already checked to be one whole frame of at most [`MAX_FRAME`]
    /// bytes (by the parser, or built by this crate).
    pub(crate) fn copy_from(frame: &[u8]) -> RawFrame {
        let frame = &frame[..frame.len().min(MAX_FRAME)];
        let mut bytes = [0u8; MAX_FRAME];
        bytes[..frame.len()].copy_from_slice(frame);
        RawFrame {
            bytes,
            len: frame.len() as u16,
        }
    }

    /// Serialises `msg` as an unsigned MAVLink 2 frame with `header`.
    pub fn encode(header: MavHeader, msg: &MavMessage) -> RawFrame {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(header, msg);
        RawFrame::copy_from(raw.raw_bytes())
    }

    /// The frame's bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// MAVLink 1 or 2.
    pub fn version(&self) -> MavlinkVersion {
        if self.bytes[0] == STX_V2 {
            MavlinkVersion::V2
        } else {
            MavlinkVersion::V1
        }
    }

    fn is_v2(&self) -> bool {
        self.bytes[0] == STX_V2
    }

    /// A MAVLink 2 frame with the "signed" flag (a signature block follows).
    pub fn is_signed(&self) -> bool {
        self.is_v2() && self.bytes[2] & IFLAG_SIGNED != 0
    }

    /// The sender's sequence number.
    pub fn sequence(&self) -> u8 {
        if self.is_v2() {
            self.bytes[4]
        } else {
            self.bytes[2]
        }
    }

    /// The sender's system id.
    pub fn system_id(&self) -> u8 {
        if self.is_v2() {
            self.bytes[5]
        } else {
            self.bytes[3]
        }
    }

    /// The sender's component id.
    pub fn component_id(&self) -> u8 {
        if self.is_v2() {
            self.bytes[6]
        } else {
            self.bytes[4]
        }
    }

    /// The message id (24 bits in MAVLink 2, 8 in MAVLink 1).
    pub fn message_id(&self) -> u32 {
        if self.is_v2() {
            u32::from_le_bytes([self.bytes[7], self.bytes[8], self.bytes[9], 0])
        } else {
            u32::from(self.bytes[5])
        }
    }

    /// The payload as sent (MAVLink 2 drops trailing zero bytes: read past the end as 0).
    pub fn payload(&self) -> &[u8] {
        let start = if self.is_v2() { V2_HEADER } else { V1_HEADER };
        &self.bytes[start..start + usize::from(self.bytes[1])]
    }

    /// The payload byte at `offset`, 0 where MAVLink 2 truncated it.
    pub fn payload_byte(&self, offset: usize) -> u8 {
        self.payload().get(offset).copied().unwrap_or(0)
    }

    /// The header the `mavlink` crate would report for this frame.
    pub fn header(&self) -> MavHeader {
        MavHeader {
            system_id: u32::from(self.system_id()),
            component_id: self.component_id(),
            sequence: self.sequence(),
        }
    }

    /// Decodes the payload with the ardupilotmega dialect.
    pub fn decode(&self) -> Result<MavMessage, mavlink::error::ParserError> {
        MavMessage::parse(self.version(), self.message_id(), self.payload())
    }

    /// Whom the frame is addressed to, from the dialect's target field offsets.
    pub fn target(&self) -> Target {
        let Some(info) = message_info(self.message_id()) else {
            return Target::Broadcast;
        };
        let Some(system) = info.target_system.map(|o| self.payload_byte(o)) else {
            return Target::Broadcast;
        };
        match info.target_component.map(|o| self.payload_byte(o)) {
            _ if system == 0 => Target::Broadcast,
            None | Some(0) => Target::System(system),
            Some(component) => Target::Component(system, component),
        }
    }

    /// The MAV_CMD of a COMMAND_LONG or COMMAND_INT frame.
    pub fn command(&self) -> Option<u16> {
        matches!(self.message_id(), COMMAND_LONG_ID | COMMAND_INT_ID).then(|| {
            u16::from_le_bytes([
                self.payload_byte(COMMAND_OFFSET),
                self.payload_byte(COMMAND_OFFSET + 1),
            ])
        })
    }
}
