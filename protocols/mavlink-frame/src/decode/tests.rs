//! Decoder tests: partial, adjacent, corrupted, oversized and random input;
//! extension fields on the wire.

use super::*;
use crate::parser::MAX_BUFFERED;
use crate::raw::{CHECKSUM_LEN, IFLAG_SIGNED, SIGNATURE_LEN, STX_V1, V2_HEADER as HEADER_V2};
use mavlink::dialects::ardupilotmega::{
    GimbalDeviceFlags, MavAutopilot, MavCmd, MavModeFlag, MavState, MavType, COMMAND_LONG_DATA,
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, HEARTBEAT_DATA, SERVO_OUTPUT_RAW_DATA,
};

fn hdr(seq: u8) -> MavHeader {
    MavHeader {
        system_id: 255,
        component_id: 190,
        sequence: seq,
    }
}

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 4,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn arm_command() -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: 1.0,
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: 1,
        ..COMMAND_LONG_DATA::DEFAULT
    })
}

fn v2(seq: u8, msg: &MavMessage) -> Vec<u8> {
    let mut out = Vec::new();
    encode(hdr(seq), msg, &mut out);
    out
}

fn v1(seq: u8, msg: &MavMessage) -> Vec<u8> {
    let mut out = Vec::new();
    mavlink::write_v1_msg(&mut out, hdr(seq), msg).expect("vec write");
    out
}

/// Decode everything currently decodable.
fn drain(d: &mut FrameDecoder) -> (Vec<Inbound>, Vec<BadFrame>) {
    let (mut ok, mut bad) = (Vec::new(), Vec::new());
    while let Some(r) = d.next_frame() {
        match r {
            Ok(f) => ok.push(f),
            Err(e) => bad.push(e),
        }
    }
    (ok, bad)
}

fn msgs(frames: &[Inbound]) -> Vec<MavMessage> {
    frames
        .iter()
        .filter_map(|f| match f {
            Inbound::Message { msg, .. } => Some(msg.clone()),
            Inbound::UnknownCommand { .. } => None,
        })
        .collect()
}

#[test]
fn round_trip_with_header() {
    let mut d = FrameDecoder::new();
    d.push(&v2(7, &heartbeat()));
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty());
    assert_eq!(
        ok,
        vec![Inbound::Message {
            header: hdr(7),
            version: MavlinkVersion::V2,
            msg: heartbeat(),
        }]
    );
    assert_eq!(d.buffered(), 0);
}

#[test]
fn mavlink1_is_accepted() {
    let mut d = FrameDecoder::new();
    d.push(&v1(3, &arm_command()));
    let (ok, _) = drain(&mut d);
    assert!(matches!(
        &ok[..],
        [Inbound::Message { version: MavlinkVersion::V1, msg, .. }] if *msg == arm_command()
    ));
}

#[test]
fn every_chunk_size_gives_the_same_frames() {
    let mut input = vec![0x00, 0x42, 0x13];
    input.extend(v2(1, &heartbeat()));
    input.extend(v1(2, &arm_command()));
    input.extend(v2(3, &arm_command()));
    input.extend([0xAA, 0xBB]);
    for chunk in 1..=input.len() {
        let mut d = FrameDecoder::new();
        let mut got = Vec::new();
        for part in input.chunks(chunk) {
            d.push(part);
            got.extend(drain(&mut d).0);
        }
        assert_eq!(
            msgs(&got),
            vec![heartbeat(), arm_command(), arm_command()],
            "chunk size {chunk}"
        );
    }
}

#[test]
fn corrupted_checksum_then_valid_frame() {
    let mut bad_frame = v2(1, &arm_command());
    let last = bad_frame.len() - 1;
    bad_frame[last] ^= 0xFF;
    let mut d = FrameDecoder::new();
    d.push(&bad_frame);
    d.push(&v2(2, &heartbeat()));
    let (ok, bad) = drain(&mut d);
    assert_eq!(msgs(&ok), vec![heartbeat()]);
    assert!(bad.contains(&BadFrame::Checksum {
        id: COMMAND_LONG_DATA::ID
    }));
}

#[test]
fn frame_hidden_inside_a_failed_candidate_is_found() {
    // A fake marker claiming a long COMMAND_LONG swallows the real frame; the
    // real one must still come out once the candidate's checksum fails.
    let mut input = vec![STX_V2, 200, 0, 0, 0, 1, 1, 76, 0, 0];
    input.extend(v2(9, &heartbeat()));
    input.extend(vec![0u8; 250]);
    let mut d = FrameDecoder::new();
    d.push(&input);
    let (ok, bad) = drain(&mut d);
    assert_eq!(msgs(&ok), vec![heartbeat()]);
    assert!(matches!(bad[0], BadFrame::Checksum { id: 76 }));
    assert_eq!(d.buffered(), 0);
}

#[test]
fn unknown_message_id_is_rejected_from_the_header_alone() {
    let mut d = FrameDecoder::new();
    // Declares 255 payload bytes of message 0xFFFFFF, then a real frame.
    d.push(&[STX_V2, 255, 0, 0, 0, 1, 1, 0xFF, 0xFF, 0xFF]);
    d.push(&v2(1, &heartbeat()));
    let (ok, bad) = drain(&mut d);
    assert_eq!(msgs(&ok), vec![heartbeat()]);
    assert_eq!(bad[0], BadFrame::UnknownMessage { id: 0xFF_FFFF });
}

#[test]
fn partial_frame_waits_and_buffer_stays_bounded() {
    let frame = v2(1, &heartbeat());
    let mut d = FrameDecoder::new();
    d.push(&frame[..frame.len() - 1]);
    assert_eq!(d.next_frame(), None);
    assert_eq!(d.buffered(), frame.len() - 1);
    d.push(&frame[frame.len() - 1..]);
    assert_eq!(msgs(&drain(&mut d).0), vec![heartbeat()]);

    // A caller that never drains cannot make it grow without bound.
    let mut d = FrameDecoder::new();
    for _ in 0..100 {
        d.push(&[0u8; 4096]);
    }
    assert!(d.buffered() <= MAX_BUFFERED);
}

#[test]
fn unsupported_incompat_flags_are_rejected() {
    let mut frame = v2(1, &heartbeat());
    frame[2] = 0x80;
    let mut d = FrameDecoder::new();
    d.push(&frame);
    let (ok, bad) = drain(&mut d);
    assert!(ok.is_empty());
    assert_eq!(bad[0], BadFrame::IncompatFlags { flags: 0x80 });
}

#[test]
fn signed_frames_are_accepted_without_verification() {
    let mut frame = v2(1, &heartbeat());
    frame[2] = IFLAG_SIGNED;
    let crc_at = frame.len() - 2;
    let crc = calculate_crc(&frame[1..crc_at], HEARTBEAT_DATA::EXTRA_CRC);
    frame[crc_at..].copy_from_slice(&crc.to_le_bytes());
    frame.extend([0u8; SIGNATURE_LEN]);
    frame.extend(v2(2, &heartbeat()));
    let mut d = FrameDecoder::new();
    d.push(&frame);
    assert_eq!(msgs(&drain(&mut d).0), vec![heartbeat(), heartbeat()]);
}

#[test]
fn command_with_unknown_number_is_still_extracted() {
    let mut frame = v2(4, &arm_command());
    // Patch the command field (payload offset 28) to 65000 and re-checksum.
    let payload_at = HEADER_V2;
    frame[payload_at + 28..payload_at + 30].copy_from_slice(&65000u16.to_le_bytes());
    let crc_at = frame.len() - 2;
    let crc = calculate_crc(&frame[1..crc_at], COMMAND_LONG_DATA::EXTRA_CRC);
    frame[crc_at..].copy_from_slice(&crc.to_le_bytes());
    let mut d = FrameDecoder::new();
    d.push(&frame);
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty(), "{bad:?}");
    assert_eq!(
        ok,
        vec![Inbound::UnknownCommand {
            header: hdr(4),
            command: 65000,
            target_system: 1,
            target_component: 1,
        }]
    );
}

#[test]
fn raw_command_ack_is_a_valid_command_ack() {
    let mut out = Vec::new();
    encode_command_ack_raw(hdr(5), 400, MavResult::MAV_RESULT_UNSUPPORTED, &mut out);
    let mut d = FrameDecoder::new();
    d.push(&out);
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty());
    assert_eq!(
        msgs(&ok),
        vec![MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result: MavResult::MAV_RESULT_UNSUPPORTED,
            ..COMMAND_ACK_DATA::DEFAULT
        })]
    );
}

#[test]
fn random_bytes_never_panic_and_a_later_frame_survives() {
    // Deterministic xorshift so failures reproduce.
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for round in 0..200 {
        let len = (next() % 600) as usize;
        let mut input: Vec<u8> = (0..len)
            .map(|_| {
                // Plenty of markers to exercise resync.
                match next() % 8 {
                    0 => STX_V2,
                    1 => STX_V1,
                    _ => next() as u8,
                }
            })
            .collect();
        input.extend(v2(1, &heartbeat()));
        // Enough filler to complete any candidate that swallowed the frame.
        input.extend(vec![0u8; 300]);
        let mut d = FrameDecoder::new();
        let mut got = Vec::new();
        for part in input.chunks(1 + round % 37) {
            d.push(part);
            got.extend(drain(&mut d).0);
        }
        assert!(
            msgs(&got).contains(&heartbeat()),
            "round {round}: frame lost"
        );
        assert_eq!(d.buffered(), 0, "round {round}: every byte consumed");
    }
}

/// Bytes of GIMBAL_DEVICE_ATTITUDE_STATUS's extension fields on the wire:
/// delta_yaw, delta_yaw_velocity (f32), gimbal_device_id (u8).
const GIMBAL_STATUS_EXTENSION_LEN: usize = 9;
/// Bytes of SERVO_OUTPUT_RAW's extension fields: servo9_raw..servo16_raw (u16).
const SERVO_OUTPUT_EXTENSION_LEN: usize = 16;

fn gimbal_status(delta_yaw: f32, device: u8) -> GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
        time_boot_ms: 1234,
        q: [0.9, -0.1, -0.2, 0.3],
        flags: GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
        delta_yaw,
        delta_yaw_velocity: -0.25,
        gimbal_device_id: device,
        ..GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::DEFAULT
    }
}

fn gimbal_frame(seq: u8, status: &GIMBAL_DEVICE_ATTITUDE_STATUS_DATA) -> Vec<u8> {
    v2(
        seq,
        &MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(status.clone()),
    )
}

#[test]
fn gimbal_status_carries_its_extension_fields() {
    type D = GIMBAL_DEVICE_ATTITUDE_STATUS_DATA;
    let base_len = D::ENCODED_LEN - GIMBAL_STATUS_EXTENSION_LEN;
    let status = gimbal_status(1.5, 1);
    let frame = gimbal_frame(3, &status);
    // Full payload: nothing to truncate, the device id (last byte) is 1.
    assert_eq!(usize::from(frame[1]), D::ENCODED_LEN);
    let ext = &frame[HEADER_V2 + base_len..];
    assert_eq!(ext[0..4], 1.5f32.to_le_bytes());
    assert_eq!(ext[4..8], (-0.25f32).to_le_bytes());
    assert_eq!(ext[8], 1);
    assert_eq!(
        frame.len(),
        HEADER_V2 + usize::from(frame[1]) + CHECKSUM_LEN
    );

    let mut d = FrameDecoder::new();
    d.push(&frame);
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty(), "{bad:?}");
    assert_eq!(
        ok,
        vec![Inbound::Message {
            header: hdr(3),
            version: MavlinkVersion::V2,
            msg: MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(status),
        }]
    );
}

#[test]
fn gimbal_status_truncates_trailing_zeros_across_the_extensions() {
    let mut zero = gimbal_status(0.0, 0);
    zero.delta_yaw_velocity = 0.0;
    let frame = gimbal_frame(0, &zero);
    // The last non-zero base byte is the flags' low byte (offset 36).
    assert_eq!(frame[1], 37);
    let mut d = FrameDecoder::new();
    d.push(&frame);
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty(), "{bad:?}");
    assert_eq!(
        msgs(&ok),
        vec![MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(zero)]
    );
}

#[test]
fn servo_output_raw_carries_servos_9_to_16() {
    type D = SERVO_OUTPUT_RAW_DATA;
    let base_len = D::ENCODED_LEN - SERVO_OUTPUT_EXTENSION_LEN;
    let servos = SERVO_OUTPUT_RAW_DATA {
        time_usec: 5_000_000,
        servo1_raw: 1000,
        servo5_raw: 1900,
        servo9_raw: 1100,
        servo16_raw: 2000,
        ..D::DEFAULT
    };
    let frame = v2(7, &MavMessage::SERVO_OUTPUT_RAW(servos.clone()));
    assert_eq!(
        usize::from(frame[1]),
        D::ENCODED_LEN,
        "servo 16 is set: nothing truncated"
    );
    let ext = &frame[HEADER_V2 + base_len..];
    assert_eq!(ext[0..2], 1100u16.to_le_bytes());
    assert_eq!(ext[14..16], 2000u16.to_le_bytes());
    let mut d = FrameDecoder::new();
    d.push(&frame);
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty(), "{bad:?}");
    assert_eq!(
        msgs(&ok),
        vec![MavMessage::SERVO_OUTPUT_RAW(servos.clone())]
    );

    // Nothing above servo 8: the extensions are truncated away entirely.
    let base_only = SERVO_OUTPUT_RAW_DATA {
        servo9_raw: 0,
        servo16_raw: 0,
        ..servos
    };
    let frame = v2(8, &MavMessage::SERVO_OUTPUT_RAW(base_only.clone()));
    // The last non-zero byte is servo5's high byte (offset 13).
    assert_eq!(frame[1], 14);
    d.push(&frame);
    let (ok, bad) = drain(&mut d);
    assert!(bad.is_empty(), "{bad:?}");
    assert_eq!(msgs(&ok), vec![MavMessage::SERVO_OUTPUT_RAW(base_only)]);
}
