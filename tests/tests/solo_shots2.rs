//! Shot engine II end to end, through the real Solo protocol against vehicle-sim:
//! multipoint cable cam (record, play, attach, seek), zipline, pano (camera
//! triggers), the Solo geofence (a shot stopped before a keep-out polygon) and a
//! survey of a keep-in polygon.

mod solo_common;

use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    topics, AckResult, Button, ButtonEvent, ButtonEventKind, CommandAck, CommandKind,
    CommandSource, FlightMode, VehicleState,
};
use skymesh_runtime::ipc::Subscriber;
use skymesh_shot_engine::shots::{GeoPoint, Keypoint, Limits, SplinePath};
use solo_common::*;
use solo_proto::{shots, GeofenceData, SoloMessage};

/// Accepted camera triggers the shot engine sent, drained from `acks` (drain often:
/// every 25 Hz setpoint is acknowledged too, and the subscriber buffers 64).
fn camera_triggers(acks: &mut Subscriber<CommandAck>) -> usize {
    let mut n = 0;
    while let Ok(Some(a)) = acks.try_recv() {
        n += usize::from(
            a.source == CommandSource::ShotEngine.to_wire()
                && a.kind == CommandKind::CameraCapture.to_wire()
                && a.result() == Some(AckResult::Accepted),
        );
    }
    n
}

/// Waits until the vehicle has been slower than 0.2 m/s for a second.
async fn settle(v: &mut Vehicle, timeout: Duration, what: &str) -> VehicleState {
    let mut still_since: Option<Instant> = None;
    v.wait_until(timeout, what, |s| {
        if speed(s) < 0.2 && s.vel_ned_mps[2].abs() < 0.2 {
            let t = *still_since.get_or_insert_with(Instant::now);
            t.elapsed() > Duration::from_secs(1)
        } else {
            still_since = None;
            false
        }
    })
    .await
}

/// A square polygon of half-size `half_m` around `c`, counter-clockwise, as [lat, lon].
fn square(c: (f64, f64), north_m: f64, half_n: f64, half_e: f64) -> Vec<[f64; 2]> {
    [(-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
        .iter()
        .map(|&(n, e)| {
            let p = offset(c, north_m + n * half_n, e * half_e);
            [p.0, p.1]
        })
        .collect()
}

#[test]
fn multipoint_and_zipline_fly_vehicle_sim() {
    let mut mesh = start_mesh();
    runtime().block_on(async {
        let bus = mesh.bus("e2e-solo-multipoint").unwrap();
        let mut v = Vehicle::new(&bus);
        v.take_off(10.0).await;
        let mut app = app(&mesh).await;

        // ---- Record three keypoints in an L: here, 30 m north, then 30 m east of that.
        let here = pos(&v.now().await);
        enter(&mut app, shots::MULTIPOINT).await;
        let mut keypoints = Vec::new();
        for (i, (p, alt)) in [
            (here, 10.0f32),
            (offset(here, 30.0, 0.0), 10.0),
            (offset(here, 30.0, 30.0), 14.0),
        ]
        .into_iter()
        .enumerate()
        {
            if i > 0 {
                v.fly_to(p, alt).await;
            }
            app.send(&SoloMessage::RecordPosition).await.unwrap();
            let SoloMessage::SplinePoint(k) = expect(&mut app, "SPLINE_POINT", |m| {
                matches!(m, SoloMessage::SplinePoint(_))
            })
            .await
            else {
                unreachable!()
            };
            assert_eq!((k.status, k.index), (0, i as i32), "{k:?}");
            keypoints.push(k);
        }

        // ---- Play: every keypoint with its uPosition, then the durations.
        app.send(&SoloMessage::SplinePlay).await.unwrap();
        let mut us = Vec::new();
        while us.len() < 3 {
            if let SoloMessage::SplinePoint(k) = expect(&mut app, "SPLINE_POINTs of play", |m| {
                matches!(m, SoloMessage::SplinePoint(_))
            })
            .await
            {
                us.push(k.u_position);
            }
        }
        assert_eq!(us.first(), Some(&0.0));
        assert_eq!(us.last(), Some(&1.0));
        expect(&mut app, "SPLINE_DURATIONS", |m| {
            matches!(m, SoloMessage::SplineDurations { min_time_s, max_time_s }
                if *min_time_s > 0.0 && max_time_s >= min_time_s)
        })
        .await;

        // ---- Attach to keypoint 0 (the vehicle is at keypoint 2), then seek to u = 0.5.
        app.send(&SoloMessage::SplineAttach(0)).await.unwrap();
        expect_within(&mut app, Duration::from_secs(60), "SPLINE_ATTACH", |m| {
            *m == SoloMessage::SplineAttach(0)
        })
        .await;
        app.send(&SoloMessage::SplineSeek {
            u_position: 0.5,
            cruise_state: 0,
        })
        .await
        .unwrap();
        tokio::time::sleep(Duration::from_secs(2)).await;
        let stopped = settle(&mut v, Duration::from_secs(60), "stopped at u = 0.5").await;
        let path = SplinePath::new(
            &keypoints
                .iter()
                .map(|k| Keypoint {
                    position: GeoPoint {
                        lat_deg: k.lat_deg,
                        lon_deg: k.lon_deg,
                        alt_rel_m: k.alt_m,
                    },
                    pitch_deg: k.pitch_deg,
                    yaw_deg: k.yaw_deg,
                })
                .collect::<Vec<_>>(),
            &Limits {
                max_speed_mps: 6.0,
                max_accel_mps2: 2.0,
                max_climb_mps: 1.5,
                position_gain: 0.5,
            },
        )
        .unwrap();
        let want = path.position_at_u(0.5);
        let (n, e) = ne((want.lat_deg, want.lon_deg), pos(&stopped));
        let off = n
            .hypot(e)
            .hypot(f64::from(stopped.alt_rel_m - want.alt_rel_m));
        println!("multipoint: stopped {off:.2} m from the spline point at u = 0.5");
        assert!(
            off < 2.0,
            "stopped {off:.2} m from the spline point at u = 0.5"
        );
        leave(&mut app).await;

        // ---- Zipline along the camera's yaw at 4 m/s.
        let start = v.now().await;
        let yaw = v
            .payload
            .latest()
            .unwrap()
            .filter(|p| p.is_gimbal_valid())
            .map_or(0.0, |p| p.gimbal_yaw_deg);
        let line_deg = f64::from(start.heading_deg + yaw);
        enter(&mut app, shots::ZIPLINE).await;
        expect(&mut app, "ZIPLINE_OPTIONS on entry", |m| {
            matches!(m, SoloMessage::ZiplineOptions { .. })
        })
        .await;
        app.send(&SoloMessage::ZiplineOptions {
            cruise_speed: 4.0,
            is_3d: 0,
            cam_pointing: 0,
        })
        .await
        .unwrap();
        let t0 = Instant::now();
        let mut worst_cross = 0.0f64;
        let mut along = 0.0f64;
        while t0.elapsed() < Duration::from_secs(8) {
            let s = v.now().await;
            let (n, e) = ne(pos(&start), pos(&s));
            let (sin, cos) = line_deg.to_radians().sin_cos();
            along = n * cos + e * sin;
            worst_cross = worst_cross.max((e * cos - n * sin).abs());
        }
        println!("zipline: {along:.1} m along, ≤ {worst_cross:.2} m off the line");
        assert!(
            along > 15.0,
            "zipline moved only {along:.1} m along its line"
        );
        assert!(
            worst_cross < 1.5,
            "zipline left its line by {worst_cross:.2} m"
        );
        // The controller's camera button during the zipline: the GoPro (video mode)
        // starts recording, and the app is told.
        let mut buttons = bus
            .publisher::<ButtonEvent>(&topics::input_buttons())
            .unwrap();
        buttons
            .publish(ButtonEvent::new(
                1,
                Button::CameraClick,
                ButtonEventKind::Press,
            ))
            .unwrap();
        expect(
            &mut app,
            "GOPRO_V2_STATE recording after the camera button",
            |m| matches!(m, SoloMessage::GoProV2State(g) if g.recording == 1),
        )
        .await;
        leave(&mut app).await;
    });
    mesh.stop(Duration::from_secs(10)).unwrap();
}

#[test]
fn pano_geofence_and_survey_fly_vehicle_sim() {
    let mut mesh = start_mesh_with("survey_speed_mps = 6.0\n");
    runtime().block_on(async {
        let bus = mesh.bus("e2e-solo-pano").unwrap();
        let mut v = Vehicle::new(&bus);
        let mut acks = bus
            .subscriber::<CommandAck>(&topics::vehicle_command_ack(1))
            .unwrap();
        v.take_off(10.0).await;
        let mut app = app(&mesh).await;

        // ---- Pano: a 120° cylinder, one camera trigger per station.
        enter(&mut app, shots::PANO).await;
        camera_triggers(&mut acks);
        app.send(&SoloMessage::PanoOptions {
            pano_type: 0,
            run_state: 1,
            cylinder_fov: 120,
            deg_second_yaw: 0.0,
            lens_fov: 60.0,
        })
        .await
        .unwrap();
        let mut last = (0u8, 0u8);
        let mut triggers = 0;
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            assert!(Instant::now() < deadline, "pano did not finish: {last:?}");
            triggers += camera_triggers(&mut acks);
            match app.recv(Duration::from_millis(100)).await {
                Some(SoloMessage::PanoState { index, total }) => last = (index, total),
                Some(SoloMessage::GetCurrentShot(shots::NONE)) => break,
                _ => {}
            }
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
        triggers += camera_triggers(&mut acks);
        println!("pano: {} stations, {triggers} camera triggers", last.1);
        assert!(last.1 >= 2, "a 120° cylinder needs several stations");
        assert_eq!(triggers, usize::from(last.1), "one trigger per station");

        // ---- Geofence: a keep-out 25..45 m north; a selfie toward 70 m north is stopped.
        let here = pos(&v.now().await);
        app.send(&SoloMessage::GeofenceSetData(GeofenceData {
            coord: vec![square(here, 35.0, 10.0, 20.0)],
            sub_coord: vec![square(here, 35.0, 17.0, 27.0)],
            kinds: vec![1],
        }))
        .await
        .unwrap();
        expect(&mut app, "GEOFENCE_SET_ACK valid", |m| {
            *m == SoloMessage::GeofenceSetAck {
                count: 1,
                valid: true,
            }
        })
        .await;
        enter(&mut app, shots::SELFIE).await;
        app.send(&SoloMessage::ShotOptions { cruise_speed: 5.0 })
            .await
            .unwrap();
        for l in [
            loc(offset(here, 5.0, 0.0), 10.0),
            loc(offset(here, 70.0, 0.0), 10.0),
            loc(here, 0.0),
        ] {
            app.send(&SoloMessage::Location(l)).await.unwrap();
        }
        let mut max_north = f64::MIN;
        let mut activated = false;
        let deadline = Instant::now() + Duration::from_secs(60);
        while Instant::now() < deadline && !activated {
            if let Some(m) = app.recv(Duration::from_millis(100)).await {
                activated |= m == SoloMessage::GeofenceActivated;
            }
            if let Some(s) = v.state.latest().unwrap() {
                max_north = max_north.max(ne(here, pos(&s)).0);
            }
        }
        assert!(activated, "no GEOFENCE_ACTIVATED (max north {max_north:.1} m)");
        let held = settle(&mut v, Duration::from_secs(30), "held at the fence").await;
        let (held_n, held_e) = ne(here, pos(&held));
        max_north = max_north.max(held_n);
        println!("geofence: closest approach {:.1} m before the keep-out, held at {held_n:.1} m N", 25.0 - max_north);
        assert!(max_north < 25.0, "entered the keep-out: {max_north:.1} m north");
        assert!(
            (held_n - 18.0).abs() < 3.0 && held_e.abs() < 5.0,
            "held at ({held_n:.1} N, {held_e:.1} E), not on the hold line at 18 m N"
        );
        let deadline = Instant::now() + Duration::from_secs(20);
        while v.status().await.flight_mode() != FlightMode::Loiter {
            assert!(Instant::now() < deadline, "not handed back in LOITER");
            tokio::time::sleep(Duration::from_millis(200)).await;
        }

        // ---- Survey: clear the fence, set a keep-in 100 m square with a 70 m hold line.
        app.send(&SoloMessage::GeofenceClear).await.unwrap();
        expect(&mut app, "GEOFENCE_SET_ACK after clear", |m| {
            matches!(m, SoloMessage::GeofenceSetAck { count: 0, .. })
        })
        .await;
        let centre = pos(&v.now().await);
        app.send(&SoloMessage::GeofenceSetData(GeofenceData {
            coord: vec![square(centre, 0.0, 50.0, 50.0)],
            sub_coord: vec![square(centre, 0.0, 35.0, 35.0)],
            kinds: vec![0],
        }))
        .await
        .unwrap();
        expect(&mut app, "GEOFENCE_SET_ACK keep-in", |m| {
            *m == SoloMessage::GeofenceSetAck {
                count: 1,
                valid: true,
            }
        })
        .await;
        camera_triggers(&mut acks);
        app.send(&SoloMessage::SurveyStart).await.unwrap();
        let mut track = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(240);
        let mut ended = false;
        let mut triggers = 0;
        while Instant::now() < deadline && !ended {
            triggers += camera_triggers(&mut acks);
            if let Some(m) = app.recv(Duration::from_millis(200)).await {
                ended |= m == SoloMessage::GetCurrentShot(shots::NONE);
            }
            if let Some(s) = v.state.latest().unwrap() {
                track.push(ne(centre, pos(&s)));
            }
        }
        assert!(ended, "the survey did not finish");
        triggers += camera_triggers(&mut acks);
        // Lane spacing at 30 m with the configured 122.6° lens and 0.65 sidelap.
        let spacing = 2.0 * 30.0 * (122.6f64 / 2.0).to_radians().tan() * (1.0 - 0.65);
        let mut worst = 0.0f64;
        for gn in (-35..=35).step_by(5) {
            for ge in (-35..=35).step_by(5) {
                let d = track
                    .iter()
                    .map(|&(n, e)| (n - f64::from(gn)).hypot(e - f64::from(ge)))
                    .fold(f64::MAX, f64::min);
                worst = worst.max(d);
            }
        }
        println!("survey: {triggers} photos, every point of the area within {worst:.1} m of the track (lane spacing {spacing:.1} m)");
        assert!(triggers >= 3, "survey took {triggers} photos");
        assert!(
            worst <= spacing / 2.0 + 3.0,
            "a point of the area is {worst:.1} m from the track (lane spacing {spacing:.1} m)"
        );
    });
    mesh.stop(Duration::from_secs(10)).unwrap();
}
