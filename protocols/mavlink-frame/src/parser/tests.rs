//! Framer tests: targets and fields of frames, adjacent frames of every kind,
//! every chunk size, junk and bad checksums, datagram ends, random input.

use super::*;
use crate::raw::{message_info, Target, COMMAND_ACK_ID, MESSAGES};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType, COMMAND_ACK_DATA,
    COMMAND_LONG_DATA, HEARTBEAT_DATA, PARAM_REQUEST_LIST_DATA,
};
use mavlink::{MavHeader, MavlinkVersion, Message};

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
fn command_ack_targets_are_read_from_the_extension_fields() {
    let mut ack = COMMAND_ACK_DATA {
        command: MavCmd::MAV_CMD_DO_SET_MODE,
        result: MavResult::MAV_RESULT_ACCEPTED,
        ..COMMAND_ACK_DATA::DEFAULT
    };
    // Targets 0 (autopilots without the extensions): broadcast.
    let f = RawFrame::encode(header(1, 1), &MavMessage::COMMAND_ACK(ack.clone()));
    assert!(f.payload().len() <= 3, "MAVLink 2 drops trailing zeros");
    assert_eq!(f.target(), Target::Broadcast);
    ack.target_system = 255;
    ack.target_component = 190;
    let typed = RawFrame::encode(header(1, 1), &MavMessage::COMMAND_ACK(ack.clone()));
    assert_eq!(typed.target(), Target::Component(255, 190));
    // ArduPilot appends progress, result_param2, target_system, target_component.
    let mut wire = vec![STX_V2, 10, 0, 0, 3, 1, 1, 77, 0, 0];
    wire.extend_from_slice(&[176, 0, 0, 0, 0, 0, 0, 0, 255, 190]);
    let crc = mavlink::calculate_crc(&wire[1..], MavMessage::extra_crc(77));
    wire.extend_from_slice(&crc.to_le_bytes());
    let (frames, _) = parse_all(&[&wire]);
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].target(), Target::Component(255, 190));
    assert_eq!(frames[0].decode().unwrap(), MavMessage::COMMAND_ACK(ack));
    let info = message_info(COMMAND_ACK_ID).unwrap();
    assert_eq!(
        (info.target_system, info.target_component),
        (Some(8), Some(9))
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
