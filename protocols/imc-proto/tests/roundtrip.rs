//! Every message type round-trips through encode → decode in both byte orders (the
//! big-endian datagram made by the test's own converter); random valid messages do
//! the same; random bytes, random payloads behind a valid frame and every prefix of
//! a datagram never panic, and whatever decodes re-encodes to the same bytes.

mod common;

use common::{frame_le, payload_of, to_big_endian};
use imc_proto::{
    decode_datagram, encode_datagram, known_ids, message_name, ByteOrder, Header, Message, CRC_LEN,
    HEADER_LEN,
};
use proptest::prelude::*;

/// encode → decode little-endian, and through the big-endian converter.
fn round_trip(header: &Header, message: &Message) {
    let le = encode_datagram(header, message).expect("encodes");
    assert_eq!(le[0..2], [0x54, 0xFE], "little-endian sync on the wire");
    assert_eq!(le[2..4], message.id().to_le_bytes());
    let size = le.len() - HEADER_LEN - CRC_LEN;
    assert_eq!(le[4..6], u16::try_from(size).expect("fits").to_le_bytes());

    let p = decode_datagram(&le).expect("little-endian decodes");
    assert_eq!(p.byte_order, ByteOrder::Little);
    assert_eq!(&p.message, message);
    let expected_header = Header {
        mgid: message.id(),
        size: u16::try_from(size).expect("fits"),
        ..*header
    };
    assert_eq!(p.header, expected_header);

    let be = to_big_endian(&le);
    let q = decode_datagram(&be).expect("big-endian decodes");
    assert_eq!(q.byte_order, ByteOrder::Big);
    assert_eq!(&q.message, message);
    assert_eq!(q.header, expected_header);
    // Re-encoding what came in big-endian gives the little-endian datagram again.
    assert_eq!(encode_datagram(&q.header, &q.message).expect("encodes"), le);
}

#[test]
fn every_message_type_has_a_sample_and_round_trips() {
    let samples = common::samples();
    let ids: Vec<u16> = samples.iter().map(Message::id).collect();
    assert_eq!(ids, known_ids().collect::<Vec<_>>(), "one sample per id");
    for m in &samples {
        assert_eq!(message_name(m.id()), Some(m.name()));
        assert_eq!(m.validate(), Ok(()), "{}", m.name());
        round_trip(&common::fixture_header(0, 0), m);
    }
}

#[test]
fn every_prefix_of_every_sample_is_refused() {
    for m in common::samples() {
        let bytes = encode_datagram(&common::fixture_header(0, 0), &m).expect("encodes");
        for cut in 0..bytes.len() {
            assert!(
                decode_datagram(&bytes[..cut]).is_err(),
                "{} cut at {cut}",
                m.name()
            );
        }
        // And every shorter payload, re-framed, is refused by the fields themselves.
        let payload = payload_of(&bytes);
        for cut in 0..payload.len() {
            let short = frame_le(m.id(), &payload[..cut]);
            assert!(
                decode_datagram(&short).is_err(),
                "{} payload cut at {cut}",
                m.name()
            );
        }
    }
}

#[test]
fn ids_and_names_follow_facts() {
    let expected: &[(u16, &str)] = &[
        (150, "Heartbeat"),
        (151, "Announce"),
        (300, "CameraZoom"),
        (301, "SetThrusterActuation"),
        (302, "SetServoPosition"),
        (303, "SetControlSurfaceDeflection"),
        (304, "RemoteActionsRequest"),
        (305, "RemoteActions"),
        (306, "ButtonEvent"),
        (307, "LcdControl"),
        (308, "PowerOperation"),
        (309, "PowerChannelControl"),
        (310, "QueryPowerChannelState"),
        (311, "PowerChannelState"),
        (312, "LedBrightness"),
        (313, "QueryLedBrightness"),
        (314, "SetLedBrightness"),
        (315, "SetPWM"),
        (316, "PWM"),
        (2000, "GpioState"),
        (2001, "GpioStateGet"),
        (2002, "GpioStateSet"),
    ];
    let got: Vec<(u16, &str)> = known_ids()
        .map(|id| (id, message_name(id).expect("named")))
        .collect();
    assert_eq!(got, expected);
    assert_eq!(message_name(317), None);
}

proptest! {
    #[test]
    fn random_valid_messages_round_trip_in_both_orders(
        header in common::header(),
        message in common::message(),
    ) {
        round_trip(&header, &message);
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..128)) {
        let _ = decode_datagram(&bytes);
    }

    #[test]
    fn random_bytes_with_a_sync_never_panic(
        big in any::<bool>(),
        rest in prop::collection::vec(any::<u8>(), 0..128),
    ) {
        let mut bytes = if big { vec![0xFE, 0x54] } else { vec![0x54, 0xFE] };
        bytes.extend_from_slice(&rest);
        let _ = decode_datagram(&bytes);
    }

    /// A valid frame around random payload bytes reaches the field decoders; whatever
    /// they accept re-encodes to exactly the same datagram.
    #[test]
    fn random_payloads_behind_a_valid_frame(
        pick in 0usize..24,
        payload in prop::collection::vec(any::<u8>(), 0..48),
    ) {
        let ids: Vec<u16> = known_ids().chain([0, 65_535]).collect();
        let id = ids[pick % ids.len()];
        let bytes = frame_le(id, &payload);
        if let Ok(p) = decode_datagram(&bytes) {
            prop_assert_eq!(p.message.id(), id);
            prop_assert_eq!(encode_datagram(&p.header, &p.message).expect("encodes"), bytes.clone());
            let be = decode_datagram(&to_big_endian(&bytes)).expect("big-endian decodes");
            prop_assert_eq!(be.message, p.message);
        }
    }
}
