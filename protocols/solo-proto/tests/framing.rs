//! The framer under hostile input: absurd lengths, bad frames followed by good ones,
//! adjacent frames, and the one-frame-per-datagram rule.

use bytes::{BufMut, BytesMut};
use solo_proto::{
    decode_datagram, ids, DatagramError, DecodeError, FrameError, Location, RawFrame, SoloMessage,
    TlvCodec, HEADER_LEN, MAX_VALUE_LEN,
};
use tokio_util::codec::{Decoder, Encoder};

fn frame(msg_type: u32, value: &[u8]) -> Vec<u8> {
    let mut v = msg_type.to_le_bytes().to_vec();
    v.extend_from_slice(&u32::try_from(value.len()).expect("small").to_le_bytes());
    v.extend_from_slice(value);
    v
}

fn set_shot(shot: i32) -> Vec<u8> {
    frame(ids::SET_CURRENT_SHOT, &shot.to_le_bytes())
}

#[test]
fn absurd_declared_length_is_refused_without_buffering() {
    let mut codec = TlvCodec::new();
    let mut buf = BytesMut::with_capacity(64);
    buf.extend_from_slice(&[0x02, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0x01, 0x02]);
    let capacity = buf.capacity();
    match codec.decode(&mut buf) {
        Err(FrameError::TooLong { declared, max }) => {
            assert_eq!(declared, 0xFFFF_FFFF);
            assert_eq!(max, MAX_VALUE_LEN);
        }
        other => panic!("expected TooLong, got {other:?}"),
    }
    // Nothing was reserved for the declared 4 GiB.
    assert_eq!(buf.capacity(), capacity);
}

#[test]
fn length_just_over_the_limit_is_refused_and_at_the_limit_waits() {
    let mut codec = TlvCodec::new();
    let over = u32::try_from(MAX_VALUE_LEN + 1).expect("fits");
    let mut buf = BytesMut::new();
    buf.put_u32_le(ids::SHOTMANAGER_ERROR);
    buf.put_u32_le(over);
    assert!(matches!(
        codec.decode(&mut buf),
        Err(FrameError::TooLong { declared, .. }) if declared == over
    ));

    // Exactly the limit is fine: the codec waits for the bytes without reserving them.
    let mut buf = BytesMut::with_capacity(16);
    buf.put_u32_le(ids::SHOTMANAGER_ERROR);
    buf.put_u32_le(u32::try_from(MAX_VALUE_LEN).expect("fits"));
    let capacity = buf.capacity();
    assert!(codec.decode(&mut buf).expect("header is fine").is_none());
    assert_eq!(buf.capacity(), capacity);
    assert_eq!(buf.len(), HEADER_LEN);
}

#[test]
fn a_custom_limit_applies() {
    let mut codec = TlvCodec::with_max_value_len(4);
    assert_eq!(codec.max_value_len(), 4);
    let mut buf = BytesMut::from(&frame(ids::LOCATION, &[0; 20])[..]);
    assert!(matches!(
        codec.decode(&mut buf),
        Err(FrameError::TooLong {
            declared: 20,
            max: 4
        })
    ));
    let mut buf = BytesMut::from(&set_shot(2)[..]);
    assert!(codec.decode(&mut buf).expect("fits").is_some());
}

#[test]
fn the_header_alone_is_not_a_frame() {
    let mut codec = TlvCodec::new();
    let mut buf = BytesMut::new();
    for b in [0x01, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00] {
        buf.put_u8(b);
        assert!(codec.decode(&mut buf).expect("partial").is_none());
    }
    buf.put_u8(0x00);
    assert!(codec.decode(&mut buf).expect("partial").is_none());
    assert_eq!(
        buf.len(),
        HEADER_LEN,
        "nothing consumed until the frame is whole"
    );
}

#[test]
fn wrong_length_frame_is_consumed_and_the_next_frame_decodes() {
    // A LOCATION with 19 bytes instead of 20, then a valid SET_CURRENT_SHOT.
    let mut bytes = frame(ids::LOCATION, &[0x11; 19]);
    bytes.extend_from_slice(&set_shot(1));
    let mut buf = BytesMut::from(&bytes[..]);
    let mut codec = TlvCodec::new();

    let bad = codec
        .decode(&mut buf)
        .expect("framed")
        .expect("whole frame");
    assert_eq!(bad.msg_type, ids::LOCATION);
    assert_eq!(bad.value.len(), 19);
    let err = bad.decode().expect_err("wrong length");
    assert_eq!(
        err,
        DecodeError::WrongLength {
            msg_type: ids::LOCATION,
            name: "location",
            expected: 20,
            got: 19
        }
    );
    assert_eq!(err.kind(), "wrong_length");

    let good = codec
        .decode(&mut buf)
        .expect("framed")
        .expect("whole frame");
    assert_eq!(good.decode(), Ok(SoloMessage::SetCurrentShot(1)));
    assert!(buf.is_empty());
}

#[test]
fn wrong_length_for_an_empty_message_is_consumed_too() {
    // SOLO_PAUSE with the 8 bytes the spec's table claims: refused, stream in sync.
    let mut bytes = frame(ids::PAUSE, &[0; 8]);
    bytes.extend_from_slice(&set_shot(0));
    let mut buf = BytesMut::from(&bytes[..]);
    let mut codec = TlvCodec::new();
    let first = codec.decode(&mut buf).expect("framed").expect("frame");
    assert!(matches!(
        first.decode(),
        Err(DecodeError::WrongLength {
            expected: 0,
            got: 8,
            ..
        })
    ));
    let second = codec.decode(&mut buf).expect("framed").expect("frame");
    assert_eq!(second.decode(), Ok(SoloMessage::SetCurrentShot(0)));
}

#[test]
fn unknown_type_is_consumed_and_the_next_frame_decodes() {
    // 27 is SOLO_POWER_STATE in the reference, which skymesh does not speak.
    let mut bytes = frame(27, &[1, 2, 3, 4, 5]);
    bytes.extend_from_slice(&frame(4242, &[]));
    bytes.extend_from_slice(&set_shot(5));
    let mut buf = BytesMut::from(&bytes[..]);
    let mut codec = TlvCodec::new();

    let unknown = codec.decode(&mut buf).expect("framed").expect("frame");
    assert_eq!(unknown.decode(), Err(DecodeError::UnknownType(27)));
    assert_eq!(DecodeError::UnknownType(27).kind(), "unknown_type");
    let empty_unknown = codec.decode(&mut buf).expect("framed").expect("frame");
    assert_eq!(empty_unknown.decode(), Err(DecodeError::UnknownType(4242)));
    let good = codec.decode(&mut buf).expect("framed").expect("frame");
    assert_eq!(good.decode(), Ok(SoloMessage::SetCurrentShot(5)));
    assert!(buf.is_empty());
}

#[test]
fn invalid_value_is_consumed_and_the_next_frame_decodes() {
    let mut nan_location = Vec::new();
    nan_location.extend_from_slice(&f64::NAN.to_le_bytes());
    nan_location.extend_from_slice(&0f64.to_le_bytes());
    nan_location.extend_from_slice(&0f32.to_le_bytes());
    let mut bytes = frame(ids::LOCATION, &nan_location);
    bytes.extend_from_slice(&set_shot(2));
    let mut buf = BytesMut::from(&bytes[..]);
    let mut codec = TlvCodec::new();
    let bad = codec.decode(&mut buf).expect("framed").expect("frame");
    let err = bad.decode().expect_err("NaN");
    assert_eq!(err.kind(), "invalid_value");
    assert_eq!(err.msg_type(), ids::LOCATION);
    let good = codec.decode(&mut buf).expect("framed").expect("frame");
    assert_eq!(good.decode(), Ok(SoloMessage::SetCurrentShot(2)));
}

#[test]
fn adjacent_frames_in_one_buffer_all_decode() {
    let messages = [
        SoloMessage::SetCurrentShot(1),
        SoloMessage::Pause,
        SoloMessage::Location(Location {
            lat_deg: 1.0,
            lon_deg: 2.0,
            alt_m: 3.0,
        }),
        SoloMessage::GoProRequestState,
        SoloMessage::ShotOptions { cruise_speed: 4.0 },
    ];
    let mut codec = TlvCodec::new();
    let mut buf = BytesMut::new();
    for m in &messages {
        codec.encode(m, &mut buf).expect("encode");
    }
    let mut decoded = Vec::new();
    while let Some(f) = codec.decode(&mut buf).expect("framed") {
        decoded.push(f.decode().expect("valid"));
    }
    assert_eq!(decoded, messages);
    assert!(buf.is_empty());
}

#[test]
fn raw_frames_forward_unchanged() {
    let original = set_shot(6);
    let mut codec = TlvCodec::new();
    let mut buf = BytesMut::from(&original[..]);
    let raw: RawFrame = codec.decode(&mut buf).expect("framed").expect("frame");
    let mut out = BytesMut::new();
    codec.encode(&raw, &mut out).expect("encode");
    assert_eq!(&out[..], &original[..]);
    // Owned messages encode the same way as borrowed ones.
    let mut owned = BytesMut::new();
    codec
        .encode(SoloMessage::SetCurrentShot(6), &mut owned)
        .expect("encode");
    assert_eq!(&owned[..], &original[..]);
}

fn location_datagram() -> Vec<u8> {
    let mut value = Vec::new();
    value.extend_from_slice(&37.5f64.to_le_bytes());
    value.extend_from_slice(&(-122.25f64).to_le_bytes());
    value.extend_from_slice(&10.0f32.to_le_bytes());
    frame(ids::LOCATION, &value)
}

#[test]
fn datagram_with_one_whole_frame_decodes() {
    assert_eq!(
        decode_datagram(&location_datagram()),
        Ok(SoloMessage::Location(Location {
            lat_deg: 37.5,
            lon_deg: -122.25,
            alt_m: 10.0
        }))
    );
}

#[test]
fn datagram_errors() {
    let good = location_datagram();
    assert_eq!(
        decode_datagram(&good[..5]),
        Err(DatagramError::ShortHeader { got: 5 })
    );
    assert_eq!(
        decode_datagram(&good[..good.len() - 1]),
        Err(DatagramError::Truncated {
            declared: 20,
            got: 19
        })
    );
    let mut long = good.clone();
    long.extend_from_slice(&[0, 0]);
    let err = decode_datagram(&long).expect_err("trailing");
    assert_eq!(
        err,
        DatagramError::TrailingBytes {
            declared: 20,
            extra: 2
        }
    );
    assert_eq!(err.kind(), "trailing_bytes");
    // Two frames in one datagram are trailing bytes too.
    let mut two = good.clone();
    two.extend_from_slice(&good);
    assert!(matches!(
        decode_datagram(&two),
        Err(DatagramError::TrailingBytes { extra: 28, .. })
    ));
    // A huge declared length is just a truncated datagram.
    let mut huge = good.clone();
    huge[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(
        decode_datagram(&huge),
        Err(DatagramError::Truncated {
            declared: u32::MAX,
            ..
        })
    ));
    // Value errors come through with their own kind.
    let err = decode_datagram(&frame(ids::LOCATION, &[0xFF; 20])).expect_err("NaN");
    assert_eq!(err.kind(), "invalid_value");
    assert_eq!(
        decode_datagram(&frame(99, &[])),
        Err(DatagramError::Decode(DecodeError::UnknownType(99)))
    );
}
