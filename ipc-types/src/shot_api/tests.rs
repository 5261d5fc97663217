use proptest::prelude::*;

use super::*;

fn point(status: i16) -> SplinePoint {
    SplinePoint {
        version: 0,
        abs_alt_ref_m: 584.5,
        index: 3,
        lat_deg: -35.36,
        lon_deg: 149.16,
        alt_m: 20.0,
        pitch_deg: -30.0,
        yaw_deg: 90.0,
        u_position: 0.5,
        status,
    }
}

const HERE: Location = Location {
    lat_deg: -35.363261,
    lon_deg: 149.165230,
    alt_m: 20.0,
};

const BUTTON: ButtonSetting = ButtonSetting {
    button: 4,
    event: 0,
    shot: 2,
    mode: -1,
};

fn gopro() -> GoProState {
    GoProState {
        version: 2,
        status: 2,
        recording: 1,
        extra_u8: [1, 2, 3, 4, 5, 6, 7],
        extra_u16: [10, 20, 30, 40, 50],
        ..GoProState::default()
    }
}

/// One of every request.
fn every_request() -> Vec<ShotRequest> {
    use ShotRequest as R;
    vec![
        R::StartShot(shots::ORBIT),
        R::Location(HERE),
        R::RecordPosition,
        R::CableOptions {
            cam_interpolation: 1,
            yaw_direction_cw: 0,
            cruise_speed: -2.5,
        },
        R::GetButtonSetting(BUTTON),
        R::SetButtonSetting(BUTTON),
        R::Pause,
        R::FollowOptions {
            cruise_speed: 3.0,
            look_at: 1,
        },
        R::FollowOptionsV2 {
            cruise_speed: 3.0,
            look_at: 0,
            follow_preference: 2,
        },
        R::ShotOptions { cruise_speed: 4.0 },
        R::GoProSetEnabled(1),
        R::GoProSetRequest {
            command: 5,
            value: 7,
        },
        R::GoProSetExtendedRequest {
            command: 9,
            value: [1, 2, 3, 4],
        },
        R::GoProRecord(2),
        R::GoProRequestState,
        R::SplinePoint(point(0)),
        R::GeofenceUpdatePoly {
            action: 1,
            polygon_index: 2,
            vertex_index: 3,
            lat_deg: -35.1,
            lon_deg: 149.1,
            sub_lat_deg: -35.2,
            sub_lon_deg: 149.2,
        },
        R::GeofenceClear,
        R::SplineRecord,
        R::SplinePlay,
        R::SplineSeek {
            u_position: 0.25,
            cruise_state: -1,
        },
        R::SplinePathSettings {
            camera_control: 1,
            desired_time_s: 30.0,
        },
        R::SplineAttach(4),
        R::ZiplineOptions {
            cruise_speed: 2.0,
            is_3d: 1,
            cam_pointing: 0,
        },
        R::ZiplineLock,
        R::PanoOptions {
            pano_type: 1,
            run_state: 1,
            cylinder_fov: 220,
            deg_second_yaw: 10.0,
            lens_fov: 90.0,
        },
        R::RewindOptions {
            enabled: 1,
            hover: 0,
            rewind_distance: 40.0,
        },
        R::HomeLocation(HERE),
        R::InspectStart {
            takeoff_alt_m: 10.0,
        },
        R::InspectSetWaypoint {
            lat_deg: -35.3,
            lon_deg: 149.1,
            alt_m: 15.0,
        },
        R::InspectMoveGimbal {
            pitch_deg: -45.0,
            roll_deg: 0.0,
            yaw_deg: 10.0,
        },
        R::InspectMoveVehicle {
            vx: 1.0,
            vy: -1.0,
            vz: 0.5,
        },
        R::ScanStart,
        R::SurveyStart,
    ]
}

/// One of every event.
fn every_event() -> Vec<ShotEvent> {
    use ShotEvent as E;
    vec![
        E::CurrentShot(shots::NONE),
        E::Refused(1),
        E::Error("pano is not implemented".into()),
        E::Location(HERE),
        E::HomeLocation(HERE),
        E::ButtonSetting(BUTTON),
        E::Pause,
        E::CableOptions {
            cam_interpolation: 0,
            yaw_direction_cw: 1,
            cruise_speed: 1.5,
        },
        E::FollowOptions {
            cruise_speed: 3.0,
            look_at: 1,
        },
        E::FollowOptionsV2 {
            cruise_speed: 3.0,
            look_at: 1,
            follow_preference: 1,
        },
        E::ShotOptions { cruise_speed: -4.0 },
        E::PanoOptions {
            pano_type: 0,
            run_state: 0,
            cylinder_fov: 90,
            deg_second_yaw: 5.0,
            lens_fov: 120.0,
        },
        E::ZiplineOptions {
            cruise_speed: 2.0,
            is_3d: 0,
            cam_pointing: 1,
        },
        E::RewindOptions {
            enabled: 0,
            hover: 1,
            rewind_distance: 20.0,
        },
        E::PanoState { index: 3, total: 9 },
        E::GoProV1State(GoProState {
            version: 1,
            ..gopro()
        }),
        E::GoProV2State(gopro()),
        E::GeofenceSetAck {
            count: 2,
            valid: true,
        },
        E::GeofenceActivated,
        E::GeofenceClear,
        E::CableCamWaypoint {
            lat_deg: -35.0,
            lon_deg: 149.0,
            alt_m: 12.0,
            yaw_deg: 45.0,
            pitch_deg: -10.0,
        },
        E::SplinePoint(point(-4)),
        E::SplinePlay,
        E::SplinePlaybackStatus {
            u_position: 0.75,
            cruise_state: 1,
        },
        E::SplineDurations {
            min_time_s: 5.0,
            max_time_s: 120.0,
        },
        E::SplineAttach(2),
    ]
}

#[test]
fn every_request_round_trips_with_its_own_kind() {
    let all = every_request();
    let mut kinds = std::collections::HashSet::new();
    let mut names = std::collections::HashSet::new();
    for r in &all {
        let s = ShotRequestSample::new(7, r);
        assert_eq!(s.session, 7);
        assert_eq!(s.request().as_ref(), Ok(r), "{}", r.name());
        assert!(kinds.insert(s.kind), "kind {} reused", s.kind);
        assert!(names.insert(r.name()), "name {} reused", r.name());
    }
    assert_eq!(kinds.len(), 34, "one kind per variant");
}

#[test]
fn every_event_round_trips_with_its_own_kind() {
    let all = every_event();
    let mut kinds = std::collections::HashSet::new();
    let mut names = std::collections::HashSet::new();
    for e in &all {
        let s = ShotEventSample::new(0, e);
        assert_eq!(s.event().as_ref(), Ok(e), "{}", e.name());
        assert!(kinds.insert(s.kind), "kind {} reused", s.kind);
        assert!(names.insert(e.name()), "name {} reused", e.name());
    }
    assert_eq!(kinds.len(), 26, "one kind per variant");
}

#[test]
fn bodies_are_packed_little_endian() {
    let s = ShotRequestSample::new(1, &ShotRequest::StartShot(-1));
    assert_eq!((s.kind, s.len), (1, 4));
    assert_eq!(s.body[..4], (-1i32).to_le_bytes());
    let s = ShotEventSample::new(0, &ShotEvent::SplinePoint(point(0)));
    assert_eq!(s.len, 44, "a keypoint is 44 bytes");
    let s = ShotEventSample::new(0, &ShotEvent::GoProV2State(gopro()));
    assert_eq!(s.len, 36);
}

#[test]
fn error_text_is_cut_to_the_capacity_at_a_character_boundary() {
    let long = "é".repeat(SHOT_BODY_CAPACITY);
    let s = ShotEventSample::new(0, &ShotEvent::Error(long));
    assert_eq!(usize::from(s.len), SHOT_BODY_CAPACITY);
    let ShotEvent::Error(text) = s.event().unwrap() else {
        panic!("not an error")
    };
    assert_eq!(text, "é".repeat(SHOT_BODY_CAPACITY / 2));
}

#[test]
fn bad_bodies_are_refused() {
    let mut s = ShotRequestSample::new(1, &ShotRequest::ShotOptions { cruise_speed: 1.0 });
    s.len = 3;
    assert!(matches!(
        s.request(),
        Err(ShotDecodeError::WrongLength { .. })
    ));
    s.len = 5;
    assert!(matches!(
        s.request(),
        Err(ShotDecodeError::WrongLength { .. })
    ));
    s.len = u16::MAX;
    assert!(s.request().is_err(), "a forged length is refused");
    let mut s = ShotRequestSample::new(1, &ShotRequest::ShotOptions { cruise_speed: 1.0 });
    s.body[..4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(matches!(s.request(), Err(ShotDecodeError::Invalid(_))));
    let s = ShotRequestSample::new(
        1,
        &ShotRequest::Location(Location {
            lat_deg: 91.0,
            ..HERE
        }),
    );
    assert!(matches!(s.request(), Err(ShotDecodeError::Invalid(_))));
    let s = ShotRequestSample {
        kind: 999,
        ..Default::default()
    };
    assert_eq!(s.request(), Err(ShotDecodeError::UnknownKind(999)));
    assert_eq!(
        ShotEventSample::default().event(),
        Err(ShotDecodeError::UnknownKind(0))
    );
}

#[test]
fn locations_validate_like_the_decoder() {
    assert!(HERE.validate().is_ok());
    assert!(Location {
        lon_deg: 180.5,
        ..HERE
    }
    .validate()
    .is_err());
    assert!(Location {
        alt_m: f32::INFINITY,
        ..HERE
    }
    .validate()
    .is_err());
}

#[test]
fn shot_names_cover_the_numbering() {
    for s in shots::MIN..=shots::MAX {
        assert!(shots::name(s).is_some());
    }
    assert_eq!(shots::name(shots::MAX + 1), None);
}

proptest! {
    #[test]
    fn any_body_decodes_or_is_refused(kind in 0u16..40, len in 0u16..300, fill: u8) {
        let r = ShotRequestSample { kind, len, body: [fill; SHOT_BODY_CAPACITY], ..Default::default() };
        let _ = r.request();
        let e = ShotEventSample { kind, len, body: [fill; SHOT_BODY_CAPACITY], ..Default::default() };
        let _ = e.event();
    }

    #[test]
    fn keypoints_round_trip(
        lat in -90.0f64..=90.0, lon in -180.0f64..=180.0, alt in -1e4f32..1e4,
        index: i32, status: i16, u in 0.0f32..1.0,
    ) {
        let p = SplinePoint { lat_deg: lat, lon_deg: lon, alt_m: alt, index, status, u_position: u, ..point(0) };
        let s = ShotRequestSample::new(1, &ShotRequest::SplinePoint(p));
        prop_assert_eq!(s.request(), Ok(ShotRequest::SplinePoint(p)));
        let s = ShotEventSample::new(1, &ShotEvent::SplinePoint(p));
        prop_assert_eq!(s.event(), Ok(ShotEvent::SplinePoint(p)));
    }

    #[test]
    fn error_text_round_trips(text in "\\PC{0,60}") {
        let s = ShotEventSample::new(0, &ShotEvent::Error(text.clone()));
        prop_assert_eq!(s.event(), Ok(ShotEvent::Error(text)));
    }
}
