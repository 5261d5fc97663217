//! Solo app messages ↔ the shot engine's protocol-neutral requests and events
//! (pure). The engine knows no Solo id or byte: this is where the Solo app
//! protocol's vocabulary meets the engine's, one message for one request or event.
//! Shot indices pass through unchanged (the bus numbers shots as Solo does).

use skymesh_ipc_types::shot_api as api;
use skymesh_ipc_types::{ShotEvent, ShotRequest};
use solo_proto::SoloMessage;

fn location(l: &solo_proto::Location) -> api::Location {
    api::Location {
        lat_deg: l.lat_deg,
        lon_deg: l.lon_deg,
        alt_m: l.alt_m,
    }
}

fn solo_location(l: &api::Location) -> solo_proto::Location {
    solo_proto::Location {
        lat_deg: l.lat_deg,
        lon_deg: l.lon_deg,
        alt_m: l.alt_m,
    }
}

fn button(b: &solo_proto::ButtonSetting) -> api::ButtonSetting {
    api::ButtonSetting {
        button: b.button,
        event: b.event,
        shot: b.shot,
        mode: b.mode,
    }
}

fn solo_button(b: &api::ButtonSetting) -> solo_proto::ButtonSetting {
    solo_proto::ButtonSetting {
        button: b.button,
        event: b.event,
        shot: b.shot,
        mode: b.mode,
    }
}

fn point(p: &solo_proto::SplinePoint) -> api::SplinePoint {
    api::SplinePoint {
        version: p.version,
        abs_alt_ref_m: p.abs_alt_ref_m,
        index: p.index,
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_m: p.alt_m,
        pitch_deg: p.pitch_deg,
        yaw_deg: p.yaw_deg,
        u_position: p.u_position,
        status: p.status,
    }
}

fn solo_point(p: &api::SplinePoint) -> solo_proto::SplinePoint {
    solo_proto::SplinePoint {
        version: p.version,
        abs_alt_ref_m: p.abs_alt_ref_m,
        index: p.index,
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
        alt_m: p.alt_m,
        pitch_deg: p.pitch_deg,
        yaw_deg: p.yaw_deg,
        u_position: p.u_position,
        status: p.status,
    }
}

fn solo_gopro(s: &api::GoProState) -> solo_proto::GoProState {
    solo_proto::GoProState {
        version: s.version,
        model: s.model,
        status: s.status,
        recording: s.recording,
        capture_mode: s.capture_mode,
        ntsc_pal: s.ntsc_pal,
        video_resolution: s.video_resolution,
        video_fps: s.video_fps,
        video_fov: s.video_fov,
        video_low_light: s.video_low_light,
        photo_resolution: s.photo_resolution,
        photo_burst_rate: s.photo_burst_rate,
        video_protune: s.video_protune,
        video_white_balance: s.video_white_balance,
        video_color: s.video_color,
        video_gain: s.video_gain,
        video_sharpness: s.video_sharpness,
        video_exposure: s.video_exposure,
        gimbal_enabled: s.gimbal_enabled,
        extra_u8: s.extra_u8,
        extra_u16: s.extra_u16,
    }
}

/// The engine's request for a message the app sent; `None` for what the app does
/// not send to the engine (the vehicle's own messages, which [`crate::inbound`]
/// drops as wrong-direction, and GEOFENCE_SET_DATA, which travels as an
/// `AppGeofence`).
pub fn request(msg: &SoloMessage) -> Option<ShotRequest> {
    use ShotRequest as R;
    use SoloMessage as M;
    Some(match msg {
        M::SetCurrentShot(shot) => R::StartShot(*shot),
        M::Location(l) => R::Location(location(l)),
        M::RecordPosition => R::RecordPosition,
        M::CableCamOptions {
            cam_interpolation,
            yaw_direction_cw,
            cruise_speed,
        } => R::CableOptions {
            cam_interpolation: *cam_interpolation,
            yaw_direction_cw: *yaw_direction_cw,
            cruise_speed: *cruise_speed,
        },
        M::GetButtonSetting(b) => R::GetButtonSetting(button(b)),
        M::SetButtonSetting(b) => R::SetButtonSetting(button(b)),
        M::Pause => R::Pause,
        M::FollowOptions {
            cruise_speed,
            look_at,
        } => R::FollowOptions {
            cruise_speed: *cruise_speed,
            look_at: *look_at,
        },
        M::FollowOptionsV2 {
            cruise_speed,
            look_at,
            follow_preference,
        } => R::FollowOptionsV2 {
            cruise_speed: *cruise_speed,
            look_at: *look_at,
            follow_preference: *follow_preference,
        },
        M::ShotOptions { cruise_speed } => R::ShotOptions {
            cruise_speed: *cruise_speed,
        },
        M::GoProSetEnabled(v) => R::GoProSetEnabled(*v),
        M::GoProSetRequest { command, value } => R::GoProSetRequest {
            command: *command,
            value: *value,
        },
        M::GoProSetExtendedRequest { command, value } => R::GoProSetExtendedRequest {
            command: *command,
            value: *value,
        },
        M::GoProRecord(v) => R::GoProRecord(*v),
        M::GoProRequestState => R::GoProRequestState,
        M::SplinePoint(p) => R::SplinePoint(point(p)),
        M::GeofenceUpdatePoly {
            action,
            polygon_index,
            vertex_index,
            lat_deg,
            lon_deg,
            sub_lat_deg,
            sub_lon_deg,
        } => R::GeofenceUpdatePoly {
            action: *action,
            polygon_index: *polygon_index,
            vertex_index: *vertex_index,
            lat_deg: *lat_deg,
            lon_deg: *lon_deg,
            sub_lat_deg: *sub_lat_deg,
            sub_lon_deg: *sub_lon_deg,
        },
        M::GeofenceClear => R::GeofenceClear,
        M::SplineRecord => R::SplineRecord,
        M::SplinePlay => R::SplinePlay,
        M::SplineSeek {
            u_position,
            cruise_state,
        } => R::SplineSeek {
            u_position: *u_position,
            cruise_state: *cruise_state,
        },
        M::SplinePathSettings {
            camera_control,
            desired_time_s,
        } => R::SplinePathSettings {
            camera_control: *camera_control,
            desired_time_s: *desired_time_s,
        },
        M::SplineAttach(i) => R::SplineAttach(*i),
        M::ZiplineOptions {
            cruise_speed,
            is_3d,
            cam_pointing,
        } => R::ZiplineOptions {
            cruise_speed: *cruise_speed,
            is_3d: *is_3d,
            cam_pointing: *cam_pointing,
        },
        M::ZiplineLock => R::ZiplineLock,
        M::PanoOptions {
            pano_type,
            run_state,
            cylinder_fov,
            deg_second_yaw,
            lens_fov,
        } => R::PanoOptions {
            pano_type: *pano_type,
            run_state: *run_state,
            cylinder_fov: *cylinder_fov,
            deg_second_yaw: *deg_second_yaw,
            lens_fov: *lens_fov,
        },
        M::RewindOptions {
            enabled,
            hover,
            rewind_distance,
        } => R::RewindOptions {
            enabled: *enabled,
            hover: *hover,
            rewind_distance: *rewind_distance,
        },
        M::HomeLocation(l) => R::HomeLocation(location(l)),
        M::InspectStart { takeoff_alt_m } => R::InspectStart {
            takeoff_alt_m: *takeoff_alt_m,
        },
        M::InspectSetWaypoint {
            lat_deg,
            lon_deg,
            alt_m,
        } => R::InspectSetWaypoint {
            lat_deg: *lat_deg,
            lon_deg: *lon_deg,
            alt_m: *alt_m,
        },
        M::InspectMoveGimbal {
            pitch_deg,
            roll_deg,
            yaw_deg,
        } => R::InspectMoveGimbal {
            pitch_deg: *pitch_deg,
            roll_deg: *roll_deg,
            yaw_deg: *yaw_deg,
        },
        M::InspectMoveVehicle { vx, vy, vz } => R::InspectMoveVehicle {
            vx: *vx,
            vy: *vy,
            vz: *vz,
        },
        M::ScanStart => R::ScanStart,
        M::SurveyStart => R::SurveyStart,
        M::GeofenceSetData(_)
        | M::GetCurrentShot(_)
        | M::ShotError(_)
        | M::ShotManagerError(_)
        | M::CableCamWaypoint { .. }
        | M::SecondPhoneNotification
        | M::GeofenceSetAck { .. }
        | M::GeofenceActivated
        | M::GoProV1State(_)
        | M::GoProV2State(_)
        | M::GoProPhoto { .. }
        | M::PanoState { .. }
        | M::SplinePlaybackStatus { .. }
        | M::SplineDurations { .. } => return None,
    })
}

/// The Solo message that carries `request`: the inverse of [`request`], for tools
/// and tests that stand where the engine stands and read what the app asked.
pub fn solo_request(request: &ShotRequest) -> SoloMessage {
    use ShotRequest as R;
    use SoloMessage as M;
    match request {
        R::StartShot(shot) => M::SetCurrentShot(*shot),
        R::Location(l) => M::Location(solo_location(l)),
        R::RecordPosition => M::RecordPosition,
        R::CableOptions {
            cam_interpolation,
            yaw_direction_cw,
            cruise_speed,
        } => M::CableCamOptions {
            cam_interpolation: *cam_interpolation,
            yaw_direction_cw: *yaw_direction_cw,
            cruise_speed: *cruise_speed,
        },
        R::GetButtonSetting(b) => M::GetButtonSetting(solo_button(b)),
        R::SetButtonSetting(b) => M::SetButtonSetting(solo_button(b)),
        R::Pause => M::Pause,
        R::FollowOptions {
            cruise_speed,
            look_at,
        } => M::FollowOptions {
            cruise_speed: *cruise_speed,
            look_at: *look_at,
        },
        R::FollowOptionsV2 {
            cruise_speed,
            look_at,
            follow_preference,
        } => M::FollowOptionsV2 {
            cruise_speed: *cruise_speed,
            look_at: *look_at,
            follow_preference: *follow_preference,
        },
        R::ShotOptions { cruise_speed } => M::ShotOptions {
            cruise_speed: *cruise_speed,
        },
        R::GoProSetEnabled(v) => M::GoProSetEnabled(*v),
        R::GoProSetRequest { command, value } => M::GoProSetRequest {
            command: *command,
            value: *value,
        },
        R::GoProSetExtendedRequest { command, value } => M::GoProSetExtendedRequest {
            command: *command,
            value: *value,
        },
        R::GoProRecord(v) => M::GoProRecord(*v),
        R::GoProRequestState => M::GoProRequestState,
        R::SplinePoint(p) => M::SplinePoint(solo_point(p)),
        R::GeofenceUpdatePoly {
            action,
            polygon_index,
            vertex_index,
            lat_deg,
            lon_deg,
            sub_lat_deg,
            sub_lon_deg,
        } => M::GeofenceUpdatePoly {
            action: *action,
            polygon_index: *polygon_index,
            vertex_index: *vertex_index,
            lat_deg: *lat_deg,
            lon_deg: *lon_deg,
            sub_lat_deg: *sub_lat_deg,
            sub_lon_deg: *sub_lon_deg,
        },
        R::GeofenceClear => M::GeofenceClear,
        R::SplineRecord => M::SplineRecord,
        R::SplinePlay => M::SplinePlay,
        R::SplineSeek {
            u_position,
            cruise_state,
        } => M::SplineSeek {
            u_position: *u_position,
            cruise_state: *cruise_state,
        },
        R::SplinePathSettings {
            camera_control,
            desired_time_s,
        } => M::SplinePathSettings {
            camera_control: *camera_control,
            desired_time_s: *desired_time_s,
        },
        R::SplineAttach(i) => M::SplineAttach(*i),
        R::ZiplineOptions {
            cruise_speed,
            is_3d,
            cam_pointing,
        } => M::ZiplineOptions {
            cruise_speed: *cruise_speed,
            is_3d: *is_3d,
            cam_pointing: *cam_pointing,
        },
        R::ZiplineLock => M::ZiplineLock,
        R::PanoOptions {
            pano_type,
            run_state,
            cylinder_fov,
            deg_second_yaw,
            lens_fov,
        } => M::PanoOptions {
            pano_type: *pano_type,
            run_state: *run_state,
            cylinder_fov: *cylinder_fov,
            deg_second_yaw: *deg_second_yaw,
            lens_fov: *lens_fov,
        },
        R::RewindOptions {
            enabled,
            hover,
            rewind_distance,
        } => M::RewindOptions {
            enabled: *enabled,
            hover: *hover,
            rewind_distance: *rewind_distance,
        },
        R::HomeLocation(l) => M::HomeLocation(solo_location(l)),
        R::InspectStart { takeoff_alt_m } => M::InspectStart {
            takeoff_alt_m: *takeoff_alt_m,
        },
        R::InspectSetWaypoint {
            lat_deg,
            lon_deg,
            alt_m,
        } => M::InspectSetWaypoint {
            lat_deg: *lat_deg,
            lon_deg: *lon_deg,
            alt_m: *alt_m,
        },
        R::InspectMoveGimbal {
            pitch_deg,
            roll_deg,
            yaw_deg,
        } => M::InspectMoveGimbal {
            pitch_deg: *pitch_deg,
            roll_deg: *roll_deg,
            yaw_deg: *yaw_deg,
        },
        R::InspectMoveVehicle { vx, vy, vz } => M::InspectMoveVehicle {
            vx: *vx,
            vy: *vy,
            vz: *vz,
        },
        R::ScanStart => M::ScanStart,
        R::SurveyStart => M::SurveyStart,
    }
}

/// The Solo message that tells the app an engine event.
pub fn event(ev: &ShotEvent) -> SoloMessage {
    use ShotEvent as E;
    use SoloMessage as M;
    match ev {
        E::CurrentShot(shot) => M::GetCurrentShot(*shot),
        E::Refused(code) => M::ShotError(*code),
        E::Error(text) => M::ShotManagerError(text.clone()),
        E::Location(l) => M::Location(solo_location(l)),
        E::HomeLocation(l) => M::HomeLocation(solo_location(l)),
        E::ButtonSetting(b) => M::GetButtonSetting(solo_button(b)),
        E::Pause => M::Pause,
        E::CableOptions {
            cam_interpolation,
            yaw_direction_cw,
            cruise_speed,
        } => M::CableCamOptions {
            cam_interpolation: *cam_interpolation,
            yaw_direction_cw: *yaw_direction_cw,
            cruise_speed: *cruise_speed,
        },
        E::FollowOptions {
            cruise_speed,
            look_at,
        } => M::FollowOptions {
            cruise_speed: *cruise_speed,
            look_at: *look_at,
        },
        E::FollowOptionsV2 {
            cruise_speed,
            look_at,
            follow_preference,
        } => M::FollowOptionsV2 {
            cruise_speed: *cruise_speed,
            look_at: *look_at,
            follow_preference: *follow_preference,
        },
        E::ShotOptions { cruise_speed } => M::ShotOptions {
            cruise_speed: *cruise_speed,
        },
        E::PanoOptions {
            pano_type,
            run_state,
            cylinder_fov,
            deg_second_yaw,
            lens_fov,
        } => M::PanoOptions {
            pano_type: *pano_type,
            run_state: *run_state,
            cylinder_fov: *cylinder_fov,
            deg_second_yaw: *deg_second_yaw,
            lens_fov: *lens_fov,
        },
        E::ZiplineOptions {
            cruise_speed,
            is_3d,
            cam_pointing,
        } => M::ZiplineOptions {
            cruise_speed: *cruise_speed,
            is_3d: *is_3d,
            cam_pointing: *cam_pointing,
        },
        E::RewindOptions {
            enabled,
            hover,
            rewind_distance,
        } => M::RewindOptions {
            enabled: *enabled,
            hover: *hover,
            rewind_distance: *rewind_distance,
        },
        E::PanoState { index, total } => M::PanoState {
            index: *index,
            total: *total,
        },
        E::GoProV1State(s) => M::GoProV1State(solo_gopro(s)),
        E::GoProV2State(s) => M::GoProV2State(solo_gopro(s)),
        E::GeofenceSetAck { count, valid } => M::GeofenceSetAck {
            count: *count,
            valid: *valid,
        },
        E::GeofenceActivated => M::GeofenceActivated,
        E::GeofenceClear => M::GeofenceClear,
        E::CableCamWaypoint {
            lat_deg,
            lon_deg,
            alt_m,
            yaw_deg,
            pitch_deg,
        } => M::CableCamWaypoint {
            lat_deg: *lat_deg,
            lon_deg: *lon_deg,
            alt_m: *alt_m,
            yaw_deg: *yaw_deg,
            pitch_deg: *pitch_deg,
        },
        E::SplinePoint(p) => M::SplinePoint(solo_point(p)),
        E::SplinePlay => M::SplinePlay,
        E::SplinePlaybackStatus {
            u_position,
            cruise_state,
        } => M::SplinePlaybackStatus {
            u_position: *u_position,
            cruise_state: *cruise_state,
        },
        E::SplineDurations {
            min_time_s,
            max_time_s,
        } => M::SplineDurations {
            min_time_s: *min_time_s,
            max_time_s: *max_time_s,
        },
        E::SplineAttach(i) => M::SplineAttach(*i),
    }
}

#[cfg(test)]
mod tests {
    use bytes::BytesMut;
    use solo_proto::ids;

    use super::*;

    /// App messages become requests that survive the bus (that every type the
    /// app may send has one is the exhaustive match's job).
    #[test]
    fn every_app_message_has_a_request() {
        let samples = [
            SoloMessage::SetCurrentShot(1),
            SoloMessage::Location(solo_proto::Location {
                lat_deg: -35.36,
                lon_deg: 149.16,
                alt_m: 20.0,
            }),
            SoloMessage::RecordPosition,
            SoloMessage::CableCamOptions {
                cam_interpolation: 1,
                yaw_direction_cw: 0,
                cruise_speed: 2.0,
            },
            SoloMessage::Pause,
            SoloMessage::ShotOptions { cruise_speed: -3.0 },
            SoloMessage::GoProSetExtendedRequest {
                command: 5,
                value: [1, 2, 3, 4],
            },
            SoloMessage::SplineSeek {
                u_position: 0.5,
                cruise_state: -1,
            },
            SoloMessage::PanoOptions {
                pano_type: 1,
                run_state: 0,
                cylinder_fov: 180,
                deg_second_yaw: 10.0,
                lens_fov: 90.0,
            },
            SoloMessage::InspectMoveVehicle {
                vx: 1.0,
                vy: 0.0,
                vz: -0.5,
            },
            SoloMessage::SurveyStart,
        ];
        for m in &samples {
            let r = request(m).unwrap_or_else(|| panic!("{} has no request", m.name()));
            let s = skymesh_ipc_types::ShotRequestSample::new(1, &r);
            assert_eq!(s.request().as_ref(), Ok(&r));
            assert_eq!(&solo_request(&r), m, "back to the same Solo message");
        }
    }

    #[test]
    fn the_vehicles_own_messages_are_not_requests() {
        assert_eq!(request(&SoloMessage::GetCurrentShot(1)), None);
        assert_eq!(request(&SoloMessage::ShotManagerError("x".into())), None);
    }

    #[test]
    fn events_become_valid_solo_messages() {
        let events = [
            ShotEvent::CurrentShot(-1),
            ShotEvent::Refused(1),
            ShotEvent::Error("pano is not implemented".into()),
            ShotEvent::ButtonSetting(api::ButtonSetting {
                button: 4,
                event: 0,
                shot: 2,
                mode: -1,
            }),
            ShotEvent::GeofenceSetAck {
                count: 1,
                valid: true,
            },
            ShotEvent::GoProV2State(api::GoProState::default()),
            ShotEvent::SplineDurations {
                min_time_s: 1.0,
                max_time_s: 9.0,
            },
        ];
        let expected = [
            ids::GET_CURRENT_SHOT,
            ids::SHOT_ERROR,
            ids::SHOTMANAGER_ERROR,
            ids::GET_BUTTON_SETTING,
            ids::GEOFENCE_SET_ACK,
            ids::GOPRO_V2_STATE,
            ids::SPLINE_DURATIONS,
        ];
        for (e, id) in events.iter().zip(expected) {
            let m = event(e);
            assert_eq!(m.msg_type(), id, "{}", e.name());
            assert!(m.validate().is_ok(), "{}", e.name());
            let mut value = BytesMut::new();
            m.encode_value(&mut value);
            assert_eq!(SoloMessage::decode(id, &value).unwrap(), m);
        }
    }

    #[test]
    fn requests_and_events_keep_the_solo_fields() {
        let p = solo_proto::SplinePoint {
            version: 0,
            abs_alt_ref_m: 584.0,
            index: 2,
            lat_deg: -35.3,
            lon_deg: 149.1,
            alt_m: 12.0,
            pitch_deg: -20.0,
            yaw_deg: 45.0,
            u_position: 0.3,
            status: 0,
        };
        let Some(ShotRequest::SplinePoint(neutral)) = request(&SoloMessage::SplinePoint(p)) else {
            panic!("a keypoint request")
        };
        assert_eq!(
            event(&ShotEvent::SplinePoint(neutral)),
            SoloMessage::SplinePoint(p)
        );
    }
}
