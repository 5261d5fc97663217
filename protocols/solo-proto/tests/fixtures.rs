//! Hand-written byte fixtures (not produced by this crate's encoder), decoded through
//! the framer, with trailing bytes after the last frame.

use bytes::BytesMut;
use solo_proto::{
    ids, ButtonSetting, GoProState, Location, RawFrame, SoloMessage, SplinePoint, TlvCodec,
};
use tokio_util::codec::Decoder;

/// SOLO_MESSAGE_LOCATION: lat 37.5, lon −122.25, alt 10.0.
const LOCATION: &[u8] = &[
    0x02, 0x00, 0x00, 0x00, 0x14, 0x00, 0x00, 0x00, // type 2, length 20
    0x00, 0x00, 0x00, 0x00, 0x00, 0xC0, 0x42, 0x40, // f64 37.5
    0x00, 0x00, 0x00, 0x00, 0x00, 0x90, 0x5E, 0xC0, // f64 -122.25
    0x00, 0x00, 0x20, 0x41, // f32 10.0
];

/// SOLO_MESSAGE_SET_CURRENT_SHOT: orbit (1).
const SET_SHOT_ORBIT: &[u8] = &[
    0x01, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00,
];

/// SOLO_MESSAGE_GET_CURRENT_SHOT: none (−1).
const GET_SHOT_NONE: &[u8] = &[
    0x00, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0xFF,
];

/// SOLO_PAUSE, empty value as DroneKit-Android sends it.
const PAUSE: &[u8] = &[0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00];

/// SOLO_CABLE_CAM_OPTIONS: interpolate on, counter-clockwise, 5 m/s.
const CABLE_CAM_OPTIONS: &[u8] = &[
    0x04, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00, 0x00, // type 4, length 8
    0x01, 0x00, 0x00, 0x00, // u16 1, u16 0
    0x00, 0x00, 0xA0, 0x40, // f32 5.0
];

/// SOLO_SHOT_OPTIONS: −2.5 m/s (negative is valid).
const SHOT_OPTIONS: &[u8] = &[
    0x14, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00, 0x00, 0x00, 0x00, 0x20, 0xC0,
];

/// SOLO_GET_BUTTON_SETTING: button A, press, orbit, no mode.
const BUTTON: &[u8] = &[
    0x05, 0x00, 0x00, 0x00, 0x10, 0x00, 0x00, 0x00, // type 5, length 16
    0x04, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // A, press
    0x01, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, // orbit, mode -1
];

/// GEOFENCE_SET_ACK: 2 polygons, valid.
const GEOFENCE_ACK: &[u8] = &[
    0xB9, 0x0B, 0x00, 0x00, 0x03, 0x00, 0x00, 0x00, 0x02, 0x00, 0x01,
];

/// GOPRO_RECORD: toggle (2).
const GOPRO_RECORD: &[u8] = &[
    0x8B, 0x13, 0x00, 0x00, 0x04, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00,
];

/// SOLO_SPLINE_SEEK: u 0.5, cruising toward the start.
const SPLINE_SEEK: &[u8] = &[
    0x35, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x3F, 0xFF, 0xFF, 0xFF, 0xFF,
];

/// SOLO_PANO_OPTIONS (22, 12 bytes with lens FOV): cylinder, run, 220°, 2 °/s, 160°.
const PANO_OPTIONS: &[u8] = &[
    0x16, 0x00, 0x00, 0x00, 0x0C, 0x00, 0x00, 0x00, // type 22, length 12
    0x00, 0x01, 0xDC, 0x00, // cylinder, run, i16 220
    0x00, 0x00, 0x00, 0x40, // f32 2.0
    0x00, 0x00, 0x20, 0x43, // f32 160.0
];

/// SOLO_MESSAGE_SHOTMANAGER_ERROR: "oops!" then an invalid UTF-8 byte.
const SHOTMANAGER_ERROR: &[u8] = &[
    0xE8, 0x03, 0x00, 0x00, 0x06, 0x00, 0x00, 0x00, b'o', b'o', b'p', b's', b'!', 0xFF,
];

/// GOPRO_V2_STATE: version 2, connected, recording, photo mode, gimbal on, extras.
const GOPRO_V2_STATE: &[u8] = &[
    0x8E, 0x13, 0x00, 0x00, 0x24, 0x00, 0x00, 0x00, // type 5006, length 36
    0x02, 0x00, 0x02, 0x01, 0x01, 0x00, 0x09, 0x05, // version .. video_fps
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // video_fov .. video_gain
    0x00, 0x00, 0x01, // sharpness, exposure, gimbal_enabled
    0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, // extra u8
    0x02, 0x01, 0x00, 0x00, 0xFF, 0xFF, 0x07, 0x00, 0x08, 0x00, // extra u16
];

/// SOLO_SPLINE_POINT (44 bytes, FACTS order).
const SPLINE_POINT: &[u8] = &[
    0x34, 0x00, 0x00, 0x00, 0x2C, 0x00, 0x00, 0x00, // type 52, length 44
    0x00, 0x00, // i16 version 0
    0x00, 0x80, 0xCC, 0x42, // f32 abs_alt_ref 102.25
    0x03, 0x00, 0x00, 0x00, // i32 index 3
    0x00, 0x00, 0x00, 0x00, 0x00, 0xC0, 0x40, 0xC0, // f64 lat -33.5
    0x00, 0x00, 0x00, 0x00, 0x00, 0xE8, 0x62, 0x40, // f64 lon 151.25
    0x00, 0x00, 0xF0, 0x41, // f32 alt 30.0
    0x00, 0x00, 0x34, 0xC2, // f32 pitch -45.0
    0x00, 0x00, 0x87, 0x43, // f32 yaw 270.0
    0x00, 0x00, 0x40, 0x3F, // f32 u 0.75
    0xFE, 0xFF, // i16 status -2
];

/// GEOFENCE_SET_DATA: the spec's example JSON (one polygon, shortened), framed by hand.
fn geofence_frame() -> Vec<u8> {
    let json = br#"{ "coord": [[[37.873391778802457, -122.30124440324217], [37.873425469262187, -122.30088420379124], [37.87289578293214, -122.30071240112851]]], "subCoord": [[[37.873405777181389, -122.30090131123818], [37.872916521332435, -122.30074261865762], [37.872958695063687, -122.3012216429134]]], "type": [0] }"#;
    let mut frame = vec![0xB8, 0x0B, 0x00, 0x00]; // 3000
    frame.extend_from_slice(&u32::try_from(json.len()).expect("short").to_le_bytes());
    frame.extend_from_slice(json);
    frame
}

fn expected() -> Vec<SoloMessage> {
    vec![
        SoloMessage::Location(Location {
            lat_deg: 37.5,
            lon_deg: -122.25,
            alt_m: 10.0,
        }),
        SoloMessage::SetCurrentShot(solo_proto::shots::ORBIT),
        SoloMessage::GetCurrentShot(solo_proto::shots::NONE),
        SoloMessage::Pause,
        SoloMessage::CableCamOptions {
            cam_interpolation: 1,
            yaw_direction_cw: 0,
            cruise_speed: 5.0,
        },
        SoloMessage::ShotOptions { cruise_speed: -2.5 },
        SoloMessage::GetButtonSetting(ButtonSetting {
            button: 4,
            event: 0,
            shot: 1,
            mode: -1,
        }),
        SoloMessage::GeofenceSetAck {
            count: 2,
            valid: true,
        },
        SoloMessage::GoProRecord(2),
        SoloMessage::SplineSeek {
            u_position: 0.5,
            cruise_state: -1,
        },
        SoloMessage::PanoOptions {
            pano_type: 0,
            run_state: 1,
            cylinder_fov: 220,
            deg_second_yaw: 2.0,
            lens_fov: 160.0,
        },
        SoloMessage::ShotManagerError("oops!\u{FFFD}".to_string()),
        SoloMessage::GoProV2State(GoProState {
            version: 2,
            status: 2,
            recording: 1,
            capture_mode: 1,
            video_resolution: 9,
            video_fps: 5,
            gimbal_enabled: 1,
            extra_u8: [1, 2, 3, 4, 5, 6, 7],
            extra_u16: [0x0102, 0, 0xFFFF, 7, 8],
            ..GoProState::default()
        }),
        SoloMessage::SplinePoint(SplinePoint {
            version: 0,
            abs_alt_ref_m: 102.25,
            index: 3,
            lat_deg: -33.5,
            lon_deg: 151.25,
            alt_m: 30.0,
            pitch_deg: -45.0,
            yaw_deg: 270.0,
            u_position: 0.75,
            status: -2,
        }),
        SoloMessage::GeofenceSetData(solo_proto::GeofenceData {
            coord: vec![vec![
                [37.87339177880246, -122.30124440324217],
                [37.87342546926219, -122.30088420379124],
                [37.87289578293214, -122.30071240112851],
            ]],
            sub_coord: vec![vec![
                [37.87340577718139, -122.30090131123818],
                [37.872916521332435, -122.30074261865762],
                [37.87295869506369, -122.3012216429134],
            ]],
            kinds: vec![0],
        }),
    ]
}

/// Every fixture back to back.
pub fn stream() -> Vec<u8> {
    let mut all = Vec::new();
    for f in [
        LOCATION,
        SET_SHOT_ORBIT,
        GET_SHOT_NONE,
        PAUSE,
        CABLE_CAM_OPTIONS,
        SHOT_OPTIONS,
        BUTTON,
        GEOFENCE_ACK,
        GOPRO_RECORD,
        SPLINE_SEEK,
        PANO_OPTIONS,
        SHOTMANAGER_ERROR,
        GOPRO_V2_STATE,
        SPLINE_POINT,
    ] {
        all.extend_from_slice(f);
    }
    all.extend_from_slice(&geofence_frame());
    all
}

/// Trailing bytes: the first five bytes of another LOCATION frame.
const TRAILING: &[u8] = &[0x02, 0x00, 0x00, 0x00, 0x14];

fn decode_all(codec: &mut TlvCodec, buf: &mut BytesMut) -> Vec<RawFrame> {
    let mut frames = Vec::new();
    while let Some(frame) = codec.decode(buf).expect("no framing error") {
        frames.push(frame);
    }
    frames
}

#[test]
fn fixtures_decode_with_trailing_bytes_left_in_the_buffer() {
    let mut buf = BytesMut::from(&stream()[..]);
    buf.extend_from_slice(TRAILING);
    let mut codec = TlvCodec::new();
    let frames = decode_all(&mut codec, &mut buf);
    let messages: Vec<SoloMessage> = frames
        .iter()
        .map(|f| f.decode().expect("valid fixture"))
        .collect();
    assert_eq!(messages, expected());
    // The partial frame stays buffered, untouched, waiting for more bytes.
    assert_eq!(&buf[..], TRAILING);
}

#[test]
fn fixtures_decode_fed_one_byte_at_a_time() {
    let bytes = stream();
    let mut codec = TlvCodec::new();
    let mut buf = BytesMut::new();
    let mut messages = Vec::new();
    for b in bytes.iter().chain(TRAILING) {
        buf.extend_from_slice(&[*b]);
        while let Some(frame) = codec.decode(&mut buf).expect("no framing error") {
            messages.push(frame.decode().expect("valid fixture"));
        }
    }
    assert_eq!(messages, expected());
    assert_eq!(&buf[..], TRAILING);
}

#[test]
fn fixtures_decode_at_every_chunk_size() {
    let mut bytes = stream();
    bytes.extend_from_slice(TRAILING);
    for chunk in 1..=bytes.len() {
        let mut codec = TlvCodec::new();
        let mut buf = BytesMut::new();
        let mut messages = Vec::new();
        for piece in bytes.chunks(chunk) {
            buf.extend_from_slice(piece);
            while let Some(frame) = codec.decode(&mut buf).expect("no framing error") {
                messages.push(frame.decode().expect("valid fixture"));
            }
        }
        assert_eq!(messages, expected(), "chunk size {chunk}");
        assert_eq!(&buf[..], TRAILING, "chunk size {chunk}");
    }
}

#[test]
fn fixture_type_ids_match_facts() {
    assert_eq!(
        u32::from_le_bytes([0xB9, 0x0B, 0, 0]),
        ids::GEOFENCE_SET_ACK
    );
    assert_eq!(u32::from_le_bytes([0x8E, 0x13, 0, 0]), ids::GOPRO_V2_STATE);
    assert_eq!(u32::from_le_bytes([0x16, 0, 0, 0]), ids::PANO_OPTIONS);
}

#[test]
fn our_encoding_matches_the_hand_written_bytes() {
    // The other direction: fixed-layout fixtures re-encode to exactly their bytes.
    for (fixture, msg) in [
        (LOCATION, &expected()[0]),
        (SET_SHOT_ORBIT, &expected()[1]),
        (PAUSE, &expected()[3]),
        (CABLE_CAM_OPTIONS, &expected()[4]),
        (BUTTON, &expected()[6]),
        (GEOFENCE_ACK, &expected()[7]),
        (PANO_OPTIONS, &expected()[10]),
        (GOPRO_V2_STATE, &expected()[12]),
        (SPLINE_POINT, &expected()[13]),
    ] {
        assert_eq!(&msg.to_bytes()[..], fixture, "{}", msg.name());
    }
}
