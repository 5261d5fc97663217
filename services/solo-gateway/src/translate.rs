//! Solo app messages ↔ the shot engine's protocol-neutral requests and events
//! (pure). The engine knows no Solo id or byte: this is where the Solo app
//! protocol's vocabulary meets the engine's, one message for one request or event.
//! Shot indices pass through unchanged (the bus numbers shots as Solo does).
//!
//! Where both sides carry the same fields under the same names, the pairing is
//! listed once (`Solo = Engine { fields };` in `shot_options!`, `request_fields!`,
//! `event_fields!`) and `to_engine!` / `to_solo!` write the `match` arms of
//! either direction from it; the arms that differ are written out by hand.

use skymesh_ipc_types::shot_api as api;
use skymesh_ipc_types::{ShotEvent, ShotRequest};
use solo_proto::SoloMessage;

/// `fn name(&From) -> To`, copying the listed fields by name.
macro_rules! copy_fields {
    (fn $name:ident(&$From:path) -> $To:path { $($f:ident),* $(,)? }) => {
        fn $name(v: &$From) -> $To {
            $To { $($f: v.$f),* }
        }
    };
}

/// Both directions between a Solo struct and its engine twin.
macro_rules! twin_structs {
    ($to_api:ident, $to_solo:ident: $Solo:path, $Api:path { $($f:ident),* $(,)? }) => {
        copy_fields!(fn $to_api(&$Solo) -> $Api { $($f),* });
        copy_fields!(fn $to_solo(&$Api) -> $Solo { $($f),* });
    };
}

twin_structs!(location, solo_location: solo_proto::Location, api::Location {
    lat_deg, lon_deg, alt_m
});

twin_structs!(button, solo_button: solo_proto::ButtonSetting, api::ButtonSetting {
    button, event, shot, mode
});

twin_structs!(point, solo_point: solo_proto::SplinePoint, api::SplinePoint {
    version, abs_alt_ref_m, index, lat_deg, lon_deg, alt_m, pitch_deg, yaw_deg, u_position,
    status
});

copy_fields!(fn solo_gopro(&api::GoProState) -> solo_proto::GoProState {
    version, model, status, recording, capture_mode, ntsc_pal, video_resolution, video_fps,
    video_fov, video_low_light, photo_resolution, photo_burst_rate, video_protune,
    video_white_balance, video_color, video_gain, video_sharpness, video_exposure,
    gimbal_enabled, extra_u8, extra_u16
});

/// The shot options, which travel both ways: the app sets them (requests) and
/// the engine reports them (events). `list!(then!(args))` calls `then!` with the
/// list appended to `args` (lists chain: `a!(b!(then!(args)))`).
macro_rules! shot_options {
    ($then:ident!($($args:tt)*) $($more:tt)*) => {
        $then!($($args)* $($more)*
            CableCamOptions = CableOptions { cam_interpolation, yaw_direction_cw, cruise_speed };
            FollowOptions = FollowOptions { cruise_speed, look_at };
            FollowOptionsV2 = FollowOptionsV2 { cruise_speed, look_at, follow_preference };
            ShotOptions = ShotOptions { cruise_speed };
            ZiplineOptions = ZiplineOptions { cruise_speed, is_3d, cam_pointing };
            PanoOptions = PanoOptions {
                pano_type, run_state, cylinder_fov, deg_second_yaw, lens_fov
            };
            RewindOptions = RewindOptions { enabled, hover, rewind_distance };
        )
    };
}

/// What only the app asks, with the same fields on both sides.
macro_rules! request_fields {
    ($then:ident!($($args:tt)*) $($more:tt)*) => {
        $then!($($args)* $($more)*
            GoProSetRequest = GoProSetRequest { command, value };
            GoProSetExtendedRequest = GoProSetExtendedRequest { command, value };
            GeofenceUpdatePoly = GeofenceUpdatePoly {
                action, polygon_index, vertex_index, lat_deg, lon_deg, sub_lat_deg, sub_lon_deg
            };
            SplineSeek = SplineSeek { u_position, cruise_state };
            SplinePathSettings = SplinePathSettings { camera_control, desired_time_s };
            InspectStart = InspectStart { takeoff_alt_m };
            InspectSetWaypoint = InspectSetWaypoint { lat_deg, lon_deg, alt_m };
            InspectMoveGimbal = InspectMoveGimbal { pitch_deg, roll_deg, yaw_deg };
            InspectMoveVehicle = InspectMoveVehicle { vx, vy, vz };
        )
    };
}

/// What only the engine tells, with the same fields on both sides.
macro_rules! event_fields {
    ($then:ident!($($args:tt)*) $($more:tt)*) => {
        $then!($($args)* $($more)*
            PanoState = PanoState { index, total };
            GeofenceSetAck = GeofenceSetAck { count, valid };
            CableCamWaypoint = CableCamWaypoint { lat_deg, lon_deg, alt_m, yaw_deg, pitch_deg };
            SplinePlaybackStatus = SplinePlaybackStatus { u_position, cruise_state };
            SplineDurations = SplineDurations { min_time_s, max_time_s };
        )
    };
}

/// `match msg { listed Solo variants => the engine's, hand arms }`.
macro_rules! to_engine {
    ($msg:expr => $To:ident { $($arms:tt)* }
     $($solo:ident = $eng:ident { $($f:ident),* $(,)? };)*) => {
        match $msg {
            $(SoloMessage::$solo { $($f),* } => $To::$eng { $($f: *$f),* },)*
            $($arms)*
        }
    };
}

/// `match value { listed engine variants => the Solo ones, hand arms }`.
macro_rules! to_solo {
    ($value:expr => $From:ident { $($arms:tt)* }
     $($solo:ident = $eng:ident { $($f:ident),* $(,)? };)*) => {
        match $value {
            $($From::$eng { $($f),* } => SoloMessage::$solo { $($f: *$f),* },)*
            $($arms)*
        }
    };
}

/// The engine's request for a message the app sent; `None` for what the app does
/// not send to the engine (the vehicle's own messages, which [`crate::inbound`]
/// drops as wrong-direction, and GEOFENCE_SET_DATA, which travels as an
/// `AppGeofence`).
pub fn request(msg: &SoloMessage) -> Option<ShotRequest> {
    use ShotRequest as R;
    use SoloMessage as M;
    Some(shot_options!(request_fields!(to_engine!(msg => R {
        M::SetCurrentShot(shot) => R::StartShot(*shot),
        M::Location(l) => R::Location(location(l)),
        M::RecordPosition => R::RecordPosition,
        M::GetButtonSetting(b) => R::GetButtonSetting(button(b)),
        M::SetButtonSetting(b) => R::SetButtonSetting(button(b)),
        M::Pause => R::Pause,
        M::GoProSetEnabled(v) => R::GoProSetEnabled(*v),
        M::GoProRecord(v) => R::GoProRecord(*v),
        M::GoProRequestState => R::GoProRequestState,
        M::SplinePoint(p) => R::SplinePoint(point(p)),
        M::GeofenceClear => R::GeofenceClear,
        M::SplineRecord => R::SplineRecord,
        M::SplinePlay => R::SplinePlay,
        M::SplineAttach(i) => R::SplineAttach(*i),
        M::ZiplineLock => R::ZiplineLock,
        M::HomeLocation(l) => R::HomeLocation(location(l)),
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
    }))))
}

/// The Solo message that carries `request`: the inverse of [`request`], for tools
/// and tests that stand where the engine stands and read what the app asked.
pub fn solo_request(request: &ShotRequest) -> SoloMessage {
    use ShotRequest as R;
    use SoloMessage as M;
    shot_options!(request_fields!(to_solo!(request => R {
        R::StartShot(shot) => M::SetCurrentShot(*shot),
        R::Location(l) => M::Location(solo_location(l)),
        R::RecordPosition => M::RecordPosition,
        R::GetButtonSetting(b) => M::GetButtonSetting(solo_button(b)),
        R::SetButtonSetting(b) => M::SetButtonSetting(solo_button(b)),
        R::Pause => M::Pause,
        R::GoProSetEnabled(v) => M::GoProSetEnabled(*v),
        R::GoProRecord(v) => M::GoProRecord(*v),
        R::GoProRequestState => M::GoProRequestState,
        R::SplinePoint(p) => M::SplinePoint(solo_point(p)),
        R::GeofenceClear => M::GeofenceClear,
        R::SplineRecord => M::SplineRecord,
        R::SplinePlay => M::SplinePlay,
        R::SplineAttach(i) => M::SplineAttach(*i),
        R::ZiplineLock => M::ZiplineLock,
        R::HomeLocation(l) => M::HomeLocation(solo_location(l)),
        R::ScanStart => M::ScanStart,
        R::SurveyStart => M::SurveyStart,
    })))
}

/// The Solo message that tells the app an engine event.
pub fn event(ev: &ShotEvent) -> SoloMessage {
    use ShotEvent as E;
    use SoloMessage as M;
    shot_options!(event_fields!(to_solo!(ev => E {
        E::CurrentShot(shot) => M::GetCurrentShot(*shot),
        E::Refused(code) => M::ShotError(*code),
        E::Error(text) => M::ShotManagerError(text.clone()),
        E::Location(l) => M::Location(solo_location(l)),
        E::HomeLocation(l) => M::HomeLocation(solo_location(l)),
        E::ButtonSetting(b) => M::GetButtonSetting(solo_button(b)),
        E::Pause => M::Pause,
        E::GoProV1State(s) => M::GoProV1State(solo_gopro(s)),
        E::GoProV2State(s) => M::GoProV2State(solo_gopro(s)),
        E::GeofenceActivated => M::GeofenceActivated,
        E::GeofenceClear => M::GeofenceClear,
        E::SplinePoint(p) => M::SplinePoint(solo_point(p)),
        E::SplinePlay => M::SplinePlay,
        E::SplineAttach(i) => M::SplineAttach(*i),
    })))
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
