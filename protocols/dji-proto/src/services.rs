//! `parse_service`: every `services` method's `data` checked against the document's
//! Data table, fields in the table's order (the first violation is reported).
//!
//! Required: every field of the table except those the document marks optional or
//! deprecated (takeoff_to_point's `exit_wayline_when_rc_lost`,
//! `commander_mode_lost_action`, `commander_flight_height`, `simulate_mission`).

use serde_json::Value;

use crate::check::{
    enum_str_value, int_value, is_host_port, is_payload_index, no_data, reject, text_value,
    unknown_method, Obj,
};
use crate::codes::{
    BAD_ARRAY_SIZE, BAD_TEXT, MAX_SECRET_LEN, MAX_TEXT_LEN, NOT_IN_ENUM, OUT_OF_RANGE, WRONG_TYPE,
};
use crate::requests::{
    CameraMode, CameraType, DrcModeEnter, FlyToPoint, FlyToPointUpdate, GeoPoint, MqttBroker,
    RcLostAction, ServiceRequest, SimulateMission, StorageLens, TakeoffToPoint,
};
use crate::{Envelope, Reject};

/// Gimbal/screen-drag rates: the document gives none; skymesh refuses beyond this.
pub(crate) const MAX_DRAG_SPEED_DEG_S: f64 = 360.0;

const ALL_CAMERAS: &[(&str, CameraType)] = &[
    ("wide", CameraType::Wide),
    ("zoom", CameraType::Zoom),
    ("ir", CameraType::Ir),
];
/// Exposure and focus methods: the document allows only wide|zoom.
const VISIBLE_CAMERAS: &[(&str, CameraType)] =
    &[("wide", CameraType::Wide), ("zoom", CameraType::Zoom)];
const STORAGE_LENSES: &[(&str, StorageLens)] = &[
    ("current", StorageLens::Current),
    ("wide", StorageLens::Wide),
    ("zoom", StorageLens::Zoom),
    ("ir", StorageLens::Ir),
];
const BOOL_01: &[(i64, u8)] = &[(0, 0), (1, 1)];

pub(crate) fn parse(env: &Envelope) -> Result<ServiceRequest, Reject> {
    use ServiceRequest as S;
    let d = &env.data;
    Ok(match env.method.as_str() {
        "flight_authority_grab" => no_data(d).map(|()| S::FlightAuthorityGrab)?,
        "payload_authority_grab" => S::PayloadAuthorityGrab {
            payload_index: payload_index(&Obj::data(d)?)?,
        },
        "drc_mode_enter" => S::DrcModeEnter(drc_mode_enter(&Obj::data(d)?)?),
        "drc_mode_exit" => no_data(d).map(|()| S::DrcModeExit)?,
        "takeoff_to_point" => S::TakeoffToPoint(takeoff_to_point(&Obj::data(d)?)?),
        "fly_to_point" => {
            let o = Obj::data(d)?;
            S::FlyToPoint(FlyToPoint {
                fly_to_id: o.text("fly_to_id")?,
                max_speed: o.int("max_speed", 0..=15)?,
                points: points(&o)?,
            })
        }
        "fly_to_point_stop" => no_data(d).map(|()| S::FlyToPointStop)?,
        "fly_to_point_update" => {
            let o = Obj::data(d)?;
            S::FlyToPointUpdate(FlyToPointUpdate {
                max_speed: o.int("max_speed", 1..=15)?,
                points: points(&o)?,
            })
        }
        "camera_mode_switch" => {
            let o = Obj::data(d)?;
            S::CameraModeSwitch {
                payload_index: payload_index(&o)?,
                camera_mode: o.enum_int(
                    "camera_mode",
                    &[
                        (0, CameraMode::Photo),
                        (1, CameraMode::Video),
                        (2, CameraMode::LowLight),
                        (3, CameraMode::Panorama),
                    ],
                )?,
            }
        }
        "camera_photo_take" => S::CameraPhotoTake {
            payload_index: payload_index(&Obj::data(d)?)?,
        },
        "camera_photo_stop" => S::CameraPhotoStop {
            payload_index: payload_index(&Obj::data(d)?)?,
        },
        "camera_recording_start" => S::CameraRecordingStart {
            payload_index: payload_index(&Obj::data(d)?)?,
        },
        "camera_recording_stop" => S::CameraRecordingStop {
            payload_index: payload_index(&Obj::data(d)?)?,
        },
        "camera_screen_drag" => {
            let o = Obj::data(d)?;
            S::CameraScreenDrag {
                payload_index: payload_index(&o)?,
                locked: o.boolean("locked")?,
                pitch_speed: o.num("pitch_speed", -MAX_DRAG_SPEED_DEG_S, MAX_DRAG_SPEED_DEG_S)?,
                yaw_speed: o.num("yaw_speed", -MAX_DRAG_SPEED_DEG_S, MAX_DRAG_SPEED_DEG_S)?,
            }
        }
        "camera_aim" => {
            let o = Obj::data(d)?;
            S::CameraAim {
                payload_index: payload_index(&o)?,
                camera_type: o.enum_str("camera_type", ALL_CAMERAS)?,
                locked: o.boolean("locked")?,
                x: o.num("x", 0.0, 1.0)?,
                y: o.num("y", 0.0, 1.0)?,
            }
        }
        "camera_focal_length_set" => {
            let o = Obj::data(d)?;
            let payload_index = payload_index(&o)?;
            let camera_type = o.enum_str("camera_type", ALL_CAMERAS)?;
            let zoom_factor = o.num("zoom_factor", 2.0, 200.0)?;
            if camera_type == CameraType::Ir && zoom_factor > 20.0 {
                return Err(reject(
                    OUT_OF_RANGE,
                    o.path_of("zoom_factor"),
                    "above max 20 for camera_type ir",
                ));
            }
            S::CameraFocalLengthSet {
                payload_index,
                camera_type,
                zoom_factor,
            }
        }
        "gimbal_reset" => {
            let o = Obj::data(d)?;
            S::GimbalReset {
                payload_index: payload_index(&o)?,
                reset_mode: o.enum_int("reset_mode", &[(0, 0), (1, 1), (2, 2), (3, 3)])?,
            }
        }
        "camera_look_at" => {
            let o = Obj::data(d)?;
            S::CameraLookAt {
                payload_index: payload_index(&o)?,
                locked: o.boolean("locked")?,
                latitude: o.num("latitude", -90.0, 90.0)?,
                longitude: o.num("longitude", -180.0, 180.0)?,
                height: o.num("height", 2.0, 10000.0)?,
            }
        }
        "camera_screen_split" => {
            let o = Obj::data(d)?;
            S::CameraScreenSplit {
                payload_index: payload_index(&o)?,
                enable: o.boolean("enable")?,
            }
        }
        "photo_storage_set" => {
            let o = Obj::data(d)?;
            S::PhotoStorageSet {
                payload_index: payload_index(&o)?,
                photo_storage_settings: storage(&o, "photo_storage_settings")?,
            }
        }
        "video_storage_set" => {
            let o = Obj::data(d)?;
            S::VideoStorageSet {
                payload_index: payload_index(&o)?,
                video_storage_settings: storage(&o, "video_storage_settings")?,
            }
        }
        "camera_exposure_mode_set" => {
            let o = Obj::data(d)?;
            S::CameraExposureModeSet {
                payload_index: payload_index(&o)?,
                camera_type: o.enum_str("camera_type", VISIBLE_CAMERAS)?,
                exposure_mode: o.enum_int("exposure_mode", &[(1, 1), (2, 2), (3, 3), (4, 4)])?,
            }
        }
        "camera_exposure_set" => {
            let o = Obj::data(d)?;
            S::CameraExposureSet {
                payload_index: payload_index(&o)?,
                camera_type: o.enum_str("camera_type", VISIBLE_CAMERAS)?,
                exposure_value: exposure_value(&o)?,
            }
        }
        "camera_focus_mode_set" => {
            let o = Obj::data(d)?;
            S::CameraFocusModeSet {
                payload_index: payload_index(&o)?,
                camera_type: o.enum_str("camera_type", VISIBLE_CAMERAS)?,
                focus_mode: o.enum_int("focus_mode", &[(0, 0), (1, 1), (2, 2)])?,
            }
        }
        "camera_focus_value_set" => {
            let o = Obj::data(d)?;
            S::CameraFocusValueSet {
                payload_index: payload_index(&o)?,
                camera_type: o.enum_str("camera_type", VISIBLE_CAMERAS)?,
                focus_value: o.int("focus_value", 0..=i64::MAX)?,
            }
        }
        "camera_point_focus_action" => {
            let o = Obj::data(d)?;
            S::CameraPointFocusAction {
                payload_index: payload_index(&o)?,
                camera_type: o.enum_str("camera_type", VISIBLE_CAMERAS)?,
                x: o.num("x", 0.0, 1.0)?,
                y: o.num("y", 0.0, 1.0)?,
            }
        }
        "ir_metering_mode_set" => {
            let o = Obj::data(d)?;
            S::IrMeteringModeSet {
                payload_index: payload_index(&o)?,
                mode: o.enum_int("mode", &[(0, 0), (1, 1), (2, 2)])?,
            }
        }
        "ir_metering_point_set" => {
            let o = Obj::data(d)?;
            S::IrMeteringPointSet {
                payload_index: payload_index(&o)?,
                x: o.num("x", 0.0, 1.0)?,
                y: o.num("y", 0.0, 1.0)?,
            }
        }
        "ir_metering_area_set" => {
            let o = Obj::data(d)?;
            S::IrMeteringAreaSet {
                payload_index: payload_index(&o)?,
                x: o.num("x", 0.0, 1.0)?,
                y: o.num("y", 0.0, 1.0)?,
                width: o.num("width", 0.0, 1.0)?,
                height: o.num("height", 0.0, 1.0)?,
            }
        }
        "poi_mode_enter" => {
            let o = Obj::data(d)?;
            S::PoiModeEnter {
                latitude: o.num("latitude", -90.0, 90.0)?,
                longitude: o.num("longitude", -180.0, 180.0)?,
                height: o.num("height", 2.0, 10000.0)?,
            }
        }
        "poi_mode_exit" => no_data(d).map(|()| S::PoiModeExit)?,
        "poi_circle_speed_set" => S::PoiCircleSpeedSet {
            circle_speed: Obj::data(d)?.finite("circle_speed")?,
        },
        other => return Err(unknown_method(other)),
    })
}

/// `payload_index`: non-empty text `{type}-{subtype}-{gimbalindex}`.
fn payload_index(o: &Obj<'_>) -> Result<String, Reject> {
    let text = o.text("payload_index")?;
    if !is_payload_index(&text) {
        return Err(reject(
            BAD_TEXT,
            o.path_of("payload_index"),
            "expected {type}-{subtype}-{gimbalindex}",
        ));
    }
    Ok(text)
}

fn drc_mode_enter(o: &Obj<'_>) -> Result<DrcModeEnter, Reject> {
    let b = o.object("mqtt_broker")?;
    let address = b.text("address")?;
    if !is_host_port(&address) {
        return Err(reject(
            BAD_TEXT,
            b.path_of("address"),
            "expected host:port with port 1..=65535",
        ));
    }
    let mqtt_broker = MqttBroker {
        address,
        client_id: b.text("client_id")?,
        // Credentials may be empty (a broker without authentication); the password is
        // often a JWT, so it may be longer than other text.
        username: {
            let (v, path) = b.req("username")?;
            text_value(v, &path, true, MAX_TEXT_LEN)?
        },
        password: {
            let (v, path) = b.req("password")?;
            text_value(v, &path, true, MAX_SECRET_LEN)?
        },
        expire_time: b.int("expire_time", 0..=i64::MAX)?,
        enable_tls: b.boolean("enable_tls")?,
    };
    Ok(DrcModeEnter {
        mqtt_broker,
        osd_frequency: o.int_u8("osd_frequency", 1..=30)?,
        hsi_frequency: o.int_u8("hsi_frequency", 1..=30)?,
    })
}

fn takeoff_to_point(o: &Obj<'_>) -> Result<TakeoffToPoint, Reject> {
    Ok(TakeoffToPoint {
        target_latitude: o.num("target_latitude", -90.0, 90.0)?,
        target_longitude: o.num("target_longitude", -180.0, 180.0)?,
        target_height: o.num("target_height", 2.0, 1500.0)?,
        security_takeoff_height: o.num("security_takeoff_height", 20.0, 1500.0)?,
        rth_altitude: o.int("rth_altitude", 2..=1500)?,
        rc_lost_action: o.enum_int(
            "rc_lost_action",
            &[
                (0, RcLostAction::Hover),
                (1, RcLostAction::Land),
                (2, RcLostAction::ReturnHome),
            ],
        )?,
        exit_wayline_when_rc_lost: o.opt_enum_int("exit_wayline_when_rc_lost", BOOL_01)?,
        commander_mode_lost_action: o.opt_enum_int("commander_mode_lost_action", BOOL_01)?,
        commander_flight_height: o.opt_num("commander_flight_height", 2.0, 3000.0)?,
        flight_id: o.text("flight_id")?,
        max_speed: o.int("max_speed", 1..=15)?,
        simulate_mission: o
            .opt_object("simulate_mission")?
            .map(|s| {
                Ok::<_, Reject>(SimulateMission {
                    is_enable: is_enable(&s)?,
                    latitude: s.num("latitude", -90.0, 90.0)?,
                    longitude: s.num("longitude", -180.0, 180.0)?,
                })
            })
            .transpose()?,
    })
}

/// `simulate_mission.is_enable`: the document's enum_int 0/1; a JSON bool is taken too.
fn is_enable(s: &Obj<'_>) -> Result<bool, Reject> {
    let (v, path) = s.req("is_enable")?;
    match v {
        Value::Bool(b) => Ok(*b),
        _ => crate::check::enum_int_value(v, &path, &[(0, false), (1, true)]),
    }
}

/// `points`: exactly one target point ("Only supports 1 target point").
fn points(o: &Obj<'_>) -> Result<Vec<GeoPoint>, Reject> {
    let (items, path) = o.array("points", 1..=1)?;
    items
        .iter()
        .enumerate()
        .map(|(i, item)| {
            let p = Obj::of(item, format!("{path}[{i}]"))?;
            Ok(GeoPoint {
                latitude: p.num("latitude", -90.0, 90.0)?,
                longitude: p.num("longitude", -180.0, 180.0)?,
                height: p.num("height", 2.0, 10000.0)?,
            })
        })
        .collect()
}

/// Storage settings: 1..=4 of current|wide|zoom|ir, each at most once.
fn storage(o: &Obj<'_>, key: &str) -> Result<Vec<StorageLens>, Reject> {
    let (items, path) = o.array(key, 1..=STORAGE_LENSES.len())?;
    let mut lenses = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let item_path = format!("{path}[{i}]");
        let lens = enum_str_value(item, &item_path, STORAGE_LENSES)?;
        if lenses.contains(&lens) {
            return Err(reject(BAD_ARRAY_SIZE, item_path, "repeats an earlier item"));
        }
        lenses.push(lens);
    }
    Ok(lenses)
}

/// `exposure_value`: the document types it enum_string with keys "1".."31" and "255",
/// but its example sends the integer 5; both forms are accepted.
fn exposure_value(o: &Obj<'_>) -> Result<u8, Reject> {
    let (v, path) = o.req("exposure_value")?;
    let value = match v {
        Value::String(s) => s.parse::<u8>().ok().filter(|n| n.to_string() == *s),
        Value::Number(_) => {
            let n = int_value(v, &path, i64::MIN..=i64::MAX).map_err(|e| {
                if e.code == OUT_OF_RANGE {
                    reject(NOT_IN_ENUM, &path, "not one of 1..=31|255")
                } else {
                    e
                }
            })?;
            u8::try_from(n).ok()
        }
        _ => {
            return Err(reject(
                WRONG_TYPE,
                path,
                "expected enum string (\"1\"..\"31\", \"255\") or integer",
            ))
        }
    };
    value
        .filter(|n| is_exposure_value(*n))
        .ok_or_else(|| reject(NOT_IN_ENUM, path, "not one of 1..=31|255"))
}

pub(crate) fn is_exposure_value(n: u8) -> bool {
    (1..=31).contains(&n) || n == 255
}
