//! Every way a datagram is refused, each its own [`DecodeError`] variant, built by hand
//! (payloads written byte by byte behind a valid frame so the check under test is the
//! one that fires), and the encoder's two limits.

mod common;

use std::collections::BTreeSet;

use common::{fixture_header, frame_le, reframe, to_big_endian};
use imc_proto::{
    decode_datagram, encode_datagram, DecodeError, EncodeError, Message, CRC_LEN, HEADER_LEN,
    MAX_DATAGRAM,
};

fn invalid(message: &'static str, field: &'static str, value: f64) -> Result<(), DecodeError> {
    Err(DecodeError::InvalidValue {
        message,
        field,
        value,
    })
}

/// Decodes `payload` as message `id` behind a valid little-endian frame.
fn decode_payload(id: u16, payload: &[u8]) -> Result<(), DecodeError> {
    decode_datagram(&frame_le(id, payload)).map(|_| ())
}

fn f32le(v: f32) -> [u8; 4] {
    v.to_le_bytes()
}

fn f64le(v: f64) -> [u8; 8] {
    v.to_le_bytes()
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

#[test]
fn too_short() {
    assert_eq!(decode_datagram(&[]), Err(DecodeError::TooShort { len: 0 }));
    assert_eq!(
        decode_datagram(&[0x54, 0xFE]),
        Err(DecodeError::TooShort { len: 2 })
    );
    let heartbeat = frame_le(150, &[]);
    assert_eq!(heartbeat.len(), HEADER_LEN + CRC_LEN);
    assert_eq!(
        decode_datagram(&heartbeat[..21]),
        Err(DecodeError::TooShort { len: 21 })
    );
}

#[test]
fn too_long() {
    // Checked before anything else: no buffering or CRC over an oversized datagram.
    let mut big = frame_le(150, &[]);
    big.resize(MAX_DATAGRAM + 1, 0);
    assert_eq!(
        decode_datagram(&big),
        Err(DecodeError::TooLong {
            len: MAX_DATAGRAM + 1,
            max: MAX_DATAGRAM
        })
    );
}

#[test]
fn bad_sync() {
    let mut bytes = frame_le(150, &[]);
    bytes[0] = 0x55;
    assert_eq!(decode_datagram(&bytes), Err(DecodeError::BadSync(0xFE55)));
    // The sync as a little-endian sender writes it, but both bytes equal.
    bytes[0..2].copy_from_slice(&[0xFE, 0xFE]);
    assert_eq!(decode_datagram(&bytes), Err(DecodeError::BadSync(0xFEFE)));
}

#[test]
fn size_mismatch_both_ways() {
    let mut bytes = frame_le(313, &[0x01, 0x00, b'a']);
    bytes[4] = 4; // declares 4, holds 3
    assert_eq!(
        decode_datagram(&bytes),
        Err(DecodeError::SizeMismatch {
            declared: 4,
            actual: 3
        })
    );
    bytes[4] = 2; // declares 2, holds 3
    assert_eq!(
        decode_datagram(&bytes),
        Err(DecodeError::SizeMismatch {
            declared: 2,
            actual: 3
        })
    );
    // An absurd size is only compared, never allocated.
    bytes[4..6].copy_from_slice(&[0xFF, 0xFF]);
    assert_eq!(
        decode_datagram(&bytes),
        Err(DecodeError::SizeMismatch {
            declared: 65_535,
            actual: 3
        })
    );
}

#[test]
fn crc_is_checked_before_the_id_and_fields() {
    // An unknown id and a garbage payload: the CRC is what fails.
    let mut bytes = frame_le(999, &[0xFF; 5]);
    let n = bytes.len();
    bytes[n - 2] ^= 0xFF;
    assert!(matches!(
        decode_datagram(&bytes),
        Err(DecodeError::BadCrc { .. })
    ));
    // A CRC written in the wrong byte order is a bad CRC too.
    let mut swapped = frame_le(150, &[]);
    assert_ne!(swapped[20], swapped[21]);
    swapped.swap(20, 21);
    assert!(matches!(
        decode_datagram(&swapped),
        Err(DecodeError::BadCrc { .. })
    ));
}

#[test]
fn unknown_id_with_valid_header_and_crc() {
    assert_eq!(
        decode_datagram(&frame_le(999, &[1, 2, 3])),
        Err(DecodeError::UnknownId(999))
    );
    assert_eq!(
        decode_datagram(&frame_le(0xFFFF, &[])),
        Err(DecodeError::UnknownId(0xFFFF))
    );
    // Big-endian too: the id is read in the sender's order.
    let mut be = frame_le(150, &[]);
    be = to_big_endian(&be);
    be[2..4].copy_from_slice(&[0x03, 0xE7]); // 999 big-endian
    let be = reframe(&be, &[]);
    assert_eq!(decode_datagram(&be), Err(DecodeError::UnknownId(999)));
}

#[test]
fn truncated_and_trailing() {
    // GpioStateSet: the name claims 5 bytes, 2 follow.
    assert_eq!(
        decode_payload(2002, &[0x05, 0x00, b'a', b'b']),
        Err(DecodeError::Truncated {
            message: "GpioStateSet",
            field: "name"
        })
    );
    // The length prefix itself cut.
    assert_eq!(
        decode_payload(2001, &[0x05]),
        Err(DecodeError::Truncated {
            message: "GpioStateGet",
            field: "name"
        })
    );
    // Fields with no payload at all.
    assert_eq!(
        decode_payload(306, &[]),
        Err(DecodeError::Truncated {
            message: "ButtonEvent",
            field: "button"
        })
    );
    // QueryPowerChannelState has no fields: any byte is trailing.
    assert_eq!(
        decode_payload(310, &[0, 0, 0]),
        Err(DecodeError::TrailingBytes {
            message: "QueryPowerChannelState",
            extra: 3
        })
    );
}

#[test]
fn text_must_be_utf8() {
    assert_eq!(
        decode_payload(313, &[0x02, 0x00, 0xC3, 0x28]),
        Err(DecodeError::InvalidText {
            message: "QueryLedBrightness",
            field: "name"
        })
    );
    assert_eq!(
        decode_payload(307, &[0x03, 0x01, 0x00, 0xFF]),
        Err(DecodeError::InvalidText {
            message: "LcdControl",
            field: "text"
        })
    );
    // Multi-byte UTF-8 is fine.
    assert_eq!(decode_payload(313, &[0x02, 0x00, 0xC3, 0xA9]), Ok(()));
}

#[test]
fn enumerations_out_of_range() {
    let name = [0x01, 0x00, b'x'];
    assert_eq!(
        decode_payload(300, &[1, 2, 4]),
        invalid("CameraZoom", "action", 4.0)
    );
    assert_eq!(
        decode_payload(304, &[3, 0, 0]),
        invalid("RemoteActionsRequest", "op", 3.0)
    );
    assert_eq!(
        decode_payload(307, &[5, 0, 0]),
        invalid("LcdControl", "op", 5.0)
    );
    assert_eq!(
        decode_payload(308, &cat(&[&[7], &f32le(0.0), &f64le(0.0)])),
        invalid("PowerOperation", "op", 7.0)
    );
    assert_eq!(
        decode_payload(309, &cat(&[&name, &[8], &f64le(0.0)])),
        invalid("PowerChannelControl", "op", 8.0)
    );
    // RESTART (7) is accepted although the document's range column says max=6.
    assert_eq!(
        decode_payload(309, &cat(&[&name, &[7], &f64le(0.0)])),
        Ok(())
    );
    assert_eq!(
        decode_payload(311, &cat(&[&name, &[2]])),
        invalid("PowerChannelState", "state", 2.0)
    );
    let announce = |sys_type: u8| {
        cat(&[
            &name,
            &[sys_type],
            &[0xFF, 0xFF],
            &f64le(0.0),
            &f64le(0.0),
            &f32le(0.0),
            &[0, 0],
        ])
    };
    assert_eq!(decode_payload(151, &announce(8)), Ok(()));
    assert_eq!(
        decode_payload(151, &announce(9)),
        invalid("Announce", "sys_type", 9.0)
    );
}

#[test]
fn actuator_ranges() {
    let thr = |v: f32| decode_payload(301, &cat(&[&[0], &f32le(v)]));
    assert_eq!(thr(1.0), Ok(()));
    assert_eq!(thr(-1.0), Ok(()));
    assert_eq!(
        thr(1.0001),
        invalid("SetThrusterActuation", "value", f64::from(1.0001f32))
    );
    assert_eq!(thr(-2.0), invalid("SetThrusterActuation", "value", -2.0));
    assert!(matches!(
        thr(f32::NAN),
        Err(DecodeError::InvalidValue { field: "value", .. })
    ));

    let servo = |v: f32| decode_payload(302, &cat(&[&[0], &f32le(v)]));
    assert_eq!(servo(std::f32::consts::FRAC_PI_2), Ok(()));
    assert_eq!(servo(-std::f32::consts::FRAC_PI_2), Ok(()));
    assert_eq!(
        servo(1.58),
        invalid("SetServoPosition", "value", f64::from(1.58f32))
    );
    assert_eq!(
        servo(f32::INFINITY),
        invalid("SetServoPosition", "value", f64::INFINITY)
    );

    let surface = |v: f32| decode_payload(303, &cat(&[&[0], &f32le(v)]));
    assert_eq!(surface(100.0), Ok(()));
    assert_eq!(
        surface(f32::NEG_INFINITY),
        invalid("SetControlSurfaceDeflection", "angle", f64::NEG_INFINITY)
    );
    assert!(surface(f32::NAN).is_err());
}

#[test]
fn pwm_duty_cycle_within_period() {
    let pwm = |id: u16, period: u32, duty: u32| {
        decode_payload(
            id,
            &cat(&[&[1], &period.to_le_bytes(), &duty.to_le_bytes()]),
        )
    };
    for (id, name) in [(315, "SetPWM"), (316, "PWM")] {
        assert_eq!(pwm(id, 20_000, 20_000), Ok(()));
        assert_eq!(pwm(id, 0, 0), Ok(()));
        assert_eq!(
            pwm(id, 20_000, 20_001),
            invalid(name, "duty_cycle", 20_001.0)
        );
    }
}

#[test]
fn announce_position_and_height() {
    let announce = |lat: f64, lon: f64, height: f32| {
        decode_payload(
            151,
            &cat(&[
                &[0, 0, 4, 0, 0],
                &f64le(lat),
                &f64le(lon),
                &f32le(height),
                &[0, 0],
            ]),
        )
    };
    let half_pi = std::f64::consts::FRAC_PI_2;
    let pi = std::f64::consts::PI;
    assert_eq!(announce(half_pi, -pi, -50.0), Ok(()));
    assert_eq!(announce(1.6, 0.0, 0.0), invalid("Announce", "lat", 1.6));
    assert_eq!(announce(0.0, -3.2, 0.0), invalid("Announce", "lon", -3.2));
    assert!(matches!(
        announce(f64::NAN, 0.0, 0.0),
        Err(DecodeError::InvalidValue { field: "lat", .. })
    ));
    assert_eq!(
        announce(0.0, f64::INFINITY, 0.0),
        invalid("Announce", "lon", f64::INFINITY)
    );
    assert!(matches!(
        announce(0.0, 0.0, f32::NAN),
        Err(DecodeError::InvalidValue {
            field: "height",
            ..
        })
    ));
}

#[test]
fn power_times() {
    let op = |time_remain: f32, sched_time: f64| {
        decode_payload(308, &cat(&[&[1], &f32le(time_remain), &f64le(sched_time)]))
    };
    assert_eq!(op(-1.0, -1.0), Ok(()));
    assert_eq!(
        op(f32::INFINITY, 0.0),
        invalid("PowerOperation", "time_remain", f64::INFINITY)
    );
    assert!(matches!(
        op(0.0, f64::NAN),
        Err(DecodeError::InvalidValue {
            field: "sched_time",
            ..
        })
    ));

    let channel =
        |sched_time: f64| decode_payload(309, &cat(&[&[1, 0, b'x'], &[3], &f64le(sched_time)]));
    assert_eq!(channel(0.0), Ok(()));
    assert_eq!(channel(3600.0), Ok(()));
    assert_eq!(
        channel(-1.0),
        invalid("PowerChannelControl", "sched_time", -1.0)
    );
    assert_eq!(
        channel(f64::INFINITY),
        invalid("PowerChannelControl", "sched_time", f64::INFINITY)
    );
}

#[test]
fn every_decode_error_kind_is_reachable() {
    let mut heartbeat_bad_crc = frame_le(150, &[]);
    heartbeat_bad_crc[21] ^= 1;
    let mut bad_sync = frame_le(150, &[]);
    bad_sync[0] = 0;
    let mut mismatch = frame_le(150, &[]);
    mismatch[4] = 1;
    let cases: Vec<Vec<u8>> = vec![
        vec![0; 3],
        vec![0; MAX_DATAGRAM + 1],
        bad_sync,
        mismatch,
        heartbeat_bad_crc,
        frame_le(999, &[]),
        frame_le(306, &[1]),
        frame_le(150, &[1]),
        frame_le(300, &[0, 0, 9]),
        frame_le(313, &[1, 0, 0xFF]),
    ];
    let kinds: BTreeSet<&str> = cases
        .iter()
        .map(|c| decode_datagram(c).expect_err("refused").kind())
        .collect();
    let all: BTreeSet<&str> = [
        "too_short",
        "too_long",
        "bad_sync",
        "size_mismatch",
        "bad_crc",
        "unknown_id",
        "truncated",
        "trailing_bytes",
        "invalid_value",
        "invalid_text",
    ]
    .into();
    assert_eq!(kinds, all);
}

#[test]
fn encoder_limits() {
    let h = fixture_header(0, 0);
    // A text longer than a u16 length can say.
    let huge = "x".repeat(70_000);
    assert_eq!(
        encode_datagram(&h, &Message::QueryLedBrightness { name: huge }),
        Err(EncodeError::TextTooLong {
            message: "QueryLedBrightness",
            field: "name",
            len: 70_000
        })
    );
    // The largest text that fits one datagram, and one byte more.
    let fits = MAX_DATAGRAM - HEADER_LEN - CRC_LEN - 2;
    let m = Message::QueryLedBrightness {
        name: "y".repeat(fits),
    };
    let bytes = encode_datagram(&h, &m).expect("fits");
    assert_eq!(bytes.len(), MAX_DATAGRAM);
    assert_eq!(decode_datagram(&bytes).expect("decodes").message, m);
    assert_eq!(
        encode_datagram(
            &h,
            &Message::QueryLedBrightness {
                name: "y".repeat(fits + 1)
            }
        ),
        Err(EncodeError::TooLong {
            len: MAX_DATAGRAM + 1,
            max: MAX_DATAGRAM
        })
    );
}

#[test]
fn errors_name_what_failed() {
    let e = decode_datagram(&frame_le(
        315,
        &cat(&[&[1], &5u32.to_le_bytes(), &6u32.to_le_bytes()]),
    ))
    .expect_err("refused");
    assert_eq!(
        e.to_string(),
        "SetPWM: field duty_cycle has invalid value 6"
    );
    assert_eq!(e.kind(), "invalid_value");
}
