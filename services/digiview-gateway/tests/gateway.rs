//! digiview-gateway in-process against a fake pipeline: GET answers decode to the
//! published state, SETs reach the pipeline and its answers come back, hostile input
//! gets DigiView's error codes, periodic GETs, QUIT, chunking and slow clients.

mod common;

use std::time::Duration;

use common::{fake_direction, known_state, payload, Client, Gateway, PATIENCE};
use digiview_proto::{
    Ai, BoundingBox, CamOffset, CamOpticsAndControl, CamTargeting, Capture, DetectedRoi, Detection,
    FixedName, Frame, GetRequest, MessageType, Model, Param, ParamType, RoiSelector,
    SingleTargetTracking, StreamName, SystemStatus, VideoOutput, DATA_LEN,
};
use skymesh_ipc_types::{ViewControlKind, VisionOrigin, VisionResult};

fn main_stream() -> StreamName {
    FixedName::new("main").unwrap()
}

fn get_data(stream: &str, cam: Option<u8>) -> [u8; DATA_LEN] {
    GetRequest {
        stream: FixedName::new(stream).unwrap(),
        cam,
    }
    .encode()
}

/// What `p` looks like after a trip through the wire's fixed point.
fn wire(p: Param) -> Param {
    let (pt, data) = p.encode();
    Param::decode(pt, &data).unwrap()
}

async fn get_one(c: &mut Client, pt: ParamType, data: [u8; DATA_LEN]) -> Param {
    c.get(pt, data, 0, 77).await;
    let r = c.recv().await;
    assert_eq!(r.timestamp, 77, "replies echo the request's timestamp");
    assert_eq!(r.param_type, pt as u8);
    payload(&r)
}

async fn expect_code(c: &mut Client, code: MessageType, param_type: u8, ts: u64) {
    let r = c.recv().await;
    assert_eq!(
        (r.message_type, r.param_type, r.timestamp),
        (code as u8, param_type, ts),
        "{r:?}"
    );
}

#[tokio::test]
async fn every_get_decodes_to_the_published_state() {
    let gw = Gateway::start().await;
    let s = known_state();
    let st = &s.streams[0];
    let mut c = gw.client().await;

    let got = get_one(&mut c, ParamType::SystemStatus, [0; DATA_LEN]).await;
    let want = Param::SystemStatus(SystemStatus {
        status: 1,
        error: 0,
        temperature: 48.5,
    });
    assert_eq!(got, wire(want));

    let got = get_one(&mut c, ParamType::Ai, [0; DATA_LEN]).await;
    let want = Param::Ai(Ai {
        enabled: true,
        track_model: FixedName::new("people").unwrap(),
        scan_model: FixedName::new("blobs").unwrap(),
    });
    assert_eq!(got, want);

    let got = get_one(&mut c, ParamType::Detection, [0; DATA_LEN]).await;
    let want = Param::Detection(Detection {
        mode: 7,
        sorting_mode: 1,
        track_confidence: 0.5,
        scan_confidence: 0.25,
        track_overlap: 0.3,
        scan_overlap: 0.6,
        creation_score: 10,
        bonus_detection: 20,
        bonus_redetection: 30,
        missed_detection_penalty: 40,
        missed_redetection_penalty: 50,
    });
    assert_eq!(got, wire(want));

    let got = get_one(&mut c, ParamType::VideoOutput, get_data("main", None)).await;
    let views = st
        .cams
        .iter()
        .map(|c| BoundingBox {
            x: c.view_rect[0],
            y: c.view_rect[1],
            w: c.view_rect[2],
            h: c.view_rect[3],
        })
        .collect();
    let want = Param::VideoOutput(VideoOutput {
        stream: main_stream(),
        width: 1280,
        height: 720,
        fps: 0,
        layout_mode: 4,
        layout_views: 4,
        overlay_mode: 2,
        views,
        overlay_box: BoundingBox {
            x: 1160,
            y: 0,
            w: 120,
            h: 720,
        },
        single_detection_size: 120,
    });
    assert_eq!(got, want);
    // The layout byte on the wire: num_views << 4 | layout.
    c.get(ParamType::VideoOutput, get_data("main", None), 0, 1)
        .await;
    assert_eq!(c.recv().await.data[13], (4 << 4) | 4);

    let got = get_one(&mut c, ParamType::Capture, get_data("main", None)).await;
    let want = Param::Capture(Capture {
        stream: main_stream(),
        single_image: false,
        record_video: true,
        images_captured: 3,
        videos_captured: 1,
    });
    assert_eq!(got, want);

    let cam = &st.cams[2];
    let got = get_one(&mut c, ParamType::CamTargeting, get_data("main", Some(2))).await;
    let want = Param::CamTargeting(CamTargeting {
        stream: main_stream(),
        cam: 2,
        mode: cam.targeting_mode,
        euler_delta: false,
        yaw: f64::from(cam.yaw_rad),
        pitch: f64::from(cam.pitch_rad),
        roll: 0.0,
        lock_flags: 0b011,
        x_offset: f64::from(cam.x_offset),
        y_offset: f64::from(cam.y_offset),
        latitude: cam.target_lat_deg,
        longitude: cam.target_lon_deg,
        altitude: -30.0,
    });
    assert_eq!(got, wire(want));

    let cam = &st.cams[3];
    let got = get_one(
        &mut c,
        ParamType::CamOpticsAndControl,
        get_data("main", Some(3)),
    )
    .await;
    let want = Param::CamOpticsAndControl(CamOpticsAndControl {
        stream: main_stream(),
        cam: 3,
        zoom: cam.zoom,
        fov: f64::from(cam.fov_rad),
        crop_mode: 1,
    });
    assert_eq!(got, wire(want));

    let got = get_one(
        &mut c,
        ParamType::SingleTargetTracking,
        get_data("main", None),
    )
    .await;
    let t = &st.stt;
    let want = Param::SingleTargetTracking(SingleTargetTracking {
        command: 2,
        stream: main_stream(),
        cam: 1,
        x_offset: 0.0,
        y_offset: 0.0,
        detection_id: 4,
        zoom: 3,
        confidence: f64::from(t.confidence),
        yaw_global: f64::from(t.yaw_global_rad),
        pitch_global: f64::from(t.pitch_global_rad),
        rel_frame: 1,
        // rel_frame 1: heading-relative.
        yaw_rel: f64::from(t.yaw_heading_rad),
        pitch_rel: f64::from(t.pitch_heading_rad),
    });
    assert_eq!(got, wire(want));
    gw.wait_metric("skymesh_digiview_replies_total", "type=current", 10.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn model_is_one_reply_per_model() {
    let gw = Gateway::start().await;
    let mut c = gw.client().await;
    c.get(ParamType::Model, [0; DATA_LEN], 0, 5).await;
    let a = payload(&c.recv().await);
    let b = payload(&c.recv().await);
    let name = |s: &str| {
        Param::Model(Model {
            name: FixedName::new(s).unwrap(),
        })
    };
    assert_eq!((a, b), (name("blobs"), name("people")));
    c.nothing_for(Duration::from_millis(300)).await;
    gw.stop().await;
}

fn roi(i: usize, index: u8, total: u8) -> Param {
    let s = known_state();
    let d = &s.detections[i];
    let geo = d.geo_valid != 0;
    wire(Param::DetectedRoi(DetectedRoi {
        index,
        score: d.score,
        total,
        object_type: d.object_type,
        yaw_global: f64::from(d.yaw_global_rad),
        pitch_global: f64::from(d.pitch_global_rad),
        // The default roi_rel_frame: camera.
        rel_frame: 2,
        yaw_rel: f64::from(d.yaw_camera_rad),
        pitch_rel: f64::from(d.pitch_camera_rad),
        latitude: if geo { d.lat_deg } else { 0.0 },
        longitude: if geo { d.lon_deg } else { 0.0 },
        altitude: if geo { f64::from(d.alt_msl_m) } else { 0.0 },
        distance: if geo { f64::from(d.distance_m) } else { 0.0 },
    }))
}

#[tokio::test]
async fn detected_roi_one_visible_and_all() {
    let gw = Gateway::start().await;
    let mut c = gw.client().await;
    // One, by sorted index: the second detection (not geolocated: zeros).
    c.get(ParamType::DetectedRoi, RoiSelector::One(1).encode(), 0, 1)
        .await;
    assert_eq!(payload(&c.recv().await), roi(1, 1, 1));
    // 254: those in the overlay (slots 0 and 1: detections 0 and 2).
    c.get(
        ParamType::DetectedRoi,
        RoiSelector::AllVisible.encode(),
        0,
        2,
    )
    .await;
    assert_eq!(payload(&c.recv().await), roi(0, 0, 2));
    assert_eq!(payload(&c.recv().await), roi(2, 1, 2));
    // 255: all three.
    c.get(ParamType::DetectedRoi, RoiSelector::AllKnown.encode(), 0, 3)
        .await;
    for i in 0..3 {
        assert_eq!(payload(&c.recv().await), roi(i, i as u8, 3));
    }
    // No such detection: DATA_ERROR.
    c.get(ParamType::DetectedRoi, RoiSelector::One(9).encode(), 0, 4)
        .await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::DetectedRoi as u8,
        4,
    )
    .await;
    gw.stop().await;
}

#[tokio::test]
async fn cam_offset_is_the_pipelines_direction_in_wire_units() {
    let mut gw = Gateway::start().await;
    let mut c = gw.client().await;
    let request = Param::CamOffset(CamOffset {
        stream: main_stream(),
        cam: 1,
        x: 0.5,
        y: -0.25,
        ..CamOffset::default()
    });
    let (_, data) = request.encode();
    // The x/y the gateway reads are the wire's.
    let Param::CamOffset(sent) = Param::decode(ParamType::CamOffset, &data).unwrap() else {
        unreachable!()
    };
    let got = get_one(&mut c, ParamType::CamOffset, data).await;
    let asked = gw.next_control().await;
    assert_eq!(asked.kind(), Ok(ViewControlKind::DirectionAt));
    assert_eq!(
        (
            asked.stream.as_str(),
            asked.cam,
            asked.x_offset,
            asked.y_offset
        ),
        ("main", 1, sent.x, sent.y)
    );
    let [yg, pg, yc, pc] = fake_direction(sent.x, sent.y);
    let want = Param::CamOffset(CamOffset {
        stream: main_stream(),
        cam: 1,
        x: sent.x,
        y: sent.y,
        yaw_global: yg,
        pitch_global: pg,
        yaw_rel: yc,
        pitch_rel: pc,
    });
    assert_eq!(got, wire(want.clone()));
    // x outside [-1, 1] cannot be encoded as i16 except -32768: DATA_ERROR, the
    // pipeline is not asked.
    let mut bad = data;
    bad[9..11].copy_from_slice(&i16::MIN.to_le_bytes());
    c.get(ParamType::CamOffset, bad, 0, 8).await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::CamOffset as u8,
        8,
    )
    .await;
    // A camera the layout does not show: DATA_ERROR from the state.
    let mut hidden = data;
    hidden[8] = 7;
    c.get(ParamType::CamOffset, hidden, 0, 9).await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::CamOffset as u8,
        9,
    )
    .await;
    assert!(gw.controls.try_recv().is_err());
    // The pipeline has no direction for the view yet: DATA_ERROR; no answer: UNKNOWN.
    gw.answer_with(Some((VisionResult::Ignored, "no view direction yet")));
    c.get(ParamType::CamOffset, data, 0, 10).await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::CamOffset as u8,
        10,
    )
    .await;
    gw.answer_with(None);
    c.get(ParamType::CamOffset, data, 0, 11).await;
    expect_code(&mut c, MessageType::Unknown, ParamType::CamOffset as u8, 11).await;
    // Periodic: the pipeline is asked at every tick.
    gw.answer_with(Some((VisionResult::Applied, "")));
    c.get(ParamType::CamOffset, data, 100, 12).await;
    for _ in 0..3 {
        let r = c.recv().await;
        assert_eq!(
            (r.message_type, r.timestamp, r.interval_ms),
            (MessageType::Current as u8, 12, 100)
        );
        assert_eq!(payload(&r), wire(want.clone()));
    }
    gw.stop().await;
}

fn ai_set() -> Param {
    Param::Ai(Ai {
        enabled: false,
        track_model: FixedName::new("people").unwrap(),
        scan_model: FixedName::new("blobs").unwrap(),
    })
}

#[tokio::test]
async fn sets_reach_the_pipeline_and_its_answers_come_back() {
    let mut gw = Gateway::start_with(|s| s.set_timeout = Duration::from_millis(300)).await;
    let mut c = gw.client().await;

    c.set(&ai_set(), 1001).await;
    expect_code(
        &mut c,
        MessageType::Acknowledgement,
        ParamType::Ai as u8,
        1001,
    )
    .await;
    let ctl = gw.next_control().await;
    assert_eq!(ctl.kind(), Ok(ViewControlKind::Ai));
    assert_eq!(ctl.origin, VisionOrigin::DigiView.to_wire());
    assert_eq!(
        (
            ctl.ai_enabled,
            ctl.scan_model.as_str(),
            ctl.track_model.as_str()
        ),
        (0, "blobs", "people")
    );
    assert_ne!(ctl.request_id, 0);

    gw.answer_with(Some((VisionResult::Ignored, "no such model")));
    c.set(&ai_set(), 1002).await;
    expect_code(&mut c, MessageType::DataError, ParamType::Ai as u8, 1002).await;
    let second = gw.next_control().await;
    assert_ne!(second.request_id, ctl.request_id);

    gw.answer_with(Some((VisionResult::Unsupported, "not here")));
    c.set(&ai_set(), 1003).await;
    expect_code(&mut c, MessageType::Unknown, ParamType::Ai as u8, 1003).await;

    // No answer within set_timeout: UNKNOWN; a GET sent meanwhile is answered after.
    gw.answer_with(None);
    c.set(&ai_set(), 1004).await;
    c.get(ParamType::SystemStatus, [0; DATA_LEN], 0, 1005).await;
    expect_code(&mut c, MessageType::Unknown, ParamType::Ai as u8, 1004).await;
    let r = c.recv().await;
    assert_eq!(
        (r.message_type, r.timestamp),
        (MessageType::Current as u8, 1005)
    );
    gw.wait_metric(
        "skymesh_digiview_refused_total",
        "reason=pipeline_timeout",
        1.0,
    )
    .await;
    gw.wait_metric("skymesh_digiview_set_results_total", "result=applied", 1.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn hostile_frames_get_their_error_codes() {
    let mut gw = Gateway::start().await;
    let mut c = gw.client().await;
    let get = |pt| Frame {
        timestamp: 42,
        ..Frame::new(MessageType::Get, pt)
    };

    // Checksum.
    let mut bytes = get(ParamType::Ai).encode();
    bytes[80] ^= 0xFF;
    c.send_raw(&bytes).await;
    expect_code(&mut c, MessageType::ChecksumError, ParamType::Ai as u8, 42).await;
    // Unknown parameter type, unknown message type, bad version: UNKNOWN.
    for (offset, value, param) in [(10usize, 200u8, 200u8), (9, 77, 1), (8, 3, 1)] {
        let mut bytes = get(ParamType::Ai).encode();
        bytes[offset] = value;
        bytes[80] = digiview_proto::crc8_bluetooth(&bytes[..80]);
        c.send_raw(&bytes).await;
        expect_code(&mut c, MessageType::Unknown, param, 42).await;
    }
    // SENSOR / CAM_DEPTH_ESTIMATION: disabled as in DigiView.
    c.send(&get(ParamType::Sensor)).await;
    expect_code(&mut c, MessageType::Unknown, ParamType::Sensor as u8, 42).await;
    // Unknown stream; camera not in the layout: DATA_ERROR.
    c.get(ParamType::VideoOutput, get_data("nope", None), 0, 43)
        .await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::VideoOutput as u8,
        43,
    )
    .await;
    c.get(ParamType::CamTargeting, get_data("main", Some(7)), 0, 44)
        .await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::CamTargeting as u8,
        44,
    )
    .await;
    // An interval of 1..99 ms: DATA_ERROR.
    c.get(ParamType::SystemStatus, [0; DATA_LEN], 50, 45).await;
    expect_code(&mut c, MessageType::DataError, 0, 45).await;
    // SET out of range: DATA_ERROR, never forwarded.
    let bad = Param::Detection(Detection {
        sorting_mode: 9,
        ..Detection::default()
    });
    c.set(&bad, 46).await;
    expect_code(
        &mut c,
        MessageType::DataError,
        ParamType::Detection as u8,
        46,
    )
    .await;
    // SET of a GET-only type.
    c.set(&Param::SystemStatus(SystemStatus::default()), 47)
        .await;
    expect_code(&mut c, MessageType::DataError, 0, 47).await;
    // A reply type from a client.
    c.send(&Frame {
        timestamp: 48,
        ..Frame::new(MessageType::Acknowledgement, ParamType::Ai)
    })
    .await;
    expect_code(&mut c, MessageType::Unknown, ParamType::Ai as u8, 48).await;
    // Still serving.
    assert!(matches!(
        get_one(&mut c, ParamType::SystemStatus, [0; DATA_LEN]).await,
        Param::SystemStatus(_)
    ));
    assert!(
        gw.controls.try_recv().is_err(),
        "nothing refused reaches the pipeline"
    );
    gw.wait_metric("skymesh_digiview_refused_total", "reason=bad_checksum", 1.0)
        .await;
    gw.wait_metric("skymesh_digiview_frames_in_total", "type=invalid", 4.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn a_client_not_in_write_allowed_gets_forbidden() {
    let mut gw = Gateway::start_with(|s| {
        s.write_allowed =
            skymesh_digiview_gateway::privilege::AddrSet::new(vec!["10.0.0.0/8".parse().unwrap()]);
    })
    .await;
    let mut c = gw.client().await;
    c.set(&ai_set(), 9).await;
    expect_code(&mut c, MessageType::Forbidden, ParamType::Ai as u8, 9).await;
    // GETs are open to everybody.
    assert!(matches!(
        get_one(&mut c, ParamType::Ai, [0; DATA_LEN]).await,
        Param::Ai(_)
    ));
    assert!(gw.controls.try_recv().is_err());
    gw.wait_metric("skymesh_digiview_refused_total", "reason=forbidden", 1.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn periodic_get_repeats_and_interval_zero_cancels() {
    let gw = Gateway::start().await;
    let mut c = gw.client().await;
    c.get(ParamType::SystemStatus, [0; DATA_LEN], 100, 500)
        .await;
    for _ in 0..4 {
        let r = c.recv().await;
        assert_eq!(
            (r.message_type, r.timestamp, r.interval_ms),
            (MessageType::Current as u8, 500, 100)
        );
    }
    gw.wait_metric("skymesh_digiview_periodic_gets", "", 1.0)
        .await;
    c.get(ParamType::SystemStatus, [0; DATA_LEN], 0, 501).await;
    // Periodic replies already queued may come first; the once-reply ends them.
    loop {
        let r = c.recv().await;
        if r.timestamp == 501 {
            assert_eq!(r.interval_ms, 0);
            break;
        }
        assert_eq!(r.timestamp, 500);
    }
    c.nothing_for(Duration::from_millis(500)).await;
    gw.wait_metric("skymesh_digiview_periodic_gets", "", 0.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn quit_closes_the_connection() {
    let gw = Gateway::start().await;
    let mut c = gw.client().await;
    c.send(&Frame::new(MessageType::Quit, ParamType::SystemStatus))
        .await;
    assert!(c.closed().await);
    gw.wait_metric("skymesh_digiview_disconnects_total", "reason=quit", 1.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn a_frame_delivered_one_byte_at_a_time_is_answered() {
    let gw = Gateway::start().await;
    let mut c = gw.client().await;
    let f = Frame {
        timestamp: 3,
        ..Frame::new(MessageType::Get, ParamType::Ai)
    };
    for b in f.encode() {
        c.send_raw(&[b]).await;
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    let r = c.recv().await;
    assert_eq!(
        (r.message_type, r.timestamp),
        (MessageType::Current as u8, 3)
    );
    gw.stop().await;
}

#[tokio::test]
async fn garbage_shifts_the_frames_until_the_client_reconnects() {
    let gw = Gateway::start().await;
    let get = Frame {
        timestamp: 11,
        ..Frame::new(MessageType::Get, ParamType::Ai)
    }
    .encode();

    // 5 bytes of garbage: every later frame is cut 5 bytes early and fails its
    // checksum (no sync word to find the next frame by).
    let mut c = gw.client().await;
    c.send_raw(&[0xAA, 0x55, 0x00, 0xFF, 0x13]).await;
    c.send_raw(&get).await;
    c.send_raw(&get).await;
    for _ in 0..2 {
        let r = c.recv().await;
        assert_eq!(r.message_type, MessageType::ChecksumError as u8, "{r:?}");
    }
    // Reconnecting starts aligned again.
    let mut c = gw.client().await;
    c.send_raw(&get).await;
    let r = c.recv().await;
    assert_eq!(
        (r.message_type, r.timestamp),
        (MessageType::Current as u8, 11)
    );

    // Garbage of a whole frame's length only costs that frame.
    c.send_raw(&[0x5A; 88]).await;
    c.send_raw(&get).await;
    assert_eq!(
        c.recv().await.message_type,
        MessageType::ChecksumError as u8
    );
    assert_eq!(c.recv().await.message_type, MessageType::Current as u8);
    gw.stop().await;
}

#[tokio::test]
async fn a_frame_left_incomplete_closes_the_connection() {
    let gw = Gateway::start_with(|s| s.partial_frame_timeout = Duration::from_millis(300)).await;
    let mut c = gw.client().await;
    c.send_raw(&[0; 10]).await;
    assert!(c.closed().await);
    gw.wait_metric(
        "skymesh_digiview_disconnects_total",
        "reason=partial_frame_timeout",
        1.0,
    )
    .await;
    gw.stop().await;
}

#[tokio::test]
async fn gets_while_the_pipeline_is_down_are_unknown() {
    let gw = Gateway::start_with(|s| s.state_timeout = Duration::from_millis(300)).await;
    *gw.state.lock().unwrap() = None;
    let mut c = gw.client().await;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        c.get(ParamType::Ai, [0; DATA_LEN], 0, 6).await;
        let r = c.recv().await;
        if r.message_type == MessageType::Unknown as u8 {
            break;
        }
        assert!(tokio::time::Instant::now() < deadline, "never UNKNOWN");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(gw
        .metric("skymesh_digiview_refused_total", "reason=pipeline_down")
        .is_some());
    gw.stop().await;
}

#[tokio::test]
async fn a_flood_beyond_the_rate_limit_is_dropped_unanswered() {
    let gw = Gateway::start_with(|s| s.max_frames_per_s = 5).await;
    let mut c = gw.client().await;
    let get = Frame::new(MessageType::Get, ParamType::SystemStatus).encode();
    let flood: Vec<u8> = (0..40).flat_map(|_| get).collect();
    c.send_raw(&flood).await;
    let mut answered = 0;
    while c.recv_within(Duration::from_millis(500)).await.is_some() {
        answered += 1;
    }
    assert!((5..40).contains(&answered), "{answered} answered");
    let dropped = gw
        .metric("skymesh_digiview_refused_total", "reason=rate_limited")
        .unwrap_or(0.0);
    assert_eq!(dropped as usize + answered, 40);
    gw.stop().await;
}

#[tokio::test]
async fn clients_beyond_max_clients_are_closed_and_the_others_served() {
    let gw = Gateway::start_with(|s| s.max_clients = 2).await;
    let mut a = gw.client().await;
    let mut b = gw.client().await;
    // Both are served before the third arrives (the slots are taken).
    for c in [&mut a, &mut b] {
        c.get(ParamType::SystemStatus, [0; DATA_LEN], 0, 1).await;
        c.recv().await;
    }
    let mut third = gw.client().await;
    assert!(third.closed().await, "a third client is closed at accept");
    gw.wait_metric(
        "skymesh_digiview_connections_total",
        "result=refused_max_clients",
        1.0,
    )
    .await;
    a.get(ParamType::SystemStatus, [0; DATA_LEN], 0, 2).await;
    a.recv().await;
    // A slot freed by a leaving client is given to the next one.
    drop(b);
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        let mut c = gw.client().await;
        c.get(ParamType::SystemStatus, [0; DATA_LEN], 0, 3).await;
        if c.recv_within(Duration::from_millis(500)).await.is_some() {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the freed slot was never given to a new client"
        );
    }
    gw.stop().await;
}

/// The next demand word within 2.5 s (the renewal period is 1 s).
async fn next(
    words: &mut skymesh_runtime::Subscriber<skymesh_ipc_types::VisionDemand>,
) -> Option<skymesh_ipc_types::VisionDemand> {
    words
        .recv_timeout(Duration::from_millis(2500))
        .await
        .expect("demand topic")
}

#[tokio::test]
async fn a_connected_client_is_demand_for_the_pipeline() {
    use skymesh_ipc_types::{topics, ServiceId, VisionDemand};
    use skymesh_runtime::{Bus, Stats};

    let gw = Gateway::start().await;
    let tool =
        Bus::open(&gw.domain, "demand-watch", ServiceId::Tool, 1, Stats::new()).expect("tool bus");
    let mut words = tool
        .subscriber::<VisionDemand>(&topics::vision_demand())
        .expect("demand subscriber");
    // The harness's probe client has come and gone: its words end with a withdrawal,
    // then nothing while no client is connected.
    let mut last = None;
    while let Some(w) = next(&mut words).await {
        last = Some(w.wanted);
    }
    assert_ne!(last, Some(1), "the probe client's word was not withdrawn");

    let c = gw.client().await;
    assert_eq!(
        next(&mut words).await.map(|w| w.wanted),
        Some(1),
        "a client connected"
    );
    // Renewed (the pipeline's lease is 3 s).
    assert_eq!(next(&mut words).await.map(|w| w.wanted), Some(1), "renewed");

    drop(c);
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        let w = next(&mut words).await.expect("a word");
        if w.wanted == 0 {
            break;
        }
        assert!(tokio::time::Instant::now() < deadline, "never withdrawn");
    }
    assert_eq!(
        next(&mut words).await,
        None,
        "nothing more once nobody is connected"
    );
    gw.stop().await;
}
