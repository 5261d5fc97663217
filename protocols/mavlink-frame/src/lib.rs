//! MAVLink 1/2 framing and MAVLink 2 message signing over byte buffers: no I/O,
//! no clock. One framer for everything in skymesh that reads MAVLink bytes (the
//! router in autopilot-link, the simulated autopilot in vehicle-sim).
//!
//! The `mavlink` crate (ardupilotmega dialect, MAVLink 2 extension fields on)
//! provides what it already knows: each message id's CRC_EXTRA, the target field
//! accessors, parsing and serialising payloads. This crate adds what its reader
//! lacks:
//! - [`FrameParser`]: splits a byte stream into [`RawFrame`]s exactly as they
//!   were on the wire (scan for STX, length, CRC with the message's CRC_EXTRA,
//!   resync one byte after a bad candidate), either forwarding frames whose id the
//!   dialect does not know (a router must) or rejecting them (an endpoint that
//!   only answers its dialect).
//! - [`FrameDecoder`]: the parser plus payload decoding into [`Inbound`]
//!   messages, including COMMAND_LONG/COMMAND_INT with command numbers the
//!   dialect lacks, so they can still be answered.
//! - [`RawFrame::target`]: whom a frame is addressed to, without decoding it.
//! - [`signing`]: MAVLink 2 signatures (sign, verify, replay protection).

mod decode;
mod parser;
mod raw;
pub mod signing;

pub use decode::{encode, encode_command_ack_raw, FrameDecoder, Inbound};
pub use parser::{BadFrame, FrameParser, UnknownIds, MAX_BUFFERED};
pub use raw::{
    message_info, MessageInfo, RawFrame, Target, COMMAND_ACK_ID, COMMAND_INT_ID, COMMAND_LONG_ID,
    MAX_FRAME, STX_V1, STX_V2,
};
