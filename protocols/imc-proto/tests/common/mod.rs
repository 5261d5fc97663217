//! Shared by the integration tests: one sample of every message, proptest strategies
//! producing random *valid* messages, and byte-level helpers written from FACTS.md
//! independently of the crate's encoder (a big-endian converter, a re-framer).
#![allow(dead_code)]

use std::f32::consts::FRAC_PI_2 as FRAC_PI_2_F32;
use std::f64::consts::{FRAC_PI_2, PI};

use imc_proto::{
    crc16_arc, Announce, ChannelOp, ChannelState, Header, LcdOperation, Message, PowerOp,
    RemoteActionsOp, SystemType, ZoomAction, CRC_LEN, HEADER_LEN,
};
use proptest::prelude::*;

/// The header every fixture uses: t = 1.5 s, from 0x4001/5 to 0x2000/any.
pub fn fixture_header(mgid: u16, size: u16) -> Header {
    Header {
        mgid,
        size,
        timestamp: 1.5,
        src: 0x4001,
        src_ent: 5,
        dst: 0x2000,
        dst_ent: 255,
    }
}

/// One message of every implemented type, in ascending id order.
pub fn samples() -> Vec<Message> {
    vec![
        Message::Heartbeat,
        Message::Announce(Announce {
            sys_name: "skymesh-01".into(),
            sys_type: SystemType::Uav,
            owner: 0xFFFF,
            lat: 0.7188,
            lon: -0.1514,
            height: 112.5,
            services: "imc+udp://10.0.0.5:6002/;imc+info://0.0.0/".into(),
        }),
        Message::CameraZoom {
            id: 1,
            zoom: 40,
            action: ZoomAction::In,
        },
        Message::SetThrusterActuation { id: 3, value: -0.5 },
        Message::SetServoPosition {
            id: 9,
            value: FRAC_PI_2_F32,
        },
        Message::SetControlSurfaceDeflection { id: 2, angle: 4.0 },
        Message::RemoteActionsRequest {
            op: RemoteActionsOp::Report,
            actions: "Propulsion=Axis;PanTilt=Hat;Lights=Button".into(),
        },
        Message::RemoteActions {
            actions: "Propulsion=0.6;Lights=1".into(),
        },
        Message::ButtonEvent {
            button: 4,
            value: 1,
        },
        Message::LcdControl {
            op: LcdOperation::Write1,
            text: "batt 87% ✓".into(),
        },
        Message::PowerOperation {
            op: PowerOp::PowerDownInProgress,
            time_remain: 12.5,
            sched_time: 1_700_000_000.25,
        },
        Message::PowerChannelControl {
            name: "camera".into(),
            op: ChannelOp::Restart,
            sched_time: 0.0,
        },
        Message::QueryPowerChannelState,
        Message::PowerChannelState {
            name: "radio".into(),
            state: ChannelState::On,
        },
        Message::LedBrightness {
            name: "nav".into(),
            value: 255,
        },
        Message::QueryLedBrightness { name: "nav".into() },
        Message::SetLedBrightness {
            name: "strobe".into(),
            value: 0,
        },
        Message::SetPwm {
            id: 7,
            period: 20_000,
            duty_cycle: 20_000,
        },
        Message::Pwm {
            id: 7,
            period: 20_000,
            duty_cycle: 1_000,
        },
        Message::GpioState {
            name: "payload_en".into(),
            value: 1,
        },
        Message::GpioStateGet {
            name: "payload_en".into(),
        },
        Message::GpioStateSet {
            name: "".into(),
            value: 0,
        },
    ]
}

// ---------------------------------------------------------------------------
// Byte-level helpers (independent of the encoder).

/// A field type of FACTS.md's list, for walking a payload without the crate.
#[derive(Debug, Clone, Copy)]
enum Field {
    U8,
    U16,
    U32,
    F32,
    F64,
    Text,
}

/// Field layout per id, transcribed from FACTS.md "IMC".
fn layout(id: u16) -> &'static [Field] {
    use Field::*;
    match id {
        150 | 310 => &[],
        151 => &[Text, U8, U16, F64, F64, F32, Text],
        300 => &[U8, U8, U8],
        301..=303 => &[U8, F32],
        304 | 307 => &[U8, Text],
        305 | 313 | 2001 => &[Text],
        306 => &[U8, U8],
        308 => &[U8, F32, F64],
        309 => &[Text, U8, F64],
        311 | 312 | 314 | 2000 | 2002 => &[Text, U8],
        315 | 316 => &[U8, U32, U32],
        other => panic!("no layout for id {other}"),
    }
}

fn swap_at(bytes: &mut [u8], at: usize, width: usize) {
    bytes[at..at + width].reverse();
}

/// Turns a little-endian datagram into the same datagram as a big-endian sender
/// writes it: every header and payload field byte-swapped (walking FACTS.md's
/// layout, which must consume the payload exactly), CRC recomputed over the new
/// bytes and written big-endian.
pub fn to_big_endian(le: &[u8]) -> Vec<u8> {
    assert_eq!(le[0..2], [0x54, 0xFE], "input is little-endian");
    let mut out = le[..le.len() - CRC_LEN].to_vec();
    for (at, width) in [(0, 2), (2, 2), (4, 2), (6, 8), (14, 2), (17, 2)] {
        swap_at(&mut out, at, width);
    }
    let id = u16::from_le_bytes([le[2], le[3]]);
    let mut at = HEADER_LEN;
    for field in layout(id) {
        match field {
            Field::U8 => at += 1,
            Field::U16 => {
                swap_at(&mut out, at, 2);
                at += 2;
            }
            Field::U32 | Field::F32 => {
                swap_at(&mut out, at, 4);
                at += 4;
            }
            Field::F64 => {
                swap_at(&mut out, at, 8);
                at += 8;
            }
            Field::Text => {
                let len = usize::from(u16::from_le_bytes([out[at], out[at + 1]]));
                swap_at(&mut out, at, 2);
                at += 2 + len;
            }
        }
    }
    assert_eq!(at, out.len(), "layout of {id} consumes the payload");
    let crc = crc16_arc(&out);
    out.extend_from_slice(&crc.to_be_bytes());
    out
}

/// `datagram` (either byte order) with its payload replaced by `payload`: the size
/// field and the CRC are rewritten in the datagram's byte order, so the result is
/// well framed whatever the payload holds.
pub fn reframe(datagram: &[u8], payload: &[u8]) -> Vec<u8> {
    let big = datagram[0..2] == [0xFE, 0x54];
    let size = u16::try_from(payload.len()).expect("payload fits");
    let mut out = datagram[..HEADER_LEN].to_vec();
    out[4..6].copy_from_slice(&if big {
        size.to_be_bytes()
    } else {
        size.to_le_bytes()
    });
    out.extend_from_slice(payload);
    let crc = crc16_arc(&out);
    out.extend_from_slice(&if big {
        crc.to_be_bytes()
    } else {
        crc.to_le_bytes()
    });
    out
}

/// A well-framed little-endian datagram of message `mgid` carrying `payload`
/// (fixture header: t = 1.5, 0x4001/5 → 0x2000/255).
pub fn frame_le(mgid: u16, payload: &[u8]) -> Vec<u8> {
    let mut header = vec![
        0x54, 0xFE, 0x00, 0x00, 0x00, 0x00, // sync, mgid, size (below)
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF8, 0x3F, // timestamp 1.5
        0x01, 0x40, 0x05, 0x00, 0x20, 0xFF, // src 0x4001/5, dst 0x2000/255
    ];
    header[2..4].copy_from_slice(&mgid.to_le_bytes());
    header.extend_from_slice(&[0, 0]);
    reframe(&header, payload)
}

/// The payload bytes of a datagram.
pub fn payload_of(datagram: &[u8]) -> &[u8] {
    &datagram[HEADER_LEN..datagram.len() - CRC_LEN]
}

// ---------------------------------------------------------------------------
// Strategies: random valid messages.

fn text() -> impl Strategy<Value = String> {
    ".{0,24}"
}

fn finite_f32() -> impl Strategy<Value = f32> {
    any::<f32>().prop_filter("finite", |v| v.is_finite())
}

fn finite_f64() -> impl Strategy<Value = f64> {
    any::<f64>().prop_filter("finite", |v| v.is_finite())
}

fn pwm() -> impl Strategy<Value = (u8, u32, u32)> {
    (any::<u8>(), any::<u32>()).prop_flat_map(|(id, period)| (Just(id), Just(period), 0..=period))
}

pub fn announce() -> impl Strategy<Value = Announce> {
    (
        text(),
        prop::sample::select(SystemType::ALL),
        any::<u16>(),
        -FRAC_PI_2..=FRAC_PI_2,
        -PI..=PI,
        finite_f32(),
        text(),
    )
        .prop_map(
            |(sys_name, sys_type, owner, lat, lon, height, services)| Announce {
                sys_name,
                sys_type,
                owner,
                lat,
                lon,
                height,
                services,
            },
        )
}

/// Any valid message of any implemented type, fields anywhere in their ranges.
pub fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        Just(Message::Heartbeat),
        announce().prop_map(Message::Announce),
        (
            any::<u8>(),
            any::<u8>(),
            prop::sample::select(ZoomAction::ALL)
        )
            .prop_map(|(id, zoom, action)| Message::CameraZoom { id, zoom, action }),
        (any::<u8>(), -1.0f32..=1.0)
            .prop_map(|(id, value)| Message::SetThrusterActuation { id, value }),
        (any::<u8>(), -FRAC_PI_2_F32..=FRAC_PI_2_F32)
            .prop_map(|(id, value)| Message::SetServoPosition { id, value }),
        (any::<u8>(), finite_f32())
            .prop_map(|(id, angle)| Message::SetControlSurfaceDeflection { id, angle }),
        (prop::sample::select(RemoteActionsOp::ALL), text())
            .prop_map(|(op, actions)| Message::RemoteActionsRequest { op, actions }),
        text().prop_map(|actions| Message::RemoteActions { actions }),
        (any::<u8>(), any::<u8>())
            .prop_map(|(button, value)| Message::ButtonEvent { button, value }),
        (prop::sample::select(LcdOperation::ALL), text())
            .prop_map(|(op, text)| Message::LcdControl { op, text }),
        (
            prop::sample::select(PowerOp::ALL),
            finite_f32(),
            finite_f64()
        )
            .prop_map(|(op, time_remain, sched_time)| Message::PowerOperation {
                op,
                time_remain,
                sched_time,
            }),
        (
            text(),
            prop::sample::select(ChannelOp::ALL),
            finite_f64().prop_map(f64::abs)
        )
            .prop_map(|(name, op, sched_time)| Message::PowerChannelControl {
                name,
                op,
                sched_time,
            }),
        Just(Message::QueryPowerChannelState),
        (text(), prop::sample::select(ChannelState::ALL))
            .prop_map(|(name, state)| Message::PowerChannelState { name, state }),
        (text(), any::<u8>()).prop_map(|(name, value)| Message::LedBrightness { name, value }),
        text().prop_map(|name| Message::QueryLedBrightness { name }),
        (text(), any::<u8>()).prop_map(|(name, value)| Message::SetLedBrightness { name, value }),
        pwm().prop_map(|(id, period, duty_cycle)| Message::SetPwm {
            id,
            period,
            duty_cycle,
        }),
        pwm().prop_map(|(id, period, duty_cycle)| Message::Pwm {
            id,
            period,
            duty_cycle,
        }),
        (text(), any::<u8>()).prop_map(|(name, value)| Message::GpioState { name, value }),
        text().prop_map(|name| Message::GpioStateGet { name }),
        (text(), any::<u8>()).prop_map(|(name, value)| Message::GpioStateSet { name, value }),
    ]
}

/// Any header: finite timestamp, any addresses (mgid and size are the encoder's).
pub fn header() -> impl Strategy<Value = Header> {
    (
        finite_f64(),
        any::<u16>(),
        any::<u8>(),
        any::<u16>(),
        any::<u8>(),
    )
        .prop_map(|(timestamp, src, src_ent, dst, dst_ent)| {
            Header::new(timestamp, src, src_ent, dst, dst_ent)
        })
}
