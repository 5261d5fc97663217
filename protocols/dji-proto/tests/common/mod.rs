//! Shared by the integration tests: the document's examples, JSON helpers (field path
//! → pointer, set/remove a field, numeric-insensitive comparison) and proptest
//! strategies producing random *valid* requests of every method.
#![allow(dead_code)]

pub mod examples;

use dji_proto::{
    parse_envelope, CameraMode, CameraType, DrcDown, DrcModeEnter, DroneControl, Envelope,
    FlyToPoint, FlyToPointUpdate, GeoPoint, MqttBroker, RcLostAction, ServiceRequest,
    SimulateMission, StorageLens, TakeoffToPoint, TopicKind,
};
use proptest::prelude::*;
use proptest::strategy::{BoxedStrategy, Union};
use serde_json::Value;

/// The envelope of a `services` example.
pub fn service_envelope(method: &str) -> Envelope {
    let text = examples::example(examples::SERVICES, method);
    parse_envelope(TopicKind::Services, text.as_bytes()).expect("example parses")
}

/// `data.points[0].latitude` → `/points/0/latitude` (a pointer into `data`).
pub fn pointer(path: &str) -> String {
    let rest = path.strip_prefix("data").expect("paths start at data");
    rest.replace('[', ".").replace(']', "").replace('.', "/")
}

/// Sets (`Some`) or removes (`None`) the field at `path` (`data....`) in `data`;
/// the parent must exist. Setting `data` itself replaces it.
pub fn change(data: &mut Value, path: &str, new: Option<Value>) {
    let ptr = pointer(path);
    if ptr.is_empty() {
        *data = new.unwrap_or(Value::Null);
        return;
    }
    let (parent, last) = ptr.rsplit_once('/').expect("pointer");
    let target = data
        .pointer_mut(parent)
        .unwrap_or_else(|| panic!("no parent {parent} for {path}"));
    match (target, new) {
        (Value::Object(map), Some(v)) => {
            map.insert(last.to_owned(), v);
        }
        (Value::Object(map), None) => {
            map.remove(last);
        }
        (Value::Array(items), Some(v)) => {
            let i: usize = last.parse().expect("index");
            items[i] = v;
        }
        (Value::Array(items), None) => {
            let i: usize = last.parse().expect("index");
            items.remove(i);
        }
        (other, _) => panic!("{path}: parent is {other}"),
    }
}

/// Every number as f64, so `0` and `0.0` compare equal (the document writes integers
/// where our structs hold floats).
pub fn numbers_as_f64(v: &Value) -> Value {
    match v {
        Value::Number(n) => serde_json::Number::from_f64(n.as_f64().expect("finite"))
            .map_or(Value::Null, Value::Number),
        Value::Array(items) => items.iter().map(numbers_as_f64).collect(),
        Value::Object(map) => Value::Object(
            map.iter()
                .map(|(k, v)| (k.clone(), numbers_as_f64(v)))
                .collect(),
        ),
        other => other.clone(),
    }
}

/// Asserts two JSON values are equal, numbers compared as f64.
#[track_caller]
pub fn assert_json_eq(ours: &Value, expected: &Value) {
    assert_eq!(
        numbers_as_f64(ours),
        numbers_as_f64(expected),
        "\n ours:     {ours}\n expected: {expected}"
    );
}

// --- strategies: random valid requests ---

fn payload_index() -> impl Strategy<Value = String> {
    (0u32..100, 0u32..10, 0u32..10).prop_map(|(a, b, c)| format!("{a}-{b}-{c}"))
}

fn text() -> impl Strategy<Value = String> {
    "[A-Za-z0-9_\\-]{1,64}"
}

fn lat() -> impl Strategy<Value = f64> {
    -90.0..=90.0f64
}

fn lon() -> impl Strategy<Value = f64> {
    -180.0..=180.0f64
}

fn unit() -> impl Strategy<Value = f64> {
    0.0..=1.0f64
}

fn geo_point() -> impl Strategy<Value = GeoPoint> {
    (lat(), lon(), 2.0..=10000.0f64).prop_map(|(latitude, longitude, height)| GeoPoint {
        latitude,
        longitude,
        height,
    })
}

fn visible_camera() -> impl Strategy<Value = CameraType> {
    prop_oneof![Just(CameraType::Wide), Just(CameraType::Zoom)]
}

fn any_camera() -> impl Strategy<Value = CameraType> {
    prop_oneof![
        Just(CameraType::Wide),
        Just(CameraType::Zoom),
        Just(CameraType::Ir)
    ]
}

fn lenses() -> impl Strategy<Value = Vec<StorageLens>> {
    proptest::sample::subsequence(
        vec![
            StorageLens::Current,
            StorageLens::Wide,
            StorageLens::Zoom,
            StorageLens::Ir,
        ],
        1..=4,
    )
    .prop_shuffle()
}

fn drc_mode_enter() -> impl Strategy<Value = DrcModeEnter> {
    (
        ("[a-z]{1,20}(\\.[a-z]{1,10}){0,2}", 1u16..=65535),
        text(),
        "[A-Za-z0-9_]{0,32}",
        "[A-Za-z0-9_.\\-]{0,600}",
        0i64..=i64::MAX,
        any::<bool>(),
        1u8..=30,
        1u8..=30,
    )
        .prop_map(
            |((host, port), client_id, username, password, expire_time, enable_tls, osd, hsi)| {
                DrcModeEnter {
                    mqtt_broker: MqttBroker {
                        address: format!("{host}:{port}"),
                        client_id,
                        username,
                        password,
                        expire_time,
                        enable_tls,
                    },
                    osd_frequency: osd,
                    hsi_frequency: hsi,
                }
            },
        )
}

fn takeoff() -> impl Strategy<Value = TakeoffToPoint> {
    (
        (lat(), lon(), 2.0..=1500.0f64, 20.0..=1500.0f64, 2i64..=1500),
        prop_oneof![
            Just(RcLostAction::Hover),
            Just(RcLostAction::Land),
            Just(RcLostAction::ReturnHome)
        ],
        (
            proptest::option::of(0u8..=1),
            proptest::option::of(0u8..=1),
            proptest::option::of(2.0..=3000.0f64),
        ),
        text(),
        1i64..=15,
        proptest::option::of((any::<bool>(), lat(), lon()).prop_map(
            |(is_enable, latitude, longitude)| SimulateMission {
                is_enable,
                latitude,
                longitude,
            },
        )),
    )
        .prop_map(
            |((tlat, tlon, th, sth, rth), rc, (exit, cmd, cfh), flight_id, max_speed, sim)| {
                TakeoffToPoint {
                    target_latitude: tlat,
                    target_longitude: tlon,
                    target_height: th,
                    security_takeoff_height: sth,
                    rth_altitude: rth,
                    rc_lost_action: rc,
                    exit_wayline_when_rc_lost: exit,
                    commander_mode_lost_action: cmd,
                    commander_flight_height: cfh,
                    flight_id,
                    max_speed,
                    simulate_mission: sim,
                }
            },
        )
}

/// A random valid request of any of the document's 32 methods.
pub fn service_request() -> impl Strategy<Value = ServiceRequest> {
    use ServiceRequest as S;
    let pi = payload_index;
    let arms: Vec<BoxedStrategy<ServiceRequest>> = vec![
        Just(S::FlightAuthorityGrab).boxed(),
        pi().prop_map(|payload_index| S::PayloadAuthorityGrab { payload_index })
            .boxed(),
        drc_mode_enter().prop_map(S::DrcModeEnter).boxed(),
        Just(S::DrcModeExit).boxed(),
        takeoff().prop_map(S::TakeoffToPoint).boxed(),
        (text(), 0i64..=15, geo_point())
            .prop_map(|(fly_to_id, max_speed, p)| {
                S::FlyToPoint(FlyToPoint {
                    fly_to_id,
                    max_speed,
                    points: vec![p],
                })
            })
            .boxed(),
        Just(S::FlyToPointStop).boxed(),
        (1i64..=15, geo_point())
            .prop_map(|(max_speed, p)| {
                S::FlyToPointUpdate(FlyToPointUpdate {
                    max_speed,
                    points: vec![p],
                })
            })
            .boxed(),
        (
            pi(),
            prop_oneof![
                Just(CameraMode::Photo),
                Just(CameraMode::Video),
                Just(CameraMode::LowLight),
                Just(CameraMode::Panorama)
            ],
        )
            .prop_map(|(payload_index, camera_mode)| S::CameraModeSwitch {
                payload_index,
                camera_mode,
            })
            .boxed(),
        pi().prop_map(|payload_index| S::CameraPhotoTake { payload_index })
            .boxed(),
        pi().prop_map(|payload_index| S::CameraPhotoStop { payload_index })
            .boxed(),
        pi().prop_map(|payload_index| S::CameraRecordingStart { payload_index })
            .boxed(),
        pi().prop_map(|payload_index| S::CameraRecordingStop { payload_index })
            .boxed(),
        (pi(), any::<bool>(), -360.0..=360.0f64, -360.0..=360.0f64)
            .prop_map(
                |(payload_index, locked, pitch_speed, yaw_speed)| S::CameraScreenDrag {
                    payload_index,
                    locked,
                    pitch_speed,
                    yaw_speed,
                },
            )
            .boxed(),
        (pi(), any_camera(), any::<bool>(), unit(), unit())
            .prop_map(|(payload_index, camera_type, locked, x, y)| S::CameraAim {
                payload_index,
                camera_type,
                locked,
                x,
                y,
            })
            .boxed(),
        (pi(), any_camera(), 2.0..=200.0f64)
            .prop_map(
                |(payload_index, camera_type, zoom)| S::CameraFocalLengthSet {
                    payload_index,
                    camera_type,
                    // ir: 2..=20 (the same draw folded into the smaller range)
                    zoom_factor: if camera_type == CameraType::Ir {
                        2.0 + (zoom - 2.0) * 18.0 / 198.0
                    } else {
                        zoom
                    },
                },
            )
            .boxed(),
        (pi(), 0u8..=3)
            .prop_map(|(payload_index, reset_mode)| S::GimbalReset {
                payload_index,
                reset_mode,
            })
            .boxed(),
        (pi(), any::<bool>(), lat(), lon(), 2.0..=10000.0f64)
            .prop_map(
                |(payload_index, locked, latitude, longitude, height)| S::CameraLookAt {
                    payload_index,
                    locked,
                    latitude,
                    longitude,
                    height,
                },
            )
            .boxed(),
        (pi(), any::<bool>())
            .prop_map(|(payload_index, enable)| S::CameraScreenSplit {
                payload_index,
                enable,
            })
            .boxed(),
        (pi(), lenses())
            .prop_map(
                |(payload_index, photo_storage_settings)| S::PhotoStorageSet {
                    payload_index,
                    photo_storage_settings,
                },
            )
            .boxed(),
        (pi(), lenses())
            .prop_map(
                |(payload_index, video_storage_settings)| S::VideoStorageSet {
                    payload_index,
                    video_storage_settings,
                },
            )
            .boxed(),
        (pi(), visible_camera(), 1u8..=4)
            .prop_map(
                |(payload_index, camera_type, exposure_mode)| S::CameraExposureModeSet {
                    payload_index,
                    camera_type,
                    exposure_mode,
                },
            )
            .boxed(),
        (pi(), visible_camera(), prop_oneof![1u8..=31, Just(255u8)])
            .prop_map(
                |(payload_index, camera_type, exposure_value)| S::CameraExposureSet {
                    payload_index,
                    camera_type,
                    exposure_value,
                },
            )
            .boxed(),
        (pi(), visible_camera(), 0u8..=2)
            .prop_map(
                |(payload_index, camera_type, focus_mode)| S::CameraFocusModeSet {
                    payload_index,
                    camera_type,
                    focus_mode,
                },
            )
            .boxed(),
        (pi(), visible_camera(), 0i64..=i64::MAX)
            .prop_map(
                |(payload_index, camera_type, focus_value)| S::CameraFocusValueSet {
                    payload_index,
                    camera_type,
                    focus_value,
                },
            )
            .boxed(),
        (pi(), visible_camera(), unit(), unit())
            .prop_map(
                |(payload_index, camera_type, x, y)| S::CameraPointFocusAction {
                    payload_index,
                    camera_type,
                    x,
                    y,
                },
            )
            .boxed(),
        (pi(), 0u8..=2)
            .prop_map(|(payload_index, mode)| S::IrMeteringModeSet {
                payload_index,
                mode,
            })
            .boxed(),
        (pi(), unit(), unit())
            .prop_map(|(payload_index, x, y)| S::IrMeteringPointSet {
                payload_index,
                x,
                y,
            })
            .boxed(),
        (pi(), unit(), unit(), unit(), unit())
            .prop_map(
                |(payload_index, x, y, width, height)| S::IrMeteringAreaSet {
                    payload_index,
                    x,
                    y,
                    width,
                    height,
                },
            )
            .boxed(),
        (lat(), lon(), 2.0..=10000.0f64)
            .prop_map(|(latitude, longitude, height)| S::PoiModeEnter {
                latitude,
                longitude,
                height,
            })
            .boxed(),
        Just(S::PoiModeExit).boxed(),
        (-1.0e6..=1.0e6f64)
            .prop_map(|circle_speed| S::PoiCircleSpeedSet { circle_speed })
            .boxed(),
    ];
    Union::new(arms)
}

/// A random valid `drc/down` message.
pub fn drc_down() -> impl Strategy<Value = DrcDown> {
    prop_oneof![
        (
            0i64..=i64::MAX,
            -17.0..=17.0f64,
            -17.0..=17.0f64,
            -4.0..=5.0f64,
            -90.0..=90.0f64
        )
            .prop_map(|(seq, x, y, h, w)| DrcDown::DroneControl(DroneControl {
                seq,
                x,
                y,
                h,
                w
            })),
        Just(DrcDown::DroneEmergencyStop),
        (any::<i64>(), any::<i64>())
            .prop_map(|(seq, timestamp)| DrcDown::HeartBeat { seq, timestamp }),
    ]
}

/// Arbitrary JSON (bounded depth and size).
pub fn any_json() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::from),
        any::<u64>().prop_map(Value::from),
        (-1.0e7..1.0e7f64).prop_map(Value::from),
        "[a-z0-9_:\\-]{0,12}".prop_map(Value::String),
        // Strings a parser might mistake for valid values.
        prop_oneof![
            Just("39-0-7"),
            Just("wide"),
            Just("ir"),
            Just("current"),
            Just("5"),
            Just("h:1")
        ]
        .prop_map(|s| Value::String(s.to_owned())),
    ];
    leaf.prop_recursive(4, 48, 8, |inner| {
        prop_oneof![
            proptest::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
            proptest::collection::btree_map(
                prop_oneof![
                    "[a-z_]{1,10}",
                    // The documented names, so objects hit real fields.
                    prop_oneof![
                        Just("payload_index"),
                        Just("camera_type"),
                        Just("points"),
                        Just("latitude"),
                        Just("longitude"),
                        Just("height"),
                        Just("seq"),
                        Just("x"),
                        Just("mqtt_broker"),
                        Just("address"),
                    ]
                    .prop_map(str::to_owned),
                ],
                inner,
                0..6
            )
            .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}
