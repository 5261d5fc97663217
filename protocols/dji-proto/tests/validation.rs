//! Every constrained field refused the documented way: each row changes the document's
//! example (tests/common/examples.rs) and names the code and field path expected.
//! Also: boundary values that must pass, unknown fields, methods without data, unknown
//! methods, the DRC methods and events_reply.

mod common;

use common::{change, service_envelope};
use dji_proto::codes::{
    BAD_ARRAY_SIZE, BAD_TEXT, MAX_SECRET_LEN, MAX_TEXT_LEN, MISSING_FIELD, NOT_IN_ENUM,
    OUT_OF_RANGE, UNKNOWN_METHOD, WRONG_TYPE,
};
use dji_proto::{
    parse_drc, parse_envelope, parse_event_reply, parse_service, CameraType, DrcDown, Envelope,
    ServiceRequest, TopicKind, SERVICE_METHODS,
};
use serde_json::{json, Value};

/// One violation: `changes` applied to `method`'s example data must give `code` at `field`.
struct Case {
    method: &'static str,
    changes: Vec<(&'static str, Option<Value>)>,
    field: &'static str,
    code: u32,
}

/// Set `path` to `value`; expect `code` at `path`.
fn set(method: &'static str, path: &'static str, value: Value, code: u32) -> Case {
    Case {
        method,
        changes: vec![(path, Some(value))],
        field: path,
        code,
    }
}

/// Remove `path`; expect MISSING_FIELD at `path`.
fn missing(method: &'static str, path: &'static str) -> Case {
    Case {
        method,
        changes: vec![(path, None)],
        field: path,
        code: MISSING_FIELD,
    }
}

fn run(cases: &[Case]) {
    for case in cases {
        let mut env = service_envelope(case.method);
        for (path, value) in &case.changes {
            change(&mut env.data, path, value.clone());
        }
        let err = parse_service(&env).expect_err(&format!(
            "{} {:?} accepted: {}",
            case.method, case.changes, env.data
        ));
        assert_eq!(
            (err.code, err.field.as_str()),
            (case.code, case.field),
            "{} {:?}: {err}",
            case.method,
            case.changes
        );
        assert!(!err.reason.is_empty());
    }
}

/// Apply `changes` to `method`'s example; it must still parse.
fn accepted(method: &str, changes: &[(&str, Option<Value>)]) -> ServiceRequest {
    let mut env = service_envelope(method);
    for (path, value) in changes {
        change(&mut env.data, path, value.clone());
    }
    parse_service(&env).unwrap_or_else(|e| panic!("{method} {changes:?} refused: {e}"))
}

fn long(len: usize) -> Value {
    Value::String("a".repeat(len))
}

#[test]
fn data_itself() {
    let with_data: Vec<&str> = SERVICE_METHODS
        .iter()
        .copied()
        .filter(|m| {
            !matches!(
                *m,
                "flight_authority_grab" | "drc_mode_exit" | "fly_to_point_stop" | "poi_mode_exit"
            )
        })
        .collect();
    assert_eq!(with_data.len(), 28);
    let mut cases = Vec::new();
    for method in with_data {
        cases.push(missing(method, "data"));
        cases.push(set(method, "data", json!(5), WRONG_TYPE));
        cases.push(set(method, "data", json!([]), WRONG_TYPE));
        cases.push(set(method, "data", json!("{}"), WRONG_TYPE));
    }
    run(&cases);
}

#[test]
fn methods_without_data_take_null_or_any_object() {
    for method in [
        "flight_authority_grab",
        "drc_mode_exit",
        "fly_to_point_stop",
        "poi_mode_exit",
    ] {
        for data in [Value::Null, json!({}), json!({"future": [1, 2]})] {
            let env = Envelope::new(method, data.clone());
            assert!(parse_service(&env).is_ok(), "{method} {data}");
        }
        for data in [json!(0), json!("x"), json!([]), json!(true)] {
            let err = parse_service(&Envelope::new(method, data.clone())).expect_err("refused");
            assert_eq!(
                (err.code, err.field.as_str()),
                (WRONG_TYPE, "data"),
                "{data}"
            );
        }
    }
    // The example's data field absent altogether.
    let text = br#"{"tid":"t","bid":"b","method":"drc_mode_exit","timestamp":1}"#;
    let env = parse_envelope(TopicKind::Services, text).expect("parses");
    assert_eq!(env.data, Value::Null);
    assert_eq!(parse_service(&env), Ok(ServiceRequest::DrcModeExit));
}

#[test]
fn payload_index_everywhere() {
    let mut cases = Vec::new();
    for &method in SERVICE_METHODS {
        if service_envelope(method).data.get("payload_index").is_none() {
            continue;
        }
        let p = "data.payload_index";
        cases.push(missing(method, p));
        cases.push(set(method, p, Value::Null, MISSING_FIELD));
        cases.push(set(method, p, json!(39), WRONG_TYPE));
        cases.push(set(method, p, json!(""), BAD_TEXT));
        cases.push(set(method, p, json!("39-0"), BAD_TEXT));
        cases.push(set(method, p, json!("39-0-x"), BAD_TEXT));
        cases.push(set(method, p, json!("39-0-7-1"), BAD_TEXT));
        cases.push(set(method, p, long(MAX_TEXT_LEN + 1), BAD_TEXT));
    }
    assert_eq!(cases.len(), 22 * 8, "22 payload methods");
    run(&cases);
}

#[test]
fn drc_mode_enter() {
    let m = "drc_mode_enter";
    run(&[
        missing(m, "data.mqtt_broker"),
        set(
            m,
            "data.mqtt_broker",
            json!("mqtt.dji.com:8883"),
            WRONG_TYPE,
        ),
        missing(m, "data.mqtt_broker.address"),
        set(m, "data.mqtt_broker.address", json!(8883), WRONG_TYPE),
        set(m, "data.mqtt_broker.address", json!(""), BAD_TEXT),
        set(
            m,
            "data.mqtt_broker.address",
            json!("mqtt.dji.com"),
            BAD_TEXT,
        ),
        set(
            m,
            "data.mqtt_broker.address",
            json!("mqtt.dji.com:0"),
            BAD_TEXT,
        ),
        set(
            m,
            "data.mqtt_broker.address",
            json!("mqtt.dji.com:65536"),
            BAD_TEXT,
        ),
        set(
            m,
            "data.mqtt_broker.address",
            json!("ssl://mqtt.dji.com:8883"),
            BAD_TEXT,
        ),
        set(
            m,
            "data.mqtt_broker.address",
            long(MAX_TEXT_LEN + 1),
            BAD_TEXT,
        ),
        missing(m, "data.mqtt_broker.client_id"),
        set(m, "data.mqtt_broker.client_id", json!(""), BAD_TEXT),
        set(m, "data.mqtt_broker.client_id", json!(1), WRONG_TYPE),
        missing(m, "data.mqtt_broker.username"),
        set(m, "data.mqtt_broker.username", json!(1), WRONG_TYPE),
        set(
            m,
            "data.mqtt_broker.username",
            long(MAX_TEXT_LEN + 1),
            BAD_TEXT,
        ),
        missing(m, "data.mqtt_broker.password"),
        set(m, "data.mqtt_broker.password", json!(false), WRONG_TYPE),
        set(
            m,
            "data.mqtt_broker.password",
            long(MAX_SECRET_LEN + 1),
            BAD_TEXT,
        ),
        missing(m, "data.mqtt_broker.expire_time"),
        set(m, "data.mqtt_broker.expire_time", json!(-1), OUT_OF_RANGE),
        set(m, "data.mqtt_broker.expire_time", json!(1.5), WRONG_TYPE),
        set(
            m,
            "data.mqtt_broker.expire_time",
            json!("1672744922"),
            WRONG_TYPE,
        ),
        missing(m, "data.mqtt_broker.enable_tls"),
        set(m, "data.mqtt_broker.enable_tls", json!(1), WRONG_TYPE),
        missing(m, "data.osd_frequency"),
        set(m, "data.osd_frequency", json!(0), OUT_OF_RANGE),
        set(m, "data.osd_frequency", json!(31), OUT_OF_RANGE),
        set(m, "data.osd_frequency", json!(10.5), WRONG_TYPE),
        set(m, "data.osd_frequency", json!(10.0), WRONG_TYPE),
        missing(m, "data.hsi_frequency"),
        set(m, "data.hsi_frequency", json!(0), OUT_OF_RANGE),
        set(m, "data.hsi_frequency", json!(31), OUT_OF_RANGE),
        set(m, "data.hsi_frequency", json!("1"), WRONG_TYPE),
    ]);
    // Boundaries and forms that pass.
    for (path, value) in [
        ("data.mqtt_broker.address", json!("192.0.2.1:8883")),
        ("data.mqtt_broker.address", json!("[2001:db8::1]:1")),
        ("data.mqtt_broker.address", json!("broker:65535")),
        ("data.mqtt_broker.username", json!("")),
        ("data.mqtt_broker.password", json!("")),
        ("data.mqtt_broker.password", long(MAX_SECRET_LEN)),
        ("data.mqtt_broker.client_id", long(MAX_TEXT_LEN)),
        ("data.mqtt_broker.expire_time", json!(0)),
        ("data.osd_frequency", json!(30)),
        ("data.hsi_frequency", json!(30)),
    ] {
        accepted(m, &[(path, Some(value))]);
    }
}

#[test]
fn takeoff_to_point() {
    let m = "takeoff_to_point";
    let sim = |v: Value| set(m, "data.simulate_mission", v, 0);
    let mut cases = vec![
        missing(m, "data.target_latitude"),
        set(m, "data.target_latitude", json!(-90.1), OUT_OF_RANGE),
        set(m, "data.target_latitude", json!(90.1), OUT_OF_RANGE),
        set(m, "data.target_latitude", json!("12.23"), WRONG_TYPE),
        missing(m, "data.target_longitude"),
        set(m, "data.target_longitude", json!(-180.1), OUT_OF_RANGE),
        set(m, "data.target_longitude", json!(180.1), OUT_OF_RANGE),
        missing(m, "data.target_height"),
        set(m, "data.target_height", json!(1.9), OUT_OF_RANGE),
        set(m, "data.target_height", json!(1500.1), OUT_OF_RANGE),
        missing(m, "data.security_takeoff_height"),
        set(m, "data.security_takeoff_height", json!(19.9), OUT_OF_RANGE),
        set(
            m,
            "data.security_takeoff_height",
            json!(1500.1),
            OUT_OF_RANGE,
        ),
        missing(m, "data.rth_altitude"),
        set(m, "data.rth_altitude", json!(1), OUT_OF_RANGE),
        set(m, "data.rth_altitude", json!(1501), OUT_OF_RANGE),
        set(m, "data.rth_altitude", json!(100.5), WRONG_TYPE),
        missing(m, "data.rc_lost_action"),
        set(m, "data.rc_lost_action", json!(3), NOT_IN_ENUM),
        set(m, "data.rc_lost_action", json!(-1), NOT_IN_ENUM),
        set(m, "data.rc_lost_action", json!(1.0), WRONG_TYPE),
        set(m, "data.rc_lost_action", json!("0"), WRONG_TYPE),
        set(m, "data.exit_wayline_when_rc_lost", json!(2), NOT_IN_ENUM),
        set(m, "data.exit_wayline_when_rc_lost", json!(true), WRONG_TYPE),
        set(m, "data.commander_mode_lost_action", json!(2), NOT_IN_ENUM),
        set(m, "data.commander_mode_lost_action", json!("1"), WRONG_TYPE),
        set(m, "data.commander_flight_height", json!(1.9), OUT_OF_RANGE),
        set(
            m,
            "data.commander_flight_height",
            json!(3000.1),
            OUT_OF_RANGE,
        ),
        set(m, "data.commander_flight_height", json!([80]), WRONG_TYPE),
        missing(m, "data.flight_id"),
        set(m, "data.flight_id", json!(""), BAD_TEXT),
        set(m, "data.flight_id", json!(7), WRONG_TYPE),
        set(m, "data.flight_id", long(MAX_TEXT_LEN + 1), BAD_TEXT),
        missing(m, "data.max_speed"),
        set(m, "data.max_speed", json!(0), OUT_OF_RANGE),
        set(m, "data.max_speed", json!(16), OUT_OF_RANGE),
        set(m, "data.max_speed", json!(12.5), WRONG_TYPE),
        set(m, "data.simulate_mission", json!(1), WRONG_TYPE),
    ];
    // simulate_mission's own fields (set the struct, then expect a nested path).
    for (value, field, code) in [
        (
            json!({"latitude": 1, "longitude": 1}),
            "data.simulate_mission.is_enable",
            MISSING_FIELD,
        ),
        (
            json!({"is_enable": 2, "latitude": 1, "longitude": 1}),
            "data.simulate_mission.is_enable",
            NOT_IN_ENUM,
        ),
        (
            json!({"is_enable": "1", "latitude": 1, "longitude": 1}),
            "data.simulate_mission.is_enable",
            WRONG_TYPE,
        ),
        (
            json!({"is_enable": 1, "latitude": 90.5, "longitude": 1}),
            "data.simulate_mission.latitude",
            OUT_OF_RANGE,
        ),
        (
            json!({"is_enable": 1, "latitude": 1}),
            "data.simulate_mission.longitude",
            MISSING_FIELD,
        ),
        (
            json!({"is_enable": 1, "latitude": 1, "longitude": -180.5}),
            "data.simulate_mission.longitude",
            OUT_OF_RANGE,
        ),
    ] {
        let mut c = sim(value);
        c.field = field;
        c.code = code;
        cases.push(c);
    }
    run(&cases);
    for (path, value) in [
        ("data.target_latitude", json!(-90)),
        ("data.target_longitude", json!(180)),
        ("data.target_height", json!(2)),
        ("data.target_height", json!(1500.0)),
        ("data.security_takeoff_height", json!(20)),
        ("data.rth_altitude", json!(2)),
        ("data.rth_altitude", json!(1500)),
        ("data.rc_lost_action", json!(2)),
        ("data.commander_flight_height", json!(3000)),
        ("data.max_speed", json!(1)),
        ("data.max_speed", json!(15)),
    ] {
        accepted(m, &[(path, Some(value))]);
    }
}

#[test]
fn fly_to_point_and_update() {
    let mut cases = Vec::new();
    for m in ["fly_to_point", "fly_to_point_update"] {
        cases.extend([
            missing(m, "data.max_speed"),
            set(m, "data.max_speed", json!(-1), OUT_OF_RANGE),
            set(m, "data.max_speed", json!(16), OUT_OF_RANGE),
            set(m, "data.max_speed", json!(12.5), WRONG_TYPE),
            missing(m, "data.points"),
            set(m, "data.points", json!({}), WRONG_TYPE),
            set(m, "data.points", json!([]), BAD_ARRAY_SIZE),
            set(
                m,
                "data.points",
                json!([{"latitude": 1, "longitude": 1, "height": 10}, {"latitude": 2, "longitude": 2, "height": 10}]),
                BAD_ARRAY_SIZE,
            ),
            set(m, "data.points[0]", json!(5), WRONG_TYPE),
            set(m, "data.points[0]", Value::Null, MISSING_FIELD),
            missing(m, "data.points[0].latitude"),
            set(m, "data.points[0].latitude", json!(90.000001), OUT_OF_RANGE),
            set(m, "data.points[0].latitude", json!(-91), OUT_OF_RANGE),
            set(m, "data.points[0].latitude", json!("12.23"), WRONG_TYPE),
            missing(m, "data.points[0].longitude"),
            set(m, "data.points[0].longitude", json!(181), OUT_OF_RANGE),
            set(m, "data.points[0].longitude", json!(-180.5), OUT_OF_RANGE),
            missing(m, "data.points[0].height"),
            set(m, "data.points[0].height", json!(1.9), OUT_OF_RANGE),
            set(m, "data.points[0].height", json!(10000.1), OUT_OF_RANGE),
            set(m, "data.points[0].height", json!(true), WRONG_TYPE),
        ]);
    }
    cases.extend([
        // fly_to_point's max_speed starts at 0, the update's at 1.
        set(
            "fly_to_point_update",
            "data.max_speed",
            json!(0),
            OUT_OF_RANGE,
        ),
        missing("fly_to_point", "data.fly_to_id"),
        set("fly_to_point", "data.fly_to_id", json!(""), BAD_TEXT),
        set("fly_to_point", "data.fly_to_id", json!(["id"]), WRONG_TYPE),
    ]);
    run(&cases);
    accepted("fly_to_point", &[("data.max_speed", Some(json!(0)))]);
    accepted(
        "fly_to_point",
        &[("data.points[0].height", Some(json!(10000)))],
    );
    accepted(
        "fly_to_point_update",
        &[("data.points[0].height", Some(json!(2)))],
    );
}

#[test]
fn camera_methods() {
    run(&[
        missing("camera_mode_switch", "data.camera_mode"),
        set(
            "camera_mode_switch",
            "data.camera_mode",
            json!(4),
            NOT_IN_ENUM,
        ),
        set(
            "camera_mode_switch",
            "data.camera_mode",
            json!("0"),
            WRONG_TYPE,
        ),
        missing("camera_screen_drag", "data.locked"),
        set(
            "camera_screen_drag",
            "data.locked",
            json!("true"),
            WRONG_TYPE,
        ),
        missing("camera_screen_drag", "data.pitch_speed"),
        set(
            "camera_screen_drag",
            "data.pitch_speed",
            json!(360.5),
            OUT_OF_RANGE,
        ),
        set(
            "camera_screen_drag",
            "data.pitch_speed",
            json!(-361),
            OUT_OF_RANGE,
        ),
        set(
            "camera_screen_drag",
            "data.pitch_speed",
            json!("0.1"),
            WRONG_TYPE,
        ),
        missing("camera_screen_drag", "data.yaw_speed"),
        set(
            "camera_screen_drag",
            "data.yaw_speed",
            json!(1e300),
            OUT_OF_RANGE,
        ),
        missing("camera_aim", "data.camera_type"),
        set(
            "camera_aim",
            "data.camera_type",
            json!("thermal"),
            NOT_IN_ENUM,
        ),
        set("camera_aim", "data.camera_type", json!("Zoom"), NOT_IN_ENUM),
        set("camera_aim", "data.camera_type", json!(1), WRONG_TYPE),
        missing("camera_aim", "data.locked"),
        set("camera_aim", "data.x", json!(-0.1), OUT_OF_RANGE),
        set("camera_aim", "data.x", json!(1.1), OUT_OF_RANGE),
        missing("camera_aim", "data.y"),
        set("camera_aim", "data.y", json!(1.0001), OUT_OF_RANGE),
        set(
            "camera_focal_length_set",
            "data.camera_type",
            json!("tele"),
            NOT_IN_ENUM,
        ),
        missing("camera_focal_length_set", "data.zoom_factor"),
        set(
            "camera_focal_length_set",
            "data.zoom_factor",
            json!(1.9),
            OUT_OF_RANGE,
        ),
        set(
            "camera_focal_length_set",
            "data.zoom_factor",
            json!(200.1),
            OUT_OF_RANGE,
        ),
        set(
            "camera_focal_length_set",
            "data.zoom_factor",
            json!("5"),
            WRONG_TYPE,
        ),
        Case {
            method: "camera_focal_length_set",
            changes: vec![
                ("data.camera_type", Some(json!("ir"))),
                ("data.zoom_factor", Some(json!(20.5))),
            ],
            field: "data.zoom_factor",
            code: OUT_OF_RANGE,
        },
        missing("gimbal_reset", "data.reset_mode"),
        set("gimbal_reset", "data.reset_mode", json!(4), NOT_IN_ENUM),
        set("gimbal_reset", "data.reset_mode", json!(0.5), WRONG_TYPE),
        missing("camera_look_at", "data.locked"),
        set("camera_look_at", "data.locked", json!(0), WRONG_TYPE),
        set("camera_look_at", "data.latitude", json!(90.5), OUT_OF_RANGE),
        missing("camera_look_at", "data.longitude"),
        set(
            "camera_look_at",
            "data.longitude",
            json!(-181),
            OUT_OF_RANGE,
        ),
        set("camera_look_at", "data.height", json!(1.9), OUT_OF_RANGE),
        set(
            "camera_look_at",
            "data.height",
            json!(10000.5),
            OUT_OF_RANGE,
        ),
        missing("camera_screen_split", "data.enable"),
        set(
            "camera_screen_split",
            "data.enable",
            json!("yes"),
            WRONG_TYPE,
        ),
    ]);
    accepted("camera_aim", &[("data.camera_type", Some(json!("ir")))]);
    accepted(
        "camera_aim",
        &[("data.x", Some(json!(0))), ("data.y", Some(json!(1)))],
    );
    accepted(
        "camera_screen_drag",
        &[("data.pitch_speed", Some(json!(-360)))],
    );
    let ServiceRequest::CameraFocalLengthSet {
        camera_type,
        zoom_factor,
        ..
    } = accepted(
        "camera_focal_length_set",
        &[
            ("data.camera_type", Some(json!("ir"))),
            ("data.zoom_factor", Some(json!(20))),
        ],
    )
    else {
        panic!("not zoom");
    };
    assert_eq!((camera_type, zoom_factor), (CameraType::Ir, 20.0));
    accepted(
        "camera_focal_length_set",
        &[("data.zoom_factor", Some(json!(200)))],
    );
    accepted("gimbal_reset", &[("data.reset_mode", Some(json!(3)))]);
}

#[test]
fn storage_settings() {
    let mut cases = Vec::new();
    for (m, key) in [
        ("photo_storage_set", "data.photo_storage_settings"),
        ("video_storage_set", "data.video_storage_settings"),
    ] {
        cases.extend([
            missing(m, key),
            set(m, key, json!("wide"), WRONG_TYPE),
            set(m, key, json!([]), BAD_ARRAY_SIZE),
            set(
                m,
                key,
                json!(["current", "wide", "zoom", "ir", "ir"]),
                BAD_ARRAY_SIZE,
            ),
        ]);
    }
    let m = "photo_storage_set";
    for (value, field, code) in [
        (
            json!(["wide", "wide"]),
            "data.photo_storage_settings[1]",
            BAD_ARRAY_SIZE,
        ),
        (
            json!(["tele"]),
            "data.photo_storage_settings[0]",
            NOT_IN_ENUM,
        ),
        (
            json!(["wide", 1]),
            "data.photo_storage_settings[1]",
            WRONG_TYPE,
        ),
        (json!([null]), "data.photo_storage_settings[0]", WRONG_TYPE),
    ] {
        let mut c = set(m, "data.photo_storage_settings", value, 0);
        c.field = field;
        c.code = code;
        cases.push(c);
    }
    run(&cases);
    accepted(
        "video_storage_set",
        &[("data.video_storage_settings", Some(json!(["ir"])))],
    );
}

#[test]
fn exposure_and_focus() {
    let mut cases = Vec::new();
    for m in [
        "camera_exposure_mode_set",
        "camera_exposure_set",
        "camera_focus_mode_set",
        "camera_focus_value_set",
        "camera_point_focus_action",
    ] {
        cases.extend([
            missing(m, "data.camera_type"),
            // These methods allow only wide|zoom.
            set(m, "data.camera_type", json!("ir"), NOT_IN_ENUM),
            set(m, "data.camera_type", json!(true), WRONG_TYPE),
        ]);
    }
    let ev = "data.exposure_value";
    cases.extend([
        missing("camera_exposure_mode_set", "data.exposure_mode"),
        set(
            "camera_exposure_mode_set",
            "data.exposure_mode",
            json!(0),
            NOT_IN_ENUM,
        ),
        set(
            "camera_exposure_mode_set",
            "data.exposure_mode",
            json!(5),
            NOT_IN_ENUM,
        ),
        missing("camera_exposure_set", ev),
        set("camera_exposure_set", ev, json!(0), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!(32), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!(254), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!(-5), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!(u64::MAX), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!("0"), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!("32"), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!("05"), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!("+5"), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!("-5.0EV"), NOT_IN_ENUM),
        set("camera_exposure_set", ev, json!(5.5), WRONG_TYPE),
        set("camera_exposure_set", ev, json!(5.0), WRONG_TYPE),
        set("camera_exposure_set", ev, json!(true), WRONG_TYPE),
        missing("camera_focus_mode_set", "data.focus_mode"),
        set(
            "camera_focus_mode_set",
            "data.focus_mode",
            json!(3),
            NOT_IN_ENUM,
        ),
        missing("camera_focus_value_set", "data.focus_value"),
        set(
            "camera_focus_value_set",
            "data.focus_value",
            json!(-1),
            OUT_OF_RANGE,
        ),
        set(
            "camera_focus_value_set",
            "data.focus_value",
            json!(5.5),
            WRONG_TYPE,
        ),
        missing("camera_point_focus_action", "data.x"),
        set(
            "camera_point_focus_action",
            "data.x",
            json!(1.1),
            OUT_OF_RANGE,
        ),
        set(
            "camera_point_focus_action",
            "data.y",
            json!(-0.1),
            OUT_OF_RANGE,
        ),
    ]);
    run(&cases);
    for (value, want) in [
        (json!("5"), 5),
        (json!(5), 5),
        (json!("1"), 1),
        (json!(31), 31),
        (json!("31"), 31),
        (json!(255), 255),
        (json!("255"), 255),
    ] {
        let ServiceRequest::CameraExposureSet { exposure_value, .. } =
            accepted("camera_exposure_set", &[(ev, Some(value.clone()))])
        else {
            panic!("not exposure");
        };
        assert_eq!(exposure_value, want, "{value}");
    }
    accepted(
        "camera_exposure_mode_set",
        &[("data.camera_type", Some(json!("wide")))],
    );
    accepted(
        "camera_focus_value_set",
        &[("data.focus_value", Some(json!(0)))],
    );
}

#[test]
fn ir_metering_and_poi() {
    run(&[
        missing("ir_metering_mode_set", "data.mode"),
        set("ir_metering_mode_set", "data.mode", json!(3), NOT_IN_ENUM),
        missing("ir_metering_point_set", "data.x"),
        set(
            "ir_metering_point_set",
            "data.x",
            json!(-0.01),
            OUT_OF_RANGE,
        ),
        set("ir_metering_point_set", "data.y", json!(2), OUT_OF_RANGE),
        set("ir_metering_area_set", "data.x", json!("0.5"), WRONG_TYPE),
        missing("ir_metering_area_set", "data.y"),
        missing("ir_metering_area_set", "data.width"),
        set(
            "ir_metering_area_set",
            "data.width",
            json!(1.1),
            OUT_OF_RANGE,
        ),
        missing("ir_metering_area_set", "data.height"),
        set(
            "ir_metering_area_set",
            "data.height",
            json!(-0.1),
            OUT_OF_RANGE,
        ),
        missing("poi_mode_enter", "data.latitude"),
        set(
            "poi_mode_enter",
            "data.latitude",
            json!(-90.5),
            OUT_OF_RANGE,
        ),
        set(
            "poi_mode_enter",
            "data.longitude",
            json!(180.5),
            OUT_OF_RANGE,
        ),
        missing("poi_mode_enter", "data.height"),
        set("poi_mode_enter", "data.height", json!(1), OUT_OF_RANGE),
        set("poi_mode_enter", "data.height", json!(10001), OUT_OF_RANGE),
        missing("poi_circle_speed_set", "data.circle_speed"),
        set(
            "poi_circle_speed_set",
            "data.circle_speed",
            json!("fast"),
            WRONG_TYPE,
        ),
    ]);
    // The POI speed maximum is the gateway's (poi_status_notify), not the codec's.
    accepted(
        "poi_circle_speed_set",
        &[("data.circle_speed", Some(json!(-1000)))],
    );
    accepted(
        "ir_metering_area_set",
        &[
            ("data.width", Some(json!(1))),
            ("data.height", Some(json!(0))),
        ],
    );
}

#[test]
fn unknown_fields_are_ignored() {
    for &method in SERVICE_METHODS {
        let mut env = service_envelope(method);
        let plain = parse_service(&env).expect("example valid");
        if let Value::Object(map) = &mut env.data {
            map.insert("a_future_field".into(), json!({"nested": [1, "x", null]}));
        }
        assert_eq!(parse_service(&env), Ok(plain), "{method}");
    }
}

#[test]
fn first_violation_in_table_order_is_reported() {
    let mut env = service_envelope("takeoff_to_point");
    env.data["max_speed"] = json!(99);
    env.data["target_height"] = json!(0);
    let err = parse_service(&env).expect_err("refused");
    assert_eq!(err.field, "data.target_height");
}

#[test]
fn unknown_methods() {
    for method in [
        "",
        "flight_authority_grabx",
        "FLIGHT_AUTHORITY_GRAB",
        "drone_control",
    ] {
        let err = parse_service(&Envelope::new(method, json!({}))).expect_err("refused");
        assert_eq!((err.code, err.field.as_str()), (UNKNOWN_METHOD, method));
    }
    // A long method name is clipped in the refusal (it goes to logs).
    let long_method = "é".repeat(1000);
    let err = parse_service(&Envelope::new(&long_method, Value::Null)).expect_err("refused");
    assert_eq!(err.code, UNKNOWN_METHOD);
    assert!(err.field.len() <= MAX_TEXT_LEN && long_method.starts_with(&err.field));
    for method in ["fly_to_point", "heart_beat2", ""] {
        let err = parse_drc(&Envelope::new(method, json!({}))).expect_err("refused");
        assert_eq!(err.code, UNKNOWN_METHOD, "{method}");
    }
}

fn drone_control(data: Value) -> Result<DrcDown, (u32, String)> {
    parse_drc(&Envelope::new("drone_control", data)).map_err(|e| (e.code, e.field))
}

#[test]
fn drone_control_fields() {
    let base = json!({"seq": 1, "x": 2.34, "y": -2.45, "h": 2.76, "w": 2.86});
    let cases: &[(&str, Option<Value>, u32)] = &[
        ("data.seq", None, MISSING_FIELD),
        ("data.seq", Some(json!(-1)), OUT_OF_RANGE),
        ("data.seq", Some(json!(1.5)), WRONG_TYPE),
        ("data.seq", Some(json!("1")), WRONG_TYPE),
        ("data.x", None, MISSING_FIELD),
        ("data.x", Some(json!(17.01)), OUT_OF_RANGE),
        ("data.x", Some(json!(-17.01)), OUT_OF_RANGE),
        ("data.x", Some(json!("1")), WRONG_TYPE),
        ("data.y", None, MISSING_FIELD),
        ("data.y", Some(json!(18)), OUT_OF_RANGE),
        ("data.y", Some(json!(-18)), OUT_OF_RANGE),
        ("data.h", None, MISSING_FIELD),
        ("data.h", Some(json!(5.01)), OUT_OF_RANGE),
        ("data.h", Some(json!(-4.01)), OUT_OF_RANGE),
        ("data.h", Some(json!(null)), MISSING_FIELD),
        ("data.w", None, MISSING_FIELD),
        ("data.w", Some(json!(90.5)), OUT_OF_RANGE),
        ("data.w", Some(json!(-91)), OUT_OF_RANGE),
        ("data.w", Some(json!([1])), WRONG_TYPE),
    ];
    for (path, value, code) in cases {
        let mut data = base.clone();
        change(&mut data, path, value.clone());
        assert_eq!(
            drone_control(data),
            Err((*code, (*path).to_owned())),
            "{path} {value:?}"
        );
    }
    assert_eq!(
        drone_control(Value::Null),
        Err((MISSING_FIELD, "data".into()))
    );
    assert_eq!(drone_control(json!([])), Err((WRONG_TYPE, "data".into())));
    // Boundaries (h is −4..=5: the document lists min 5, max −4).
    for (key, value) in [
        ("x", 17),
        ("x", -17),
        ("y", 17),
        ("h", 5),
        ("h", -4),
        ("w", 90),
        ("w", -90),
    ] {
        let mut data = base.clone();
        data[key] = json!(value);
        assert!(drone_control(data).is_ok(), "{key} {value}");
    }
    // A top-level seq is checked as `seq`.
    let mut env = Envelope::new("drone_control", json!({"x": 0, "y": 0, "h": 0, "w": 0}));
    env.seq = Some(-3);
    let err = parse_drc(&env).expect_err("refused");
    assert_eq!((err.code, err.field.as_str()), (OUT_OF_RANGE, "seq"));
}

#[test]
fn emergency_stop_and_heart_beat() {
    for data in [Value::Null, json!({}), json!({"reason": "x"})] {
        assert_eq!(
            parse_drc(&Envelope::new("drone_emergency_stop", data)),
            Ok(DrcDown::DroneEmergencyStop)
        );
    }
    let err = parse_drc(&Envelope::new("drone_emergency_stop", json!(1))).expect_err("refused");
    assert_eq!(err.code, WRONG_TYPE);

    let hb =
        |data: Value| parse_drc(&Envelope::new("heart_beat", data)).map_err(|e| (e.code, e.field));
    assert_eq!(
        hb(json!({"seq": -1, "timestamp": 0})),
        Ok(DrcDown::HeartBeat {
            seq: -1,
            timestamp: 0
        })
    );
    assert_eq!(
        hb(json!({"timestamp": 1})),
        Err((MISSING_FIELD, "data.seq".into()))
    );
    assert_eq!(
        hb(json!({"seq": 1})),
        Err((MISSING_FIELD, "data.timestamp".into()))
    );
    assert_eq!(
        hb(json!({"seq": 1.5, "timestamp": 1})),
        Err((WRONG_TYPE, "data.seq".into()))
    );
    assert_eq!(
        hb(json!({"seq": 1, "timestamp": "1"})),
        Err((WRONG_TYPE, "data.timestamp".into()))
    );
    assert_eq!(
        hb(json!({"seq": 1, "timestamp": u64::MAX})),
        Err((OUT_OF_RANGE, "data.timestamp".into()))
    );
    assert_eq!(hb(Value::Null), Err((MISSING_FIELD, "data".into())));
}

#[test]
fn events_reply_result() {
    let reply = |data: Value| {
        parse_event_reply(&Envelope::new("poi_status_notify", data)).map_err(|e| (e.code, e.field))
    };
    assert_eq!(
        reply(json!({"result": 319030})).map(|r| r.result),
        Ok(319030)
    );
    assert_eq!(reply(json!({})), Err((MISSING_FIELD, "data.result".into())));
    assert_eq!(
        reply(json!({"result": "0"})),
        Err((WRONG_TYPE, "data.result".into()))
    );
    assert_eq!(
        reply(json!({"result": 0.5})),
        Err((WRONG_TYPE, "data.result".into()))
    );
    assert_eq!(reply(Value::Null), Err((MISSING_FIELD, "data".into())));
}
