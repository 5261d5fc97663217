//! Hand-written byte fixtures (not produced by this crate's encoder) in both byte
//! orders, checked field by field, then broken: a wrong CRC, a payload one byte short,
//! one trailing byte, and a datagram cut without fixing the size.
//!
//! The little-endian fixtures are byte-identical to what DUNE's own IMC serializer
//! (`imcpy` 1.1.2, the Python bindings of DUNE-IMC) writes for the same values, and
//! DUNE's `Packet.deserialize` accepts every big-endian one (and refuses a wrong
//! CRC): `scripts/dune-crosscheck.py` checks that after a fixture changes (no Python
//! at test time).

mod common;

use common::{fixture_header, frame_le, payload_of, reframe};
use imc_proto::{
    crc16_arc, decode_datagram, encode_datagram, ByteOrder, ChannelOp, DecodeError, Message,
    Packet, SystemType,
};

const HEARTBEAT_LE: &[u8] = &[
    // header: sync, mgid 150, size 0
    0x54, 0xFE, 0x96, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8,
    0x3F, // timestamp 1.5
    0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x71, 0x33, // crc 0x3371
];

const HEARTBEAT_BE: &[u8] = &[
    // header: sync, mgid 150, size 0
    0xFE, 0x54, 0x00, 0x96, 0x00, 0x00, 0x3F, 0xF8, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // timestamp 1.5
    0x40, 0x01, 0x05, 0x20, 0x00, 0xFF, // src 0x4001/5, dst 0x2000/255
    0xBA, 0x80, // crc 0xba80
];

const SET_LED_BRIGHTNESS_LE: &[u8] = &[
    // header: sync, mgid 314, size 7
    0x54, 0xFE, 0x3A, 0x01, 0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8,
    0x3F, // timestamp 1.5
    0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x04, 0x00, // name length 4
    b'l', b'e', b'd', b'0', 0xC8, // value 200
    0x3B, 0xE4, // crc 0xe43b
];

const SET_LED_BRIGHTNESS_BE: &[u8] = &[
    // header: sync, mgid 314, size 7
    0xFE, 0x54, 0x01, 0x3A, 0x00, 0x07, 0x3F, 0xF8, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // timestamp 1.5
    0x40, 0x01, 0x05, 0x20, 0x00, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x00, 0x04, // name length 4
    b'l', b'e', b'd', b'0', 0xC8, // value 200
    0xFF, 0x49, // crc 0xff49
];

const POWER_CHANNEL_CONTROL_LE: &[u8] = &[
    // header: sync, mgid 309, size 14
    0x54, 0xFE, 0x35, 0x01, 0x0E, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8,
    0x3F, // timestamp 1.5
    0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x03, 0x00, // name length 3
    b'c', b'a', b'm', 0x03, // op SCHED_ON
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x3E, 0x40, // sched_time 30.0
    0x1F, 0xC8, // crc 0xc81f
];

const POWER_CHANNEL_CONTROL_BE: &[u8] = &[
    // header: sync, mgid 309, size 14
    0xFE, 0x54, 0x01, 0x35, 0x00, 0x0E, 0x3F, 0xF8, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // timestamp 1.5
    0x40, 0x01, 0x05, 0x20, 0x00, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x00, 0x03, // name length 3
    b'c', b'a', b'm', 0x03, // op SCHED_ON
    0x40, 0x3E, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // sched_time 30.0
    0x7B, 0x30, // crc 0x7b30
];

const SET_PWM_LE: &[u8] = &[
    // header: sync, mgid 315, size 9
    0x54, 0xFE, 0x3B, 0x01, 0x09, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8,
    0x3F, // timestamp 1.5
    0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x02, // id 2
    0x20, 0x4E, 0x00, 0x00, // period 20000
    0xDC, 0x05, 0x00, 0x00, // duty_cycle 1500
    0x4F, 0xCC, // crc 0xcc4f
];

const SET_PWM_BE: &[u8] = &[
    // header: sync, mgid 315, size 9
    0xFE, 0x54, 0x01, 0x3B, 0x00, 0x09, 0x3F, 0xF8, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // timestamp 1.5
    0x40, 0x01, 0x05, 0x20, 0x00, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x02, // id 2
    0x00, 0x00, 0x4E, 0x20, // period 20000
    0x00, 0x00, 0x05, 0xDC, // duty_cycle 1500
    0xCC, 0x6D, // crc 0xcc6d
];

const REMOTE_ACTIONS_LE: &[u8] = &[
    // header: sync, mgid 305, size 24
    0x54, 0xFE, 0x31, 0x01, 0x18, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8,
    0x3F, // timestamp 1.5
    0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x16, 0x00, // actions length 22
    b'P', b'r', b'o', b'p', b'e', b'l', b'l', b'e', b'r', b'=', b'0', b'.', b'6', b',', b'L', b'i',
    b'g', b'h', b't', b's', b'=', b'1', 0xD5, 0xC4, // crc 0xc4d5
];

const REMOTE_ACTIONS_BE: &[u8] = &[
    // header: sync, mgid 305, size 24
    0xFE, 0x54, 0x01, 0x31, 0x00, 0x18, 0x3F, 0xF8, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // timestamp 1.5
    0x40, 0x01, 0x05, 0x20, 0x00, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x00, 0x16, // actions length 22
    b'P', b'r', b'o', b'p', b'e', b'l', b'l', b'e', b'r', b'=', b'0', b'.', b'6', b',', b'L', b'i',
    b'g', b'h', b't', b's', b'=', b'1', 0x1B, 0xE7, // crc 0x1be7
];

const ANNOUNCE_LE: &[u8] = &[
    // header: sync, mgid 151, size 54
    0x54, 0xFE, 0x97, 0x00, 0x36, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8,
    0x3F, // timestamp 1.5
    0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x03, 0x00, // sys_name length 3
    b's', b'k', b'y', 0x04, // sys_type UAV
    0xFF, 0xFF, // owner 0xFFFF
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xE0, 0x3F, // lat 0.5
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xC0, // lon -2.0
    0x00, 0x00, 0xC8, 0x42, // height 100.0
    0x18, 0x00, // services length 24
    b'i', b'm', b'c', b'+', b'u', b'd', b'p', b':', b'/', b'/', b'1', b'0', b'.', b'0', b'.', b'0',
    b'.', b'5', b':', b'6', b'0', b'0', b'2', b'/', 0x94, 0x73, // crc 0x7394
];

const ANNOUNCE_BE: &[u8] = &[
    // header: sync, mgid 151, size 54
    0xFE, 0x54, 0x00, 0x97, 0x00, 0x36, 0x3F, 0xF8, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // timestamp 1.5
    0x40, 0x01, 0x05, 0x20, 0x00, 0xFF, // src 0x4001/5, dst 0x2000/255
    0x00, 0x03, // sys_name length 3
    b's', b'k', b'y', 0x04, // sys_type UAV
    0xFF, 0xFF, // owner 0xFFFF
    0x3F, 0xE0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // lat 0.5
    0xC0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // lon -2.0
    0x42, 0xC8, 0x00, 0x00, // height 100.0
    0x00, 0x18, // services length 24
    b'i', b'm', b'c', b'+', b'u', b'd', b'p', b':', b'/', b'/', b'1', b'0', b'.', b'0', b'.', b'0',
    b'.', b'5', b':', b'6', b'0', b'0', b'2', b'/', 0xB7, 0x2B, // crc 0xb72b
];

/// Decodes `bytes`, checks the header and byte order, and returns the message.
fn decode_fixture(bytes: &[u8], order: ByteOrder, mgid: u16, size: u16) -> Message {
    let Packet {
        header,
        byte_order,
        message,
    } = decode_datagram(bytes).expect("fixture decodes");
    assert_eq!(byte_order, order);
    assert_eq!(header.mgid, mgid);
    assert_eq!(header.size, size);
    assert_eq!(header.timestamp, 1.5);
    assert_eq!(header.src, 0x4001);
    assert_eq!(header.src_ent, 5);
    assert_eq!(header.dst, 0x2000);
    assert_eq!(header.dst_ent, 255);
    assert_eq!(header, fixture_header(mgid, size));
    message
}

/// The breakages every fixture must survive as errors. `last_field` is the field a
/// payload one byte short ends inside (`None` for an empty payload).
fn check_broken(bytes: &[u8], message: &'static str, last_field: Option<&'static str>) {
    let big = bytes[0] == 0xFE;
    let n = bytes.len();

    // Wrong CRC: the last byte flipped.
    let mut bad = bytes.to_vec();
    bad[n - 1] ^= 0x01;
    let good = if big {
        u16::from_be_bytes([bytes[n - 2], bytes[n - 1]])
    } else {
        u16::from_le_bytes([bytes[n - 2], bytes[n - 1]])
    };
    assert_eq!(
        decode_datagram(&bad),
        Err(DecodeError::BadCrc {
            received: if big { good ^ 0x0001 } else { good ^ 0x0100 },
            computed: good,
        }),
        "{message} wrong CRC"
    );
    assert_eq!(crc16_arc(&bytes[..n - 2]), good, "{message} CRC");

    // A payload one byte short, re-framed (size and CRC right): the last field runs
    // past the payload.
    let payload = payload_of(bytes);
    if let Some(field) = last_field {
        let short = reframe(bytes, &payload[..payload.len() - 1]);
        assert_eq!(
            decode_datagram(&short),
            Err(DecodeError::Truncated { message, field }),
            "{message} truncated"
        );
    }

    // One trailing byte, re-framed.
    let mut longer = payload.to_vec();
    longer.push(0x00);
    assert_eq!(
        decode_datagram(&reframe(bytes, &longer)),
        Err(DecodeError::TrailingBytes { message, extra: 1 }),
        "{message} trailing byte"
    );

    // The datagram cut by one byte, or one byte added, without fixing the size.
    let declared = payload.len();
    let cut = if declared == 0 {
        DecodeError::TooShort { len: n - 1 }
    } else {
        DecodeError::SizeMismatch {
            declared,
            actual: declared - 1,
        }
    };
    assert_eq!(decode_datagram(&bytes[..n - 1]), Err(cut), "{message} cut");
    let mut appended = bytes.to_vec();
    appended.push(0);
    assert_eq!(
        decode_datagram(&appended),
        Err(DecodeError::SizeMismatch {
            declared,
            actual: declared + 1
        }),
        "{message} appended"
    );
}

/// The encoder writes exactly the little-endian fixture from the decoded values.
fn check_encodes_to(le: &[u8]) {
    let packet = decode_datagram(le).expect("decodes");
    assert_eq!(
        encode_datagram(&packet.header, &packet.message).expect("encodes"),
        le
    );
}

#[test]
fn heartbeat() {
    for (bytes, order) in [
        (HEARTBEAT_LE, ByteOrder::Little),
        (HEARTBEAT_BE, ByteOrder::Big),
    ] {
        assert_eq!(
            decode_fixture(bytes, order, 150, 0),
            Message::Heartbeat,
            "{order:?}"
        );
        check_broken(bytes, "Heartbeat", None);
    }
    check_encodes_to(HEARTBEAT_LE);
}

#[test]
fn set_led_brightness() {
    for (bytes, order) in [
        (SET_LED_BRIGHTNESS_LE, ByteOrder::Little),
        (SET_LED_BRIGHTNESS_BE, ByteOrder::Big),
    ] {
        let Message::SetLedBrightness { name, value } = decode_fixture(bytes, order, 314, 7) else {
            panic!("{order:?}: not SetLedBrightness");
        };
        assert_eq!(name, "led0");
        assert_eq!(value, 200);
        check_broken(bytes, "SetLedBrightness", Some("value"));
    }
    check_encodes_to(SET_LED_BRIGHTNESS_LE);
}

#[test]
fn power_channel_control() {
    for (bytes, order) in [
        (POWER_CHANNEL_CONTROL_LE, ByteOrder::Little),
        (POWER_CHANNEL_CONTROL_BE, ByteOrder::Big),
    ] {
        let Message::PowerChannelControl {
            name,
            op,
            sched_time,
        } = decode_fixture(bytes, order, 309, 14)
        else {
            panic!("{order:?}: not PowerChannelControl");
        };
        assert_eq!(name, "cam");
        assert_eq!(op, ChannelOp::ScheduleOn);
        assert_eq!(sched_time, 30.0);
        check_broken(bytes, "PowerChannelControl", Some("sched_time"));
    }
    check_encodes_to(POWER_CHANNEL_CONTROL_LE);
}

#[test]
fn set_pwm() {
    for (bytes, order) in [
        (SET_PWM_LE, ByteOrder::Little),
        (SET_PWM_BE, ByteOrder::Big),
    ] {
        let Message::SetPwm {
            id,
            period,
            duty_cycle,
        } = decode_fixture(bytes, order, 315, 9)
        else {
            panic!("{order:?}: not SetPWM");
        };
        assert_eq!(id, 2);
        assert_eq!(period, 20_000);
        assert_eq!(duty_cycle, 1_500);
        check_broken(bytes, "SetPWM", Some("duty_cycle"));
    }
    check_encodes_to(SET_PWM_LE);
}

#[test]
fn remote_actions() {
    for (bytes, order) in [
        (REMOTE_ACTIONS_LE, ByteOrder::Little),
        (REMOTE_ACTIONS_BE, ByteOrder::Big),
    ] {
        let Message::RemoteActions { actions } = decode_fixture(bytes, order, 305, 24) else {
            panic!("{order:?}: not RemoteActions");
        };
        assert_eq!(actions, "Propeller=0.6,Lights=1");
        assert_eq!(
            imc_proto::parse_tuple_list(&actions),
            Ok(vec![
                ("Propeller".to_owned(), "0.6".to_owned()),
                ("Lights".to_owned(), "1".to_owned())
            ])
        );
        check_broken(bytes, "RemoteActions", Some("actions"));
    }
    check_encodes_to(REMOTE_ACTIONS_LE);
}

#[test]
fn announce() {
    for (bytes, order) in [
        (ANNOUNCE_LE, ByteOrder::Little),
        (ANNOUNCE_BE, ByteOrder::Big),
    ] {
        let Message::Announce(a) = decode_fixture(bytes, order, 151, 54) else {
            panic!("{order:?}: not Announce");
        };
        assert_eq!(a.sys_name, "sky");
        assert_eq!(a.sys_type, SystemType::Uav);
        assert_eq!(a.owner, 0xFFFF);
        assert_eq!(a.lat, 0.5);
        assert_eq!(a.lon, -2.0);
        assert_eq!(a.height, 100.0);
        assert_eq!(a.services, "imc+udp://10.0.0.5:6002/");
        check_broken(bytes, "Announce", Some("services"));
    }
    check_encodes_to(ANNOUNCE_LE);
}

#[test]
fn crc_check_value_and_fixture_crcs() {
    assert_eq!(crc16_arc(b"123456789"), 0xBB3D);
    // The CRC covers header and payload as they are on the wire, so the two byte
    // orders of one message have different CRCs.
    assert_eq!(crc16_arc(&HEARTBEAT_LE[..20]), 0x3371);
    assert_eq!(crc16_arc(&HEARTBEAT_BE[..20]), 0xBA80);
}

#[test]
fn same_message_in_both_orders_decodes_equal() {
    for (le, be) in [
        (HEARTBEAT_LE, HEARTBEAT_BE),
        (SET_LED_BRIGHTNESS_LE, SET_LED_BRIGHTNESS_BE),
        (POWER_CHANNEL_CONTROL_LE, POWER_CHANNEL_CONTROL_BE),
        (SET_PWM_LE, SET_PWM_BE),
        (REMOTE_ACTIONS_LE, REMOTE_ACTIONS_BE),
        (ANNOUNCE_LE, ANNOUNCE_BE),
    ] {
        let (a, b) = (decode_datagram(le), decode_datagram(be));
        let (a, b) = (a.expect("le"), b.expect("be"));
        assert_eq!(a.header, b.header);
        assert_eq!(a.message, b.message);
        // The big-endian helper the round-trip tests use agrees with the fixture.
        assert_eq!(common::to_big_endian(le), be);
    }
}

#[test]
fn hand_built_frame_matches_fixture() {
    // `frame_le` (used by the validation tests) builds the fixtures' header.
    assert_eq!(frame_le(315, payload_of(SET_PWM_LE)), SET_PWM_LE);
}
