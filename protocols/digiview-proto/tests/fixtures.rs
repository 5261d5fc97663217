//! Hand-written byte fixtures (not produced by this crate's encoder), checked field
//! by field at FACTS.md's offsets. Every checksum was computed outside this crate by
//! a bit-wise CRC-8/BLUETOOTH (reflected poly 0xA7 = 0xE5, init 0) written in Python.

use digiview_proto::{
    crc8_bluetooth, BoundingBox, CamTargeting, Capture, DetectedRoi, Detection, Frame, FrameError,
    GetRequest, MessageType, Param, ParamType, RawFrame, RoiSelector, SingleTargetTracking,
    StreamName, VideoOutput, FRAME_LEN,
};

/// Header (16 bytes, hand-written), payload prefix, zero rest, checksum at 80, zero pad.
fn assemble(header: [u8; 16], data: &[u8], checksum: u8) -> [u8; FRAME_LEN] {
    let mut f = [0u8; FRAME_LEN];
    f[..16].copy_from_slice(&header);
    f[16..16 + data.len()].copy_from_slice(data);
    f[80] = checksum;
    f
}

fn stream(s: &str) -> StreamName {
    StreamName::new(s).unwrap()
}

/// The frame decodes to `expected`, its payload to `param`, and both encode back to
/// exactly the fixture.
fn check(bytes: [u8; FRAME_LEN], expected_header: Frame, param: Param) {
    let frame = Frame::decode(&bytes).expect("fixture decodes");
    assert_eq!(frame.timestamp, expected_header.timestamp);
    assert_eq!(frame.version, 0);
    assert_eq!(frame.message_type, expected_header.message_type);
    assert_eq!(frame.param_type, expected_header.param_type);
    assert_eq!(frame.interval_ms, expected_header.interval_ms);
    let decoded = Param::decode(frame.param_type, &frame.data).expect("payload decodes");
    assert_eq!(decoded, param);
    decoded.validate().expect("fixture values are in range");
    let (pt, data) = param.encode();
    assert_eq!(pt, frame.param_type);
    assert_eq!(data, frame.data, "payload bytes differ from the fixture");
    assert_eq!(frame.encode(), bytes, "frame bytes differ from the fixture");
}

fn header(timestamp: u64, mt: MessageType, pt: ParamType, interval_ms: u32) -> Frame {
    Frame {
        timestamp,
        interval_ms,
        ..Frame::new(mt, pt)
    }
}

#[test]
fn crc8_bluetooth_check_value() {
    assert_eq!(crc8_bluetooth(b"123456789"), 0x26);
    assert_eq!(crc8_bluetooth(b""), 0x00);
}

fn cam_targeting_set() -> [u8; FRAME_LEN] {
    #[rustfmt::skip]
    let data = [
        b'c', b'a', b'm', b'0', 0, 0, 0, 0, // 0 stream
        1,    // 8 cam
        0,    // 9 mode directional
        1,    // 10 euler_delta
        0x23, 0x06, 0x00, 0x00, // 11 yaw 1.571 rad
        0x0C, 0xFE, 0xFF, 0xFF, // 15 pitch -0.5 rad
        0x00, 0x00, 0x00, 0x00, // 19 roll 0
        0x03, // 23 lock_flags 0b011
        0x00, 0x40, // 24 x 16384 / 32767
        0x01, 0x80, // 26 y -32767 / 32767
        0xC1, 0xE7, 0x00, 0x00, // 28 lat 59.329
        0x94, 0x46, 0x00, 0x00, // 32 lon 18.068
        0xB4, 0xD6, 0x01, 0x00, // 36 alt 120.5
    ];
    #[rustfmt::skip]
    let hdr = [
        0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01, // timestamp
        0x00, 0x02, 0x07, 0x00, // version 0, SET, CAM_TARGETING, pad
        0x00, 0x00, 0x00, 0x00, // interval 0
    ];
    assemble(hdr, &data, 0x0D)
}

#[test]
fn cam_targeting_set_fixture() {
    check(
        cam_targeting_set(),
        header(
            0x0102_0304_0506_0708,
            MessageType::Set,
            ParamType::CamTargeting,
            0,
        ),
        Param::CamTargeting(CamTargeting {
            stream: stream("cam0"),
            cam: 1,
            mode: 0,
            euler_delta: true,
            yaw: 1.571,
            pitch: -0.5,
            roll: 0.0,
            lock_flags: 3,
            x_offset: 16384.0 / 32767.0,
            y_offset: -1.0,
            latitude: 59.329,
            longitude: 18.068,
            altitude: 120.5,
        }),
    );
}

#[test]
fn detected_roi_current_fixture() {
    #[rustfmt::skip]
    let data = [
        2, 200, 5,   // index, score, total
        0x03, 0x00,  // 3 type
        0x48, 0xF4, 0xFF, 0xFF, // 5 yaw_g -3.0
        0x06, 0xFF, 0xFF, 0xFF, // 9 pitch_g -0.25
        2,           // 13 rel_frame camera
        0x64, 0x00, 0x00, 0x00, // 14 yaw_rel 0.1
        0x32, 0x00, 0x00, 0x00, // 18 pitch_rel 0.05
        0xE8, 0x03, 0x00, 0x00, // 22 lat 1.0
        0x18, 0xFC, 0xFF, 0xFF, // 26 lon -1.0
        0x50, 0xC3, 0x00, 0x00, // 30 alt 50.0
        0x37, 0x14, 0x01, 0x00, // 34 dist 70.711
    ];
    #[rustfmt::skip]
    let hdr = [0xE8, 0x03, 0, 0, 0, 0, 0, 0, 0x00, 0x03, 0x06, 0x00, 0, 0, 0, 0];
    check(
        assemble(hdr, &data, 0x28),
        header(1000, MessageType::Current, ParamType::DetectedRoi, 0),
        Param::DetectedRoi(DetectedRoi {
            index: 2,
            score: 200,
            total: 5,
            object_type: 3,
            yaw_global: -3.0,
            pitch_global: -0.25,
            rel_frame: 2,
            yaw_rel: 0.1,
            pitch_rel: 0.05,
            latitude: 1.0,
            longitude: -1.0,
            altitude: 50.0,
            distance: 70.711,
        }),
    );
}

#[test]
fn video_output_current_fixture() {
    #[rustfmt::skip]
    let data = [
        b'm', b'a', b'i', b'n', 0, 0, 0, 0, // 0 stream
        0x80, 0x07, // 8 width 1920
        0x38, 0x04, // 10 height 1080
        30,         // 12 fps
        0x22,       // 13 views 2 (high nibble), layout 2
        2,          // 14 overlay mode
        2,          // 15 num_views
        0x00, 0x00, 0x00, 0x00, 0x52, 0x03, 0x38, 0x04, // 16 view 0: 0,0 850x1080
        0x52, 0x03, 0x00, 0x00, 0x52, 0x03, 0x38, 0x04, // 24 view 1: 850,0 850x1080
        0xA4, 0x06, 0x00, 0x00, 0xDC, 0x00, 0x38, 0x04, // 32 overlay 1700,0 220x1080
        0xDC, 0x00, // 40 single detection size 220
    ];
    #[rustfmt::skip]
    let hdr = [7, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x03, 0x03, 0x00, 0, 0, 0, 0];
    check(
        assemble(hdr, &data, 0x9A),
        header(7, MessageType::Current, ParamType::VideoOutput, 0),
        Param::VideoOutput(VideoOutput {
            stream: stream("main"),
            width: 1920,
            height: 1080,
            fps: 30,
            layout_mode: 2,
            layout_views: 2,
            overlay_mode: 2,
            views: vec![
                BoundingBox {
                    x: 0,
                    y: 0,
                    w: 850,
                    h: 1080,
                },
                BoundingBox {
                    x: 850,
                    y: 0,
                    w: 850,
                    h: 1080,
                },
            ],
            overlay_box: BoundingBox {
                x: 1700,
                y: 0,
                w: 220,
                h: 1080,
            },
            single_detection_size: 220,
        }),
    );
}

#[test]
fn capture_set_fixture() {
    let data = [
        b'c', b'a', b'm', b'0', 0, 0, 0, 0, 0b11, 0x02, 0x01, 0x07, 0x00,
    ];
    let hdr = [0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x02, 0x04, 0x00, 0, 0, 0, 0];
    check(
        assemble(hdr, &data, 0x75),
        header(0, MessageType::Set, ParamType::Capture, 0),
        Param::Capture(Capture {
            stream: stream("cam0"),
            single_image: true,
            record_video: true,
            images_captured: 0x0102,
            videos_captured: 7,
        }),
    );
}

#[test]
fn detection_set_fixture() {
    // mode 0, sorting 1, track 0.5 → 128, scan 0.25 → 64, track overlap 0.3 → 77,
    // scan overlap 0, creation 10, bonuses 5 and 6, penalty 7, penalty 255 (keep).
    let data = [0, 1, 0x80, 64, 77, 0, 10, 5, 6, 7, 255];
    let hdr = [0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x02, 0x05, 0x00, 0, 0, 0, 0];
    check(
        assemble(hdr, &data, 0x3B),
        header(0, MessageType::Set, ParamType::Detection, 0),
        Param::Detection(Detection {
            mode: 0,
            sorting_mode: 1,
            track_confidence: 128.0 / 255.0,
            scan_confidence: 64.0 / 255.0,
            track_overlap: 77.0 / 255.0,
            scan_overlap: 0.0,
            creation_score: 10,
            bonus_detection: 5,
            bonus_redetection: 6,
            missed_detection_penalty: 7,
            missed_redetection_penalty: 255,
        }),
    );
    // The same values as the user writes them round to the fixture's bytes.
    let (_, data_from_floats) = Param::Detection(Detection {
        track_confidence: 0.5,
        scan_confidence: 0.25,
        track_overlap: 0.3,
        sorting_mode: 1,
        creation_score: 10,
        bonus_detection: 5,
        bonus_redetection: 6,
        missed_detection_penalty: 7,
        missed_redetection_penalty: 255,
        ..Detection::default()
    })
    .encode();
    assert_eq!(data_from_floats[..11], data);
}

#[test]
fn single_target_tracking_set_fixture() {
    #[rustfmt::skip]
    let data = [
        1,                                      // 0 command: direction
        b't', b'r', b'k', 0, 0, 0, 0, 0,        // 1 stream
        0,                                      // 9 cam
        0x00, 0x20,                             // 10 x 8192
        0x00, 0xE0,                             // 12 y -8192
        9,                                      // 14 detection id
        0x05, 0x00,                             // 15 zoom 5
        0x6B, 0x03, 0x00, 0x00,                 // 17 confidence 0.875
        0x00, 0x00, 0x00, 0x00,                 // 21 yaw_g 0
        0x18, 0xFC, 0xFF, 0xFF,                 // 25 pitch_g -1.0
        1,                                      // 29 rel frame heading
        0, 0, 0, 0,                             // 30 yaw_rel
        0, 0, 0, 0,                             // 34 pitch_rel
    ];
    let hdr = [42, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x02, 0x0C, 0x00, 0, 0, 0, 0];
    check(
        assemble(hdr, &data, 0x3F),
        header(42, MessageType::Set, ParamType::SingleTargetTracking, 0),
        Param::SingleTargetTracking(SingleTargetTracking {
            command: 1,
            stream: stream("trk"),
            cam: 0,
            x_offset: 8192.0 / 32767.0,
            y_offset: -8192.0 / 32767.0,
            detection_id: 9,
            zoom: 5,
            confidence: 0.875,
            yaw_global: 0.0,
            pitch_global: -1.0,
            rel_frame: 1,
            yaw_rel: 0.0,
            pitch_rel: 0.0,
        }),
    );
}

#[test]
fn periodic_get_fixture() {
    let data = [b'c', b'a', b'm', b'0', 0, 0, 0, 0, 255];
    // GET, CAM_OPTICS_AND_CONTROL, every 500 ms
    let hdr = [
        5, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x01, 0x08, 0x00, 0xF4, 0x01, 0x00, 0x00,
    ];
    let bytes = assemble(hdr, &data, 0x03);
    let frame = Frame::decode(&bytes).unwrap();
    assert_eq!(frame.message_type, MessageType::Get);
    assert_eq!(frame.param_type, ParamType::CamOpticsAndControl);
    assert_eq!(frame.interval_ms, 500);
    let get = GetRequest::decode(frame.param_type, &frame.data).unwrap();
    assert_eq!(
        get,
        GetRequest {
            stream: stream("cam0"),
            cam: None
        }
    );
    assert_eq!(get.encode(), frame.data);
    assert_eq!(frame.encode(), bytes);
}

#[test]
fn detected_roi_get_selectors() {
    for (index, sel) in [
        (0, RoiSelector::One(0)),
        (253, RoiSelector::One(253)),
        (254, RoiSelector::AllVisible),
        (255, RoiSelector::AllKnown),
    ] {
        let mut data = [0u8; 64];
        data[0] = index;
        assert_eq!(RoiSelector::decode(&data), sel);
        assert_eq!(sel.encode(), data);
    }
}

#[test]
fn broken_fixtures_are_refused() {
    let good = cam_targeting_set();
    // Wrong checksum.
    let mut bad = good;
    bad[80] ^= 0x01;
    assert_eq!(
        Frame::decode(&bad),
        Err(FrameError::BadChecksum {
            received: 0x0C,
            computed: 0x0D
        })
    );
    // A flipped payload bit is caught by the checksum.
    let mut bad = good;
    bad[30] ^= 0x10;
    assert!(matches!(
        Frame::decode(&bad),
        Err(FrameError::BadChecksum { .. })
    ));

    // Header fields re-checksummed so only the field is wrong.
    let reseal = |mut f: [u8; FRAME_LEN]| {
        f[80] = crc8_bluetooth(&f[..80]);
        f
    };
    let mut bad = good;
    bad[8] = 1;
    assert_eq!(Frame::decode(&reseal(bad)), Err(FrameError::BadVersion(1)));
    let mut bad = good;
    bad[9] = 9;
    assert_eq!(
        Frame::decode(&reseal(bad)),
        Err(FrameError::UnknownMessageType(9))
    );
    let mut bad = good;
    bad[10] = 13;
    assert_eq!(
        Frame::decode(&reseal(bad)),
        Err(FrameError::UnknownParamType(13))
    );
    // The raw fields survive a refusal for the error reply.
    let raw = RawFrame::parse(&reseal(bad));
    assert_eq!(raw.timestamp, 0x0102_0304_0506_0708);
    assert_eq!(raw.param_type, 13);
}

#[test]
fn padding_is_tolerated() {
    let good = cam_targeting_set();
    // Bytes 81..88 are outside the checksum: garbage there is ignored.
    let mut padded = good;
    padded[81..].copy_from_slice(&[0xAA; 7]);
    assert_eq!(Frame::decode(&padded), Frame::decode(&good));
    // Byte 11 is inside the checksum: accepted when the sender's checksum covers it.
    let mut padded = good;
    padded[11] = 0x5A;
    padded[80] = crc8_bluetooth(&padded[..80]);
    assert_eq!(Frame::decode(&padded), Frame::decode(&good));
    // Re-encoding writes zero padding.
    assert_eq!(Frame::decode(&padded).unwrap().encode(), good);
}

#[test]
fn quit_frame() {
    let hdr = [0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0xFF, 0x00, 0x00, 0, 0, 0, 0];
    let mut bytes = assemble(hdr, &[], 0);
    bytes[80] = crc8_bluetooth(&bytes[..80]);
    assert_eq!(
        Frame::decode(&bytes).unwrap().message_type,
        MessageType::Quit
    );
}
