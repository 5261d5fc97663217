//! Hand-written byte fixtures: the bytes a GroundControl client and server put on
//! the wire, written out field by field, decoded and re-encoded.

use gc_proto::{
    pack_text, unpack_text, NetCmdType, Params, PoseRecord, Record, POSE_RECORD_LEN, RECORD_LEN,
};

/// CMD_EXT_WAYPOINT for drone 3 to (1.5, -2, 10) at 2 m/s, yaw 90° (9000).
const WAYPOINT: [u8; RECORD_LEN] = [
    0xA6, 0x00, 0x00, 0x00, // type 0xA6
    0x03, 0x00, 0x00, 0x00, // context 3
    0x28, 0x23, 0x00, 0x00, // intParam1 9000
    0x00, 0x00, 0x00, 0x00, // intParam2 0
    0x00, 0x00, 0xC0, 0x3F, // 1.5f
    0x00, 0x00, 0x00, 0xC0, // -2.0f
    0x00, 0x00, 0x20, 0x41, // 10.0f
    0x00, 0x00, 0x00, 0x40, // 2.0f
];

/// PING_REQUEST sequence 258, doubles 1.0 and -1.0.
const PING: [u8; RECORD_LEN] = [
    0x00, 0x00, 0x00, 0x00, // type 0
    0x00, 0x00, 0x00, 0x00, // context 0
    0x02, 0x01, 0x00, 0x00, // intParam1 258
    0x00, 0x00, 0x00, 0x00, // intParam2
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0x3F, // 1.0
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xF0, 0xBF, // -1.0
];

/// CMD_EXT_TEXT for drone 1: "HI THERE" (intParam2 "HI T", then "HERE\0\0\0\0", 0).
const TEXT: [u8; RECORD_LEN] = [
    0xB3, 0x00, 0x00, 0x00, // type 0xB3
    0x01, 0x00, 0x00, 0x00, // context 1
    0x00, 0x00, 0x00, 0x00, // intParam1 (reserved)
    b'H', b'I', b' ', b'T', // intParam2: the first 4 bytes
    b'H', b'E', b'R', b'E', 0, 0, 0, 0, // i64 #1
    0, 0, 0, 0, 0, 0, 0, 0, // i64 #2
];

/// ACK_CMD_SUCCESS for drone 7 of CMD_EXT_GO_EXTERNAL.
const ACK: [u8; RECORD_LEN] = [
    0x06, 0x00, 0x00, 0x00, 0x07, 0x00, 0x00, 0x00, 0xA0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
];

#[test]
fn waypoint() {
    let r = Record::decode(&WAYPOINT);
    assert_eq!(r.net_type(), Some(NetCmdType::CmdExtWaypoint));
    assert_eq!((r.context, r.int1, r.int2), (3, 9000, 0));
    assert_eq!(r.params, Params::Floats([1.5, -2.0, 10.0, 2.0]));
    assert_eq!(r.encode(), WAYPOINT);
    let built = Record::floats(
        NetCmdType::CmdExtWaypoint,
        3,
        9000,
        0,
        [1.5, -2.0, 10.0, 2.0],
    );
    assert_eq!(built.encode(), WAYPOINT);
}

#[test]
fn ping_uses_doubles() {
    let r = Record::decode(&PING);
    assert_eq!(r.net_type(), Some(NetCmdType::PingRequest));
    assert_eq!(r.int1, 258);
    assert_eq!(r.params, Params::Doubles([1.0, -1.0]));
    assert_eq!(Record::ping_request(258, 1.0, -1.0).encode(), PING);
    let mut response = PING;
    response[0] = 0x01;
    assert_eq!(Record::ping_response(&r).encode(), response);
}

#[test]
fn text_uses_longs() {
    let r = Record::decode(&TEXT);
    assert_eq!(r.net_type(), Some(NetCmdType::CmdExtText));
    let Params::Longs(longs) = r.params else {
        panic!("TEXT carries i64: {:?}", r.params)
    };
    assert_eq!(unpack_text(r.int2, longs).unwrap(), "HI THERE");
    let (int2, longs) = pack_text("HI THERE").unwrap();
    let built = Record {
        int2,
        params: Params::Longs(longs),
        ..Record::new(NetCmdType::CmdExtText, 1)
    };
    assert_eq!(built.encode(), TEXT);
}

#[test]
fn ack() {
    assert_eq!(Record::ack(true, 7, 0xA0).encode(), ACK);
    let r = Record::decode(&ACK);
    assert_eq!(r.net_type(), Some(NetCmdType::AckCmdSuccess));
}

#[test]
fn unknown_types_are_raw_float_records() {
    let mut b = WAYPOINT;
    b[0..4].copy_from_slice(&0x1234_5678i32.to_le_bytes());
    let r = Record::decode(&b);
    assert_eq!(r.kind, 0x1234_5678);
    assert_eq!(r.net_type(), None);
    assert_eq!(r.params, Params::Floats([1.5, -2.0, 10.0, 2.0]));
    assert_eq!(r.encode(), b);
}

/// Drone 2, UAV, live, at (1, 2, 3) yaw 90, target (4, 5, 6) yaw 180, red, t = 0.5 s,
/// identity quaternion, frame 7, FOLLOW_TARGET (10), idle|active, rotation -45.
fn pose_fixture() -> [u8; POSE_RECORD_LEN] {
    let mut v: Vec<u8> = Vec::new();
    v.extend(2u16.to_le_bytes());
    v.push(0);
    v.push(1);
    for f in [
        1.0f32, 2.0, 3.0, 90.0, 4.0, 5.0, 6.0, 180.0, 1.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0,
    ] {
        v.extend(f.to_le_bytes());
    }
    v.extend(7u32.to_le_bytes());
    v.extend(10i32.to_le_bytes());
    v.extend(3u32.to_le_bytes());
    v.extend((-45.0f32).to_le_bytes());
    v.try_into().expect("84 bytes")
}

#[test]
fn pose_record_field_order() {
    let b = pose_fixture();
    // Spot checks of the FACTS.md offsets.
    assert_eq!(&b[0..4], &[2, 0, 0, 1]);
    assert_eq!(&b[4..8], &1.0f32.to_le_bytes());
    assert_eq!(&b[48..52], &0.5f32.to_le_bytes());
    assert_eq!(&b[64..68], &1.0f32.to_le_bytes());
    assert_eq!(&b[68..72], &7u32.to_le_bytes());
    assert_eq!(&b[72..76], &10i32.to_le_bytes());
    assert_eq!(&b[76..80], &3u32.to_le_bytes());
    let p = PoseRecord::decode(&b);
    assert_eq!(
        p,
        PoseRecord {
            id: 2,
            object_type: 0,
            liveness: 1,
            tracking: [1.0, 2.0, 3.0],
            tracking_yaw_deg: 90.0,
            target: [4.0, 5.0, 6.0],
            target_yaw_deg: 180.0,
            color: [1.0, 0.0, 0.0],
            timestamp: 0.5,
            quaternion: [0.0, 0.0, 0.0, 1.0],
            frame_count: 7,
            drone_state: 10,
            flags: 3,
            relative_rotation_deg: -45.0,
        }
    );
    assert_eq!(p.encode(), b);
}
