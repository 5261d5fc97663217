//! The field primitives in both byte orders, including the inline message and the
//! message list that no implemented message carries yet (a future one will).

use imc_proto::wire::{Reader, Writer};
use imc_proto::{ByteOrder, DecodeError, EncodeError, Message, ZoomAction};

const ORDERS: [ByteOrder; 2] = [ByteOrder::Little, ByteOrder::Big];

#[test]
fn integers_and_floats_in_both_orders() {
    for order in ORDERS {
        let mut w = Writer::new(order, "T");
        w.u8(0xAB);
        w.i8(-3);
        w.u16(0xBEEF);
        w.i16(-300);
        w.u32(0xDEAD_BEEF);
        w.i32(-70_000);
        w.u64(u64::MAX - 1);
        w.i64(i64::MIN);
        w.f32(-0.25);
        w.f64(1e300);
        let bytes = w.into_bytes();
        assert_eq!(bytes.len(), 1 + 1 + 2 + 2 + 4 + 4 + 8 + 8 + 4 + 8);
        let mut r = Reader::new(&bytes, order, "T");
        assert_eq!(r.u8("a"), Ok(0xAB));
        assert_eq!(r.i8("b"), Ok(-3));
        assert_eq!(r.u16("c"), Ok(0xBEEF));
        assert_eq!(r.i16("d"), Ok(-300));
        assert_eq!(r.u32("e"), Ok(0xDEAD_BEEF));
        assert_eq!(r.i32("f"), Ok(-70_000));
        assert_eq!(r.u64("g"), Ok(u64::MAX - 1));
        assert_eq!(r.i64("h"), Ok(i64::MIN));
        assert_eq!(r.f32("i"), Ok(-0.25));
        assert_eq!(r.f64("j"), Ok(1e300));
        assert_eq!(r.remaining(), 0);
        assert_eq!(r.finish(), Ok(()));
    }
}

#[test]
fn plaintext_and_rawdata_bytes() {
    let mut w = Writer::new(ByteOrder::Big, "T");
    w.plaintext("t", "hé").expect("short");
    w.rawdata("r", &[0, 0xFF]).expect("short");
    assert_eq!(
        w.into_bytes(),
        [0x00, 0x03, b'h', 0xC3, 0xA9, 0x00, 0x02, 0x00, 0xFF]
    );
    let bytes = [0x03, 0x00, b'h', 0xC3, 0xA9, 0x02, 0x00, 0x00, 0xFF];
    let mut r = Reader::new(&bytes, ByteOrder::Little, "T");
    assert_eq!(r.plaintext("t").as_deref(), Ok("hé"));
    assert_eq!(r.rawdata("r"), Ok(vec![0, 0xFF]));
    assert_eq!(r.finish(), Ok(()));

    // rawdata need not be UTF-8; plaintext must be.
    let bad = [0x01, 0x00, 0xFF];
    assert_eq!(
        Reader::new(&bad, ByteOrder::Little, "T").rawdata("r"),
        Ok(vec![0xFF])
    );
    assert_eq!(
        Reader::new(&bad, ByteOrder::Little, "T").plaintext("t"),
        Err(DecodeError::InvalidText {
            message: "T",
            field: "t"
        })
    );

    let mut w = Writer::new(ByteOrder::Little, "T");
    assert_eq!(
        w.rawdata("r", &vec![0; 65_536]),
        Err(EncodeError::TextTooLong {
            message: "T",
            field: "r",
            len: 65_536
        })
    );
    assert!(w.is_empty(), "nothing written on error");
    assert_eq!(w.rawdata("r", &vec![0; 65_535]), Ok(()));
    assert_eq!(w.len(), 65_537);
}

#[test]
fn inline_message_bytes_in_both_orders() {
    let pwm = Message::SetPwm {
        id: 2,
        period: 20_000,
        duty_cycle: 1_500,
    };
    // Hand-written: id 315 then SetPWM's fields; 0xFFFF for none.
    let le: &[u8] = &[
        0x3B, 0x01, // id 315
        0x02, 0x20, 0x4E, 0x00, 0x00, 0xDC, 0x05, 0x00, 0x00, // id, period, duty
        0xFF, 0xFF, // none
    ];
    let be: &[u8] = &[
        0x01, 0x3B, // id 315
        0x02, 0x00, 0x00, 0x4E, 0x20, 0x00, 0x00, 0x05, 0xDC, // id, period, duty
        0xFF, 0xFF, // none
    ];
    for (order, bytes) in [(ByteOrder::Little, le), (ByteOrder::Big, be)] {
        let mut w = Writer::new(order, "Outer");
        w.inline_message(Some(&pwm)).expect("writes");
        w.inline_message(None).expect("writes");
        assert_eq!(w.into_bytes(), bytes, "{order:?}");

        let mut r = Reader::new(bytes, order, "Outer");
        assert_eq!(r.inline_message("msg"), Ok(Some(pwm.clone())));
        assert_eq!(r.inline_message("none"), Ok(None));
        assert_eq!(r.finish(), Ok(()));
    }
}

#[test]
fn message_list_bytes_in_both_orders() {
    let list = vec![
        Message::Heartbeat,
        Message::ButtonEvent {
            button: 1,
            value: 2,
        },
        Message::QueryLedBrightness { name: "a".into() },
    ];
    let le: &[u8] = &[
        0x03, 0x00, // count 3
        0x96, 0x00, // Heartbeat
        0x32, 0x01, 0x01, 0x02, // ButtonEvent 1, 2
        0x39, 0x01, 0x01, 0x00, b'a', // QueryLedBrightness "a"
    ];
    let be: &[u8] = &[
        0x00, 0x03, // count 3
        0x00, 0x96, // Heartbeat
        0x01, 0x32, 0x01, 0x02, // ButtonEvent 1, 2
        0x01, 0x39, 0x00, 0x01, b'a', // QueryLedBrightness "a"
    ];
    for (order, bytes) in [(ByteOrder::Little, le), (ByteOrder::Big, be)] {
        let mut w = Writer::new(order, "Outer");
        w.message_list(&list).expect("writes");
        assert_eq!(w.into_bytes(), bytes, "{order:?}");
        let mut r = Reader::new(bytes, order, "Outer");
        assert_eq!(r.message_list("list"), Ok(list.clone()));
        assert_eq!(r.finish(), Ok(()));

        // Empty list.
        let mut w = Writer::new(order, "Outer");
        w.message_list(&[]).expect("writes");
        let bytes = w.into_bytes();
        assert_eq!(bytes, [0, 0]);
        assert_eq!(
            Reader::new(&bytes, order, "Outer").message_list("list"),
            Ok(vec![])
        );
    }
}

#[test]
fn nested_errors_name_the_inner_message_then_the_outer_again() {
    // Inline CameraZoom with an out-of-range action.
    let bytes = [0x2C, 0x01, 0x01, 0x02, 0x09];
    assert_eq!(
        Reader::new(&bytes, ByteOrder::Little, "Outer").inline_message("m"),
        Err(DecodeError::InvalidValue {
            message: "CameraZoom",
            field: "action",
            value: 9.0
        })
    );
    // Inline SetPWM with duty above period: the value checks apply inside too.
    let bytes = [0x3B, 0x01, 0x00, 0x01, 0, 0, 0, 0x02, 0, 0, 0];
    assert!(matches!(
        Reader::new(&bytes, ByteOrder::Little, "Outer").inline_message("m"),
        Err(DecodeError::InvalidValue {
            message: "SetPWM",
            field: "duty_cycle",
            ..
        })
    ));
    // Inline ButtonEvent cut short.
    let bytes = [0x32, 0x01, 0x01];
    assert_eq!(
        Reader::new(&bytes, ByteOrder::Little, "Outer").inline_message("m"),
        Err(DecodeError::Truncated {
            message: "ButtonEvent",
            field: "value"
        })
    );
    // After a good inline message, errors name the outer message again.
    let bytes = [0x96, 0x00, 0x07];
    let mut r = Reader::new(&bytes, ByteOrder::Little, "Outer");
    assert_eq!(r.inline_message("m"), Ok(Some(Message::Heartbeat)));
    assert_eq!(
        r.u16("after"),
        Err(DecodeError::Truncated {
            message: "Outer",
            field: "after"
        })
    );
    // An unknown inline id cannot be skipped: its length is unknown.
    assert_eq!(
        Reader::new(&[0xE7, 0x03], ByteOrder::Little, "Outer").inline_message("m"),
        Err(DecodeError::UnknownId(999))
    );
}

#[test]
fn list_refuses_none_and_survives_a_lying_count() {
    let bytes = [0x01, 0x00, 0xFF, 0xFF];
    assert_eq!(
        Reader::new(&bytes, ByteOrder::Little, "Outer").message_list("list"),
        Err(DecodeError::InvalidValue {
            message: "Outer",
            field: "list",
            value: 65_535.0
        })
    );
    // 65535 messages announced, one present: truncated, without reserving 65535.
    let bytes = [0xFF, 0xFF, 0x96, 0x00];
    assert_eq!(
        Reader::new(&bytes, ByteOrder::Little, "Outer").message_list("list"),
        Err(DecodeError::Truncated {
            message: "Outer",
            field: "list"
        })
    );
}

#[test]
fn enumeration_reader() {
    let mut r = Reader::new(&[3, 4], ByteOrder::Big, "T");
    assert_eq!(r.enumeration::<ZoomAction>("a"), Ok(ZoomAction::Stop));
    assert_eq!(
        r.enumeration::<ZoomAction>("b"),
        Err(DecodeError::InvalidValue {
            message: "T",
            field: "b",
            value: 4.0
        })
    );
}

#[test]
fn trailing_bytes_after_the_last_field() {
    let mut r = Reader::new(&[1, 2, 3], ByteOrder::Little, "T");
    assert_eq!(r.u8("a"), Ok(1));
    assert_eq!(
        r.finish(),
        Err(DecodeError::TrailingBytes {
            message: "T",
            extra: 2
        })
    );
}
