//! LSTS IMC (Inter-Module Communication): the messages skymesh serves, as a pure codec.
//!
//! No I/O: the `imc-gateway` service owns the UDP socket and calls
//! [`decode_datagram`] / [`encode_datagram`]. One datagram carries one message:
//! a 20-byte header, the payload, a CRC-16/ARC over both.
//!
//! Wire format (`../shared/specs/imc-actuation-messages.md` and `specs/FACTS.md`):
//! header `u16 sync 0xFE54, u16 mgid, u16 size (payload only), f64 timestamp, u16 src,
//! u8 src_ent, u16 dst, u8 dst_ent`. A sender writes its own byte order; a receiver
//! that reads the sync as `0x54FE` byte-swaps every field and the CRC. skymesh
//! sends little-endian and accepts both.
//!
//! | step | function | rejects ([`DecodeError`]) |
//! |---|---|---|
//! | frame | [`decode_datagram`] | too short / too long, bad sync, declared size ≠ payload, bad CRC (checked before any field) |
//! | message | [`decode_datagram`] | id outside the set below (`UnknownId`: the gateway skips and counts it) |
//! | fields | [`wire::Reader`] | a field past the payload, bytes after the last field, text not UTF-8, enumerations out of range |
//! | values | [`Message::validate`] | NaN/±∞, values outside the document's ranges, PWM duty cycle above the period |
//!
//! IMC runs over UDP here, one message per datagram, so there is no stream framer:
//! a bad datagram is dropped whole and the next one starts clean.
//!
//! Message families, one file each:
//!
//! | file | messages (id) |
//! |---|---|
//! | `system.rs` | Heartbeat (150), Announce (151) |
//! | `actuation.rs` | CameraZoom (300), SetThrusterActuation (301), SetServoPosition (302), SetControlSurfaceDeflection (303), SetPWM (315), PWM (316) |
//! | `teleop.rs` | RemoteActionsRequest (304), RemoteActions (305), ButtonEvent (306) |
//! | `power.rs` | PowerOperation (308), PowerChannelControl (309), QueryPowerChannelState (310), PowerChannelState (311) |
//! | `devices.rs` | LcdControl (307), LedBrightness (312), QueryLedBrightness (313), SetLedBrightness (314), GpioState (2000), GpioStateGet (2001), GpioStateSet (2002) |
//! | `catalog.rs` | per id: name and family; [`Message::id`], [`Message::name`], [`message_name`] |
//! | `wire.rs` | field primitives in either byte order, including inline message and message list |
//! | `codec.rs` | header, CRC, [`decode_datagram`], [`encode_datagram`] |
//! | `tuple.rs` | TupleList text (`key=value;…`, commas accepted) |
#![forbid(unsafe_code)]

mod actuation;
mod catalog;
mod codec;
mod devices;
mod error;
mod message;
mod power;
mod system;
mod teleop;
mod tuple;
pub mod wire;

pub use catalog::{known_ids, message_name};
pub use codec::{crc16_arc, decode_datagram, encode_datagram};
pub use error::{DecodeError, EncodeError};
pub use message::{
    ids, Announce, ChannelOp, ChannelState, LcdOperation, Message, PowerOp, RemoteActionsOp,
    SystemType, ZoomAction,
};
pub use tuple::{format_tuple_list, parse_tuple_list, TupleListError};

/// The synchronisation number as its sender wrote it in its own byte order.
pub const SYNC: u16 = 0xFE54;
/// The synchronisation number as read by a receiver of the other byte order.
pub const SYNC_SWAPPED: u16 = 0x54FE;
/// Header bytes before the payload.
pub const HEADER_LEN: usize = 20;
/// CRC bytes after the payload.
pub const CRC_LEN: usize = 2;
/// Largest datagram accepted (and produced): the UDP payload limit.
pub const MAX_DATAGRAM: usize = 65_507;
/// "No address" / broadcast system address.
pub const ADDR_NONE: u16 = 0xFFFF;
/// Any entity.
pub const ENTITY_ANY: u8 = 255;
/// Inline message id meaning "no message".
pub const INLINE_NONE: u16 = 65_535;

/// Byte order a datagram was written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    Little,
    Big,
}

/// The header of one datagram. `mgid` and `size` are filled by [`encode_datagram`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Header {
    pub mgid: u16,
    /// Payload bytes.
    pub size: u16,
    /// Seconds since the Unix epoch at the sender.
    pub timestamp: f64,
    pub src: u16,
    pub src_ent: u8,
    pub dst: u16,
    pub dst_ent: u8,
}

/// One decoded datagram.
#[derive(Debug, Clone, PartialEq)]
pub struct Packet {
    pub header: Header,
    pub byte_order: ByteOrder,
    pub message: Message,
}
