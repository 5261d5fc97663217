//! The document's Example payloads (tests/common/examples.rs, its text verbatim) parse
//! to the expected typed values: every `services` method, every `drc/down` method, and
//! an `events_reply`.

mod common;

use common::examples::{self, example, DRC_DOWN, SERVICES};
use common::service_envelope;
use dji_proto::{
    parse_drc, parse_envelope, parse_event_reply, parse_service, CameraMode, CameraType, DrcDown,
    DrcModeEnter, DroneControl, EventReply, FlyToPoint, FlyToPointUpdate, GeoPoint, Malformed,
    MqttBroker, RcLostAction, ServiceRequest, StorageLens, TakeoffToPoint, TopicKind,
    SERVICE_METHODS,
};

const UUID: &str = "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx";
const PI: &str = "39-0-7";

fn pi() -> String {
    PI.to_owned()
}

fn point() -> Vec<GeoPoint> {
    vec![GeoPoint {
        latitude: 12.23,
        longitude: 12.23,
        height: 100.0,
    }]
}

/// What the document's example of `method` means.
fn expected(method: &str) -> ServiceRequest {
    use ServiceRequest as S;
    let all = vec![
        StorageLens::Current,
        StorageLens::Wide,
        StorageLens::Zoom,
        StorageLens::Ir,
    ];
    match method {
        "flight_authority_grab" => S::FlightAuthorityGrab,
        "payload_authority_grab" => S::PayloadAuthorityGrab {
            payload_index: pi(),
        },
        "drc_mode_enter" => S::DrcModeEnter(DrcModeEnter {
            mqtt_broker: MqttBroker {
                address: "mqtt.dji.com:8883".into(),
                client_id: "sn_a".into(),
                username: "sn_a_username".into(),
                password: "jwt_token".into(),
                expire_time: 1672744922,
                enable_tls: true,
            },
            osd_frequency: 10,
            hsi_frequency: 1,
        }),
        "drc_mode_exit" => S::DrcModeExit,
        "takeoff_to_point" => S::TakeoffToPoint(TakeoffToPoint {
            target_latitude: 12.23,
            target_longitude: 12.32,
            target_height: 100.0,
            security_takeoff_height: 100.0,
            rth_altitude: 100,
            rc_lost_action: RcLostAction::Hover,
            exit_wayline_when_rc_lost: None,
            commander_mode_lost_action: Some(1),
            commander_flight_height: Some(80.0),
            flight_id: "ABDEAC21DCADDA".into(),
            max_speed: 12,
            simulate_mission: None,
        }),
        "fly_to_point" => S::FlyToPoint(FlyToPoint {
            fly_to_id: UUID.into(),
            max_speed: 12,
            points: point(),
        }),
        "fly_to_point_stop" => S::FlyToPointStop,
        "fly_to_point_update" => S::FlyToPointUpdate(FlyToPointUpdate {
            max_speed: 12,
            points: point(),
        }),
        "camera_mode_switch" => S::CameraModeSwitch {
            payload_index: pi(),
            camera_mode: CameraMode::Photo,
        },
        "camera_photo_take" => S::CameraPhotoTake {
            payload_index: pi(),
        },
        "camera_photo_stop" => S::CameraPhotoStop {
            payload_index: pi(),
        },
        "camera_recording_start" => S::CameraRecordingStart {
            payload_index: pi(),
        },
        "camera_recording_stop" => S::CameraRecordingStop {
            payload_index: pi(),
        },
        "camera_screen_drag" => S::CameraScreenDrag {
            payload_index: pi(),
            locked: true,
            pitch_speed: 0.1,
            yaw_speed: 0.1,
        },
        "camera_aim" => S::CameraAim {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            locked: true,
            x: 0.5,
            y: 0.5,
        },
        "camera_focal_length_set" => S::CameraFocalLengthSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            zoom_factor: 5.0,
        },
        "gimbal_reset" => S::GimbalReset {
            payload_index: pi(),
            reset_mode: 0,
        },
        "camera_look_at" => S::CameraLookAt {
            payload_index: pi(),
            locked: true,
            latitude: 12.23,
            longitude: 12.23,
            height: 100.0,
        },
        "camera_screen_split" => S::CameraScreenSplit {
            payload_index: pi(),
            enable: true,
        },
        "photo_storage_set" => S::PhotoStorageSet {
            payload_index: pi(),
            photo_storage_settings: all,
        },
        "video_storage_set" => S::VideoStorageSet {
            payload_index: pi(),
            video_storage_settings: all,
        },
        "camera_exposure_mode_set" => S::CameraExposureModeSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            exposure_mode: 1,
        },
        "camera_exposure_set" => S::CameraExposureSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            exposure_value: 5,
        },
        "camera_focus_mode_set" => S::CameraFocusModeSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            focus_mode: 1,
        },
        "camera_focus_value_set" => S::CameraFocusValueSet {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            focus_value: 5,
        },
        "camera_point_focus_action" => S::CameraPointFocusAction {
            payload_index: pi(),
            camera_type: CameraType::Zoom,
            x: 0.5,
            y: 0.5,
        },
        "ir_metering_mode_set" => S::IrMeteringModeSet {
            payload_index: pi(),
            mode: 1,
        },
        "ir_metering_point_set" => S::IrMeteringPointSet {
            payload_index: pi(),
            x: 0.5,
            y: 0.5,
        },
        "ir_metering_area_set" => S::IrMeteringAreaSet {
            payload_index: pi(),
            x: 0.5,
            y: 0.5,
            width: 0.5,
            height: 0.5,
        },
        "poi_mode_enter" => S::PoiModeEnter {
            latitude: 12.23,
            longitude: 12.23,
            height: 100.0,
        },
        "poi_mode_exit" => S::PoiModeExit,
        "poi_circle_speed_set" => S::PoiCircleSpeedSet { circle_speed: 5.2 },
        other => panic!("no expectation for {other}"),
    }
}

#[test]
fn the_fixture_table_covers_every_service_method_in_order() {
    let methods: Vec<&str> = SERVICES.iter().map(|(m, _)| *m).collect();
    assert_eq!(methods, SERVICE_METHODS);
}

#[test]
fn every_service_example_parses_to_its_typed_value() {
    for &method in SERVICE_METHODS {
        let env = service_envelope(method);
        assert_eq!(env.tid, UUID, "{method}");
        assert_eq!(env.bid, UUID, "{method}");
        assert_eq!(env.timestamp, 1654070968655, "{method}");
        assert_eq!(env.method, method);
        assert_eq!(env.gateway, None);
        let request = parse_service(&env).unwrap_or_else(|e| panic!("{method}: {e}"));
        assert_eq!(request, expected(method), "{method}");
        assert_eq!(request.method(), method);
    }
}

#[test]
fn examples_parse_with_trailing_whitespace_and_crlf() {
    for &method in SERVICE_METHODS {
        let text = example(SERVICES, method).replace('\n', "\r\n") + " \r\n\t";
        let env = parse_envelope(TopicKind::Services, text.as_bytes()).expect("parses");
        assert_eq!(parse_service(&env), Ok(expected(method)), "{method}");
    }
}

#[test]
fn the_documents_examples_without_method_are_not_envelopes() {
    // The document omits `method` from most `services` examples; a request without it
    // cannot be dispatched (nor answered: the reply names the method).
    let text = example(SERVICES, "fly_to_point").replace("\"method\": \"fly_to_point\",\n", "");
    assert_eq!(
        parse_envelope(TopicKind::Services, text.as_bytes()),
        Err(Malformed::Missing("method"))
    );
}

#[test]
fn payload_index_accessor() {
    for &method in SERVICE_METHODS {
        let request = expected(method);
        let has = examples::example(SERVICES, method).contains("payload_index");
        assert_eq!(request.payload_index().is_some(), has, "{method}");
        if has {
            assert_eq!(request.payload_index(), Some(PI));
        }
    }
}

#[test]
fn every_drc_down_example_parses() {
    let cases = [
        (
            "drone_control",
            DrcDown::DroneControl(DroneControl {
                seq: 1,
                x: 2.34,
                y: -2.45,
                h: 2.76,
                w: 2.86,
            }),
        ),
        ("drone_emergency_stop", DrcDown::DroneEmergencyStop),
        (
            "heart_beat",
            DrcDown::HeartBeat {
                seq: 10,
                timestamp: 1670415891013,
            },
        ),
    ];
    assert_eq!(cases.len(), DRC_DOWN.len());
    for (method, want) in cases {
        let text = example(DRC_DOWN, method);
        let env = parse_envelope(TopicKind::DrcDown, text.as_bytes()).expect("parses");
        assert_eq!(
            (env.tid.as_str(), env.bid.as_str(), env.timestamp),
            ("", "", 0)
        );
        assert_eq!(parse_drc(&env), Ok(want), "{method}");
        assert_eq!(want.method(), method);
    }
}

#[test]
fn drone_control_seq_at_the_top_level() {
    let text = br#"{"method":"drone_control","seq":7,"data":{"x":1,"y":0,"h":0,"w":0}}"#;
    let env = parse_envelope(TopicKind::DrcDown, text).expect("parses");
    assert_eq!(env.seq, Some(7));
    let DrcDown::DroneControl(c) = parse_drc(&env).expect("valid") else {
        panic!("not drone_control");
    };
    assert_eq!((c.seq, c.x), (7, 1.0));
    // data.seq wins over the top level.
    let text = br#"{"method":"drone_control","seq":7,"data":{"seq":3,"x":1,"y":0,"h":0,"w":0}}"#;
    let env = parse_envelope(TopicKind::DrcDown, text).expect("parses");
    assert!(matches!(
        parse_drc(&env),
        Ok(DrcDown::DroneControl(DroneControl { seq: 3, .. }))
    ));
}

#[test]
fn an_events_reply_parses() {
    // The document has no events_reply example; this is what DJI's cloud sends.
    let text = br#"{
        "tid": "6a7bfe89-c386-4043-b600-b518e10096cc",
        "bid": "42a19f36-5117-4520-bd13-fd61d818d52e",
        "method": "fly_to_point_progress",
        "gateway": "4BRSN1234",
        "timestamp": 1654070968655,
        "data": {"result": 0}
    }"#;
    let env = parse_envelope(TopicKind::EventsReply, text).expect("parses");
    assert_eq!(env.gateway.as_deref(), Some("4BRSN1234"));
    assert_eq!(
        parse_event_reply(&env),
        Ok(EventReply {
            tid: "6a7bfe89-c386-4043-b600-b518e10096cc".into(),
            bid: "42a19f36-5117-4520-bd13-fd61d818d52e".into(),
            method: "fly_to_point_progress".into(),
            result: 0,
        })
    );
}

#[test]
fn optional_takeoff_fields_and_null_as_absent() {
    let mut env = service_envelope("takeoff_to_point");
    let data = env.data.as_object_mut().expect("object");
    data.insert("commander_flight_height".into(), serde_json::Value::Null);
    data.remove("commander_mode_lost_action");
    data.insert("exit_wayline_when_rc_lost".into(), 1.into());
    data.insert(
        "simulate_mission".into(),
        serde_json::json!({"is_enable": 1, "latitude": 22.5, "longitude": 113.9}),
    );
    let ServiceRequest::TakeoffToPoint(t) = parse_service(&env).expect("valid") else {
        panic!("not takeoff");
    };
    assert_eq!(t.commander_flight_height, None);
    assert_eq!(t.commander_mode_lost_action, None);
    assert_eq!(t.exit_wayline_when_rc_lost, Some(1));
    let sim = t.simulate_mission.expect("present");
    assert!(sim.is_enable);
    assert_eq!((sim.latitude, sim.longitude), (22.5, 113.9));
    // is_enable as a JSON bool is taken too.
    env.data["simulate_mission"]["is_enable"] = false.into();
    let ServiceRequest::TakeoffToPoint(t) = parse_service(&env).expect("valid") else {
        panic!("not takeoff");
    };
    assert_eq!(t.simulate_mission.map(|s| s.is_enable), Some(false));
}
