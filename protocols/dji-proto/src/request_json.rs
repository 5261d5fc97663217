//! The cloud's side of the inbound requests: a checked request back to its `data`
//! JSON (for fake clouds in tests, and the round-trip property `parse(to_data(r)) == r`).

use serde_json::{json, Map, Value};

use crate::requests::{
    DrcDown, DrcModeEnter, FlyToPoint, FlyToPointUpdate, GeoPoint, ServiceRequest, StorageLens,
    TakeoffToPoint,
};

fn points(points: &[GeoPoint]) -> Value {
    points
        .iter()
        .map(|p| json!({"latitude": p.latitude, "longitude": p.longitude, "height": p.height}))
        .collect()
}

fn lenses(lenses: &[StorageLens]) -> Value {
    lenses.iter().map(|l| Value::from(l.as_str())).collect()
}

fn drc_mode_enter(d: &DrcModeEnter) -> Value {
    let b = &d.mqtt_broker;
    json!({
        "mqtt_broker": {
            "address": b.address,
            "client_id": b.client_id,
            "username": b.username,
            "password": b.password,
            "expire_time": b.expire_time,
            "enable_tls": b.enable_tls,
        },
        "osd_frequency": d.osd_frequency,
        "hsi_frequency": d.hsi_frequency,
    })
}

fn takeoff(t: &TakeoffToPoint) -> Value {
    let mut m = Map::new();
    m.insert("target_latitude".into(), t.target_latitude.into());
    m.insert("target_longitude".into(), t.target_longitude.into());
    m.insert("target_height".into(), t.target_height.into());
    m.insert(
        "security_takeoff_height".into(),
        t.security_takeoff_height.into(),
    );
    m.insert("rth_altitude".into(), t.rth_altitude.into());
    m.insert("rc_lost_action".into(), (t.rc_lost_action as u8).into());
    if let Some(v) = t.exit_wayline_when_rc_lost {
        m.insert("exit_wayline_when_rc_lost".into(), v.into());
    }
    if let Some(v) = t.commander_mode_lost_action {
        m.insert("commander_mode_lost_action".into(), v.into());
    }
    if let Some(v) = t.commander_flight_height {
        m.insert("commander_flight_height".into(), v.into());
    }
    m.insert("flight_id".into(), t.flight_id.clone().into());
    m.insert("max_speed".into(), t.max_speed.into());
    if let Some(s) = &t.simulate_mission {
        m.insert(
            "simulate_mission".into(),
            json!({
                "is_enable": u8::from(s.is_enable),
                "latitude": s.latitude,
                "longitude": s.longitude,
            }),
        );
    }
    Value::Object(m)
}

impl ServiceRequest {
    /// This request's `data` as the cloud sends it (methods without data: `{}`;
    /// `exposure_value` as the document's enum string).
    pub fn to_data(&self) -> Value {
        use ServiceRequest as S;
        match self {
            S::FlightAuthorityGrab | S::DrcModeExit | S::FlyToPointStop | S::PoiModeExit => {
                json!({})
            }
            S::PayloadAuthorityGrab { payload_index }
            | S::CameraPhotoTake { payload_index }
            | S::CameraPhotoStop { payload_index }
            | S::CameraRecordingStart { payload_index }
            | S::CameraRecordingStop { payload_index } => {
                json!({ "payload_index": payload_index })
            }
            S::DrcModeEnter(d) => drc_mode_enter(d),
            S::TakeoffToPoint(t) => takeoff(t),
            S::FlyToPoint(FlyToPoint {
                fly_to_id,
                max_speed,
                points: p,
            }) => json!({ "fly_to_id": fly_to_id, "max_speed": max_speed, "points": points(p) }),
            S::FlyToPointUpdate(FlyToPointUpdate {
                max_speed,
                points: p,
            }) => json!({ "max_speed": max_speed, "points": points(p) }),
            S::CameraModeSwitch {
                payload_index,
                camera_mode,
            } => json!({ "payload_index": payload_index, "camera_mode": *camera_mode as u8 }),
            S::CameraScreenDrag {
                payload_index,
                locked,
                pitch_speed,
                yaw_speed,
            } => json!({
                "payload_index": payload_index, "locked": locked,
                "pitch_speed": pitch_speed, "yaw_speed": yaw_speed,
            }),
            S::CameraAim {
                payload_index,
                camera_type,
                locked,
                x,
                y,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "locked": locked, "x": x, "y": y,
            }),
            S::CameraFocalLengthSet {
                payload_index,
                camera_type,
                zoom_factor,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "zoom_factor": zoom_factor,
            }),
            S::GimbalReset {
                payload_index,
                reset_mode,
            } => json!({ "payload_index": payload_index, "reset_mode": reset_mode }),
            S::CameraLookAt {
                payload_index,
                locked,
                latitude,
                longitude,
                height,
            } => json!({
                "payload_index": payload_index, "locked": locked,
                "latitude": latitude, "longitude": longitude, "height": height,
            }),
            S::CameraScreenSplit {
                payload_index,
                enable,
            } => json!({ "payload_index": payload_index, "enable": enable }),
            S::PhotoStorageSet {
                payload_index,
                photo_storage_settings,
            } => json!({
                "payload_index": payload_index,
                "photo_storage_settings": lenses(photo_storage_settings),
            }),
            S::VideoStorageSet {
                payload_index,
                video_storage_settings,
            } => json!({
                "payload_index": payload_index,
                "video_storage_settings": lenses(video_storage_settings),
            }),
            S::CameraExposureModeSet {
                payload_index,
                camera_type,
                exposure_mode,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "exposure_mode": exposure_mode,
            }),
            S::CameraExposureSet {
                payload_index,
                camera_type,
                exposure_value,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "exposure_value": exposure_value.to_string(),
            }),
            S::CameraFocusModeSet {
                payload_index,
                camera_type,
                focus_mode,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "focus_mode": focus_mode,
            }),
            S::CameraFocusValueSet {
                payload_index,
                camera_type,
                focus_value,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "focus_value": focus_value,
            }),
            S::CameraPointFocusAction {
                payload_index,
                camera_type,
                x,
                y,
            } => json!({
                "payload_index": payload_index, "camera_type": camera_type.as_str(),
                "x": x, "y": y,
            }),
            S::IrMeteringModeSet {
                payload_index,
                mode,
            } => json!({ "payload_index": payload_index, "mode": mode }),
            S::IrMeteringPointSet {
                payload_index,
                x,
                y,
            } => json!({ "payload_index": payload_index, "x": x, "y": y }),
            S::IrMeteringAreaSet {
                payload_index,
                x,
                y,
                width,
                height,
            } => json!({
                "payload_index": payload_index, "x": x, "y": y,
                "width": width, "height": height,
            }),
            S::PoiModeEnter {
                latitude,
                longitude,
                height,
            } => json!({ "latitude": latitude, "longitude": longitude, "height": height }),
            S::PoiCircleSpeedSet { circle_speed } => json!({ "circle_speed": circle_speed }),
        }
    }
}

impl DrcDown {
    /// This message's `data` as the cloud sends it (`seq` inside `data`).
    pub fn to_data(&self) -> Value {
        match self {
            DrcDown::DroneControl(c) => {
                json!({ "seq": c.seq, "x": c.x, "y": c.y, "h": c.h, "w": c.w })
            }
            DrcDown::DroneEmergencyStop => json!({}),
            DrcDown::HeartBeat { seq, timestamp } => {
                json!({ "seq": seq, "timestamp": timestamp })
            }
        }
    }
}
