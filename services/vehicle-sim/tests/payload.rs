//! The gimbal and the GoPro over real loopback sockets, on paused tokio time:
//! GIMBAL_DEVICE_ATTITUDE_STATUS from the autopilot, the GoPro bridge's
//! heartbeat and answers from the gimbal (component 154).

mod common;

use std::time::Duration;

use common::{Gcs, Sim, WAIT};
use mavlink::dialects::ardupilotmega::{
    GimbalDeviceFlags, GoproCaptureMode, GoproCommand, GoproHeartbeatFlags, GoproHeartbeatStatus,
    GoproRequestStatus, MavCmd, MavMessage, MavResult, GIMBAL_DEVICE_ATTITUDE_STATUS_DATA,
    GOPRO_GET_REQUEST_DATA, GOPRO_HEARTBEAT_DATA, GOPRO_SET_REQUEST_DATA,
};
use mavlink::MavHeader;
use skymesh_vehicle_sim::RawConfig;
use tokio::time::Instant;

const ACCEPTED: MavResult = MavResult::MAV_RESULT_ACCEPTED;
const GIMBAL: u8 = 154;

/// Pitch and yaw (degrees) of a roll-free MAVLink quaternion `[w, x, y, z]`.
fn pitch_yaw_deg(q: [f32; 4]) -> (f64, f64) {
    let [w, x, y, z] = q.map(f64::from);
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    (pitch.to_degrees(), yaw.to_degrees())
}

async fn gimbal_status(gcs: &mut Gcs) -> (MavHeader, GIMBAL_DEVICE_ATTITUDE_STATUS_DATA) {
    let deadline = Instant::now() + WAIT;
    loop {
        assert!(
            Instant::now() < deadline,
            "no GIMBAL_DEVICE_ATTITUDE_STATUS"
        );
        if let (h, MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(s)) = gcs.recv_with_header().await {
            return (h, s);
        }
    }
}

async fn pitchyaw(gcs: &mut Gcs, pitch: f32, yaw: f32) -> MavResult {
    gcs.command(
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        [pitch, yaw, f32::NAN, f32::NAN, 32., 0., 0.],
    )
    .await
}

#[tokio::test(start_paused = true)]
async fn gimbal_status_arrives_at_the_requested_rate_with_its_quaternion() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    let (header, s) = gimbal_status(&mut gcs).await;
    assert_eq!((header.system_id, header.component_id), (1, 1));
    assert_eq!(
        s.flags,
        GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME
    );
    assert_eq!(s.q, [1.0, 0.0, 0.0, 0.0], "boots level and forward");

    assert_eq!(gcs.set_interval(285, 50_000.0).await, ACCEPTED);
    assert_eq!(pitchyaw(&mut gcs, -30., 20.).await, ACCEPTED);
    let until = Instant::now() + Duration::from_secs(2);
    let mut n = 0;
    while Instant::now() < until {
        if let MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(_) = gcs.recv().await {
            n += 1;
        }
    }
    assert!((30..=50).contains(&n), "{n} statuses in 2 s at 20 Hz");
    // Slewing at 90 deg/s, it is there after a second.
    let (_, s) = gimbal_status(&mut gcs).await;
    let (pitch, yaw) = pitch_yaw_deg(s.q);
    assert!((pitch + 30.0).abs() < 0.1, "pitch {pitch}");
    assert!((yaw - 20.0).abs() < 0.1, "yaw {yaw}");
    let expected = [
        (-15f64).to_radians().cos() * 10f64.to_radians().cos(),
        -(-15f64).to_radians().sin() * 10f64.to_radians().sin(),
        (-15f64).to_radians().sin() * 10f64.to_radians().cos(),
        (-15f64).to_radians().cos() * 10f64.to_radians().sin(),
    ];
    for (got, want) in s.q.iter().zip(expected) {
        assert!((f64::from(*got) - want).abs() < 1e-4, "{:?}", s.q);
    }
    assert_eq!(
        (
            s.angular_velocity_x,
            s.angular_velocity_y,
            s.angular_velocity_z
        ),
        (0.0, 0.0, 0.0),
        "settled"
    );
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn gimbal_tracks_an_roi_below() {
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    gcs.airborne(20.0).await;
    let home_lat = -35.363_261f64;
    let home_lon = 149.165_230f64;
    let roi_lat = home_lat + 40.0 / 111_318.845;
    assert_eq!(
        gcs.command(
            MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
            [0., 0., 0., 0., roi_lat as f32, home_lon as f32, 0.],
        )
        .await,
        ACCEPTED
    );
    // Let the nose and the camera settle, remembering the latest position.
    let until = Instant::now() + Duration::from_secs(10);
    let mut last_pos = None;
    while Instant::now() < until {
        if let MavMessage::GLOBAL_POSITION_INT(g) = gcs.recv().await {
            last_pos = Some(g);
        }
    }
    let g = last_pos.expect("GLOBAL_POSITION_INT");
    let (_, s) = gimbal_status(&mut gcs).await;
    let north = (roi_lat - f64::from(g.lat) / 1e7) * 111_318.845;
    let east = (home_lon - f64::from(g.lon) / 1e7) * 111_318.845 * home_lat.to_radians().cos();
    let height = f64::from(g.relative_alt) / 1000.0;
    let expected = (-height).atan2(north.hypot(east)).to_degrees();
    let (pitch, yaw) = pitch_yaw_deg(s.q);
    assert!(expected < -20.0, "{expected}");
    assert!(
        (pitch - expected).abs() < 2.0,
        "pitch {pitch}, expected {expected}"
    );
    assert!(yaw.abs() < 2.0, "the nose faces the ROI: {yaw}");
    sim.stop().await;
}

async fn gopro_heartbeat(gcs: &mut Gcs) -> GOPRO_HEARTBEAT_DATA {
    let deadline = Instant::now() + WAIT;
    loop {
        assert!(Instant::now() < deadline, "no GOPRO_HEARTBEAT");
        if let (h, MavMessage::GOPRO_HEARTBEAT(hb)) = gcs.recv_with_header().await {
            assert_eq!((h.system_id, h.component_id), (1, GIMBAL));
            return hb;
        }
    }
}

/// GOPRO_SET_REQUEST to (1, 154); the status of the response from the gimbal.
async fn gopro_set(gcs: &mut Gcs, cmd_id: GoproCommand, value: [u8; 4]) -> GoproRequestStatus {
    gcs.send(&MavMessage::GOPRO_SET_REQUEST(GOPRO_SET_REQUEST_DATA {
        target_system: 1,
        target_component: GIMBAL,
        cmd_id,
        value,
    }))
    .await;
    let deadline = Instant::now() + WAIT;
    loop {
        assert!(Instant::now() < deadline, "no GOPRO_SET_RESPONSE");
        if let (h, MavMessage::GOPRO_SET_RESPONSE(r)) = gcs.recv_with_header().await {
            assert_eq!((h.system_id, h.component_id), (1, GIMBAL));
            assert_eq!(r.cmd_id, cmd_id);
            return r.status;
        }
    }
}

async fn gopro_get(gcs: &mut Gcs, cmd_id: GoproCommand) -> (GoproRequestStatus, [u8; 4]) {
    gcs.send(&MavMessage::GOPRO_GET_REQUEST(GOPRO_GET_REQUEST_DATA {
        target_system: 1,
        target_component: GIMBAL,
        cmd_id,
    }))
    .await;
    gcs.wait_for(WAIT, "GOPRO_GET_RESPONSE", |m| match m {
        MavMessage::GOPRO_GET_RESPONSE(r) if r.cmd_id == cmd_id => Some((r.status, r.value)),
        _ => None,
    })
    .await
}

#[tokio::test(start_paused = true)]
async fn gopro_heartbeat_set_get_and_shutter() {
    use GoproCommand::*;
    let success = GoproRequestStatus::GOPRO_REQUEST_SUCCESS;
    let sim = Sim::tcp().await;
    let mut gcs = Gcs::connect(sim.addr).await;
    let hb = gopro_heartbeat(&mut gcs).await;
    assert_eq!(
        hb.status,
        GoproHeartbeatStatus::GOPRO_HEARTBEAT_STATUS_CONNECTED
    );
    assert_eq!(hb.capture_mode, GoproCaptureMode::GOPRO_CAPTURE_MODE_VIDEO);
    assert_eq!(hb.flags, GoproHeartbeatFlags::empty());
    let until = Instant::now() + Duration::from_secs(3);
    let mut n = 0;
    while Instant::now() < until {
        if let MavMessage::GOPRO_HEARTBEAT(_) = gcs.recv().await {
            n += 1;
        }
    }
    assert!((2..=4).contains(&n), "{n} GoPro heartbeats in 3 s");

    assert_eq!(
        gopro_get(&mut gcs, GOPRO_COMMAND_MODEL).await,
        (success, [4, 0, 0, 0])
    );
    assert_eq!(
        gopro_set(&mut gcs, GOPRO_COMMAND_VIDEO_SETTINGS, [8, 2, 0, 0]).await,
        success
    );
    assert_eq!(
        gopro_get(&mut gcs, GOPRO_COMMAND_VIDEO_SETTINGS).await,
        (success, [8, 2, 0, 0])
    );
    assert_eq!(
        gopro_set(&mut gcs, GOPRO_COMMAND_CAPTURE_MODE, [9, 0, 0, 0]).await,
        GoproRequestStatus::GOPRO_REQUEST_FAILED
    );

    // Video: the shutter starts recording, and the next heartbeat says so.
    assert_eq!(
        gopro_set(&mut gcs, GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]).await,
        success
    );
    let hb = gopro_heartbeat(&mut gcs).await;
    assert_eq!(hb.flags, GoproHeartbeatFlags::GOPRO_FLAG_RECORDING);
    assert_eq!(
        gopro_get(&mut gcs, GOPRO_COMMAND_SHUTTER).await,
        (success, [1, 0, 0, 0])
    );
    assert_eq!(
        gopro_set(&mut gcs, GOPRO_COMMAND_SHUTTER, [0, 0, 0, 0]).await,
        success
    );
    assert_eq!(
        gopro_heartbeat(&mut gcs).await.flags,
        GoproHeartbeatFlags::empty()
    );

    // Photo: the shutter takes photos and never records.
    assert_eq!(
        gopro_set(&mut gcs, GOPRO_COMMAND_CAPTURE_MODE, [1, 0, 0, 0]).await,
        success
    );
    let hb = gopro_heartbeat(&mut gcs).await;
    assert_eq!(hb.capture_mode, GoproCaptureMode::GOPRO_CAPTURE_MODE_PHOTO);
    for _ in 0..2 {
        assert_eq!(
            gopro_set(&mut gcs, GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]).await,
            success
        );
    }
    assert_eq!(
        gopro_heartbeat(&mut gcs).await.flags,
        GoproHeartbeatFlags::empty()
    );
    let stats = sim.stats.snapshot();
    assert_eq!(stats.gopro_photos, 2);
    assert_eq!(stats.gopro_recording, 0);
    assert_eq!(stats.gopro_set_failed, 1);
    assert_eq!(stats.gopro_set_success, 6);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn without_a_gopro_nothing_is_sent_or_answered() {
    let sim = Sim::start(RawConfig {
        gopro: false,
        ..RawConfig::default()
    })
    .await;
    let mut gcs = Gcs::connect(sim.addr).await;
    gcs.heartbeat().await;
    gcs.send(&MavMessage::GOPRO_SET_REQUEST(GOPRO_SET_REQUEST_DATA {
        target_system: 1,
        target_component: GIMBAL,
        cmd_id: GoproCommand::GOPRO_COMMAND_SHUTTER,
        value: [1, 0, 0, 0],
    }))
    .await;
    let until = Instant::now() + Duration::from_secs(3);
    let mut gimbal_statuses = 0;
    while Instant::now() < until {
        let (h, m) = gcs.recv_with_header().await;
        assert_ne!(h.component_id, GIMBAL, "{m:?}");
        assert!(
            !matches!(
                m,
                MavMessage::GOPRO_HEARTBEAT(_) | MavMessage::GOPRO_SET_RESPONSE(_)
            ),
            "{m:?}"
        );
        if let MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(_) = m {
            gimbal_statuses += 1;
        }
    }
    assert!(gimbal_statuses > 0, "the gimbal itself is still there");
    assert_eq!(sim.stats.snapshot().gopro_set_success, 0);
    sim.stop().await;
}
