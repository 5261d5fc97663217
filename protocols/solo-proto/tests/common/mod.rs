//! Shared by the integration tests: one sample of every message, and proptest
//! strategies producing random *valid* messages of every type.
#![allow(dead_code)]

use proptest::prelude::*;
use solo_proto::{ButtonSetting, GeofenceData, GoProState, Location, SoloMessage, SplinePoint};

pub fn location() -> Location {
    Location {
        lat_deg: 37.87339177880246,
        lon_deg: -122.30124440324217,
        alt_m: 25.5,
    }
}

pub fn gopro_state() -> GoProState {
    GoProState {
        version: 2,
        status: 2,
        recording: 1,
        capture_mode: 1,
        video_resolution: 9,
        video_fps: 5,
        gimbal_enabled: 1,
        extra_u8: [1, 2, 3, 4, 5, 6, 7],
        extra_u16: [0x0102, 0, 0xFFFF, 7, 8],
        ..GoProState::default()
    }
}

pub fn spline_point() -> SplinePoint {
    SplinePoint {
        version: 0,
        abs_alt_ref_m: 102.25,
        index: 3,
        lat_deg: -33.5,
        lon_deg: 151.25,
        alt_m: 30.0,
        pitch_deg: -45.0,
        yaw_deg: 270.0,
        u_position: 0.75,
        status: -2,
    }
}

pub fn geofence() -> GeofenceData {
    GeofenceData {
        coord: vec![vec![
            [37.87339177880246, -122.30124440324217],
            [37.87342546926219, -122.30088420379124],
            [37.87289578293214, -122.30071240112851],
        ]],
        sub_coord: vec![vec![
            [37.87340577718139, -122.30090131123818],
            [37.872916521332435, -122.30074261865762],
            [37.87295869506369, -122.3012216429134],
        ]],
        kinds: vec![0],
    }
}

/// One valid message of every type (48), in catalog order.
pub fn samples() -> Vec<SoloMessage> {
    use SoloMessage as M;
    let button = ButtonSetting {
        button: 4,
        event: 0,
        shot: 1,
        mode: -1,
    };
    vec![
        M::GetCurrentShot(-1),
        M::SetCurrentShot(5),
        M::Location(location()),
        M::RecordPosition,
        M::CableCamOptions {
            cam_interpolation: 1,
            yaw_direction_cw: 0,
            cruise_speed: -4.5,
        },
        M::GetButtonSetting(button),
        M::SetButtonSetting(ButtonSetting {
            button: 5,
            event: 0,
            shot: -1,
            mode: 5,
        }),
        M::Pause,
        M::FollowOptions {
            cruise_speed: 3.0,
            look_at: 1,
        },
        M::FollowOptionsV2 {
            cruise_speed: 3.0,
            look_at: 0,
            follow_preference: 2,
        },
        M::ShotOptions { cruise_speed: -2.5 },
        M::ShotError(1),
        M::PanoOptions {
            pano_type: 0,
            run_state: 1,
            cylinder_fov: 220,
            deg_second_yaw: 2.0,
            lens_fov: 160.0,
        },
        M::ZiplineOptions {
            cruise_speed: 6.0,
            is_3d: 1,
            cam_pointing: 0,
        },
        M::RewindOptions {
            enabled: 1,
            hover: 0,
            rewind_distance: 20.0,
        },
        M::PanoState {
            index: 3,
            total: 11,
        },
        M::HomeLocation(Location {
            lat_deg: -35.363261,
            lon_deg: 149.16523,
            alt_m: 584.0,
        }),
        M::ZiplineLock,
        M::SplineRecord,
        M::SplinePlay,
        M::SplinePoint(spline_point()),
        M::SplineSeek {
            u_position: 0.5,
            cruise_state: -1,
        },
        M::SplinePlaybackStatus {
            u_position: 0.25,
            cruise_state: 1,
        },
        M::SplinePathSettings {
            camera_control: 1,
            desired_time_s: 42.0,
        },
        M::SplineDurations {
            min_time_s: 12.5,
            max_time_s: 1200.0,
        },
        M::SplineAttach(2),
        M::ShotManagerError("Traceback: ZeroDivisionError ✈".to_string()),
        M::CableCamWaypoint {
            lat_deg: 47.397742,
            lon_deg: 8.545594,
            alt_m: 12.0,
            yaw_deg: 90.5,
            pitch_deg: -30.0,
        },
        M::SecondPhoneNotification,
        M::GeofenceSetData(geofence()),
        M::GeofenceSetAck {
            count: 2,
            valid: true,
        },
        M::GeofenceUpdatePoly {
            action: 1,
            polygon_index: 0,
            vertex_index: 2,
            lat_deg: 37.5,
            lon_deg: -122.25,
            sub_lat_deg: 37.49,
            sub_lon_deg: -122.24,
        },
        M::GeofenceClear,
        M::GeofenceActivated,
        M::GoProSetEnabled(1),
        M::GoProSetRequest {
            command: 1,
            value: 0x0100,
        },
        M::GoProRecord(2),
        M::GoProV1State(GoProState {
            version: 1,
            status: 2,
            ..GoProState::default()
        }),
        M::GoProV2State(gopro_state()),
        M::GoProRequestState,
        M::GoProSetExtendedRequest {
            command: 5,
            value: [1, 2, 3, 4],
        },
        M::GoProPhoto {
            lat_deg: 51.5,
            lon_deg: -0.125,
            alt_m: 40.0,
            time: 1_700_000_000,
        },
        M::InspectStart {
            takeoff_alt_m: 15.0,
        },
        M::InspectSetWaypoint {
            lat_deg: 37.5,
            lon_deg: -122.25,
            alt_m: 20.0,
        },
        M::InspectMoveGimbal {
            pitch_deg: -45.0,
            roll_deg: 0.0,
            yaw_deg: 180.0,
        },
        M::InspectMoveVehicle {
            vx: 1.0,
            vy: -0.5,
            vz: 0.25,
        },
        M::ScanStart,
        M::SurveyStart,
    ]
}

// ---- proptest strategies: random valid messages ----

fn any_f32() -> impl Strategy<Value = f32> {
    -1.0e6f32..1.0e6f32
}
fn speed() -> impl Strategy<Value = f32> {
    -100.0f32..=100.0f32
}
fn lat() -> impl Strategy<Value = f64> {
    -90.0f64..=90.0
}
fn lon() -> impl Strategy<Value = f64> {
    -180.0f64..=180.0
}
fn shot() -> impl Strategy<Value = i32> {
    -1i32..=10
}

fn arb_location() -> impl Strategy<Value = Location> {
    (lat(), lon(), any_f32()).prop_map(|(lat_deg, lon_deg, alt_m)| Location {
        lat_deg,
        lon_deg,
        alt_m,
    })
}

fn arb_button() -> impl Strategy<Value = ButtonSetting> {
    (0i32..=8, 0i32..=5, shot(), -1i32..=i32::MAX).prop_map(|(button, event, shot, mode)| {
        ButtonSetting {
            button,
            event,
            shot,
            mode,
        }
    })
}

fn arb_gopro() -> impl Strategy<Value = GoProState> {
    (any::<[u8; 19]>(), any::<[u8; 7]>(), any::<[u16; 5]>()).prop_map(|(b, extra_u8, extra_u16)| {
        GoProState {
            version: b[0],
            model: b[1],
            status: b[2],
            recording: b[3],
            capture_mode: b[4],
            ntsc_pal: b[5],
            video_resolution: b[6],
            video_fps: b[7],
            video_fov: b[8],
            video_low_light: b[9],
            photo_resolution: b[10],
            photo_burst_rate: b[11],
            video_protune: b[12],
            video_white_balance: b[13],
            video_color: b[14],
            video_gain: b[15],
            video_sharpness: b[16],
            video_exposure: b[17],
            gimbal_enabled: b[18],
            extra_u8,
            extra_u16,
        }
    })
}

fn arb_spline_point() -> impl Strategy<Value = SplinePoint> {
    (
        any::<i16>(),
        any_f32(),
        any::<i32>(),
        lat(),
        lon(),
        (any_f32(), any_f32(), any_f32(), any_f32()),
        any::<i16>(),
    )
        .prop_map(
            |(
                version,
                abs_alt_ref_m,
                index,
                lat_deg,
                lon_deg,
                (alt_m, pitch_deg, yaw_deg, u_position),
                status,
            )| {
                SplinePoint {
                    version,
                    abs_alt_ref_m,
                    index,
                    lat_deg,
                    lon_deg,
                    alt_m,
                    pitch_deg,
                    yaw_deg,
                    u_position,
                    status,
                }
            },
        )
}

fn arb_geofence() -> impl Strategy<Value = GeofenceData> {
    let polygon = || prop::collection::vec((lat(), lon()).prop_map(|(a, b)| [a, b]), 0..6);
    prop::collection::vec((polygon(), polygon(), 0u8..=1), 0..4).prop_map(|polys| {
        let mut data = GeofenceData {
            coord: Vec::new(),
            sub_coord: Vec::new(),
            kinds: Vec::new(),
        };
        for (c, s, k) in polys {
            data.coord.push(c);
            data.sub_coord.push(s);
            data.kinds.push(k);
        }
        data
    })
}

fn arb_general() -> BoxedStrategy<SoloMessage> {
    use SoloMessage as M;
    prop_oneof![
        shot().prop_map(M::GetCurrentShot),
        shot().prop_map(M::SetCurrentShot),
        arb_location().prop_map(M::Location),
        arb_location().prop_map(M::HomeLocation),
        Just(M::RecordPosition),
        arb_button().prop_map(M::GetButtonSetting),
        arb_button().prop_map(M::SetButtonSetting),
        Just(M::Pause),
        (0u32..=2).prop_map(M::ShotError),
        ".{0,64}".prop_map(M::ShotManagerError),
        (lat(), lon(), any_f32(), any_f32(), any_f32()).prop_map(
            |(lat_deg, lon_deg, alt_m, yaw_deg, pitch_deg)| M::CableCamWaypoint {
                lat_deg,
                lon_deg,
                alt_m,
                yaw_deg,
                pitch_deg
            }
        ),
        Just(M::SecondPhoneNotification),
    ]
    .boxed()
}

fn arb_options() -> BoxedStrategy<SoloMessage> {
    use SoloMessage as M;
    prop_oneof![
        (0u16..=1, 0u16..=1, speed()).prop_map(
            |(cam_interpolation, yaw_direction_cw, cruise_speed)| {
                M::CableCamOptions {
                    cam_interpolation,
                    yaw_direction_cw,
                    cruise_speed,
                }
            }
        ),
        (speed(), 0i32..=1).prop_map(|(cruise_speed, look_at)| M::FollowOptions {
            cruise_speed,
            look_at
        }),
        (speed(), 0i32..=1, 0i32..=2).prop_map(|(cruise_speed, look_at, follow_preference)| {
            M::FollowOptionsV2 {
                cruise_speed,
                look_at,
                follow_preference,
            }
        }),
        speed().prop_map(|cruise_speed| M::ShotOptions { cruise_speed }),
        (0u8..=2, 0u8..=2, any::<i16>(), any_f32(), any_f32()).prop_map(
            |(pano_type, run_state, cylinder_fov, deg_second_yaw, lens_fov)| M::PanoOptions {
                pano_type,
                run_state,
                cylinder_fov,
                deg_second_yaw,
                lens_fov
            }
        ),
        (speed(), 0u8..=1, 0u8..=1).prop_map(|(cruise_speed, is_3d, cam_pointing)| {
            M::ZiplineOptions {
                cruise_speed,
                is_3d,
                cam_pointing,
            }
        }),
        (0u8..=1, 0u8..=1, any_f32()).prop_map(|(enabled, hover, rewind_distance)| {
            M::RewindOptions {
                enabled,
                hover,
                rewind_distance,
            }
        }),
        (any::<u8>(), any::<u8>()).prop_map(|(index, total)| M::PanoState { index, total }),
        Just(M::ZiplineLock),
    ]
    .boxed()
}

fn arb_spline() -> BoxedStrategy<SoloMessage> {
    use SoloMessage as M;
    prop_oneof![
        Just(M::SplineRecord),
        Just(M::SplinePlay),
        arb_spline_point().prop_map(M::SplinePoint),
        (any_f32(), -1i32..=1).prop_map(|(u_position, cruise_state)| M::SplineSeek {
            u_position,
            cruise_state
        }),
        (any_f32(), -1i32..=1).prop_map(|(u_position, cruise_state)| {
            M::SplinePlaybackStatus {
                u_position,
                cruise_state,
            }
        }),
        (0u32..=1, any_f32()).prop_map(|(camera_control, desired_time_s)| {
            M::SplinePathSettings {
                camera_control,
                desired_time_s,
            }
        }),
        (any_f32(), any_f32()).prop_map(|(min_time_s, max_time_s)| M::SplineDurations {
            min_time_s,
            max_time_s
        }),
        any::<u32>().prop_map(M::SplineAttach),
    ]
    .boxed()
}

fn arb_gopro_msgs() -> BoxedStrategy<SoloMessage> {
    use SoloMessage as M;
    prop_oneof![
        (0u32..=1).prop_map(M::GoProSetEnabled),
        (any::<u16>(), any::<u16>())
            .prop_map(|(command, value)| M::GoProSetRequest { command, value }),
        (0u32..=2).prop_map(M::GoProRecord),
        arb_gopro().prop_map(M::GoProV1State),
        arb_gopro().prop_map(M::GoProV2State),
        Just(M::GoProRequestState),
        (any::<u16>(), any::<[u8; 4]>())
            .prop_map(|(command, value)| { M::GoProSetExtendedRequest { command, value } }),
        (lat(), lon(), any_f32(), any::<u32>()).prop_map(|(lat_deg, lon_deg, alt_m, time)| {
            M::GoProPhoto {
                lat_deg,
                lon_deg,
                alt_m,
                time,
            }
        }),
    ]
    .boxed()
}

fn arb_geofence_msgs() -> BoxedStrategy<SoloMessage> {
    use SoloMessage as M;
    prop_oneof![
        arb_geofence().prop_map(M::GeofenceSetData),
        (any::<u16>(), any::<bool>()).prop_map(|(count, valid)| M::GeofenceSetAck { count, valid }),
        (
            0u8..=2,
            any::<u16>(),
            any::<u16>(),
            lat(),
            lon(),
            lat(),
            lon()
        )
            .prop_map(
                |(
                    action,
                    polygon_index,
                    vertex_index,
                    lat_deg,
                    lon_deg,
                    sub_lat_deg,
                    sub_lon_deg,
                )| {
                    M::GeofenceUpdatePoly {
                        action,
                        polygon_index,
                        vertex_index,
                        lat_deg,
                        lon_deg,
                        sub_lat_deg,
                        sub_lon_deg,
                    }
                }
            ),
        Just(M::GeofenceClear),
        Just(M::GeofenceActivated),
    ]
    .boxed()
}

fn arb_sitescan() -> BoxedStrategy<SoloMessage> {
    use SoloMessage as M;
    prop_oneof![
        any_f32().prop_map(|takeoff_alt_m| M::InspectStart { takeoff_alt_m }),
        (-90.0f32..=90.0, -180.0f32..=180.0, any_f32()).prop_map(|(lat_deg, lon_deg, alt_m)| {
            M::InspectSetWaypoint {
                lat_deg,
                lon_deg,
                alt_m,
            }
        }),
        (any_f32(), any_f32(), any_f32()).prop_map(|(pitch_deg, roll_deg, yaw_deg)| {
            M::InspectMoveGimbal {
                pitch_deg,
                roll_deg,
                yaw_deg,
            }
        }),
        (speed(), speed(), speed()).prop_map(|(vx, vy, vz)| M::InspectMoveVehicle { vx, vy, vz }),
        Just(M::ScanStart),
        Just(M::SurveyStart),
    ]
    .boxed()
}

/// A random valid message of any type.
pub fn arb_message() -> impl Strategy<Value = SoloMessage> {
    prop_oneof![
        arb_general(),
        arb_options(),
        arb_spline(),
        arb_gopro_msgs(),
        arb_geofence_msgs(),
        arb_sitescan(),
    ]
}
