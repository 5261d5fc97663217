//! Raw MAVLink frames: split a byte stream into frames without decoding them, so
//! the router can forward every frame byte for byte, whatever its message id and
//! whether it is signed. Pure: no I/O.
//!
//! The `mavlink` crate's reader only returns frames whose message id its dialect
//! knows (it needs the id's CRC_EXTRA to check the checksum), so it would silently
//! drop newer or vendor messages. [`FrameParser`] therefore frames by itself, as
//! mavlink-router does: a frame whose id the ardupilotmega dialect knows must
//! carry a valid checksum; a frame with an unknown id cannot be checked and is
//! passed on as it is (the receiver checks it against its own dialect). Anything
//! else (junk, a bad checksum, unknown incompatibility flags) is skipped from the
//! next byte on, so the parser resynchronises on the next frame start, and is
//! counted.
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
const V2_HEADER: usize = 10;
const V1_HEADER: usize = 6;
const SIGNATURE: usize = 13;
const IFLAG_SIGNED: u8 = 0x01;
/// `COMMAND_ACK`: `target_system`/`target_component` are MAVLink 2 extension fields
/// the crate's ardupilotmega dialect does not generate; their wire offsets are fixed
/// by common.xml (command u16, result u8, progress u8, result_param2 i32, then them).
pub const COMMAND_ACK_ID: u32 = 77;
const COMMAND_ACK_TARGET: (usize, usize) = (8, 9);
/// `COMMAND_LONG` and `COMMAND_INT` both carry the MAV_CMD as u16 at payload offset 28.
pub const COMMAND_LONG_ID: u32 = 76;
pub const COMMAND_INT_ID: u32 = 75;
const COMMAND_OFFSET: usize = 28;

/// What the router needs to know about one message id of the dialect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageInfo {
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
/// crate knows which fields are targets but does not expose their offsets.
static MESSAGES: LazyLock<HashMap<u32, MessageInfo>> = LazyLock::new(|| {
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
        let mut info = MessageInfo {
            extra_crc: MavMessage::extra_crc(id),
            target_system: probe(MavMessage::target_system_id_mut),
            target_component: probe(MavMessage::target_component_id_mut),
        };
        if id == COMMAND_ACK_ID {
            info.target_system = Some(COMMAND_ACK_TARGET.0);
            info.target_component = Some(COMMAND_ACK_TARGET.1);
        }
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
    /// Wraps bytes the parser has already checked to be one whole frame.
    fn copy_from(frame: &[u8]) -> RawFrame {
        let mut bytes = [0u8; MAX_FRAME];
        bytes[..frame.len()].copy_from_slice(frame);
        RawFrame {
            bytes,
            len: frame.len() as u16,
        }
    }

    /// Wraps one whole frame built by this crate (e.g. [`crate::signing::sign`]);
    /// `frame` must not be longer than [`MAX_FRAME`].
    pub(crate) fn from_wire(frame: &[u8]) -> RawFrame {
        RawFrame::copy_from(&frame[..frame.len().min(MAX_FRAME)])
    }

    /// Serialises `msg` as an unsigned MAVLink 2 frame with `header`.
    pub fn encode(header: MavHeader, msg: &MavMessage) -> RawFrame {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(header, msg);
        RawFrame::copy_from(raw.raw_bytes())
    }

    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

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

    pub fn is_signed(&self) -> bool {
        self.is_v2() && self.bytes[2] & IFLAG_SIGNED != 0
    }

    pub fn sequence(&self) -> u8 {
        if self.is_v2() {
            self.bytes[4]
        } else {
            self.bytes[2]
        }
    }

    pub fn system_id(&self) -> u8 {
        if self.is_v2() {
            self.bytes[5]
        } else {
            self.bytes[3]
        }
    }

    pub fn component_id(&self) -> u8 {
        if self.is_v2() {
            self.bytes[6]
        } else {
            self.bytes[4]
        }
    }

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

/// Splits a byte stream into [`RawFrame`]s; see the module documentation.
///
/// Feed it with [`push`](Self::push) and drain it with [`next_frame`](Self::next_frame)
/// until `None` before pushing again: at most one partial frame (< [`MAX_FRAME`]
/// bytes) stays buffered between reads. For datagram transports call
/// [`end_datagram`](Self::end_datagram) after draining: a frame never spans
/// datagrams.
#[derive(Debug, Default)]
pub struct FrameParser {
    buf: Vec<u8>,
    start: usize,
    /// Bytes were skipped since the last good frame (one resync counts once).
    skipping: bool,
    malformed: u64,
}

impl FrameParser {
    pub fn new() -> Self {
        FrameParser {
            buf: Vec::with_capacity(4 * MAX_FRAME),
            ..FrameParser::default()
        }
    }

    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes buffered that do not form a whole frame yet.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Skipped input since the last call: runs of junk and rejected candidates, each
    /// resynchronisation counted once.
    pub fn take_malformed(&mut self) -> u64 {
        std::mem::take(&mut self.malformed)
    }

    fn skip(&mut self, n: usize) {
        self.start += n;
        if !self.skipping {
            self.skipping = true;
            self.malformed += 1;
        }
    }

    /// Drops a trailing partial frame (counted as malformed).
    pub fn end_datagram(&mut self) {
        if self.pending() > 0 {
            let n = self.pending();
            self.skip(n);
        }
        self.buf.clear();
        self.start = 0;
        self.skipping = false;
    }

    /// The next whole frame, or `None` when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<RawFrame> {
        loop {
            let avail = &self.buf[self.start..];
            let Some(at) = avail.iter().position(|b| *b == STX_V2 || *b == STX_V1) else {
                let n = avail.len();
                if n > 0 {
                    self.skip(n);
                }
                return None;
            };
            if at > 0 {
                self.skip(at);
                continue;
            }
            let v2 = avail[0] == STX_V2;
            if avail.len() < 3 {
                return None;
            }
            let (header, signature) = if v2 {
                if avail[2] & !IFLAG_SIGNED != 0 {
                    // Unknown incompatibility flags: not a frame we may handle.
                    self.skip(1);
                    continue;
                }
                let signed = avail[2] & IFLAG_SIGNED != 0;
                (V2_HEADER, if signed { SIGNATURE } else { 0 })
            } else {
                (V1_HEADER, 0)
            };
            let payload = usize::from(avail[1]);
            let total = header + payload + 2 + signature;
            if avail.len() < total {
                return None;
            }
            let id = if v2 {
                u32::from_le_bytes([avail[7], avail[8], avail[9], 0])
            } else {
                u32::from(avail[5])
            };
            if let Some(info) = message_info(id) {
                let sent =
                    u16::from_le_bytes([avail[header + payload], avail[header + payload + 1]]);
                if mavlink::calculate_crc(&avail[1..header + payload], info.extra_crc) != sent {
                    self.skip(1);
                    continue;
                }
            }
            let frame = RawFrame::copy_from(&avail[..total]);
            self.start += total;
            self.skipping = false;
            if self.start == self.buf.len() {
                self.buf.clear();
                self.start = 0;
            }
            return Some(frame);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        MavAutopilot, MavCmd, MavModeFlag, MavResult, MavState, MavType, COMMAND_ACK_DATA,
        COMMAND_LONG_DATA, HEARTBEAT_DATA, PARAM_REQUEST_LIST_DATA,
    };

    fn header(system: u8, component: u8) -> MavHeader {
        MavHeader {
            system_id: u32::from(system),
            component_id: component,
            sequence: 7,
        }
    }

    fn heartbeat() -> MavMessage {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 4,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    fn command_long(system: u8, component: u8) -> MavMessage {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: system,
            target_component: component,
            param1: 1.0,
            param2: 4.0,
            ..COMMAND_LONG_DATA::DEFAULT
        })
    }

    fn bytes(h: MavHeader, m: &MavMessage) -> Vec<u8> {
        RawFrame::encode(h, m).as_bytes().to_vec()
    }

    /// A MAVLink 2 frame with an id no dialect defines (the checksum cannot be checked).
    fn unknown_id_frame() -> Vec<u8> {
        let mut f = vec![STX_V2, 3, 0, 0, 9, 42, 200, 0x39, 0x30, 0x00, 1, 2, 3];
        f.extend_from_slice(&[0xAB, 0xCD]);
        f
    }

    /// A signed MAVLink 2 HEARTBEAT (signature bytes are opaque to the router).
    fn signed_heartbeat() -> Vec<u8> {
        let mut f = bytes(header(1, 1), &heartbeat());
        f[2] |= IFLAG_SIGNED;
        // The checksum covers the flags: recompute it, then append a signature.
        let end = f.len() - 2;
        let crc = mavlink::calculate_crc(&f[1..end], MavMessage::extra_crc(0));
        f[end..].copy_from_slice(&crc.to_le_bytes());
        f.extend_from_slice(&[0x01, 1, 2, 3, 4, 5, 6, 9, 9, 9, 9, 9, 9]);
        f
    }

    fn parse_all(chunks: &[&[u8]]) -> (Vec<RawFrame>, FrameParser) {
        let mut p = FrameParser::new();
        let mut out = Vec::new();
        for c in chunks {
            p.push(c);
            while let Some(f) = p.next_frame() {
                out.push(f);
            }
        }
        (out, p)
    }

    #[test]
    fn target_offsets_come_from_the_dialect() {
        let info = message_info(76).unwrap();
        assert_eq!(
            (info.target_system, info.target_component),
            (Some(30), Some(31))
        );
        let info = message_info(21).unwrap();
        assert_eq!(
            (info.target_system, info.target_component),
            (Some(0), Some(1))
        );
        // SET_MODE has a target system only.
        let info = message_info(11).unwrap();
        assert_eq!((info.target_system, info.target_component), (Some(4), None));
        assert_eq!(message_info(0).unwrap().target_system, None);
        assert!(message_info(0x3039).is_none());
        assert!(MESSAGES.len() > 300, "{}", MESSAGES.len());
    }

    #[test]
    fn fields_and_targets_of_frames() {
        let f = RawFrame::encode(header(255, 190), &command_long(1, 1));
        assert_eq!(
            (f.system_id(), f.component_id(), f.sequence()),
            (255, 190, 7)
        );
        assert_eq!(f.message_id(), 76);
        assert_eq!(f.target(), Target::Component(1, 1));
        assert_eq!(f.command(), Some(MavCmd::MAV_CMD_DO_SET_MODE as u16));
        assert_eq!(f.decode().unwrap(), command_long(1, 1));
        let f = RawFrame::encode(header(255, 190), &command_long(1, 0));
        assert_eq!(f.target(), Target::System(1));
        let f = RawFrame::encode(header(255, 190), &command_long(0, 1));
        assert_eq!(f.target(), Target::Broadcast);
        let list = MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
            target_system: 2,
            target_component: 0,
        });
        assert_eq!(
            RawFrame::encode(header(255, 190), &list).target(),
            Target::System(2)
        );
        assert_eq!(
            RawFrame::encode(header(1, 1), &heartbeat()).target(),
            Target::Broadcast
        );
        assert_eq!(RawFrame::encode(header(1, 1), &heartbeat()).command(), None);
    }

    #[test]
    fn command_ack_targets_are_read_from_the_extension_bytes() {
        let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            result: MavResult::MAV_RESULT_ACCEPTED,
        });
        // Our dialect writes no extensions: no target, i.e. broadcast.
        let f = RawFrame::encode(header(1, 1), &ack);
        assert!(f.payload().len() <= 3, "MAVLink 2 drops trailing zeros");
        assert_eq!(f.target(), Target::Broadcast);
        // ArduPilot appends progress, result_param2, target_system, target_component.
        let mut wire = vec![STX_V2, 10, 0, 0, 3, 1, 1, 77, 0, 0];
        wire.extend_from_slice(&[176, 0, 0, 0, 0, 0, 0, 0, 255, 190]);
        let crc = mavlink::calculate_crc(&wire[1..], MavMessage::extra_crc(77));
        wire.extend_from_slice(&crc.to_le_bytes());
        let (frames, _) = parse_all(&[&wire]);
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].target(), Target::Component(255, 190));
        assert!(
            frames[0].decode().is_ok(),
            "the dialect ignores the extension bytes"
        );
    }

    #[test]
    fn adjacent_frames_of_every_kind_come_out_byte_exact() {
        let a = bytes(header(1, 1), &heartbeat());
        let b = unknown_id_frame();
        let c = signed_heartbeat();
        let mut v1 = Vec::new();
        mavlink::write_v1_msg(&mut v1, header(1, 1), &heartbeat()).unwrap();
        let d = bytes(header(255, 190), &command_long(1, 1));
        let stream: Vec<u8> = [&a[..], &b[..], &c[..], &v1[..], &d[..]].concat();
        let (frames, mut p) = parse_all(&[&stream]);
        let got: Vec<&[u8]> = frames.iter().map(RawFrame::as_bytes).collect();
        assert_eq!(got, vec![&a[..], &b[..], &c[..], &v1[..], &d[..]]);
        assert!(frames[2].is_signed());
        assert_eq!(frames[1].message_id(), 0x3039);
        assert_eq!(frames[3].version(), MavlinkVersion::V1);
        assert_eq!(p.take_malformed(), 0);
        assert_eq!(p.pending(), 0);
    }

    #[test]
    fn every_chunk_size_gives_the_same_frames() {
        let stream: Vec<u8> = [
            bytes(header(1, 1), &heartbeat()),
            unknown_id_frame(),
            signed_heartbeat(),
            bytes(header(255, 190), &command_long(1, 1)),
        ]
        .concat();
        let (whole, _) = parse_all(&[&stream]);
        assert_eq!(whole.len(), 4);
        for size in 1..=stream.len() {
            let chunks: Vec<&[u8]> = stream.chunks(size).collect();
            let (frames, mut p) = parse_all(&chunks);
            assert_eq!(frames, whole, "chunk size {size}");
            assert_eq!(p.take_malformed(), 0);
        }
    }

    #[test]
    fn junk_and_a_bad_checksum_are_skipped_and_counted_once_each() {
        let good = bytes(header(1, 1), &heartbeat());
        let mut bad = good.clone();
        let n = bad.len();
        bad[n - 1] ^= 0xFF;
        // Junk containing a marker byte, then a corrupted frame, then good ones.
        let stream: Vec<u8> = [&[0x00, STX_V2, 0x55, 0x13, 0x42][..], &bad, &good, &good].concat();
        let (frames, mut p) = parse_all(&[&stream]);
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[0].as_bytes(), &good[..]);
        assert_eq!(
            p.take_malformed(),
            1,
            "one resync before the first good frame"
        );
        let (frames, mut p) = parse_all(&[&good, &[1, 2, 3], &good, &bad]);
        assert_eq!(frames.len(), 2);
        assert_eq!(
            p.take_malformed(),
            2,
            "junk between frames, then a bad checksum"
        );
        // A datagram that ends inside a frame.
        let (_, mut p) = parse_all(&[&good, &good[..5]]);
        assert_eq!(p.take_malformed(), 0);
        p.end_datagram();
        assert_eq!(p.take_malformed(), 1);
        assert_eq!(p.pending(), 0);
    }

    #[test]
    fn a_junk_marker_with_a_long_length_only_delays_the_frames_behind_it() {
        let good = bytes(header(1, 1), &heartbeat());
        // A MAVLink 1 "frame" of 253 payload bytes starting at a stray 0xFE: the
        // parser must wait for 261 bytes before it can reject it by its checksum.
        let mut stream = vec![STX_V1, STX_V2];
        for _ in 0..20 {
            stream.extend_from_slice(&good);
        }
        let (frames, mut p) = parse_all(&[&stream]);
        assert_eq!(frames.len(), 20, "nothing lost once enough bytes arrived");
        assert_eq!(p.take_malformed(), 1);
    }

    #[test]
    fn an_incomplete_frame_waits_and_a_datagram_end_drops_it() {
        let good = bytes(header(1, 1), &heartbeat());
        let (frames, mut p) = parse_all(&[&good[..good.len() - 1]]);
        assert!(frames.is_empty());
        assert_eq!(p.pending(), good.len() - 1);
        p.push(&good[good.len() - 1..]);
        assert_eq!(p.next_frame().unwrap().as_bytes(), &good[..]);
        // The largest declared length buffers at most one frame's worth.
        let (_, p) = parse_all(&[&[STX_V2, 255, 0, 0, 1, 1, 1, 0, 0, 0]]);
        assert_eq!(p.pending(), 10);
    }

    #[test]
    fn unknown_incompatibility_flags_are_refused() {
        let mut f = unknown_id_frame();
        f[2] = 0x02;
        let (frames, mut p) = parse_all(&[&f]);
        assert!(frames.is_empty());
        assert_eq!(p.take_malformed(), 1);
    }

    #[test]
    fn random_input_never_panics_and_stays_bounded() {
        let mut rng = fastrand::Rng::with_seed(7);
        let good = bytes(header(1, 1), &heartbeat());
        let mut p = FrameParser::new();
        let mut found = 0;
        for round in 0..2000 {
            let mut chunk: Vec<u8> = (0..rng.usize(0..600)).map(|_| rng.u8(..)).collect();
            if round % 10 == 0 {
                chunk.extend_from_slice(&good);
            }
            p.push(&chunk);
            while let Some(f) = p.next_frame() {
                assert!(f.as_bytes().len() <= MAX_FRAME);
                found += 1;
            }
            assert!(p.pending() < MAX_FRAME, "{}", p.pending());
        }
        assert!(
            found >= 150,
            "most planted frames survive random junk: {found}"
        );
    }
}
