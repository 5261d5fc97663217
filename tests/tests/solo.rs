//! The Solo app protocol end to end: a test app speaks TLV over TCP (and the follow
//! stream over UDP) to the real `skymesh-solo-gateway`, the real `skymesh-shot-engine`
//! decides, the real `autopilot-link` arbitrates and `vehicle-sim` flies. Every check
//! is made on what the vehicle actually did (its `VehicleState` / `PayloadState`) and
//! on the bytes the app received.

mod solo_common;

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use skymesh_e2e::{signal, Mesh};
use skymesh_ipc_types::{topics, Button, ButtonEvent, ButtonEventKind, VehicleState};
use skymesh_solo_gateway::client::{AppClient, FollowStreamer};
use solo_common::*;
use solo_proto::{shots, SoloMessage};

/// Shot refusals, the one-app rule and hostile input through the whole mesh.
#[test]
fn app_protocol_edges_through_the_mesh() {
    let mut mesh = start_mesh();
    runtime().block_on(async {
        let bus = mesh.bus("e2e-solo-edges").unwrap();
        let mut v = Vehicle::new(&bus);
        v.wait_ekf().await;
        let mut app = app(&mesh).await;

        // Disarmed on the ground: SOLO_SHOT_ERROR UNARMED (1), the shot is not entered.
        assert!(!v.status().await.is_armed());
        app.send(&SoloMessage::SetCurrentShot(shots::ORBIT))
            .await
            .unwrap();
        let m = expect(&mut app, "SOLO_SHOT_ERROR", |m| {
            matches!(
                m,
                SoloMessage::ShotError(_) | SoloMessage::GetCurrentShot(_)
            )
        })
        .await;
        assert_eq!(m, SoloMessage::ShotError(1), "unarmed entry");

        // A controller button on the bus reaches the engine: A (factory mapping: cable
        // cam) while disarmed is refused with SOLO_SHOT_ERROR UNARMED too.
        let mut buttons = bus
            .publisher::<ButtonEvent>(&topics::input_buttons())
            .unwrap();
        buttons
            .publish(ButtonEvent::new(1, Button::A, ButtonEventKind::Press))
            .unwrap();
        assert_eq!(
            expect(&mut app, "SOLO_SHOT_ERROR after the A button", |m| {
                matches!(
                    m,
                    SoloMessage::ShotError(_) | SoloMessage::GetCurrentShot(_)
                )
            })
            .await,
            SoloMessage::ShotError(1)
        );

        // GoPro: the app starts recording; the request goes through autopilot-link to the
        // simulated GoPro on the gimbal, and the state the app gets back says recording.
        // The GoPro heartbeat (1 Hz) may not have arrived yet: ask until it is connected.
        let deadline = Instant::now() + Duration::from_secs(15);
        loop {
            app.send(&SoloMessage::GoProRequestState).await.unwrap();
            let state = app
                .recv_until(Duration::from_secs(1), |m| {
                    matches!(m, SoloMessage::GoProV2State(_))
                })
                .await;
            if matches!(state, Some(SoloMessage::GoProV2State(g)) if g.status == 2) {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "the GoPro never connected: {state:?}"
            );
        }
        app.send(&SoloMessage::GoProRecord(1)).await.unwrap();
        expect(
            &mut app,
            "GOPRO_V2_STATE recording",
            |m| matches!(m, SoloMessage::GoProV2State(g) if g.recording == 1 && g.status == 2),
        )
        .await;
        app.send(&SoloMessage::GoProRecord(0)).await.unwrap();
        expect(
            &mut app,
            "GOPRO_V2_STATE stopped",
            |m| matches!(m, SoloMessage::GoProV2State(g) if g.recording == 0),
        )
        .await;

        // A second phone from another address is told and closed; the first keeps working.
        let mut second = AppClient::connect_from(
            [127, 0, 0, 2].into(),
            ([127, 0, 0, 1], mesh.solo_port).into(),
        )
        .await
        .unwrap();
        assert_eq!(
            second.recv(REPLY).await,
            Some(SoloMessage::SecondPhoneNotification)
        );
        assert!(second.wait_closed(REPLY).await, "second phone not closed");
        app.send(&SoloMessage::GetButtonSetting(solo_proto::ButtonSetting {
            button: 4,
            event: 0,
            shot: -1,
            mode: -1,
        }))
        .await
        .unwrap();
        expect(
            &mut app,
            "the A button setting",
            |m| matches!(m, SoloMessage::GetButtonSetting(b) if b.button == 4),
        )
        .await;

        // Wrong length, unknown type, out-of-range value: each dropped and counted,
        // and the valid frame behind them in the same write still works.
        let mut burst = Vec::new();
        burst.extend_from_slice(&[2, 0, 0, 0, 4, 0, 0, 0, 1, 2, 3, 4]); // LOCATION, 4 bytes
        burst.extend_from_slice(&[0x39, 0x30, 0, 0, 0, 0, 0, 0]); // type 12345, empty
        burst.extend_from_slice(&SoloMessage::SetCurrentShot(shots::ORBIT).to_bytes());
        let mut bad_shot = SoloMessage::SetCurrentShot(0).to_bytes().to_vec();
        bad_shot[8..12].copy_from_slice(&99i32.to_le_bytes());
        burst.extend_from_slice(&bad_shot);
        burst.extend_from_slice(
            &SoloMessage::GetButtonSetting(solo_proto::ButtonSetting {
                button: 5,
                event: 0,
                shot: -1,
                mode: -1,
            })
            .to_bytes(),
        );
        app.send_raw(&burst).await.unwrap();
        expect(
            &mut app,
            "the B button setting after the bad frames",
            |m| matches!(m, SoloMessage::GetButtonSetting(b) if b.button == 5),
        )
        .await;
        let counted = |mesh: &Mesh, kind: &str| {
            metric(
                mesh,
                &format!(
                    "skymesh_solo_malformed_total{{kind=\"{kind}\",service=\"solo-gateway\"}}"
                ),
            )
        };
        mesh.wait_for(Duration::from_secs(5), "malformed counters", |m| {
            (counted(m, "wrong_length") >= 1.0
                && counted(m, "unknown_type") >= 1.0
                && counted(m, "invalid_value") >= 1.0)
                .then_some(())
        })
        .unwrap();

        // A declared length above 64 KiB closes that connection, nothing else.
        app.send_raw(&[1, 0, 0, 0, 0xff, 0xff, 0xff, 0x7f])
            .await
            .unwrap();
        assert!(
            app.wait_closed(REPLY).await,
            "oversized frame did not close"
        );
        let mut again = AppClient::connect(([127, 0, 0, 1], mesh.solo_port).into())
            .await
            .unwrap();
        again
            .recv_until(REPLY, |m| matches!(m, SoloMessage::GetCurrentShot(_)))
            .await
            .expect("a new connection works after the oversized frame");
        assert_eq!(mesh.service("shot-engine").unwrap()["restarts"], 0);
        assert_eq!(mesh.service("solo-gateway").unwrap()["restarts"], 0);
    });
    mesh.stop(Duration::from_secs(10)).unwrap();
}

/// Orbit holds its radius around the ROI with the camera on it; cable cam flies
/// between its two recorded points.
#[test]
fn orbit_and_cable_cam_fly_vehicle_sim() {
    let mut mesh = start_mesh();
    runtime().block_on(async {
        let bus = mesh.bus("e2e-solo-orbit").unwrap();
        let mut v = Vehicle::new(&bus);
        v.take_off(10.0).await;
        let mut app = app(&mesh).await;

        // ---- Orbit: ROI 20 m north on the ground, 4 m/s.
        let start = v.now().await;
        let roi = offset(pos(&start), 20.0, 0.0);
        enter(&mut app, shots::ORBIT).await;
        app.send(&SoloMessage::Location(loc(roi, 0.0)))
            .await
            .unwrap();
        let echo = expect(&mut app, "the ROI echoed", |m| {
            matches!(m, SoloMessage::Location(_))
        })
        .await;
        let SoloMessage::Location(echo) = echo else {
            unreachable!()
        };
        let (en, ee) = ne(roi, (echo.lat_deg, echo.lon_deg));
        assert!(en.hypot(ee) < 0.5, "ROI echo {echo:?}");
        app.send(&SoloMessage::ShotOptions { cruise_speed: 4.0 })
            .await
            .unwrap();

        let r0 = 20.0;
        let t0 = Instant::now();
        let (mut min_r, mut max_r, mut swept, mut last_bearing) = (f64::MAX, 0.0f64, 0.0f64, None);
        let (mut worst_heading, mut worst_pitch) = (0.0f64, 0.0f64);
        while t0.elapsed() < Duration::from_secs(25) {
            let s = v.now().await;
            let (n, e) = ne(roi, pos(&s));
            let r = n.hypot(e);
            let bearing_from_roi = e.atan2(n).to_degrees();
            if let Some(b) = last_bearing {
                let mut d: f64 = bearing_from_roi - b;
                d = (d + 540.0) % 360.0 - 180.0;
                swept += d.abs();
            }
            last_bearing = Some(bearing_from_roi);
            if t0.elapsed() < Duration::from_secs(4) {
                continue; // accelerating onto the circle
            }
            min_r = min_r.min(r);
            max_r = max_r.max(r);
            // Camera on the ROI: the nose faces it and the gimbal looks down at it.
            let to_roi = (bearing_from_roi + 180.0).rem_euclid(360.0);
            let heading_err = ((f64::from(s.heading_deg) - to_roi + 540.0) % 360.0 - 180.0).abs();
            worst_heading = worst_heading.max(heading_err);
            if let Some(p) = v.payload.latest().unwrap() {
                if p.is_gimbal_valid() {
                    let want = -(f64::from(s.alt_rel_m)).atan2(r).to_degrees();
                    worst_pitch = worst_pitch.max((f64::from(p.gimbal_pitch_deg) - want).abs());
                }
            }
        }
        println!(
            "orbit: radius {min_r:.2}..{max_r:.2} m (wanted {r0}), swept {swept:.0}°, \
             nose off ROI ≤ {worst_heading:.1}°, gimbal off ROI ≤ {worst_pitch:.1}°"
        );
        assert!(
            min_r > r0 - 2.0 && max_r < r0 + 2.0,
            "orbit radius {min_r:.2}..{max_r:.2} m, wanted {r0} ± 2"
        );
        assert!(swept > 90.0, "orbit swept only {swept:.0}° in 25 s");
        assert!(
            worst_heading < 15.0,
            "nose off the ROI by {worst_heading:.1}°"
        );
        assert!(
            worst_pitch > 0.0 && worst_pitch < 5.0,
            "gimbal off the ROI by {worst_pitch:.1}° (0 = no gimbal reports)"
        );
        leave(&mut app).await;

        // ---- Cable cam: record A where the orbit's end leaves the vehicle at rest, fly
        // 25 m east, record B, then fly the cable. The ends flown to are the ones the
        // engine reports it recorded (its newest state when RECORD_POSITION came), each
        // checked against where this test saw the vehicle: a test's own snapshot taken
        // while the vehicle still drifts out of the orbit, or up to fly_to's tolerance
        // from its goal, can lie more than the arrival tolerance from the recorded end
        // (a run on a loaded machine held at the recorded A for 30 s, more than 1.5 m
        // from a snapshot taken at 4 m/s with 3.2 m of braking left).
        let a_state = v
            .wait_until(Duration::from_secs(30), "at rest after the orbit", |s| {
                speed(s) < 0.3
            })
            .await;
        enter(&mut app, shots::CABLECAM).await;
        app.send(&SoloMessage::RecordPosition).await.unwrap();
        let a = recorded_end(&mut app, "the first CABLE_CAM_WAYPOINT", pos(&a_state)).await;
        v.fly_to(offset(a, 0.0, 25.0), 10.0).await;
        let b_state = v.now().await;
        app.send(&SoloMessage::RecordPosition).await.unwrap();
        let b = recorded_end(&mut app, "the second CABLE_CAM_WAYPOINT", pos(&b_state)).await;
        expect(&mut app, "CABLE_CAM_OPTIONS after the second point", |m| {
            matches!(m, SoloMessage::CableCamOptions { .. })
        })
        .await;
        // Toward A (negative cruise speed), then back to B.
        for (target, speed) in [(a, -4.0f32), (b, 4.0)] {
            app.send(&SoloMessage::CableCamOptions {
                cam_interpolation: 1,
                yaw_direction_cw: 1,
                cruise_speed: speed,
            })
            .await
            .unwrap();
            let mut worst_off_line = 0.0f64;
            v.wait_until(Duration::from_secs(30), "cable end", |s| {
                worst_off_line = worst_off_line.max(off_line(a, b, pos(s)));
                let (dn, de) = ne(target, pos(s));
                dn.hypot(de) < 1.5
            })
            .await;
            assert!(
                worst_off_line < 1.5,
                "left the cable by {worst_off_line:.2} m"
            );
        }
        leave(&mut app).await;
    });
    mesh.stop(Duration::from_secs(10)).unwrap();
}

/// The end a CABLE_CAM_WAYPOINT reports recorded, which must be where the vehicle
/// was (`seen`, at rest).
async fn recorded_end(app: &mut AppClient, what: &str, seen: (f64, f64)) -> (f64, f64) {
    let SoloMessage::CableCamWaypoint {
        lat_deg, lon_deg, ..
    } = expect(app, what, |m| {
        matches!(m, SoloMessage::CableCamWaypoint { .. })
    })
    .await
    else {
        unreachable!()
    };
    let end = (lat_deg, lon_deg);
    let (n, e) = ne(seen, end);
    assert!(
        n.hypot(e) < 1.5,
        "{what}: recorded {:.2} m from where the vehicle was",
        n.hypot(e)
    );
    end
}

/// Horizontal distance of `p` from the line through `a` and `b`, metres.
fn off_line(a: (f64, f64), b: (f64, f64), p: (f64, f64)) -> f64 {
    let (bn, be) = ne(a, b);
    let (pn, pe) = ne(a, p);
    (bn * pe - be * pn).abs() / bn.hypot(be)
}

/// Selfie flies near → far → near with the camera on the ROI; follow tracks a
/// moving phone stream.
#[test]
fn selfie_and_follow_fly_vehicle_sim() {
    let mut mesh = start_mesh();
    runtime().block_on(async {
        let bus = mesh.bus("e2e-solo-selfie").unwrap();
        let mut v = Vehicle::new(&bus);
        v.take_off(10.0).await;
        let mut app = app(&mesh).await;

        // ---- Selfie: near 5 m north at 10 m, far 30 m north at 16 m, ROI at the start.
        let here = pos(&v.now().await);
        let near = offset(here, 5.0, 0.0);
        let far = offset(here, 30.0, 0.0);
        enter(&mut app, shots::SELFIE).await;
        app.send(&SoloMessage::ShotOptions { cruise_speed: 5.0 })
            .await
            .unwrap();
        for l in [loc(near, 10.0), loc(far, 16.0), loc(here, 0.0)] {
            app.send(&SoloMessage::Location(l)).await.unwrap();
        }
        let close = |p: (f64, f64), alt: f32| {
            move |s: &VehicleState| {
                let (n, e) = ne(p, pos(s));
                n.hypot(e) < 1.5 && (s.alt_rel_m - alt).abs() < 1.5
            }
        };
        v.wait_until(
            Duration::from_secs(30),
            "selfie near point",
            close(near, 10.0),
        )
        .await;
        let at_far = v
            .wait_until(
                Duration::from_secs(40),
                "selfie far point",
                close(far, 16.0),
            )
            .await;
        // Looking back at the ROI (south) from the far point.
        let heading = f64::from(at_far.heading_deg);
        assert!(
            ((heading - 180.0 + 540.0) % 360.0 - 180.0).abs() < 15.0,
            "selfie camera not on the ROI: heading {heading:.0}°"
        );
        v.wait_until(
            Duration::from_secs(40),
            "selfie back at near",
            close(near, 10.0),
        )
        .await;
        leave(&mut app).await;

        // ---- Follow: a phone 15 m south walks north-east at 2 m/s.
        let start = v.now().await;
        let phone0 = offset(pos(&start), -15.0, 0.0);
        enter(&mut app, shots::FOLLOW).await;
        let streamer = FollowStreamer::new(([127, 0, 0, 1], mesh.follow_port).into())
            .await
            .unwrap();
        let t0 = Instant::now();
        let mut worst = 0.0f64;
        let mut last_phone = phone0;
        while t0.elapsed() < Duration::from_secs(20) {
            let t = t0.elapsed().as_secs_f64();
            let d = t * 2.0 * std::f64::consts::FRAC_1_SQRT_2;
            let phone = offset(phone0, d, d);
            last_phone = phone;
            streamer.send(loc(phone, 0.0)).await.unwrap();
            tokio::time::sleep(Duration::from_millis(40)).await;
            if let Some(s) = v.state.latest().unwrap() {
                if t > 6.0 {
                    let (n, e) = ne(phone, pos(&s));
                    worst = worst.max((n.hypot(e) - 15.0).abs());
                }
            }
        }
        let end = v.now().await;
        // The engine crashes mid-shot: the arbiter brakes when its setpoints stop, the
        // supervisor restarts it, and it comes back idle and tells the app.
        let old_pid = mesh.wait_running("shot-engine", REPLY).unwrap();
        signal(old_pid, Signal::SIGKILL).unwrap();
        expect(
            &mut app,
            "SHOTMANAGER_ERROR saying the engine restarted",
            |m| matches!(m, SoloMessage::ShotManagerError(t) if t.contains("restarted")),
        )
        .await;
        expect(&mut app, "GET_CURRENT_SHOT -1 after the restart", |m| {
            *m == SoloMessage::GetCurrentShot(shots::NONE)
        })
        .await;
        v.wait_until(Duration::from_secs(5), "stale brake after the crash", |s| {
            speed(s) < 0.3
        })
        .await;
        let (mn, me) = ne(pos(&start), pos(&end));
        assert!(
            mn.hypot(me) > 25.0,
            "the vehicle did not follow: moved {:.1} m",
            mn.hypot(me)
        );
        let (n, e) = ne(last_phone, pos(&end));
        println!(
            "follow: moved {:.1} m, distance to the phone within 15 ± {worst:.1} m",
            mn.hypot(me)
        );
        assert!(
            worst < 5.0,
            "follow distance drifted by {worst:.1} m from 15 m (now {:.1} m)",
            n.hypot(e)
        );
    });
    mesh.stop(Duration::from_secs(10)).unwrap();
}
