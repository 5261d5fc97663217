//! The device's messages equal the document's examples (as JSON values, numbers
//! compared as f64), modulo tid, bid and timestamp, which are checked separately.
//! The document's `services_reply` and `events` examples omit `method` and `gateway`,
//! which FACTS.md's envelope carries; they are added to the expected value.

mod common;

use common::examples::{example, DRC_UP, EVENTS, SERVICES, SERVICES_REPLY};
use common::{assert_json_eq, service_envelope};
use dji_proto::{
    encode_drc_up, encode_event, encode_services_reply, parse_envelope, CameraPhotoTakeProgress,
    DelayInfoPush, DrcResult, DrcStatusNotify, DroneControlReply, FlyToPointProgress,
    HeartBeatEcho, HsiInfoPush, JoystickInvalidNotify, JoystickInvalidReason, LiveviewDelay,
    OsdInfoPush, PathPoint, PhotoTakeExt, PhotoTakeOutput, PhotoTakeProgress, PoiStatus,
    PoiStatusNotify, TakeoffToPointProgress, TaskStatus, TopicKind, SERVICE_METHODS,
};
use serde_json::{json, Value};

const SN: &str = "4BRSN1234";
const NOW: u64 = 1_700_000_000_123;

fn parse(bytes: &[u8]) -> Value {
    let text = std::str::from_utf8(bytes).expect("utf-8");
    assert!(
        !text.contains('\n') && !text.contains(": "),
        "compact: {text}"
    );
    serde_json::from_slice(bytes).expect("our output is JSON")
}

/// `expected` with tid/bid/timestamp taken from `ours` and `extra` fields added.
fn modulo_ids(ours: &Value, expected: &str, extra: &[(&str, Value)]) -> Value {
    let mut e: Value = serde_json::from_str(expected).expect("example JSON");
    for key in ["tid", "bid", "timestamp"] {
        if let Some(v) = ours.get(key) {
            e[key] = v.clone();
        }
    }
    for (k, v) in extra {
        e[*k] = v.clone();
    }
    e
}

#[test]
fn services_reply_for_every_method() {
    for &method in SERVICE_METHODS {
        let request = service_envelope(method);
        let ours = parse(&encode_services_reply(&request, SN, 0, None, NOW));
        assert_eq!(ours["tid"], request.tid.as_str());
        assert_eq!(ours["bid"], request.bid.as_str());
        assert_eq!(ours["timestamp"], NOW);
        let expected = modulo_ids(
            &ours,
            example(SERVICES_REPLY, method),
            &[("method", json!(method)), ("gateway", json!(SN))],
        );
        assert_json_eq(&ours, &expected);
        // A fake cloud reads it back.
        let env = parse_envelope(
            TopicKind::ServicesReply,
            &encode_services_reply(&request, SN, 0, None, NOW),
        )
        .expect("parses");
        assert_eq!((env.method.as_str(), env.timestamp), (method, NOW));
    }
}

#[test]
fn services_reply_with_code_and_output() {
    // camera_photo_take's reply table: result + output.status "in_progress".
    let request = service_envelope("camera_photo_take");
    let ours = parse(&encode_services_reply(
        &request,
        SN,
        dji_proto::codes::PAYLOAD_UNSUPPORTED,
        Some(json!({"status": "in_progress"})),
        NOW,
    ));
    assert_eq!(
        ours["data"],
        json!({"result": 314014, "output": {"status": "in_progress"}})
    );
    assert_eq!(ours["method"], "camera_photo_take");
}

fn event_matches(method: &str, data: Value) {
    let bytes = encode_event(SN, method, data, true, "tid-1", "bid-1", NOW);
    let ours = parse(&bytes);
    assert_eq!(
        (&ours["tid"], &ours["bid"], &ours["timestamp"]),
        (&json!("tid-1"), &json!("bid-1"), &json!(NOW))
    );
    let expected = modulo_ids(
        &ours,
        example(EVENTS, method),
        &[("method", json!(method)), ("gateway", json!(SN))],
    );
    assert_json_eq(&ours, &expected);
    let env = parse_envelope(TopicKind::Events, &bytes).expect("a fake cloud parses it");
    assert_eq!((env.need_reply, env.method.as_str()), (Some(1), method));
}

fn path() -> Vec<PathPoint> {
    vec![PathPoint {
        latitude: 13.23,
        longitude: 123.234,
        height: 123.234,
    }]
}

#[test]
fn every_event_example() {
    let to = |v: &dyn erased::ToValue| v.to_value();
    event_matches(
        "fly_to_point_progress",
        to(&FlyToPointProgress {
            fly_to_id: "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx".into(),
            status: TaskStatus::WaylineProgress,
            result: 0,
            way_point_index: 0,
            remaining_distance: 0.0,
            remaining_time: 0.0,
            planned_path_points: path(),
        }),
    );
    event_matches(
        "takeoff_to_point_progress",
        to(&TakeoffToPointProgress {
            status: TaskStatus::WaylineOk,
            result: 0,
            flight_id: "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx".into(),
            track_id: "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx".into(),
            way_point_index: 1,
            remaining_distance: 0.0,
            remaining_time: 0.0,
            planned_path_points: path(),
        }),
    );
    event_matches(
        "drc_status_notify",
        to(&DrcStatusNotify {
            result: 0,
            drc_state: 2,
        }),
    );
    event_matches(
        "joystick_invalid_notify",
        to(&JoystickInvalidNotify::from(JoystickInvalidReason::RcLost)),
    );
    event_matches(
        "poi_status_notify",
        to(&PoiStatusNotify {
            status: PoiStatus::InProgress,
            reason: 0,
            circle_radius: 10.1,
            circle_speed: 100.1,
            max_circle_speed: 200.2,
        }),
    );
    event_matches(
        "camera_photo_take_progress",
        to(&CameraPhotoTakeProgress {
            output: PhotoTakeOutput {
                status: "ok",
                progress: PhotoTakeProgress {
                    current_step: 0,
                    percent: 100,
                },
                ext: PhotoTakeExt { camera_mode: 3 },
            },
            result: 0,
        }),
    );
    // need_reply false is 0.
    let ours = parse(&encode_event(
        SN,
        "drc_status_notify",
        json!({}),
        false,
        "t",
        "b",
        NOW,
    ));
    assert_eq!(ours["need_reply"], 0);
}

#[test]
fn enum_names_on_the_wire() {
    let names: Vec<Value> = [
        TaskStatus::TaskReady,
        TaskStatus::WaylineProgress,
        TaskStatus::WaylineOk,
        TaskStatus::WaylineFailed,
        TaskStatus::WaylineCancel,
        TaskStatus::TaskFinish,
    ]
    .iter()
    .map(|s| serde_json::to_value(s).expect("serialises"))
    .collect();
    assert_eq!(
        names,
        [
            "task_ready",
            "wayline_progress",
            "wayline_ok",
            "wayline_failed",
            "wayline_cancel",
            "task_finish"
        ]
    );
    let poi: Vec<Value> = [PoiStatus::Failed, PoiStatus::InProgress, PoiStatus::Ok]
        .iter()
        .map(|s| serde_json::to_value(s).expect("serialises"))
        .collect();
    assert_eq!(poi, ["failed", "in_progress", "ok"]);
    for code in 0..=4u8 {
        let reason = JoystickInvalidReason::from_code(code).expect("defined");
        assert_eq!(reason.code(), code);
        assert_eq!(
            serde_json::to_value(reason).expect("serialises"),
            json!(code)
        );
        assert_eq!(JoystickInvalidNotify::from(reason).reason, code);
    }
    assert_eq!(JoystickInvalidReason::from_code(5), None);
}

fn drc_up_matches(method: &str, data: Value, extra: &[(&str, Value)]) {
    let ours = parse(&encode_drc_up(method, data, None, NOW));
    assert_eq!(ours["timestamp"], NOW);
    let expected = modulo_ids(&ours, example(DRC_UP, method), extra);
    assert_json_eq(&ours, &expected);
    let env = parse_envelope(
        TopicKind::DrcUp,
        &encode_drc_up(method, json!({}), None, NOW),
    )
    .expect("a fake cloud parses it");
    assert_eq!(env.method, method);
}

#[test]
fn every_drc_up_example() {
    let to = |v: &dyn erased::ToValue| v.to_value();
    drc_up_matches(
        "drone_control",
        to(&DroneControlReply::new(319033, -1)),
        &[],
    );
    drc_up_matches("drone_emergency_stop", to(&DrcResult { result: 0 }), &[]);
    drc_up_matches(
        "heart_beat",
        to(&HeartBeatEcho {
            seq: 10,
            timestamp: 1670415891013,
        }),
        &[],
    );
    drc_up_matches(
        "osd_info_push",
        to(&OsdInfoPush {
            attitude_head: 60.0,
            latitude: 10.0,
            longitude: 10.0,
            height: 10.0,
            speed_x: 10.0,
            speed_y: 10.0,
            speed_z: 10.0,
            gimbal_pitch: 60.0,
            gimbal_roll: 60.0,
            gimbal_yaw: 60.0,
        }),
        &[],
    );
    drc_up_matches(
        "delay_info_push",
        to(&DelayInfoPush {
            sdr_cmd_delay: 10,
            liveview_delay_list: vec![
                LiveviewDelay {
                    video_id: "1581BN210004555439234/52-0-0/normal-0".into(),
                    liveview_delay_time: 60,
                },
                LiveviewDelay {
                    video_id: "1581BN210004555439234/53-0-0/normal-0".into(),
                    liveview_delay_time: 80,
                },
            ],
        }),
        &[],
    );
}

#[test]
fn hsi_info_push_follows_the_table() {
    // The table names `around_distances` (as DJI's SDKs send it); the example writes
    // `around_distance` and adds direction flags the table does not define. Ours is the
    // table: compare with the example corrected the same way.
    let ours = parse(&encode_drc_up(
        "hsi_info_push",
        serde_json::to_value(HsiInfoPush {
            up_distance: 10,
            down_distance: 10,
            up_enable: true,
            up_work: true,
            down_enable: true,
            down_work: true,
            around_distances: vec![10, 8, 9, 16, 2],
        })
        .expect("serialises"),
        None,
        NOW,
    ));
    let mut expected: Value = serde_json::from_str(example(DRC_UP, "hsi_info_push")).expect("json");
    expected["timestamp"] = json!(NOW);
    let data = expected["data"].as_object_mut().expect("object");
    let around = data.remove("around_distance").expect("the example's name");
    data.insert("around_distances".into(), around);
    data.retain(|k, _| {
        !["left", "right", "front", "back", "vertical", "horizontal"]
            .iter()
            .any(|p| k.starts_with(p))
    });
    assert_json_eq(&ours, &expected);
}

#[test]
fn drc_up_top_level_seq() {
    let ours = parse(&encode_drc_up(
        "heart_beat",
        json!({"seq": 3}),
        Some(3),
        NOW,
    ));
    assert_eq!(
        ours,
        json!({"method": "heart_beat", "data": {"seq": 3}, "timestamp": NOW, "seq": 3})
    );
    let ours = parse(&encode_drc_up("heart_beat", json!({}), None, NOW));
    assert!(ours.get("seq").is_none());
}

#[test]
fn services_examples_reencode_through_the_cloud_side() {
    // encode_service writes what parse_service reads (the fake cloud's path).
    for &method in SERVICE_METHODS {
        let request = dji_proto::parse_service(&service_envelope(method)).expect("valid");
        let bytes = dji_proto::encode_service(&request, "t", "b", NOW);
        let env = parse_envelope(TopicKind::Services, &bytes).expect("parses");
        assert_eq!(dji_proto::parse_service(&env), Ok(request), "{method}");
        // Same data as the document's example, apart from number forms and
        // exposure_value's string form.
        let mut doc: Value = serde_json::from_str(example(SERVICES, method)).expect("json");
        if method == "camera_exposure_set" {
            doc["data"]["exposure_value"] = json!("5");
        }
        assert_json_eq(&env.data, &doc["data"]);
    }
}

/// `serde_json::to_value` behind a trait object, so one closure serves every struct.
mod erased {
    pub trait ToValue {
        fn to_value(&self) -> serde_json::Value;
    }
    impl<T: serde::Serialize> ToValue for T {
        fn to_value(&self) -> serde_json::Value {
            serde_json::to_value(self).expect("plain data serialises")
        }
    }
}
