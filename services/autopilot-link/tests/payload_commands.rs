//! The DJI gateway's camera and gimbal commands (`CameraMode`, `CameraCaptureStop`,
//! `GimbalRate`, `CameraFocus`) through the real path: bus → arbiter → MAVLink →
//! the in-process vehicle-sim → COMMAND_ACK → `CommandAck`, and the gimbal's motion
//! back in `PayloadState`. Real TCP on 127.0.0.1, real iceoryx2 in a domain of its
//! own. Every wait is for a sample that satisfies a condition within a generous
//! bound; nothing asserts on timing.

mod common;

use common::sim::Sim;
use common::{assert_accepted, Mesh};
use skymesh_ipc_types::{AckResult, CameraModeKind, Command, FocusMode, RefusalReason};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn camera_commands_reach_the_sim_and_its_refusals_come_back_denied() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;

    for (cmd, what) in [
        (
            Command::CameraMode {
                camera: 0,
                mode: CameraModeKind::Video,
            },
            "video mode",
        ),
        (
            Command::CameraMode {
                camera: 1,
                mode: CameraModeKind::Image,
            },
            "photo mode",
        ),
        (Command::CameraCaptureStop { camera: 0 }, "capture stop"),
        (
            Command::CameraFocus {
                camera: 0,
                mode: FocusMode::Meters,
                value: 12.0,
            },
            "focus at 12 m",
        ),
        (
            Command::CameraFocus {
                camera: 1,
                mode: FocusMode::AutoContinuous,
                value: 0.0,
            },
            "AF-C",
        ),
    ] {
        assert_accepted(&mesh.command(cmd).await, what);
    }

    // The simulator has one camera (id 1): another id is the autopilot's DENIED.
    for (cmd, what) in [
        (
            Command::CameraMode {
                camera: 7,
                mode: CameraModeKind::Video,
            },
            "mode of camera 7",
        ),
        (Command::CameraCaptureStop { camera: 2 }, "stop camera 2"),
        (
            Command::CameraFocus {
                camera: 3,
                mode: FocusMode::Range,
                value: 50.0,
            },
            "focus camera 3",
        ),
    ] {
        let ack = mesh.command(cmd).await;
        assert_eq!(ack.result(), Some(AckResult::Refused), "{what}: {ack:?}");
        assert_eq!(
            ack.reason(),
            Some(RefusalReason::Denied),
            "{what}: {:?}",
            ack.detail
        );
        assert_eq!(ack.mav_result, 2, "{what}: MAV_RESULT_DENIED");
    }
    mesh.stop().await;
    sim.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gimbal_rate_turns_the_gimbal_until_a_rate_of_zero() {
    let sim = Sim::start(0).await;
    let mut mesh = Mesh::start(sim.port).await;
    mesh.wait_link_up().await;
    mesh.wait_payload("a gimbal attitude", |p| p.is_gimbal_valid())
        .await;

    let rate = |pitch_rate_dps, yaw_rate_dps| Command::GimbalRate {
        pitch_rate_dps,
        yaw_rate_dps,
    };
    assert_accepted(&mesh.command(rate(-20.0, 0.0)).await, "pitch down");
    mesh.wait_payload("the gimbal pitching down past 10°", |p| {
        p.gimbal_pitch_deg < -10.0
    })
    .await;
    let stop = mesh.command(rate(0.0, 0.0)).await;
    assert_accepted(&stop, "stop");
    // Stopped: attitudes the sim sent after its ACK, half a second apart, agree.
    let after_ack = stop.header.stamp_ns;
    let first = mesh
        .wait_payload("an attitude sent after the stop", |p| {
            p.gimbal_stamp_ns > after_ack
        })
        .await;
    let later = mesh
        .wait_payload("an attitude half a second later", |p| {
            p.gimbal_stamp_ns > first.gimbal_stamp_ns + 500_000_000
        })
        .await;
    assert!(
        (later.gimbal_pitch_deg - first.gimbal_pitch_deg).abs() < 0.1,
        "{} then {}",
        first.gimbal_pitch_deg,
        later.gimbal_pitch_deg
    );
    assert!(later.gimbal_pitch_deg < -10.0, "{later:?}");
    // Turning the other way, up to the travel's end (+30°).
    assert_accepted(&mesh.command(rate(90.0, 0.0)).await, "pitch up");
    mesh.wait_payload("the gimbal at its +30° stop", |p| {
        (p.gimbal_pitch_deg - 30.0).abs() < 0.5
    })
    .await;
    mesh.stop().await;
    sim.stop().await;
}
