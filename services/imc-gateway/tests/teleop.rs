//! Remote actions and buttons: velocity setpoints rotated by the vehicle's yaw,
//! button events on the bus, the action table on QUERY.

mod common;

use std::time::Duration;

use common::{next_reply, Gateway};
use imc_proto::{parse_tuple_list, Message, RemoteActionsOp};
use skymesh_ipc_types::{
    AckResult, Button, ButtonEventKind, Command, CommandSource, RefusalReason, VehicleState,
};

#[tokio::test]
async fn remote_actions_become_velocity_setpoints_in_the_vehicle_frame() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;
    // The vehicle faces east.
    let state = VehicleState {
        vehicle_id: 1,
        attitude_valid: 1,
        position_valid: 1,
        yaw_rad: 90f32.to_radians(),
        alt_rel_m: 10.0,
        ..Default::default()
    };
    // The state streams (as autopilot-link's does) and arrives asynchronously: stream
    // remote actions as an operator would until a setpoint comes (before the first
    // state they are dropped: no_vehicle_state).
    let cmd = loop {
        gw.vehicle_state.publish(state).unwrap();
        peer.send(&Message::RemoteActions {
            actions: "Forward=0.5;Right=0;Up=0.5;Yaw=1".into(),
        })
        .await
        .unwrap();
        if let Some(c) = gw
            .commands
            .recv_timeout(Duration::from_millis(200))
            .await
            .unwrap()
        {
            break c;
        }
    };
    assert_eq!(cmd.source(), Ok(CommandSource::Imc));
    assert_eq!(
        cmd.max_age_ms, 500,
        "the arbiter brakes when the stream stops"
    );
    match cmd.command().unwrap() {
        Command::VelocityNed {
            vel_ned_mps: [n, e, d],
            yaw_rate_dps,
        } => {
            assert!(
                n.abs() < 1e-4 && (e - 1.0).abs() < 1e-4,
                "forward is east: {n} {e}"
            );
            assert!((d + 0.5).abs() < 1e-4, "up is negative down: {d}");
            assert_eq!(yaw_rate_dps, Some(45.0));
        }
        other => panic!("{other:?}"),
    }
    gw.ack(&cmd, AckResult::Accepted, RefusalReason::None);
    // Buttons in remote actions: 0 → 1 is a press, 1 → 0 (or missing) a release.
    peer.send(&Message::RemoteActions {
        actions: "Forward=0;Pause=1".into(),
    })
    .await
    .unwrap();
    let b = gw.next_button().await;
    assert_eq!(
        (b.button(), b.event()),
        (Ok(Button::Pause), Ok(ButtonEventKind::Press))
    );
    peer.send(&Message::RemoteActions {
        actions: "Forward=0".into(),
    })
    .await
    .unwrap();
    let b = gw.next_button().await;
    assert_eq!(
        (b.button(), b.event()),
        (Ok(Button::Pause), Ok(ButtonEventKind::Release))
    );
    // Out of range drops the whole message.
    peer.send(&Message::RemoteActions {
        actions: "Forward=2;A=1".into(),
    })
    .await
    .unwrap();
    gw.wait_dropped("out_of_range", 1.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn button_events_reach_the_bus() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;
    peer.send(&Message::ButtonEvent {
        button: Button::A.to_wire(),
        value: 1,
    })
    .await
    .unwrap();
    let b = gw.next_button().await;
    assert_eq!(b.vehicle_id, 1);
    assert_eq!(
        (b.button(), b.event()),
        (Ok(Button::A), Ok(ButtonEventKind::Press))
    );
    peer.send(&Message::ButtonEvent {
        button: Button::Fly.to_wire(),
        value: 0,
    })
    .await
    .unwrap();
    let b = gw.next_button().await;
    assert_eq!(
        (b.button(), b.event()),
        (Ok(Button::Fly), Ok(ButtonEventKind::Release))
    );
    peer.send(&Message::ButtonEvent {
        button: 77,
        value: 1,
    })
    .await
    .unwrap();
    gw.wait_dropped("unmapped", 1.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn query_is_answered_with_the_action_table() {
    let gw = Gateway::start().await;
    let peer = gw.peer().await;
    peer.send(&Message::RemoteActionsRequest {
        op: RemoteActionsOp::Query,
        actions: String::new(),
    })
    .await
    .unwrap();
    match next_reply(&peer).await {
        Message::RemoteActionsRequest {
            op: RemoteActionsOp::Report,
            actions,
        } => {
            let pairs = parse_tuple_list(&actions).unwrap();
            assert_eq!(pairs[0], ("Forward".to_string(), "Axis".to_string()));
            assert!(pairs.contains(&("Fly".to_string(), "Button".to_string())));
            assert_eq!(pairs.len(), 8);
        }
        other => panic!("{other:?}"),
    }
    // A peer's own REPORT is not acted on.
    peer.send(&Message::RemoteActionsRequest {
        op: RemoteActionsOp::Report,
        actions: "Lights=Button".into(),
    })
    .await
    .unwrap();
    gw.wait_dropped("unsupported", 1.0).await;
    gw.stop().await;
}
