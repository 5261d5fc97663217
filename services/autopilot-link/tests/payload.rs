//! `PayloadState` and `GoProSet` against the in-process vehicle-sim: its simulated
//! gimbal (GIMBAL_DEVICE_ATTITUDE_STATUS) and the GoPro behind it (GOPRO_HEARTBEAT,
//! GOPRO_SET_REQUEST → GOPRO_SET_RESPONSE). Real TCP on 127.0.0.1, real iceoryx2.
//!
//! Every wait is for a sample that satisfies a condition within a generous bound;
//! nothing asserts on timing.

mod common;

use common::sim::Sim;
use common::{assert_accepted, Mesh, PATIENCE};
use skymesh_ipc_types::{AckResult, Command, CommandAck, GoProStatus, RefusalReason};

/// Metres per degree of latitude (a sphere of the WGS-84 equatorial radius is close
/// enough over 30 m).
const M_PER_DEG: f64 = 6_378_137.0 * std::f64::consts::PI / 180.0;

fn assert_refused(ack: &CommandAck, reason: RefusalReason, what: &str) {
    assert_eq!(ack.result(), Some(AckResult::Refused), "{what}: {ack:?}");
    assert_eq!(ack.reason(), Some(reason), "{what}: {:?}", ack.detail);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn payload_state_follows_a_gimbal_command_and_points_down_at_the_roi() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    mesh.wait_payload("a gimbal attitude", |p| p.is_gimbal_valid())
        .await;

    assert_accepted(
        &mesh
            .command(Command::Gimbal {
                pitch_deg: -30.0,
                yaw_deg: 0.0,
            })
            .await,
        "gimbal",
    );
    let p = mesh
        .wait_payload("the gimbal 30° down", |p| {
            p.is_gimbal_valid() && (p.gimbal_pitch_deg + 30.0).abs() < 2.0
        })
        .await;
    assert!(p.gimbal_yaw_deg.abs() < 2.0, "{p:?}");
    assert!(p.gimbal_roll_deg.abs() < 1.0, "{p:?}");

    // An ROI 20 m north of the vehicle and 20 m below it: the camera looks 45° down.
    let s = mesh
        .wait_state("a position", PATIENCE, |s| s.position_valid == 1)
        .await;
    let (north_m, below_m) = (20.0, 20.0);
    let roi_alt = s.alt_rel_m - below_m as f32;
    assert_accepted(
        &mesh
            .command(Command::SetRoi {
                lat_deg: s.lat_deg + north_m / M_PER_DEG,
                lon_deg: s.lon_deg,
                alt_rel_m: roi_alt,
            })
            .await,
        "ROI",
    );
    let expected = -(below_m / north_m).atan().to_degrees() as f32;
    let p = mesh
        .wait_payload("the camera on the ROI", |p| {
            p.is_gimbal_valid() && (p.gimbal_pitch_deg - expected).abs() < 2.0
        })
        .await;
    assert!(
        p.gimbal_pitch_deg < -40.0,
        "pitch down toward the ROI: {p:?}"
    );
    assert_accepted(&mesh.command(Command::ClearRoi).await, "clear ROI");

    let rx = "skymesh_autopilot_mavlink_messages_received_total";
    assert!(mesh.metric(rx, "msg=GIMBAL_DEVICE_ATTITUDE_STATUS") > 1.0);
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gopro_settings_are_answered_by_the_gimbal_and_show_in_payload_state() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    let p = mesh
        .wait_payload("a connected GoPro", |p| {
            p.gopro_status() == GoProStatus::Connected
        })
        .await;
    assert_eq!((p.gopro_capture_mode, p.gopro_recording), (0, 0), "video");
    assert!(p.gopro_stamp_ns > 0);

    // GOPRO_COMMAND_CAPTURE_MODE (1): photo.
    let photo = Command::GoProSet {
        command: 1,
        value: [1, 0, 0, 0],
    };
    assert_accepted(&mesh.command(photo).await, "photo mode");
    mesh.wait_payload("photo mode", |p| p.gopro_capture_mode == 1)
        .await;

    // A capture mode that does not exist: the gimbal answers FAILED.
    let bogus = Command::GoProSet {
        command: 1,
        value: [200, 0, 0, 0],
    };
    let ack = mesh.command(bogus).await;
    assert_refused(&ack, RefusalReason::Failed, "capture mode 200");
    assert_eq!(ack.mav_result, 255);

    // Back to video, then GOPRO_COMMAND_SHUTTER (2) 1: recording.
    let video = Command::GoProSet {
        command: 1,
        value: [0, 0, 0, 0],
    };
    assert_accepted(&mesh.command(video).await, "video mode");
    mesh.wait_payload("video mode", |p| p.gopro_capture_mode == 0)
        .await;
    let shutter = |on: u8| Command::GoProSet {
        command: 2,
        value: [on, 0, 0, 0],
    };
    assert_accepted(&mesh.command(shutter(1)).await, "shutter on");
    let p = mesh
        .wait_payload("recording", |p| p.gopro_recording == 1)
        .await;
    assert_eq!(p.gopro_status(), GoProStatus::Connected);
    // While recording the camera refuses a mode change; the shutter stops it.
    assert_refused(
        &mesh.command(photo).await,
        RefusalReason::Failed,
        "mode change while recording",
    );
    assert_accepted(&mesh.command(shutter(0)).await, "shutter off");
    mesh.wait_payload("stopped", |p| p.gopro_recording == 0)
        .await;

    let gopro = "skymesh_autopilot_gopro_responses_total";
    assert_eq!(mesh.metric(gopro, "status=success"), 4.0);
    assert_eq!(mesh.metric(gopro, "status=failed"), 2.0);
    let cmds = "skymesh_autopilot_commands_total";
    assert_eq!(mesh.metric(cmds, "kind=gopro_set,result=accepted"), 4.0);
    assert_eq!(mesh.metric(cmds, "kind=gopro_set,result=refused"), 2.0);
    mesh.stop().await;
    sim.stop().await;
}
