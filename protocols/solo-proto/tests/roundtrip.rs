//! Every message type round-trips at its exact length; random valid messages survive
//! encode → TlvCodec (random chunking) → decode consuming every byte; random bytes
//! never panic.

mod common;

use bytes::{BufMut, BytesMut};
use proptest::prelude::*;
use solo_proto::{
    decode_datagram, expected_len, known_types, message_name, SoloMessage, TlvCodec, ValueLen,
    HEADER_LEN,
};
use tokio_util::codec::{Decoder, Encoder};

#[test]
fn every_type_has_a_sample_and_round_trips_at_its_exact_length() {
    let samples = common::samples();
    let sample_types: Vec<u32> = samples.iter().map(SoloMessage::msg_type).collect();
    let known: Vec<u32> = known_types().collect();
    assert_eq!(sample_types, known, "one sample per type, in catalog order");

    for msg in &samples {
        let t = msg.msg_type();
        assert_eq!(message_name(t), Some(msg.name()));
        let value = msg.value_bytes();
        match expected_len(t).expect("known type") {
            ValueLen::Exact(n) => assert_eq!(value.len(), n, "{}", msg.name()),
            ValueLen::Variable { max } => assert!(value.len() <= max, "{}", msg.name()),
        }
        let frame = msg.to_bytes();
        assert_eq!(frame.len(), HEADER_LEN + value.len());
        assert_eq!(frame[0..4], t.to_le_bytes());
        assert_eq!(
            frame[4..8],
            u32::try_from(value.len()).expect("small").to_le_bytes()
        );
        assert_eq!(&frame[HEADER_LEN..], &value[..]);
        assert_eq!(
            SoloMessage::decode(t, &value).as_ref(),
            Ok(msg),
            "{}",
            msg.name()
        );
        assert_eq!(msg.validate(), Ok(()), "{}", msg.name());
        assert_eq!(decode_datagram(&frame).as_ref(), Ok(msg), "{}", msg.name());

        // One byte more or less is refused for every fixed-length type.
        if let Some(ValueLen::Exact(n)) = expected_len(t) {
            let longer = vec![0u8; n + 1];
            assert!(SoloMessage::decode(t, &longer).is_err(), "{}", msg.name());
            if n > 0 {
                assert!(
                    SoloMessage::decode(t, &value[..n - 1]).is_err(),
                    "{}",
                    msg.name()
                );
            }
        }
    }
}

#[test]
fn encode_appends_after_existing_bytes() {
    let mut buf = BytesMut::from(&b"xyz"[..]);
    SoloMessage::SetCurrentShot(2).encode(&mut buf);
    assert_eq!(&buf[..3], b"xyz");
    assert_eq!(&buf[3..], &[1, 0, 0, 0, 4, 0, 0, 0, 2, 0, 0, 0]);
}

/// Feeds `bytes` to a fresh codec in the given chunk sizes (cycled), decoding every
/// frame; returns the decoded frames' results and what was left in the buffer.
fn feed(
    bytes: &[u8],
    chunks: &[usize],
) -> (Vec<Result<SoloMessage, solo_proto::DecodeError>>, usize) {
    let mut codec = TlvCodec::new();
    let mut buf = BytesMut::new();
    let mut out = Vec::new();
    let mut pos = 0;
    let mut i = 0;
    while pos < bytes.len() {
        let n = chunks[i % chunks.len()].max(1).min(bytes.len() - pos);
        i += 1;
        buf.extend_from_slice(&bytes[pos..pos + n]);
        pos += n;
        loop {
            match codec.decode(&mut buf) {
                Ok(Some(frame)) => out.push(frame.decode()),
                Ok(None) => break,
                // Random input may declare an oversized value: the stream ends there.
                Err(_) => return (out, buf.len()),
            }
        }
    }
    (out, buf.len())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_valid_messages_round_trip_through_the_codec(
        messages in prop::collection::vec(common::arb_message(), 1..12),
        chunks in prop::collection::vec(1usize..64, 1..8),
    ) {
        let mut codec = TlvCodec::new();
        let mut bytes = BytesMut::new();
        for m in &messages {
            codec.encode(m, &mut bytes).expect("encode");
            // Validation accepts everything the strategies build.
            prop_assert_eq!(m.validate(), Ok(()));
        }
        let (decoded, left) = feed(&bytes, &chunks);
        prop_assert_eq!(left, 0, "every byte consumed");
        let decoded: Vec<SoloMessage> = decoded.into_iter().map(|r| r.expect("valid")).collect();
        prop_assert_eq!(decoded, messages);
    }

    #[test]
    fn random_bytes_never_panic(
        bytes in prop::collection::vec(any::<u8>(), 0..512),
        chunks in prop::collection::vec(1usize..32, 1..6),
    ) {
        let _ = feed(&bytes, &chunks);
        let _ = decode_datagram(&bytes);
    }

    #[test]
    fn random_values_of_known_types_never_panic_and_accepted_values_re_encode_exactly(
        type_index in 0usize..48,
        value in prop::collection::vec(any::<u8>(), 0..64),
    ) {
        let msg_type = known_types().nth(type_index).expect("48 types");
        // Half the time give the value its exact length, so decoding gets past the
        // length check and the field checks see random bits (NaN, ±∞, big enums).
        let value = match expected_len(msg_type) {
            Some(ValueLen::Exact(n)) if value.len() >= n && value.len() % 2 == 0 => value[..n].to_vec(),
            _ => value,
        };
        if let Ok(msg) = SoloMessage::decode(msg_type, &value) {
            prop_assert_eq!(msg.msg_type(), msg_type);
            if let Some(ValueLen::Exact(_)) = expected_len(msg_type) {
                let mut again = BytesMut::new();
                msg.encode_value(&mut again);
                prop_assert_eq!(&again[..], &value[..]);
            }
        }
    }

    #[test]
    fn random_frames_with_valid_headers_keep_the_stream_in_sync(
        junk in prop::collection::vec((any::<u32>(), prop::collection::vec(any::<u8>(), 0..48)), 0..6),
        tail in common::arb_message(),
        chunks in prop::collection::vec(1usize..40, 1..6),
    ) {
        // Arbitrary (type, value) frames with honest lengths, then one valid message:
        // whatever the junk decodes to, the last frame is the valid message.
        let mut bytes = BytesMut::new();
        for (t, v) in &junk {
            bytes.put_u32_le(*t);
            bytes.put_u32_le(u32::try_from(v.len()).expect("small"));
            bytes.put_slice(v);
        }
        tail.encode(&mut bytes);
        let (decoded, left) = feed(&bytes, &chunks);
        prop_assert_eq!(left, 0);
        prop_assert_eq!(decoded.len(), junk.len() + 1);
        prop_assert_eq!(decoded.last().cloned(), Some(Ok(tail)));
    }
}
