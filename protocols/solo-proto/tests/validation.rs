//! Field checks: NaN/∞, coordinates, enumerations and speeds out of range are
//! `InvalidValue`; values real apps send are accepted.

use solo_proto::{
    direction, ids, ButtonSetting, DecodeError, Direction, GeofenceData, Location, SoloMessage,
};

fn invalid(msg_type: u32, value: &[u8]) -> String {
    match SoloMessage::decode(msg_type, value) {
        Err(DecodeError::InvalidValue {
            msg_type: t, what, ..
        }) => {
            assert_eq!(t, msg_type);
            what
        }
        other => panic!("type {msg_type}: expected InvalidValue, got {other:?}"),
    }
}

fn location_value(lat: f64, lon: f64, alt: f32) -> Vec<u8> {
    let mut v = lat.to_le_bytes().to_vec();
    v.extend_from_slice(&lon.to_le_bytes());
    v.extend_from_slice(&alt.to_le_bytes());
    v
}

fn i32s(values: &[i32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn locations_must_be_finite_and_on_the_globe() {
    for (lat, lon, alt) in [
        (f64::NAN, 0.0, 0.0),
        (0.0, f64::INFINITY, 0.0),
        (0.0, 0.0, f32::NAN),
        (0.0, 0.0, f32::NEG_INFINITY),
        (90.000001, 0.0, 0.0),
        (-91.0, 0.0, 0.0),
        (0.0, 180.5, 0.0),
        (0.0, -181.0, 0.0),
    ] {
        let what = invalid(ids::LOCATION, &location_value(lat, lon, alt));
        assert!(!what.is_empty());
        invalid(ids::HOME_LOCATION, &location_value(lat, lon, alt));
    }
    // The poles and the antimeridian are fine.
    assert_eq!(
        SoloMessage::decode(ids::LOCATION, &location_value(-90.0, 180.0, -5.0)),
        Ok(SoloMessage::Location(Location {
            lat_deg: -90.0,
            lon_deg: 180.0,
            alt_m: -5.0
        }))
    );
}

#[test]
fn shot_indices_are_minus_one_to_ten() {
    for t in [ids::GET_CURRENT_SHOT, ids::SET_CURRENT_SHOT] {
        assert!(invalid(t, &i32s(&[-2])).contains("shot -2"));
        invalid(t, &i32s(&[11]));
        invalid(t, &i32s(&[i32::MIN]));
        for shot in -1..=10 {
            assert!(SoloMessage::decode(t, &i32s(&[shot])).is_ok());
        }
    }
}

#[test]
fn button_settings_are_checked_field_by_field() {
    for t in [ids::GET_BUTTON_SETTING, ids::SET_BUTTON_SETTING] {
        invalid(t, &i32s(&[9, 0, 1, -1]));
        invalid(t, &i32s(&[-1, 0, 1, -1]));
        invalid(t, &i32s(&[4, 6, 1, -1]));
        invalid(t, &i32s(&[4, 0, 11, -1]));
        invalid(t, &i32s(&[4, 0, -1, -2]));
    }
    // A GET request carries −1 for both shot and mode.
    assert_eq!(
        SoloMessage::decode(ids::GET_BUTTON_SETTING, &i32s(&[5, 0, -1, -1])),
        Ok(SoloMessage::GetButtonSetting(ButtonSetting {
            button: 5,
            event: 0,
            shot: -1,
            mode: -1
        }))
    );
}

#[test]
fn enumerations_out_of_range_are_invalid() {
    invalid(ids::GOPRO_RECORD, &3u32.to_le_bytes());
    invalid(ids::GOPRO_SET_ENABLED, &2u32.to_le_bytes());
    invalid(ids::SHOT_ERROR, &3u32.to_le_bytes());
    let mut follow_v2 = 5.0f32.to_le_bytes().to_vec();
    follow_v2.extend_from_slice(&i32s(&[1, 3]));
    assert!(invalid(ids::FOLLOW_OPTIONS_V2, &follow_v2).contains("follow_preference"));
    let mut follow = 5.0f32.to_le_bytes().to_vec();
    follow.extend_from_slice(&i32s(&[2]));
    invalid(ids::FOLLOW_OPTIONS, &follow);
    let mut seek = 0.5f32.to_le_bytes().to_vec();
    seek.extend_from_slice(&i32s(&[2]));
    invalid(ids::SPLINE_SEEK, &seek);
    let mut settings = 2u32.to_le_bytes().to_vec();
    settings.extend_from_slice(&10.0f32.to_le_bytes());
    invalid(ids::SPLINE_PATH_SETTINGS, &settings);
    // pano type 3
    invalid(ids::PANO_OPTIONS, &[3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
    // zipline is_3d 2
    invalid(ids::ZIPLINE_OPTIONS, &[0, 0, 0, 0, 2, 0]);
    // rewind enabled 2
    invalid(ids::REWIND_OPTIONS, &[2, 0, 0, 0, 0, 0]);
    // cable cam interpolation 2
    invalid(ids::CABLE_CAM_OPTIONS, &[2, 0, 0, 0, 0, 0, 0, 0]);
    // geofence ack valid 2, update action 3
    invalid(ids::GEOFENCE_SET_ACK, &[1, 0, 2]);
    let mut poly = vec![3u8, 0, 0, 0, 0];
    poly.extend_from_slice(&[0; 32]);
    invalid(ids::GEOFENCE_UPDATE_POLY, &poly);
}

#[test]
fn speeds_are_finite_and_within_100_mps_either_sign() {
    for speed in [f32::NAN, f32::INFINITY, 100.5, -101.0] {
        assert!(invalid(ids::SHOT_OPTIONS, &speed.to_le_bytes()).contains("cruise_speed"));
    }
    // Negative cruise speed is the cable cam / orbit direction: accepted.
    assert_eq!(
        SoloMessage::decode(ids::SHOT_OPTIONS, &(-100.0f32).to_le_bytes()),
        Ok(SoloMessage::ShotOptions {
            cruise_speed: -100.0
        })
    );
    let mut v = Vec::new();
    for x in [1.0f32, f32::NAN, 0.0] {
        v.extend_from_slice(&x.to_le_bytes());
    }
    invalid(ids::INSPECT_MOVE_VEHICLE, &v);
}

#[test]
fn any_float_field_refuses_nan() {
    // SPLINE_DURATIONS, PANO lens FOV, INSPECT gimbal: NaN anywhere is refused.
    let mut durations = f32::NAN.to_le_bytes().to_vec();
    durations.extend_from_slice(&1.0f32.to_le_bytes());
    invalid(ids::SPLINE_DURATIONS, &durations);
    let mut pano = vec![0u8, 0, 220, 0];
    pano.extend_from_slice(&2.0f32.to_le_bytes());
    pano.extend_from_slice(&f32::INFINITY.to_le_bytes());
    assert!(invalid(ids::PANO_OPTIONS, &pano).contains("lens_fov"));
    let mut waypoint = 95.0f32.to_le_bytes().to_vec();
    waypoint.extend_from_slice(&0.0f32.to_le_bytes());
    waypoint.extend_from_slice(&0.0f32.to_le_bytes());
    invalid(ids::INSPECT_SET_WAYPOINT, &waypoint);
}

#[test]
fn geofence_update_ignores_coordinates_only_when_removing() {
    let mut remove = vec![2u8, 1, 0, 3, 0];
    remove.extend_from_slice(&[0xFF; 32]); // NaN coordinates, ignored
    assert!(matches!(
        SoloMessage::decode(ids::GEOFENCE_UPDATE_POLY, &remove),
        Ok(SoloMessage::GeofenceUpdatePoly {
            action: 2,
            polygon_index: 1,
            vertex_index: 3,
            ..
        })
    ));
    let mut update = remove.clone();
    update[0] = 0;
    invalid(ids::GEOFENCE_UPDATE_POLY, &update);
}

#[test]
fn geofence_json_is_checked() {
    let bad: &[(&str, &str)] = &[
        ("{", "malformed"),
        ("[]", "malformed"),
        (r#"{"coord": [], "subCoord": []}"#, "malformed"),
        (
            r#"{"coord": [[[1.0]]], "subCoord": [[]], "type": [0]}"#,
            "malformed",
        ),
        (
            r#"{"coord": [[]], "subCoord": [], "type": [0]}"#,
            "different sizes",
        ),
        (
            r#"{"coord": [[]], "subCoord": [[]], "type": [0, 1]}"#,
            "different sizes",
        ),
        (
            r#"{"coord": [[[95.0, 0.0]]], "subCoord": [[]], "type": [0]}"#,
            "latitude",
        ),
        (
            r#"{"coord": [[]], "subCoord": [[[0.0, 200.0]]], "type": [1]}"#,
            "latitude",
        ),
        (
            r#"{"coord": [[]], "subCoord": [[]], "type": [2]}"#,
            "type[0]",
        ),
        (
            r#"{"coord": [[[1e999, 0.0]]], "subCoord": [[]], "type": [0]}"#,
            "malformed",
        ),
    ];
    for (json, needle) in bad {
        let what = invalid(ids::GEOFENCE_SET_DATA, json.as_bytes());
        assert!(what.contains(needle), "{json}: {what}");
    }
    // Any number of polygons, including none, and extra keys are accepted.
    assert_eq!(
        SoloMessage::decode(
            ids::GEOFENCE_SET_DATA,
            br#"{"coord": [], "subCoord": [], "type": [], "version": 2}"#
        ),
        Ok(SoloMessage::GeofenceSetData(GeofenceData {
            coord: vec![],
            sub_coord: vec![],
            kinds: vec![]
        }))
    );
}

#[test]
fn shotmanager_error_is_lossy_text() {
    assert_eq!(
        SoloMessage::decode(ids::SHOTMANAGER_ERROR, &[b'a', 0xC3, 0x28, b'b']),
        Ok(SoloMessage::ShotManagerError("a\u{FFFD}(b".to_string()))
    );
    assert_eq!(
        SoloMessage::decode(ids::SHOTMANAGER_ERROR, &[]),
        Ok(SoloMessage::ShotManagerError(String::new()))
    );
    let too_long = vec![b'x'; solo_proto::MAX_VALUE_LEN + 1];
    assert!(matches!(
        SoloMessage::decode(ids::SHOTMANAGER_ERROR, &too_long),
        Err(DecodeError::WrongLength { .. })
    ));
}

#[test]
fn validate_catches_hand_built_nonsense() {
    assert!(SoloMessage::SetCurrentShot(42).validate().is_err());
    assert!(SoloMessage::ShotOptions {
        cruise_speed: f32::NAN
    }
    .validate()
    .is_err());
    assert!(SoloMessage::GeofenceSetData(GeofenceData {
        coord: vec![vec![[f64::NAN, 0.0]]],
        sub_coord: vec![vec![]],
        kinds: vec![0],
    })
    .validate()
    .is_err());
    assert_eq!(SoloMessage::SetCurrentShot(2).validate(), Ok(()));
}

#[test]
fn error_messages_name_the_message() {
    let err = SoloMessage::decode(ids::GOPRO_RECORD, &7u32.to_le_bytes()).expect_err("3+");
    assert_eq!(
        err.to_string(),
        "gopro_record (type 5003): on_off 7 is outside 0..=2"
    );
    let err = SoloMessage::decode(ids::LOCATION, &[0; 3]).expect_err("short");
    assert_eq!(
        err.to_string(),
        "location (type 2): value is 3 bytes, expected 20"
    );
    assert_eq!(
        SoloMessage::decode(77, &[])
            .expect_err("unknown")
            .to_string(),
        "unknown message type 77"
    );
}

#[test]
fn directions_the_gateway_relies_on() {
    use Direction::*;
    for (t, d) in [
        (ids::SET_CURRENT_SHOT, AppToVehicle),
        (ids::RECORD_POSITION, AppToVehicle),
        (ids::SET_BUTTON_SETTING, AppToVehicle),
        (ids::SPLINE_SEEK, AppToVehicle),
        (ids::SPLINE_PATH_SETTINGS, AppToVehicle),
        (ids::GEOFENCE_SET_DATA, AppToVehicle),
        (ids::GEOFENCE_UPDATE_POLY, AppToVehicle),
        (ids::GOPRO_SET_ENABLED, AppToVehicle),
        (ids::GOPRO_SET_REQUEST, AppToVehicle),
        (ids::GOPRO_SET_EXTENDED_REQUEST, AppToVehicle),
        (ids::GOPRO_RECORD, AppToVehicle),
        (ids::GOPRO_REQUEST_STATE, AppToVehicle),
        (ids::INSPECT_START, AppToVehicle),
        (ids::INSPECT_MOVE_VEHICLE, AppToVehicle),
        (ids::SCAN_START, AppToVehicle),
        (ids::SURVEY_START, AppToVehicle),
        (ids::ZIPLINE_LOCK, AppToVehicle),
        (ids::GET_CURRENT_SHOT, VehicleToApp),
        (ids::SHOT_ERROR, VehicleToApp),
        (ids::SHOTMANAGER_ERROR, VehicleToApp),
        (ids::CABLE_CAM_WAYPOINT, VehicleToApp),
        (ids::SECOND_PHONE_NOTIFICATION, VehicleToApp),
        (ids::SPLINE_PLAYBACK_STATUS, VehicleToApp),
        (ids::SPLINE_DURATIONS, VehicleToApp),
        (ids::GEOFENCE_SET_ACK, VehicleToApp),
        (ids::GEOFENCE_ACTIVATED, VehicleToApp),
        (ids::GOPRO_V1_STATE, VehicleToApp),
        (ids::GOPRO_V2_STATE, VehicleToApp),
        (ids::GOPRO_PHOTO, VehicleToApp),
        (ids::PANO_STATE, VehicleToApp),
        (ids::SHOT_OPTIONS, Both),
        (ids::LOCATION, Both),
        (ids::GET_BUTTON_SETTING, Both),
        (ids::PAUSE, Both),
        (ids::SPLINE_POINT, Both),
        (ids::GEOFENCE_CLEAR, Both),
        (ids::HOME_LOCATION, Both),
    ] {
        assert_eq!(direction(t), Some(d), "type {t}");
    }
}
