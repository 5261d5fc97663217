//! Bad input never crashes the gateway and never loses other state: each case is
//! counted, and what follows it still works.

mod common;

use std::time::Duration;

use common::{value_of, Gateway, PATIENCE};
use skymesh_solo_gateway::client::{AppClient, FollowStreamer};
use skymesh_solo_gateway::Settings;
use solo_proto::{ids, GeofenceData, Location, SoloMessage};

/// `header + value` with any declared type and value.
fn frame(msg_type: u32, value: &[u8]) -> Vec<u8> {
    let mut b = msg_type.to_le_bytes().to_vec();
    b.extend((value.len() as u32).to_le_bytes());
    b.extend_from_slice(value);
    b
}

#[tokio::test]
async fn bad_frames_are_counted_and_the_next_one_in_the_same_write_arrives() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;

    let mut nan = value_of(&SoloMessage::Location(Location {
        lat_deg: 1.0,
        lon_deg: 2.0,
        alt_m: 3.0,
    }));
    nan[..8].copy_from_slice(&f64::NAN.to_le_bytes());
    let mut bytes = Vec::new();
    bytes.extend(frame(ids::SET_CURRENT_SHOT, &[1, 0, 0])); // wrong length
    bytes.extend(frame(4242, &[7, 7])); // unknown type
    bytes.extend(frame(ids::LOCATION, &nan)); // invalid value
    bytes.extend(SoloMessage::GetCurrentShot(1).to_bytes()); // only the vehicle sends it
    bytes.extend(SoloMessage::SetCurrentShot(2).to_bytes()); // valid
    app.send_raw(&bytes).await.expect("send");

    let got = gw.next_from_app().await;
    assert_eq!((got.session, got.msg_type), (1, ids::SET_CURRENT_SHOT));
    assert_eq!(
        got.value(),
        value_of(&SoloMessage::SetCurrentShot(2)).as_slice()
    );
    for kind in [
        "wrong_length",
        "unknown_type",
        "invalid_value",
        "wrong_direction",
    ] {
        gw.wait_malformed(kind, 1.0).await;
    }
    // The connection is still up and in the same session.
    app.send(&SoloMessage::Pause).await.expect("send");
    let got = gw.next_from_app().await;
    assert_eq!((got.session, got.msg_type), (1, ids::PAUSE));
    assert!(!app.is_closed());
    gw.stop().await;
}

#[tokio::test]
async fn a_declared_length_above_64_kib_closes_the_connection() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let mut header = ids::LOCATION.to_le_bytes().to_vec();
    header.extend((64 * 1024 + 1u32).to_le_bytes());
    app.send_raw(&header).await.expect("send");
    assert!(app.wait_closed(PATIENCE).await, "closed");
    gw.wait_malformed("too_long", 1.0).await;
    gw.wait_session("session 1 disconnected", |s| {
        s.session == 1 && s.connected == 0
    })
    .await;

    // The gateway serves the next connection.
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(2).await;
    app.send(&SoloMessage::RecordPosition).await.expect("send");
    assert_eq!(gw.next_from_app().await.session, 2);
    gw.stop().await;
}

#[tokio::test]
async fn half_a_frame_then_silence_is_dropped() {
    let mut settings = Settings::loopback_any_port();
    settings.frame_timeout = Duration::from_millis(200);
    let mut gw = Gateway::start_with(settings).await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let bytes = SoloMessage::SetCurrentShot(1).to_bytes();
    app.send_raw(&bytes[..5]).await.expect("send");
    assert!(
        app.wait_closed(PATIENCE).await,
        "a stalled client is closed"
    );
    gw.wait_malformed("stalled", 1.0).await;
    gw.wait_session("session 1 disconnected", |s| {
        s.session == 1 && s.connected == 0
    })
    .await;
    gw.stop().await;
}

#[tokio::test]
async fn frames_delivered_one_byte_at_a_time_arrive() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let mut bytes = SoloMessage::Location(Location {
        lat_deg: 37.87,
        lon_deg: -122.30,
        alt_m: 20.0,
    })
    .to_bytes()
    .to_vec();
    bytes.extend(
        SoloMessage::CableCamOptions {
            cam_interpolation: 1,
            yaw_direction_cw: 0,
            cruise_speed: 4.0,
        }
        .to_bytes(),
    );
    for b in &bytes {
        app.send_raw(&[*b]).await.expect("send");
        // Pace the bytes so they arrive in separate reads (not a wait for anything).
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    assert_eq!(gw.next_from_app().await.msg_type, ids::LOCATION);
    assert_eq!(gw.next_from_app().await.msg_type, ids::CABLE_CAM_OPTIONS);
    gw.stop().await;
}

#[tokio::test]
async fn a_geofence_too_large_for_the_bus_is_answered_and_counted() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let square = vec![
        [37.873_391_778_8, -122.301_244_403_2],
        [37.873_425_469_3, -122.300_884_203_8],
        [37.872_895_782_9, -122.300_712_401_1],
        [37.872_942_621_2, -122.301_244_403_2],
    ];
    // Nine polygons: one more than an AppGeofence carries.
    let fence = SoloMessage::GeofenceSetData(GeofenceData {
        coord: vec![square.clone(); 9],
        sub_coord: vec![square; 9],
        kinds: vec![1; 9],
    });
    app.send(&fence).await.expect("send");
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::GeofenceSetAck {
            count: 0,
            valid: false
        })
    );
    match app.recv(PATIENCE).await {
        Some(SoloMessage::ShotManagerError(text)) => {
            assert!(text.contains("9 polygons"), "{text}");
            assert!(text.contains("at most 8"), "{text}");
        }
        other => panic!("expected SHOTMANAGER_ERROR, got {other:?}"),
    }
    gw.wait_malformed("too_large_for_bus", 1.0).await;
    // Nothing of it went on the bus; the connection works on.
    app.send(&SoloMessage::SetCurrentShot(1))
        .await
        .expect("send");
    assert_eq!(gw.next_from_app().await.msg_type, ids::SET_CURRENT_SHOT);
    assert!(gw.geofence.try_recv().expect("app_geofence").is_none());
    gw.stop().await;
}

#[tokio::test]
async fn a_geofence_whose_coord_and_subcoord_differ_in_length_is_answered_invalid() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let square = [
        [37.873_391_778_8, -122.301_244_403_2],
        [37.873_425_469_3, -122.300_884_203_8],
        [37.872_895_782_9, -122.300_712_401_1],
        [37.872_942_621_2, -122.301_244_403_2],
    ];
    // Two polygons, one sub-polygon: what the codec refuses, and must still answer
    // (issue 43 item 5: without an answer the app waits forever).
    let json =
        format!(r#"{{"coord":[{square:?},{square:?}],"subCoord":[{square:?}],"type":[0,1]}}"#);
    app.send_raw(&frame(ids::GEOFENCE_SET_DATA, json.as_bytes()))
        .await
        .expect("send");
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::GeofenceSetAck {
            count: 0,
            valid: false
        })
    );
    match app.recv(PATIENCE).await {
        Some(SoloMessage::ShotManagerError(text)) => {
            assert!(text.contains("different sizes"), "{text}");
        }
        other => panic!("expected SHOTMANAGER_ERROR, got {other:?}"),
    }
    gw.wait_malformed("invalid_value", 1.0).await;
    // A malformed vertex update is answered the same way.
    app.send_raw(&frame(ids::GEOFENCE_UPDATE_POLY, &[9; 37]))
        .await
        .expect("send");
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::GeofenceSetAck {
            count: 0,
            valid: false
        })
    );
    assert!(matches!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::ShotManagerError(_))
    ));
    // So is a GEOFENCE_CLEAR with a value (it has none).
    app.send_raw(&frame(ids::GEOFENCE_CLEAR, &[1]))
        .await
        .expect("send");
    assert_eq!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::GeofenceSetAck {
            count: 0,
            valid: false
        })
    );
    assert!(matches!(
        app.recv(PATIENCE).await,
        Some(SoloMessage::ShotManagerError(_))
    ));
    // Nothing of them went on the bus; the connection works on.
    app.send(&SoloMessage::SetCurrentShot(1))
        .await
        .expect("send");
    assert_eq!(gw.next_from_app().await.msg_type, ids::SET_CURRENT_SHOT);
    assert!(gw.geofence.try_recv().expect("app_geofence").is_none());
    gw.stop().await;
}

/// `value` with the 4 bytes at `at` replaced by `v`.
fn with_f32(m: &SoloMessage, at: usize, v: f32) -> Vec<u8> {
    let mut value = value_of(m);
    value[at..at + 4].copy_from_slice(&v.to_le_bytes());
    value
}

#[tokio::test]
async fn non_finite_and_absurd_numbers_never_reach_the_bus() {
    let mut gw = Gateway::start().await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let here = SoloMessage::Location(Location {
        lat_deg: 1.0,
        lon_deg: 2.0,
        alt_m: 3.0,
    });
    let gimbal = SoloMessage::InspectMoveGimbal {
        pitch_deg: -10.0,
        roll_deg: 0.0,
        yaw_deg: 90.0,
    };
    let seek = SoloMessage::SplineSeek {
        u_position: 0.5,
        cruise_state: 0,
    };
    let bad: Vec<(u32, Vec<u8>)> = vec![
        // LOCATION altitude (after two f64): ∞, NaN, absurd.
        (ids::LOCATION, with_f32(&here, 16, f32::INFINITY)),
        (ids::LOCATION, with_f32(&here, 16, f32::NAN)),
        (ids::LOCATION, with_f32(&here, 16, 1e30)),
        // INSPECT_MOVE_GIMBAL yaw: −∞, absurd.
        (gimbal.msg_type(), with_f32(&gimbal, 8, f32::NEG_INFINITY)),
        (gimbal.msg_type(), with_f32(&gimbal, 8, -1e12)),
        // SPLINE_SEEK u: NaN, absurd.
        (seek.msg_type(), with_f32(&seek, 0, f32::NAN)),
        (seek.msg_type(), with_f32(&seek, 0, 5e9)),
        // INSPECT_MOVE_VEHICLE vx beyond any speed.
        (
            ids::INSPECT_MOVE_VEHICLE,
            value_of(&SoloMessage::InspectMoveVehicle {
                vx: 1e30,
                vy: 0.0,
                vz: 0.0,
            }),
        ),
        // SPLINE_PATH_SETTINGS desired time of 30 years.
        (
            ids::SPLINE_PATH_SETTINGS,
            value_of(&SoloMessage::SplinePathSettings {
                camera_control: 0,
                desired_time_s: 1e9,
            }),
        ),
    ];
    let mut bytes = Vec::new();
    for (t, v) in &bad {
        bytes.extend(frame(*t, v));
    }
    bytes.extend(SoloMessage::SetCurrentShot(2).to_bytes()); // valid
    app.send_raw(&bytes).await.expect("send");
    // The valid frame is the first thing on the bus: none of the bad ones went.
    let got = gw.next_from_app().await;
    assert_eq!(got.msg_type, ids::SET_CURRENT_SHOT);
    gw.wait_malformed("invalid_value", bad.len() as f64).await;
    assert!(!app.is_closed());

    // The follow stream applies the same limits.
    let follow = FollowStreamer::bind(common::localhost(), gw.udp)
        .await
        .expect("udp");
    let mut datagram = here.to_bytes().to_vec();
    datagram[solo_proto::HEADER_LEN + 16..].copy_from_slice(&1e30f32.to_le_bytes());
    follow.send_raw(&datagram).await.expect("send");
    gw.wait_malformed("bad_datagram", 1.0).await;
    app.send(&SoloMessage::Pause).await.expect("send");
    assert_eq!(gw.next_from_app().await.msg_type, ids::PAUSE);
    gw.stop().await;
}

#[tokio::test]
async fn an_app_beyond_its_frame_rate_is_throttled_and_stays_connected() {
    let mut settings = Settings::loopback_any_port();
    settings.max_messages_per_s = 1;
    settings.message_burst = 10;
    let mut gw = Gateway::start_with(settings).await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let flood: Vec<u8> = (0..100)
        .flat_map(|_| SoloMessage::Pause.to_bytes().to_vec())
        .collect();
    app.send_raw(&flood).await.expect("send");
    // Every frame is either forwarded or dropped as rate_limited.
    let forwarded = count_throttled(&mut gw, "rate_limited", 100, |m| {
        assert_eq!(m.msg_type, ids::PAUSE);
    })
    .await;
    assert!(forwarded >= 10, "the burst passes: {forwarded}");
    // Still connected; the follow stream has its own budget.
    assert!(!app.is_closed());
    let follow = FollowStreamer::bind(common::localhost(), gw.udp)
        .await
        .expect("udp");
    let here = Location {
        lat_deg: 37.0,
        lon_deg: -122.0,
        alt_m: 2.0,
    };
    follow.send(here).await.expect("send");
    let got = gw.next_from_app().await;
    assert!(got.is_follow_stream());
    gw.stop().await;
}

#[tokio::test]
async fn follow_datagrams_beyond_the_rate_are_dropped_and_the_app_is_unaffected() {
    let mut settings = Settings::loopback_any_port();
    settings.follow_max_per_s = 5;
    let mut gw = Gateway::start_with(settings).await;
    let mut app = AppClient::connect(gw.tcp).await.expect("connect");
    gw.wait_connected(1).await;
    let follow = FollowStreamer::bind(common::localhost(), gw.udp)
        .await
        .expect("udp");
    let here = Location {
        lat_deg: 37.0,
        lon_deg: -122.0,
        alt_m: 2.0,
    };
    for _ in 0..60 {
        follow.send(here).await.expect("send");
    }
    let forwarded = count_throttled(&mut gw, "follow_rate_limited", 60, |m| {
        assert!(m.is_follow_stream());
    })
    .await;
    assert!(forwarded >= 5, "the burst passes: {forwarded}");
    // The app's own connection is untouched.
    app.send(&SoloMessage::Pause).await.expect("send");
    let got = gw.next_from_app().await;
    assert_eq!((got.msg_type, got.is_follow_stream()), (ids::PAUSE, false));
    gw.stop().await;
}

/// Waits until each of `sent` messages of a flood was either forwarded to the bus
/// (checked by `check`) or counted as `kind`, at least half of them counted; returns
/// how many were forwarded.
async fn count_throttled(
    gw: &mut Gateway,
    kind: &str,
    sent: u32,
    mut check: impl FnMut(&common::FromApp),
) -> u32 {
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut forwarded = 0;
    loop {
        let limited = gw
            .metric("skymesh_solo_malformed_total", &format!("kind={kind}"))
            .unwrap_or(0.0);
        if f64::from(forwarded) + limited == f64::from(sent) {
            assert!(
                limited >= f64::from(sent / 2),
                "the flood is throttled: {limited}"
            );
            return forwarded;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "{forwarded} forwarded, {limited} limited"
        );
        if let Some(m) = gw
            .from_app
            .recv_timeout(Duration::from_millis(100))
            .await
            .expect("shot requests")
        {
            check(&common::FromApp::new(&m));
            forwarded += 1;
        }
    }
}
