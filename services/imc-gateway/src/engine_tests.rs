//! The engine's rules, with explicit time and no I/O.

use std::time::{Duration, Instant};

use imc_proto::{
    encode_datagram, ChannelOp, ChannelState, Header, Message, PowerOp, RemoteActionsOp,
};
use skymesh_ipc_types::{
    AckResult, Button, ButtonEventKind, Command, CommandAck, CommandSource, FixedStr, HardwareOp,
    HardwareReply, HardwareResult, HardwareState, HwName, RefusalReason, SampleHeader, ServiceId,
    SystemPowerOp, VehicleState,
};

use super::*;

const PEER_ID: u16 = 0x4001;
const PEER_ENT: u8 = 5;

fn origin() -> SampleHeader {
    SampleHeader {
        service: ServiceId::ImcGateway.to_wire(),
        instance: 0,
        ..Default::default()
    }
}

fn peer() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 7001))
}

fn settings() -> Settings {
    Settings::loopback_any_port().expect("defaults")
}

fn engine_with(settings: Settings, t0: Instant) -> Engine {
    Engine::new(
        settings,
        SocketAddr::from(([127, 0, 0, 1], 6002)),
        origin(),
        t0,
    )
}

fn dgram_to(dst: u16, m: &Message) -> Vec<u8> {
    let h = Header {
        mgid: 0,
        size: 0,
        timestamp: 1.7e9,
        src: PEER_ID,
        src_ent: PEER_ENT,
        dst,
        dst_ent: 255,
    };
    encode_datagram(&h, m).expect("encode")
}

fn dgram(m: &Message) -> Vec<u8> {
    dgram_to(0x2c01, m)
}

fn feed(engine: &mut Engine, m: &Message, now: Instant) -> Outputs {
    let mut out = Outputs::default();
    engine.on_datagram(peer(), &dgram(m), now, &mut out);
    out
}

fn reasons(out: &Outputs) -> Vec<&'static str> {
    out.drops.iter().map(|d| d.reason).collect()
}

fn to_sender(message: Message) -> Send {
    Send {
        to: Destination {
            addr: peer(),
            dst: PEER_ID,
            dst_ent: PEER_ENT,
        },
        message,
    }
}

fn ack(cmd: &VehicleCommand, result: AckResult, reason: RefusalReason) -> CommandAck {
    CommandAck {
        source: CommandSource::Imc.to_wire(),
        command_id: cmd.command_id,
        kind: cmd.kind,
        result: result.to_wire(),
        reason: reason.to_wire(),
        ..Default::default()
    }
}

fn hw_reply(req: &HardwareRequest, result: HardwareResult, value: u8) -> HardwareReply {
    HardwareReply {
        request_id: req.request_id,
        requester_service: ServiceId::ImcGateway.to_wire(),
        requester_instance: 0,
        op: req.op,
        sub_op: req.sub_op,
        result: result.to_wire(),
        value,
        time_remaining_s: -1.0,
        name: req.name,
        ..Default::default()
    }
}

#[test]
fn broken_and_foreign_datagrams_change_nothing() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let good = dgram(&Message::Heartbeat);
    let mut bad_crc = good.clone();
    let last = bad_crc.len() - 1;
    bad_crc[last] ^= 0xff;
    let mut bad_sync = good.clone();
    bad_sync[0] = 0;
    for (bytes, reason) in [
        (bad_crc, "bad_crc"),
        (bad_sync, "bad_sync"),
        (good[..10].to_vec(), "too_short"),
        (dgram_to(0x1234, &Message::Heartbeat), "not_for_us"),
    ] {
        let mut out = Outputs::default();
        engine.on_datagram(peer(), &bytes, t0, &mut out);
        assert_eq!(reasons(&out), vec![reason]);
        assert!(out.received.is_empty() && out.sends.is_empty());
    }
    assert_eq!(engine.peer_count(), 0, "no peer from refused input");
    let mut out = Outputs::default();
    engine.on_datagram(
        peer(),
        &dgram_to(imc_proto::ADDR_NONE, &Message::Heartbeat),
        t0,
        &mut out,
    );
    assert_eq!(out.received, vec!["Heartbeat"], "broadcast is for us");
    assert_eq!(engine.peer_count(), 1);
}

#[test]
fn peers_outside_allowed_peers_are_dropped_before_decoding() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let stranger = SocketAddr::from(([10, 0, 0, 2], 6001));
    for m in [
        Message::SetServoPosition { id: 0, value: 0.0 },
        Message::ButtonEvent {
            button: 1,
            value: 1,
        },
        Message::Heartbeat,
    ] {
        let mut out = Outputs::default();
        engine.on_datagram(stranger, &dgram(&m), t0, &mut out);
        assert_eq!(reasons(&out), vec!["not_allowed"], "{m:?}");
        assert_eq!(out.drops[0].peer, Some(stranger));
        assert!(out.received.is_empty() && out.sends.is_empty());
        assert!(out.commands.is_empty() && out.buttons.is_empty() && out.hardware.is_empty());
    }
    // Garbage too: refused for who sent it, not for what it is.
    let mut out = Outputs::default();
    engine.on_datagram(stranger, b"xx", t0, &mut out);
    assert_eq!(reasons(&out), vec!["not_allowed"]);
    assert_eq!(engine.peer_count(), 0, "a refused peer gets no heartbeats");

    let mut s = settings();
    s.allowed_peers =
        skymesh_runtime::addresses::AddressList::new(vec!["10.0.0.0/24".parse().unwrap()]);
    let mut engine = engine_with(s, t0);
    let mut out = Outputs::default();
    engine.on_datagram(
        stranger,
        &dgram(&Message::SetServoPosition { id: 0, value: 0.0 }),
        t0,
        &mut out,
    );
    assert!(out.drops.is_empty(), "{:?}", out.drops);
    assert_eq!(out.commands.len(), 1);
    let mut out = Outputs::default();
    engine.on_datagram(peer(), &dgram(&Message::Heartbeat), t0, &mut out);
    assert_eq!(
        reasons(&out),
        vec!["not_allowed"],
        "the list replaces loopback"
    );
}

#[test]
fn servo_commands_go_to_the_arbiter_and_refusals_are_counted() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let out = feed(
        &mut engine,
        &Message::SetServoPosition { id: 0, value: 0.0 },
        t0,
    );
    assert_eq!(out.received, vec!["SetServoPosition"]);
    let cmd = out.commands[0];
    assert_eq!(cmd.source().unwrap(), CommandSource::Imc);
    assert_eq!(cmd.vehicle_id, 1);
    assert_eq!(
        cmd.command().unwrap(),
        Command::Servo {
            channel: 9,
            pwm_us: 1500
        }
    );
    let mut out = Outputs::default();
    engine.on_command_ack(
        &ack(&cmd, AckResult::Refused, RefusalReason::NoAuthority),
        &mut out,
    );
    assert_eq!(reasons(&out), vec!["refused_no_authority"]);
    assert!(out.sends.is_empty());

    let out = feed(
        &mut engine,
        &Message::SetServoPosition { id: 7, value: 0.0 },
        t0,
    );
    assert_eq!(reasons(&out), vec!["unmapped"]);
    assert!(out.commands.is_empty() && out.received.is_empty());
    // The codec already refuses a position beyond the document's ±π/2.
    let out = feed(
        &mut engine,
        &Message::SetServoPosition { id: 0, value: 2.0 },
        t0,
    );
    assert_eq!(reasons(&out), vec!["invalid_value"]);
    let out = feed(
        &mut engine,
        &Message::SetControlSurfaceDeflection { id: 0, angle: 0.1 },
        t0,
    );
    assert_eq!(reasons(&out), vec!["unmapped"], "no surfaces by default");
}

#[test]
fn pwm_is_answered_only_after_the_command_is_accepted() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let set = Message::SetPwm {
        id: 0,
        period: 20_000,
        duty_cycle: 1200,
    };
    let out = feed(&mut engine, &set, t0);
    assert!(out.sends.is_empty(), "not before the ack");
    let cmd = out.commands[0];
    assert_eq!(
        cmd.command().unwrap(),
        Command::Servo {
            channel: 10,
            pwm_us: 1200
        }
    );
    let mut out = Outputs::default();
    engine.on_command_ack(
        &ack(&cmd, AckResult::Accepted, RefusalReason::None),
        &mut out,
    );
    assert_eq!(
        out.sends,
        vec![to_sender(Message::Pwm {
            id: 0,
            period: 20_000,
            duty_cycle: 1200
        })]
    );
    // Refused: no reply.
    let out = feed(&mut engine, &set, t0);
    let mut after = Outputs::default();
    engine.on_command_ack(
        &ack(&out.commands[0], AckResult::Refused, RefusalReason::InAir),
        &mut after,
    );
    assert!(after.sends.is_empty());
    assert_eq!(reasons(&after), vec!["refused_in_air"]);
    // Another period: unsupported, nothing published.
    let out = feed(
        &mut engine,
        &Message::SetPwm {
            id: 0,
            period: 10_000,
            duty_cycle: 1200,
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["unsupported"]);
    assert!(out.commands.is_empty());
}

#[test]
fn thrusters_and_zoom_become_their_commands() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let out = feed(
        &mut engine,
        &Message::SetThrusterActuation { id: 2, value: 1.0 },
        t0,
    );
    assert_eq!(
        out.commands[0].command().unwrap(),
        Command::MotorTest {
            motor: 3,
            throttle_pct: 15.0,
            duration_s: 2.0
        }
    );
    let out = feed(
        &mut engine,
        &Message::SetThrusterActuation { id: 2, value: -0.5 },
        t0,
    );
    assert_eq!(reasons(&out), vec!["out_of_range"]);
    let out = feed(
        &mut engine,
        &Message::CameraZoom {
            id: 1,
            zoom: 0,
            action: imc_proto::ZoomAction::In,
        },
        t0,
    );
    assert_eq!(
        out.commands[0].command().unwrap(),
        Command::CameraZoom {
            camera: 1,
            mode: skymesh_ipc_types::ZoomMode::Continuous,
            value: 1.0
        }
    );
    assert!(out.commands[0].command_id > 1, "ids keep counting");
}

#[test]
fn led_requests_are_answered_from_the_hardware_reply() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let out = feed(
        &mut engine,
        &Message::SetLedBrightness {
            name: "status".into(),
            value: 128,
        },
        t0,
    );
    let req = out.hardware[0];
    assert_eq!(req.op(), Ok(HardwareOp::LedSet));
    assert_eq!((req.name.as_str(), req.value), ("status", 128));
    let mut out = Outputs::default();
    let mut foreign = hw_reply(&req, HardwareResult::Ok, 128);
    foreign.requester_service = ServiceId::GroundcontrolGateway.to_wire();
    engine.on_hardware_reply(&foreign, t0, &mut out);
    assert_eq!(out, Outputs::default(), "not ours");
    engine.on_hardware_reply(&hw_reply(&req, HardwareResult::Ok, 128), t0, &mut out);
    assert_eq!(
        out.sends,
        vec![to_sender(Message::LedBrightness {
            name: "status".into(),
            value: 128
        })]
    );

    // Unknown name: no IMC reply, counted.
    let out = feed(
        &mut engine,
        &Message::QueryLedBrightness {
            name: "nope".into(),
        },
        t0,
    );
    let mut after = Outputs::default();
    engine.on_hardware_reply(
        &hw_reply(&out.hardware[0], HardwareResult::UnknownName, 0),
        t0,
        &mut after,
    );
    assert!(after.sends.is_empty());
    assert_eq!(reasons(&after), vec!["hardware_unknown_name"]);

    // No reply at all: hardware_timeout after hardware_timeout.
    feed(
        &mut engine,
        &Message::GpioStateGet { name: "in1".into() },
        t0,
    );
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_millis(1900), &mut out);
    assert!(!reasons(&out).contains(&"hardware_timeout"));
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(2), &mut out);
    assert_eq!(reasons(&out), vec!["hardware_timeout"]);
}

fn state_with_channels(channels: &[(&str, bool)]) -> HardwareState {
    let mut s = HardwareState::default();
    for (i, (name, on)) in channels.iter().enumerate() {
        s.channels[i].name = HwName::new(name);
        s.channels[i].on = u8::from(*on);
    }
    s.n_channels = channels.len() as u8;
    s
}

#[test]
fn power_channels_are_controlled_and_queried() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let out = feed(
        &mut engine,
        &Message::PowerChannelControl {
            name: "payload".into(),
            op: ChannelOp::Toggle,
            sched_time: 0.0,
        },
        t0,
    );
    let req = out.hardware[0];
    let mut out = Outputs::default();
    engine.on_hardware_reply(&hw_reply(&req, HardwareResult::Ok, 1), t0, &mut out);
    assert_eq!(
        out.sends,
        vec![to_sender(Message::PowerChannelState {
            name: "payload".into(),
            state: ChannelState::On
        })]
    );

    let out = feed(&mut engine, &Message::QueryPowerChannelState, t0);
    assert_eq!(reasons(&out), vec!["no_hardware_state"]);
    engine.on_hardware_state(state_with_channels(&[]));
    let out = feed(&mut engine, &Message::QueryPowerChannelState, t0);
    assert_eq!(
        reasons(&out),
        vec!["no_power_channels"],
        "counted, not silent"
    );
    assert!(out.sends.is_empty());
    engine.on_hardware_state(state_with_channels(&[("payload", true), ("radio", false)]));
    let out = feed(&mut engine, &Message::QueryPowerChannelState, t0);
    assert!(
        out.hardware.is_empty(),
        "answered from the state, no round trip"
    );
    assert_eq!(
        out.sends,
        vec![
            to_sender(Message::PowerChannelState {
                name: "payload".into(),
                state: ChannelState::On
            }),
            to_sender(Message::PowerChannelState {
                name: "radio".into(),
                state: ChannelState::Off
            }),
        ]
    );
}

#[test]
fn a_power_down_is_reported_every_second_until_aborted() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let mut out = Outputs::default();
    engine.tick(t0, &mut out); // the first progress slot passes with nothing to report
    let out = feed(
        &mut engine,
        &Message::PowerOperation {
            op: PowerOp::PowerDown,
            time_remain: 0.0,
            sched_time: 0.0,
        },
        t0,
    );
    let req = out.hardware[0];
    assert_eq!(req.sub_op, SystemPowerOp::PowerDown.to_wire());
    let mut reply = hw_reply(&req, HardwareResult::Ok, 0);
    reply.sub_op = SystemPowerOp::PowerDownInProgress.to_wire();
    reply.time_remaining_s = 30.0;
    let mut out = Outputs::default();
    engine.on_hardware_reply(&reply, t0, &mut out);
    assert_eq!(
        out.sends,
        vec![to_sender(Message::PowerOperation {
            op: PowerOp::PowerDownInProgress,
            time_remain: 30.0,
            sched_time: 0.0
        })]
    );
    let mut state = HardwareState {
        system_power: SystemPowerOp::PowerDownInProgress.to_wire(),
        system_power_in_s: 29.0,
        ..Default::default()
    };
    engine.on_hardware_state(state);
    let progress = |out: &Outputs| -> Vec<Message> {
        out.sends
            .iter()
            .filter(|s| matches!(s.message, Message::PowerOperation { .. }))
            .map(|s| s.message.clone())
            .collect()
    };
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_millis(500), &mut out);
    assert!(progress(&out).is_empty(), "once a second");
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(1), &mut out);
    assert_eq!(
        progress(&out),
        vec![Message::PowerOperation {
            op: PowerOp::PowerDownInProgress,
            time_remain: 29.0,
            sched_time: 0.0
        }]
    );
    state.system_power = SystemPowerOp::PowerDownAborted.to_wire();
    engine.on_hardware_state(state);
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(2), &mut out);
    assert_eq!(
        progress(&out),
        vec![Message::PowerOperation {
            op: PowerOp::PowerDownAborted,
            time_remain: 0.0,
            sched_time: 0.0
        }]
    );
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(3), &mut out);
    assert!(progress(&out).is_empty(), "the watch ended");

    // Refused (no power-down command configured): PWR_DOWN_ABORTED and counted.
    let out = feed(
        &mut engine,
        &Message::PowerOperation {
            op: PowerOp::PowerDown,
            time_remain: 0.0,
            sched_time: 0.0,
        },
        t0,
    );
    let mut reply = hw_reply(&out.hardware[0], HardwareResult::Refused, 0);
    reply.message = FixedStr::new("no power_down_command configured");
    let mut out = Outputs::default();
    engine.on_hardware_reply(&reply, t0, &mut out);
    assert_eq!(reasons(&out), vec!["hardware_refused"]);
    assert_eq!(
        out.sends,
        vec![to_sender(Message::PowerOperation {
            op: PowerOp::PowerDownAborted,
            time_remain: 0.0,
            sched_time: 0.0
        })]
    );
}

fn vehicle_facing(yaw_deg: f32) -> VehicleState {
    VehicleState {
        attitude_valid: 1,
        position_valid: 1,
        yaw_rad: yaw_deg.to_radians(),
        lat_deg: -35.0,
        lon_deg: 149.0,
        alt_msl_m: 600.0,
        alt_rel_m: 10.0,
        ..Default::default()
    }
}

#[test]
fn remote_actions_fly_through_the_arbiter_and_press_buttons() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let out = feed(
        &mut engine,
        &Message::RemoteActions {
            actions: "Forward=1".into(),
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["no_vehicle_state"]);
    engine.on_vehicle_state(vehicle_facing(180.0));
    let out = feed(
        &mut engine,
        &Message::RemoteActions {
            actions: "Forward=1;Up=0.5;Fly=1;Lights=1".into(),
        },
        t0,
    );
    assert_eq!(out.received, vec!["RemoteActions"]);
    assert_eq!(reasons(&out), vec!["unknown_action"]);
    let cmd = out.commands[0];
    assert_eq!(cmd.max_age_ms, 500);
    match cmd.command().unwrap() {
        Command::VelocityNed {
            vel_ned_mps,
            yaw_rate_dps,
        } => {
            assert!(
                (vel_ned_mps[0] + 2.0).abs() < 1e-4,
                "facing south: forward is south"
            );
            assert!(vel_ned_mps[1].abs() < 1e-4);
            assert!((vel_ned_mps[2] + 0.5).abs() < 1e-4, "up is −down");
            assert_eq!(yaw_rate_dps, Some(0.0));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        out.buttons,
        vec![skymesh_ipc_types::ButtonEvent::new(
            1,
            Button::Fly,
            ButtonEventKind::Press
        )]
    );
    let out = feed(
        &mut engine,
        &Message::RemoteActions {
            actions: "Lights=1".into(),
        },
        t0,
    );
    assert!(out.drops.is_empty(), "an unknown name is reported once");
    assert_eq!(out.buttons[0].event(), Ok(ButtonEventKind::Release));
    assert_eq!(out.commands.len(), 1, "the stop setpoint after moving");
    let out = feed(
        &mut engine,
        &Message::RemoteActions {
            actions: "Up=3".into(),
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["out_of_range"]);
    assert!(out.commands.is_empty());
}

#[test]
fn button_events_are_mapped() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let out = feed(
        &mut engine,
        &Message::ButtonEvent {
            button: 4,
            value: 1,
        },
        t0,
    );
    assert_eq!(
        out.buttons,
        vec![skymesh_ipc_types::ButtonEvent::new(
            1,
            Button::A,
            ButtonEventKind::Press
        )]
    );
    let out = feed(
        &mut engine,
        &Message::ButtonEvent {
            button: 9,
            value: 0,
        },
        t0,
    );
    assert_eq!(out.buttons[0].button(), Ok(Button::Pause));
    assert_eq!(out.buttons[0].event(), Ok(ButtonEventKind::Release));
    let out = feed(
        &mut engine,
        &Message::ButtonEvent {
            button: 42,
            value: 1,
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["unmapped"]);
    let out = feed(
        &mut engine,
        &Message::ButtonEvent {
            button: 4,
            value: 2,
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["invalid_value"]);
    assert!(out.buttons.is_empty());
}

#[test]
fn the_action_table_is_reported_on_query() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let query = Message::RemoteActionsRequest {
        op: RemoteActionsOp::Query,
        actions: String::new(),
    };
    let out = feed(&mut engine, &query, t0);
    assert_eq!(
        out.sends,
        vec![to_sender(Message::RemoteActionsRequest {
            op: RemoteActionsOp::Report,
            actions: settings().teleop.actions_text()
        })]
    );
    let out = feed(
        &mut engine,
        &Message::RemoteActionsRequest {
            op: RemoteActionsOp::Register,
            actions: "X=Axis".into(),
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["unsupported"]);
    assert!(out.drops[0].quiet);
    let out = feed(
        &mut engine,
        &Message::LedBrightness {
            name: "x".into(),
            value: 1,
        },
        t0,
    );
    assert_eq!(reasons(&out), vec!["unsupported"]);
}

#[test]
fn heartbeats_go_to_peers_and_announces_to_destinations() {
    let t0 = Instant::now();
    let mut s = settings();
    let static_peer = SocketAddr::from(([127, 0, 0, 1], 7777));
    let group = SocketAddr::from(([127, 0, 0, 1], 30100));
    s.static_peers = vec![static_peer];
    s.announce_destinations = vec![group];
    let mut engine = engine_with(s, t0);
    engine.on_vehicle_state(vehicle_facing(0.0));
    feed(&mut engine, &Message::Heartbeat, t0);
    let mut out = Outputs::default();
    engine.tick(t0, &mut out);
    let hb: Vec<Destination> = out
        .sends
        .iter()
        .filter(|s| s.message == Message::Heartbeat)
        .map(|s| s.to)
        .collect();
    assert_eq!(
        hb,
        vec![
            Destination {
                addr: peer(),
                dst: PEER_ID,
                dst_ent: PEER_ENT
            },
            Destination::anonymous(static_peer)
        ]
    );
    let announce = out
        .sends
        .iter()
        .find_map(|s| match &s.message {
            Message::Announce(a) if s.to.addr == group => Some(a.clone()),
            _ => None,
        })
        .expect("announce");
    assert_eq!(announce.sys_name, "skymesh-1");
    assert_eq!(announce.sys_type, imc_proto::SystemType::Uav);
    assert_eq!(announce.owner, 0xFFFF);
    assert!((announce.lat - (-35.0f64).to_radians()).abs() < 1e-9);
    assert_eq!(announce.height, 600.0);
    assert_eq!(announce.services, "imc+udp://127.0.0.1:6002/");

    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_millis(900), &mut out);
    assert!(out.sends.is_empty());
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(1), &mut out);
    assert_eq!(out.sends.len(), 2, "heartbeats only; announce every 10 s");
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(31), &mut out);
    assert_eq!(
        engine.peer_count(),
        1,
        "the silent peer expired, the static one stays"
    );
    assert_eq!(out.sends.len(), 2, "one heartbeat and an announce");
}

#[test]
fn a_silent_peer_releases_its_buttons() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    engine.on_vehicle_state(vehicle_facing(0.0));
    feed(
        &mut engine,
        &Message::RemoteActions {
            actions: "A=1".into(),
        },
        t0,
    );
    let mut out = Outputs::default();
    engine.tick(t0 + Duration::from_secs(30), &mut out);
    assert_eq!(
        out.buttons,
        vec![skymesh_ipc_types::ButtonEvent::new(
            1,
            Button::A,
            ButtonEventKind::Release
        )]
    );
}

#[test]
fn idle_without_peers_nothing_is_due() {
    let t0 = Instant::now();
    let mut engine = engine_with(settings(), t0);
    let mut out = Outputs::default();
    engine.tick(t0, &mut out);
    assert_eq!(engine.next_due(t0), None, "no peers, no destinations");
}

#[test]
fn the_next_deadline_follows_peers_and_their_expiry() {
    let t0 = Instant::now();
    let s = settings();
    let (hb, timeout) = (s.heartbeat_interval, s.peer_timeout);
    let mut engine = engine_with(s, t0);
    let mut out = Outputs::default();
    engine.tick(t0, &mut out);
    // Long idle: the heartbeat schedule was not looked at for a while.
    let t1 = t0 + hb * 5 + hb / 2;
    feed(&mut engine, &Message::Heartbeat, t1);
    // The next heartbeat stays on its period grid; expiry is further out.
    assert_eq!(engine.next_due(t1), Some(t0 + hb * 6));
    assert!(t1 + timeout > t0 + hb * 6);
    let mut out = Outputs::default();
    engine.tick(t0 + hb * 6, &mut out);
    assert_eq!(out.sends.len(), 1, "one heartbeat to the peer");
    assert_eq!(engine.next_due(t0 + hb * 6), Some(t0 + hb * 7));
    // Once the peer expired, nothing is due again.
    let gone = t1 + timeout;
    let mut out = Outputs::default();
    engine.tick(gone, &mut out);
    assert_eq!(engine.peer_count(), 0);
    assert_eq!(engine.next_due(gone), None);
}
