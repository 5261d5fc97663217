//! Multipoint cable cam: record mode (one SPLINE_POINT per request), play mode,
//! attach, seek, playback status, path settings, pause and SPLINE_RECORD.

use skymesh_ipc_types::shot_api::shots::{MULTIPOINT, NONE};
use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest, SplinePoint};
use skymesh_ipc_types::{Button, Command, CommandKind, FlightMode};

use super::*;
use crate::engine::shot::ShotKind;

const HOME_MSL: f32 = 584.0;

fn point(index: i32, north_m: f64) -> SplinePoint {
    SplinePoint {
        version: 0,
        abs_alt_ref_m: 600.0,
        index,
        lat_deg: LAT + north_m * M_LAT,
        lon_deg: LON,
        alt_m: ALT,
        pitch_deg: -10.0,
        yaw_deg: 0.0,
        u_position: 0.0,
        status: 0,
    }
}

fn points(out: &Outputs) -> Vec<SplinePoint> {
    out.to_app
        .iter()
        .filter_map(|m| match m {
            ShotEvent::SplinePoint(p) => Some(*p),
            _ => None,
        })
        .collect()
}

fn statuses(out: &Outputs) -> Vec<(f32, i32)> {
    out.to_app
        .iter()
        .filter_map(|m| match m {
            ShotEvent::SplinePlaybackStatus {
                u_position,
                cruise_state,
            } => Some((*u_position, *cruise_state)),
            _ => None,
        })
        .collect()
}

fn error_text(out: &Outputs) -> Option<String> {
    out.to_app.iter().find_map(|m| match m {
        ShotEvent::Error(t) => Some(t.clone()),
        _ => None,
    })
}

/// An app connected, home at 584 m MSL, in the multipoint shot.
fn entered() -> Harness {
    let mut h = Harness::ready();
    h.status.home_alt_msl_m = HOME_MSL;
    h.push_status();
    h.drain();
    let out = h.app(ShotRequest::StartShot(MULTIPOINT));
    assert_eq!(out.to_app, [ShotEvent::CurrentShot(MULTIPOINT)]);
    assert!(out.commands.is_empty(), "record mode does not fly");
    h
}

/// Puts the vehicle `north_m` north of the start, still.
fn at(h: &mut Harness, north_m: f64) {
    h.state.lat_deg = LAT + north_m * M_LAT;
    h.state.lon_deg = LON;
    h.state.vel_ned_mps = [0.0; 3];
    h.push_state();
}

fn record_at(h: &mut Harness, north_m: f64) -> Outputs {
    at(h, north_m);
    h.app(ShotRequest::RecordPosition)
}

/// Three keypoints 0, 20, 40 m north, then play.
fn playing() -> Harness {
    let mut h = entered();
    for n in [0.0, 20.0, 40.0] {
        record_at(&mut h, n);
    }
    h.app(ShotRequest::SplinePlay);
    h
}

/// Playing, attached at keypoint 0 (the vehicle put there), in GUIDED.
fn attached() -> Harness {
    let mut h = playing();
    h.app(ShotRequest::SplineAttach(0));
    h.set_mode(FlightMode::Guided);
    at(&mut h, 0.0);
    let out = h.run(200);
    assert!(out.to_app.contains(&ShotEvent::SplineAttach(0)));
    h
}

fn path_point(h: &Harness, u: f64) -> crate::shots::GeoPoint {
    match &h.engine.active.as_ref().unwrap().kind {
        ShotKind::Multipoint(m) => m.play.as_ref().unwrap().ctrl.path().position_at_u(u),
        _ => panic!("not in multipoint"),
    }
}

#[test]
fn recorded_keypoints_are_acknowledged_once_each_and_coalesced_when_too_close() {
    let mut h = entered();
    let out = record_at(&mut h, 0.0);
    assert_eq!(
        points(&out),
        [SplinePoint {
            version: 0,
            abs_alt_ref_m: HOME_MSL,
            index: 0,
            lat_deg: LAT,
            lon_deg: LON,
            alt_m: ALT,
            pitch_deg: 0.0,
            yaw_deg: 90.0,
            u_position: 0.0,
            status: 0,
        }],
        "position, heading as yaw, camera pitch, home MSL as absAltRef"
    );
    assert_eq!(out.to_app.len(), 1);
    let out = record_at(&mut h, 10.0);
    assert_eq!(points(&out)[0].index, 1);
    assert_eq!(points(&out)[0].status, 0);
    // 1 m on: on top of keypoint 1, so it replaces it (same index, new position).
    let out = record_at(&mut h, 11.0);
    let p = points(&out);
    assert_eq!(out.to_app.len(), 1);
    assert_eq!((p[0].index, p[0].status), (1, 0));
    assert!((p[0].lat_deg - (LAT + 11.0 * M_LAT)).abs() < 1e-9);
    // A records like RECORD_POSITION.
    at(&mut h, 30.0);
    let out = h.button(Button::A);
    assert_eq!(points(&out)[0].index, 2);
    assert!(out.commands.is_empty());
}

#[test]
fn a_recording_without_a_position_still_gets_its_one_reply() {
    let mut h = entered();
    h.now += 2_000 * MS; // the vehicle state is now stale
    let out = h.app(ShotRequest::RecordPosition);
    assert_eq!(out.to_app.len(), 1);
    assert_eq!(points(&out)[0].status, -4);
}

#[test]
fn app_keypoints_are_validated_and_each_gets_one_reply() {
    let mut h = entered();
    let reply = |h: &mut Harness, p: SplinePoint| {
        let out = h.app(ShotRequest::SplinePoint(p));
        assert_eq!(out.to_app.len(), 1, "{:?}", out.to_app);
        points(&out)[0]
    };
    // Stored as sent; the first one sets the path's absAltRef.
    assert_eq!(reply(&mut h, point(0, 0.0)), point(0, 0.0));
    assert_eq!(reply(&mut h, point(0, 30.0)).status, -3, "duplicate index");
    assert_eq!(reply(&mut h, point(1, 1.0)).status, -2, "too close to 0");
    assert_eq!(
        reply(
            &mut h,
            SplinePoint {
                version: 1,
                ..point(1, 30.0)
            }
        )
        .status,
        -4,
        "unknown version"
    );
    assert_eq!(reply(&mut h, point(-1, 30.0)).status, -4);
    assert_eq!(
        reply(&mut h, point(100, 30.0)).status,
        -4,
        "beyond the most keypoints"
    );
    // A gap is fine while loading; its neighbours are checked both sides.
    assert_eq!(reply(&mut h, point(2, 40.0)).status, 0);
    assert_eq!(reply(&mut h, point(1, 39.0)).status, -2, "too close to 2");
    let ok = reply(
        &mut h,
        SplinePoint {
            abs_alt_ref_m: 1.0,
            ..point(1, 20.0)
        },
    );
    assert_eq!(ok.status, 0);
    assert_eq!(
        ok.abs_alt_ref_m, 600.0,
        "the path's absAltRef, from keypoint 0"
    );
    // The loaded path plays.
    let out = h.app(ShotRequest::SplinePlay);
    assert_eq!(points(&out).len(), 3);
}

#[test]
fn spline_point_outside_the_shot_gets_status_minus_4() {
    let mut h = Harness::ready();
    let out = h.app(ShotRequest::SplinePoint(point(0, 0.0)));
    assert_eq!(
        out.to_app,
        [ShotEvent::SplinePoint(SplinePoint {
            status: -4,
            ..point(0, 0.0)
        })]
    );
}

#[test]
fn play_needs_a_valid_path() {
    let mut h = entered();
    record_at(&mut h, 0.0);
    let out = h.app(ShotRequest::SplinePlay);
    assert!(
        error_text(&out).unwrap().contains("at least 2 keypoints"),
        "{:?}",
        out.to_app
    );
    assert!(points(&out).is_empty());
    // Indices 0 and 2: 1 is missing.
    h.app(ShotRequest::SplinePoint(point(2, 40.0)));
    let out = h.app(ShotRequest::SplinePlay);
    assert!(error_text(&out).unwrap().contains("keypoint 1 is missing"));
    assert!(out.commands.is_empty());
    // Still recording.
    assert_eq!(
        points(&h.app(ShotRequest::SplinePoint(point(1, 20.0))))[0].status,
        0
    );
    // Outside the shot.
    let mut idle = Harness::ready();
    let out = idle.app(ShotRequest::SplinePlay);
    assert!(error_text(&out).is_some());
}

#[test]
fn play_sends_every_keypoint_with_its_u_then_the_durations_and_does_not_fly() {
    let mut h = entered();
    for n in [0.0, 20.0, 40.0] {
        record_at(&mut h, n);
    }
    let out = h.app(ShotRequest::SplinePlay);
    assert!(out.commands.is_empty(), "nothing flies before ATTACH");
    let p = points(&out);
    assert_eq!(p.len(), 3);
    assert_eq!(
        p.iter().map(|p| (p.index, p.status)).collect::<Vec<_>>(),
        [(0, 0), (1, 0), (2, 0)]
    );
    assert_eq!(p[0].u_position, 0.0);
    assert!((p[1].u_position - 0.5).abs() < 0.01, "{}", p[1].u_position);
    assert_eq!(p[2].u_position, 1.0);
    match out.to_app.last() {
        Some(ShotEvent::SplineDurations {
            min_time_s,
            max_time_s,
        }) => {
            assert!(*min_time_s > 40.0 / 6.0, "{min_time_s}");
            assert!(max_time_s > min_time_s);
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(out.to_app.len(), 4);
    // In play mode, keypoints are a mode error; a seek before attaching is ignored.
    let out = h.app(ShotRequest::RecordPosition);
    assert_eq!(points(&out)[0].status, -1);
    let out = h.app(ShotRequest::SplinePoint(point(3, 80.0)));
    assert_eq!(points(&out)[0].status, -1);
    let out = h.app(ShotRequest::SplineSeek {
        u_position: 0.5,
        cruise_state: 0,
    });
    assert!(out.to_app.is_empty() && out.commands.is_empty());
    // A and B do nothing in play mode.
    assert!(h.button(Button::A).to_app.is_empty());
    // PLAY again sends the path again.
    let out = h.app(ShotRequest::SplinePlay);
    assert_eq!(points(&out).len(), 3);
}

#[test]
fn b_records_the_last_keypoint_and_plays_telling_the_app_first() {
    let mut h = entered();
    at(&mut h, 0.0);
    h.button(Button::A);
    at(&mut h, 25.0);
    let out = h.button(Button::B);
    assert_eq!(points(&out)[0].index, 1, "B records first");
    assert_eq!(out.to_app[1], ShotEvent::SplinePlay);
    assert_eq!(points(&out).len(), 3, "the recorded one, then the path");
    assert!(matches!(
        out.to_app.last(),
        Some(ShotEvent::SplineDurations { .. })
    ));
}

#[test]
fn attach_flies_to_the_keypoint_and_answers_when_there() {
    let mut h = playing();
    // The vehicle is at keypoint 2 (40 m north); attach to 0.
    let out = h.app(ShotRequest::SplineAttach(0));
    assert_eq!(
        cmds(&out),
        [
            Command::GrabFlightAuthority,
            Command::SetMode(FlightMode::Guided)
        ]
    );
    h.set_mode(FlightMode::Guided);
    let out = h.run(400);
    let v = cmds(&out)
        .into_iter()
        .rev()
        .find_map(|c| match c {
            Command::VelocityNed { vel_ned_mps, .. } => Some(vel_ned_mps),
            _ => None,
        })
        .unwrap();
    assert!(v[0] < -0.1, "south, toward keypoint 0: {v:?}");
    assert!(!out.to_app.contains(&ShotEvent::SplineAttach(0)));
    // Camera to keypoint 0's attitude (heading 90, level).
    assert!(cmds(&out).iter().any(|c| matches!(
        c,
        Command::SetYaw { yaw_deg, .. } if (*yaw_deg - 90.0).abs() < 0.5
    )));
    at(&mut h, 0.0);
    let out = h.run(200);
    let i = out
        .to_app
        .iter()
        .position(|m| *m == ShotEvent::SplineAttach(0))
        .expect("attached");
    assert_eq!(
        out.to_app[i + 1],
        ShotEvent::SplinePlaybackStatus {
            u_position: 0.0,
            cruise_state: 0
        }
    );
    // Valid once: a second attach is ignored.
    let out = h.app(ShotRequest::SplineAttach(2));
    assert!(out.to_app.is_empty() && out.commands.is_empty());
}

#[test]
fn attach_is_refused_outside_play_mode_or_past_the_path() {
    let mut h = entered();
    let out = h.app(ShotRequest::SplineAttach(0));
    assert!(error_text(&out).unwrap().contains("play mode"));
    let mut h = playing();
    let out = h.app(ShotRequest::SplineAttach(3));
    assert!(error_text(&out).unwrap().contains("cannot attach"));
    assert!(out.commands.is_empty());
    assert!(!h.engine.is_flying());
}

#[test]
fn seek_flies_to_u_with_playback_status_at_10_hz_and_stops_there() {
    let mut h = attached();
    let out = h.app(ShotRequest::SplineSeek {
        u_position: 0.5,
        cruise_state: 0,
    });
    assert_eq!(statuses(&out), [(0.0, 1)], "at once, moving toward the end");
    // The simulated vehicle does not move: the engine keeps reporting at 10 Hz.
    let out = h.run(1_000);
    let s = statuses(&out);
    assert!((9..=11).contains(&s.len()), "{}", s.len());
    assert!(s.iter().all(|(_, state)| *state == 1));
    let north = cmds(&out)
        .into_iter()
        .rev()
        .find_map(|c| match c {
            Command::VelocityNed { vel_ned_mps, .. } => Some(vel_ned_mps[0]),
            _ => None,
        })
        .unwrap();
    assert!(north > 0.5, "along the path: {north}");
    // Arrive at u = 0.5 (20 m north, keypoint 1): passed-keypoint and stop reports.
    let mid = path_point(&h, 0.5);
    assert!((mid.lat_deg - (LAT + 20.0 * M_LAT)).abs() < 0.1 * M_LAT);
    at(&mut h, 20.0);
    let out = h.run(400);
    let s = statuses(&out);
    assert!(!s.is_empty());
    let (u, state) = *s.last().unwrap();
    assert!((u - 0.5).abs() < 0.01 && state == 0, "{s:?}");
    // Stopped: no more reports.
    assert!(statuses(&h.run(500)).is_empty());
    // Seek to the end with cruise state 1 from here.
    let out = h.app(ShotRequest::SplineSeek {
        u_position: 0.5,
        cruise_state: 1,
    });
    assert_eq!(statuses(&out), [(0.5, 1)]);
}

#[test]
fn seek_before_attaching_is_ignored() {
    let mut h = playing();
    h.app(ShotRequest::SplineAttach(0));
    let out = h.app(ShotRequest::SplineSeek {
        u_position: 1.0,
        cruise_state: 1,
    });
    assert!(out.to_app.is_empty());
}

#[test]
fn pause_stops_on_the_path_and_a_second_pause_resumes_the_seek() {
    let mut h = attached();
    h.app(ShotRequest::SplineSeek {
        u_position: 1.0,
        cruise_state: 1,
    });
    h.run(400);
    let out = h.button(Button::Pause);
    assert_eq!(out.to_app, [ShotEvent::Pause]);
    assert_eq!(h.engine.status().cruise_speed_mps, 0.0);
    let out = h.run(3_000);
    let s = statuses(&out);
    assert_eq!(s.last().map(|s| s.1), Some(0), "stopped: {s:?}");
    assert!(statuses(&h.run(400)).is_empty(), "no reports while stopped");
    h.button(Button::Pause);
    let out = h.run(200);
    let s = statuses(&out);
    assert!(s.iter().any(|s| s.1 == 1), "moving again: {s:?}");
}

#[test]
fn path_settings_set_the_speed_for_the_desired_time_and_free_the_camera() {
    let mut h = playing();
    assert_eq!(
        h.engine.status().cruise_speed_mps,
        3.0,
        "configured default"
    );
    h.app(ShotRequest::SplinePathSettings {
        camera_control: 1,
        desired_time_s: 30.0,
    });
    let speed = h.engine.status().cruise_speed_mps;
    assert!(speed > 1.0 && speed < 2.0, "about 40 m in 30 s: {speed}");
    // Free camera: no yaw or gimbal command while attaching.
    h.app(ShotRequest::SplineAttach(0));
    h.set_mode(FlightMode::Guided);
    let out = h.run(400);
    assert!(!kinds(&out).contains(&CommandKind::SetYaw));
    assert!(!kinds(&out).contains(&CommandKind::Gimbal));
    // Settings sent in record mode are kept for play.
    let mut h = entered();
    h.app(ShotRequest::SplinePathSettings {
        camera_control: 0,
        desired_time_s: 200.0,
    });
    for n in [0.0, 20.0, 40.0] {
        record_at(&mut h, n);
    }
    h.app(ShotRequest::SplinePlay);
    assert_eq!(
        h.engine.status().cruise_speed_mps,
        0.5,
        "the slowest cruise"
    );
}

#[test]
fn spline_record_in_play_mode_hands_the_vehicle_back_and_starts_a_new_path() {
    let mut h = attached();
    let out = h.app(ShotRequest::SplineRecord);
    let c = cmds(&out);
    assert_eq!(c[0], Command::Brake);
    assert_eq!(c[1], Command::SetMode(FlightMode::Loiter));
    assert!(c.contains(&Command::ReleaseFlightAuthority));
    assert!(!h.engine.is_flying());
    assert_eq!(h.engine.current_shot(), MULTIPOINT, "still in the shot");
    assert!(h.run(200).commands.is_empty());
    h.set_mode(FlightMode::Loiter);
    let out = record_at(&mut h, 5.0);
    assert_eq!(points(&out)[0].index, 0, "a new path");
    assert_eq!(points(&out)[0].status, 0);
}

#[test]
fn fly_ends_the_multipoint_shot() {
    let mut h = attached();
    let out = h.button(Button::Fly);
    assert!(out.to_app.contains(&ShotEvent::CurrentShot(NONE)));
    assert!(cmds(&out).contains(&Command::SetMode(FlightMode::Loiter)));
}
