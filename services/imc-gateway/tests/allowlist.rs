//! `allowed_peers`: a peer outside the list commands nothing (actuators, hardware,
//! buttons, teleoperation), gets no replies or heartbeats, and is counted
//! (`not_allowed`); the allowed peer keeps working. The stranger binds 127.0.0.2
//! (Linux routes all of 127/8 to lo), so only its source address differs.

mod common;

use std::net::SocketAddr;
use std::time::Duration;

use common::{barrier, Gateway, GATEWAY_ID};
use imc_proto::{Message, RemoteActionsOp};
use skymesh_imc_gateway::client::ImcClient;
use skymesh_ipc_types::{Button, ButtonEventKind, Command, HardwareResult, VehicleState};
use skymesh_runtime::addresses::AddressList;
use skymesh_test_support::ServiceCli;

/// A peer on `ip` (port 0) addressed to the gateway.
async fn peer_on(gw: &Gateway, ip: [u8; 4]) -> ImcClient {
    let mut c = ImcClient::bind(SocketAddr::from((ip, 0)), gw.addr)
        .await
        .expect("bind a peer on another loopback address");
    c.identity.dst = GATEWAY_ID;
    c
}

/// Everything that acts: two actuators, two hardware requests, a button, a
/// teleoperation setpoint with a button action, and a query that would be answered.
fn acting_messages() -> Vec<Message> {
    vec![
        Message::SetServoPosition { id: 0, value: 0.0 },
        Message::SetThrusterActuation { id: 1, value: 0.5 },
        Message::SetLedBrightness {
            name: "status".into(),
            value: 200,
        },
        Message::GpioStateSet {
            name: "camera_trigger".into(),
            value: 1,
        },
        Message::ButtonEvent {
            button: Button::Fly.to_wire(),
            value: 1,
        },
        Message::RemoteActions {
            actions: "Forward=0.5;Right=0;Up=0;Yaw=0;Fly=1".into(),
        },
        Message::RemoteActionsRequest {
            op: RemoteActionsOp::Query,
            actions: String::new(),
        },
        Message::Heartbeat,
    ]
}

fn vehicle_state() -> VehicleState {
    VehicleState {
        vehicle_id: 1,
        attitude_valid: 1,
        position_valid: 1,
        alt_rel_m: 10.0,
        ..Default::default()
    }
}

/// Nothing has been published on the command, hardware and button topics.
fn assert_bus_quiet(gw: &mut Gateway) {
    assert!(
        gw.commands.try_recv().unwrap().is_none(),
        "a VehicleCommand"
    );
    assert!(
        gw.hw_requests.try_recv().unwrap().is_none(),
        "a HardwareRequest"
    );
    assert!(gw.buttons.try_recv().unwrap().is_none(), "a ButtonEvent");
}

#[tokio::test]
async fn a_peer_outside_allowed_peers_commands_nothing_and_the_allowed_one_still_works() {
    let mut gw = Gateway::start().await;
    gw.vehicle_state.publish(vehicle_state()).unwrap();
    let allowed = gw.peer().await;
    let stranger = peer_on(&gw, [127, 0, 0, 2]).await;

    let messages = acting_messages();
    for m in &messages {
        stranger.send(m).await.unwrap();
    }
    gw.wait_dropped("not_allowed", messages.len() as f64).await;
    // The allowed peer's barrier is handled after every datagram above (one loop, in
    // order) and answered with only its REPORT.
    barrier(&allowed).await;
    assert_bus_quiet(&mut gw);
    assert_eq!(
        gw.metric("skymesh_imc_peers", ""),
        Some(1.0),
        "only the allowed peer is known (gets heartbeats)"
    );
    assert_eq!(
        gw.metric(
            "skymesh_imc_messages_total",
            "direction=in,message=SetServoPosition"
        ),
        None,
        "nothing of the stranger's was accepted"
    );
    // Anything sent to the stranger would have been sent before the barrier's REPORT.
    let got = stranger
        .recv_datagram(Duration::ZERO)
        .await
        .expect("stranger socket");
    assert!(got.is_none(), "the stranger got an answer: {got:?}");

    // The same messages from the allowed peer act.
    allowed.send(&messages[0]).await.unwrap();
    assert_eq!(
        gw.next_command().await.command().unwrap(),
        Command::Servo {
            channel: 9,
            pwm_us: 1500
        }
    );
    allowed.send(&messages[2]).await.unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.name.as_str(), "status");
    gw.hw_reply(&req, HardwareResult::Ok, 200);
    allowed.send(&messages[4]).await.unwrap();
    let b = gw.next_button().await;
    assert_eq!(b.button(), Ok(Button::Fly));
    assert_eq!(b.event(), Ok(ButtonEventKind::Press));
    // Teleoperation: a setpoint comes once the vehicle state has arrived.
    let cmd = loop {
        gw.vehicle_state.publish(vehicle_state()).unwrap();
        allowed.send(&messages[5]).await.unwrap();
        if let Some(c) = gw
            .commands
            .recv_timeout(Duration::from_millis(200))
            .await
            .unwrap()
        {
            break c;
        }
    };
    assert!(
        matches!(cmd.command().unwrap(), Command::VelocityNed { .. }),
        "{cmd:?}"
    );
    assert_eq!(
        gw.metric("skymesh_imc_dropped_total", "reason=not_allowed"),
        Some(messages.len() as f64),
        "the allowed peer was never refused"
    );
    gw.stop().await;
}

#[tokio::test]
async fn the_list_replaces_the_loopback_default() {
    let mut settings = common::settings();
    settings.allowed_peers = AddressList::new(vec!["127.0.0.2/32".parse().unwrap()]);
    let mut gw = Gateway::start_with(settings).await;
    let listed = peer_on(&gw, [127, 0, 0, 2]).await;
    let loopback = gw.peer().await;

    loopback.send(&acting_messages()[0]).await.unwrap();
    gw.wait_dropped("not_allowed", 1.0).await;
    barrier(&listed).await;
    assert_bus_quiet(&mut gw);

    listed.send(&acting_messages()[0]).await.unwrap();
    assert!(matches!(
        gw.next_command().await.command().unwrap(),
        Command::Servo { channel: 9, .. }
    ));
    gw.stop().await;
}

#[tokio::test]
async fn a_bad_allowed_peers_entry_is_a_config_error_naming_the_key() {
    let cli = ServiceCli::new(env!("CARGO_BIN_EXE_skymesh-imc-gateway"), "imcal");
    cli.expect_config_errors(&[
        ("allowed_peers = [\"10.0.0.0/33\"]\n", "allowed_peers[0]"),
        (
            "allowed_peers = [\"::1\", \"neptus.local\"]\n",
            "allowed_peers[1]",
        ),
    ])
    .await;
}
