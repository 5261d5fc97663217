//! IMC end to end: a test peer speaks IMC over UDP to the real `skymesh-imc-gateway`;
//! the real `skymesh-hardware` (simulated devices) answers LED, GPIO and power
//! channel requests; servo and PWM commands go through the real autopilot-link's
//! arbiter to vehicle-sim, whose SERVO_OUTPUT_RAW the autopilot-link router passes to
//! a ground-station socket of the test; remote actions fly vehicle-sim and the
//! arbiter brakes it when they stop; a ButtonEvent reaches the real shot engine.

mod solo_common;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use imc_proto::{ChannelOp, ChannelState, Message, SystemType};
use mavlink_frame::FrameParser;
use skymesh_e2e::{binary, Mesh, MeshOptions};
use skymesh_imc_gateway::client::ImcClient;
use skymesh_ipc_types::FlightMode;
use solo_common::{metric, runtime, speed, Vehicle, STARTUP};
use tokio::net::UdpSocket;

/// The gateway's IMC address (its default).
const GATEWAY_ID: u16 = 0x2c01;
const REPLY: Duration = Duration::from_secs(10);
/// A query the gateway answers from its cached hardware state: at once.
const FIRST_REPLY: Duration = Duration::from_secs(1);
/// MAVLink SERVO_OUTPUT_RAW.
const SERVO_OUTPUT_RAW: u32 = 36;

fn start(opts: MeshOptions, services: &[&str]) -> Mesh {
    let mut mesh = Mesh::start(opts).unwrap();
    mesh.expect_running(services, STARTUP);
    mesh
}

async fn peer(mesh: &Mesh) -> ImcClient {
    let mut p = ImcClient::connect(SocketAddr::from(([127, 0, 0, 1], mesh.imc_port)))
        .await
        .unwrap();
    p.identity.dst = GATEWAY_ID;
    p
}

/// Sends `m` and returns the first reply matching `pred`.
async fn ask(
    peer: &ImcClient,
    m: &Message,
    what: &str,
    pred: impl FnMut(&Message) -> bool,
) -> Message {
    peer.request(m, REPLY, pred)
        .await
        .unwrap()
        .unwrap_or_else(|| panic!("no {what} in answer to {m:?}"))
}

/// The state of power channel `name`, from one QueryPowerChannelState answered
/// within [`FIRST_REPLY`]. The gateway answers from the hardware service's state,
/// which it has before it reports running and which it refreshes before every query:
/// one request, no retries.
async fn channel_state(peer: &ImcClient, name: &str) -> ChannelState {
    let reply = peer
        .request(
            &Message::QueryPowerChannelState,
            FIRST_REPLY,
            |m| matches!(m, Message::PowerChannelState { name: n, .. } if n == name),
        )
        .await
        .unwrap();
    match reply {
        Some(Message::PowerChannelState { state, .. }) => state,
        Some(_) => unreachable!(),
        None => panic!("no {name} in answer to QueryPowerChannelState within {FIRST_REPLY:?}"),
    }
}

#[test]
fn imc_operates_leds_gpio_power_channels_and_talks_to_peers() {
    let rt = runtime();
    let announce_sink = rt
        .block_on(ImcClient::connect(SocketAddr::from(([127, 0, 0, 1], 9))))
        .unwrap();
    let sink_addr = announce_sink.local_addr().unwrap();
    let mut mesh = start(
        MeshOptions {
            imc: true,
            attitude_hz: 25.0,
            imc_gateway_extra: format!(
                "system_name = \"skymesh-e2e\"\nannounce_interval_s = 1.0\nannounce_destinations = [\"{sink_addr}\"]\n"
            ),
            ..Default::default()
        },
        &["vehicle-sim", "autopilot-link", "hardware", "imc-gateway"],
    );
    rt.block_on(async {
        let peer = peer(&mesh).await;

        // The first request, sent the moment the gateway reports running, is answered
        // (IMC has no error reply: an unanswered query is silence for the operator).
        let t0 = Instant::now();
        assert_eq!(channel_state(&peer, "lights").await, ChannelState::Off);
        eprintln!(
            "imc: first QueryPowerChannelState answered in {:?}",
            t0.elapsed()
        );

        // The arbiter's series exist at 0 before its first decision (a dashboard
        // sees 0, not "no data"), once autopilot-link's first stats sample is in.
        let sources = [
            "safety",
            "manual_rc",
            "dji_drc",
            "shot_engine",
            "swarm_queue",
            "imc",
            "vision",
            "operator",
        ];
        let s = "service=\"autopilot-link\"";
        let series: Vec<String> = sources
            .iter()
            .flat_map(|src| {
                [
                    format!("skymesh_arbiter_decisions_total{{decision=\"accepted\",reason=\"none\",{s},source=\"{src}\"}}"),
                    format!("skymesh_arbiter_decisions_total{{decision=\"limited\",reason=\"none\",{s},source=\"{src}\"}}"),
                    format!("skymesh_arbiter_authority_holder{{{s},source=\"{src}\",vehicle=\"1\"}}"),
                    format!("skymesh_arbiter_stale_brakes_total{{{s},source=\"{src}\"}}"),
                ]
            })
            .collect();
        mesh.wait_for(Duration::from_secs(5), "autopilot-link's stats", |m| {
            m.metric("skymesh_autopilot_link_up{service=\"autopilot-link\"}")
                .ok()
                .flatten()
        })
        .unwrap();
        for series in &series {
            assert_eq!(mesh.metric(series).unwrap(), Some(0.0), "{series}");
        }

        // LEDs: set, then query.
        let set = Message::SetLedBrightness {
            name: "status".into(),
            value: 200,
        };
        let expected = Message::LedBrightness {
            name: "status".into(),
            value: 200,
        };
        assert_eq!(
            ask(&peer, &set, "LedBrightness", |m| matches!(
                m,
                Message::LedBrightness { .. }
            ))
            .await,
            expected
        );
        let query = Message::QueryLedBrightness {
            name: "status".into(),
        };
        assert_eq!(
            ask(&peer, &query, "LedBrightness", |m| matches!(
                m,
                Message::LedBrightness { .. }
            ))
            .await,
            expected
        );
        // The simulated LED's file holds what was set.
        let led = std::fs::read_to_string(mesh.hardware_dir.join("led/status")).unwrap();
        assert_eq!(led.trim(), "200");

        // GPIO: drive an output, read it back.
        let m = ask(
            &peer,
            &Message::GpioStateSet {
                name: "payload_release".into(),
                value: 1,
            },
            "GpioState",
            |m| matches!(m, Message::GpioState { .. }),
        )
        .await;
        assert_eq!(
            m,
            Message::GpioState {
                name: "payload_release".into(),
                value: 1
            }
        );
        let m = ask(
            &peer,
            &Message::GpioStateGet {
                name: "payload_release".into(),
            },
            "GpioState",
            |m| matches!(m, Message::GpioState { .. }),
        )
        .await;
        assert_eq!(
            m,
            Message::GpioState {
                name: "payload_release".into(),
                value: 1
            }
        );

        // Power channels: toggle "lights" (off by default) on, off again, then a
        // scheduled turn-on that happens a second later.
        let control = |op, sched_time| Message::PowerChannelControl {
            name: "lights".into(),
            op,
            sched_time,
        };
        let state_of = |m: Message| match m {
            Message::PowerChannelState { name, state } if name == "lights" => state,
            other => panic!("{other:?}"),
        };
        let is_lights =
            |m: &Message| matches!(m, Message::PowerChannelState { name, .. } if name == "lights");
        assert_eq!(channel_state(&peer, "lights").await, ChannelState::Off);
        let m = ask(
            &peer,
            &control(ChannelOp::Toggle, 0.0),
            "PowerChannelState",
            is_lights,
        )
        .await;
        assert_eq!(state_of(m), ChannelState::On);
        // Read after write: the query right after the reply reads the change.
        assert_eq!(
            channel_state(&peer, "lights").await,
            ChannelState::On,
            "the query after the toggle's reply"
        );
        let m = ask(
            &peer,
            &control(ChannelOp::Toggle, 0.0),
            "PowerChannelState",
            is_lights,
        )
        .await;
        assert_eq!(state_of(m), ChannelState::Off);
        let m = ask(
            &peer,
            &control(ChannelOp::ScheduleOn, 1.0),
            "PowerChannelState",
            is_lights,
        )
        .await;
        assert_eq!(state_of(m), ChannelState::Off, "scheduled, not yet on");
        let deadline = Instant::now() + REPLY;
        while channel_state(&peer, "lights").await != ChannelState::On {
            assert!(
                Instant::now() < deadline,
                "the scheduled turn-on never happened"
            );
            tokio::time::sleep(Duration::from_millis(200)).await;
        }

        // The peer that talks to the gateway gets heartbeats; the configured
        // destination gets Announce.
        let hb = peer
            .recv_until(REPLY, |p| p.message == Message::Heartbeat)
            .await
            .expect("a heartbeat from the gateway");
        assert_eq!(
            (hb.header.src, hb.header.dst),
            (GATEWAY_ID, peer.identity.src)
        );
        let a = match announce_sink
            .recv_message(REPLY, |m| matches!(m, Message::Announce(_)))
            .await
        {
            Some(Message::Announce(a)) => a,
            other => panic!("no Announce: {other:?}"),
        };
        assert_eq!(a.sys_name, "skymesh-e2e");
        assert_eq!(a.sys_type, SystemType::Uav);
        assert_eq!(
            a.services,
            format!("imc+udp://127.0.0.1:{}/", mesh.imc_port)
        );

        // Broken input is counted, the gateway keeps serving.
        let mut bad = peer.datagram(&query).unwrap();
        let last = bad.len() - 1;
        bad[last] ^= 0xff;
        peer.send_raw(&bad).await.unwrap();
        assert_eq!(
            ask(&peer, &query, "LedBrightness", |m| matches!(
                m,
                Message::LedBrightness { .. }
            ))
            .await,
            expected
        );
    });

    // The command-line client speaks the same protocol.
    let out = std::process::Command::new(binary("skymesh-imc"))
        .args([
            "--to",
            &format!("127.0.0.1:{}", mesh.imc_port),
            "--wait",
            "3",
        ])
        .args(["led", "query", "status"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("LedBrightness name=status value=200"),
        "skymesh-imc printed: {stdout}"
    );

    mesh.wait_for(Duration::from_secs(10), "IMC metrics", |m| {
        let s = "service=\"imc-gateway\"";
        (metric(m, &format!("skymesh_imc_dropped_total{{reason=\"bad_crc\",{s}}}")) >= 1.0
            && metric(
                m,
                &format!("skymesh_imc_messages_total{{direction=\"in\",message=\"SetLedBrightness\",{s}}}"),
            ) >= 1.0
            && metric(m, &format!("skymesh_imc_peers{{{s}}}")) >= 1.0)
            .then_some(())
    })
    .unwrap();
    assert_eq!(mesh.service("imc-gateway").unwrap()["restarts"], 0);
    assert_eq!(mesh.service("hardware").unwrap()["restarts"], 0);
    mesh.stop(Duration::from_secs(10)).unwrap();
}

/// Waits until vehicle-sim's SERVO_OUTPUT_RAW (through autopilot-link's router)
/// shows `pwm` on output `channel` (9..=16: MAVLink 2 extension fields).
async fn wait_servo_output(gcs: &UdpSocket, channel: usize, pwm: u16) {
    assert!((9..=16).contains(&channel));
    // time_usec u32, servo1..8 u16, port u8, then servo9..16.
    let offset = 21 + 2 * (channel - 9);
    let deadline = Instant::now() + REPLY;
    let mut parser = FrameParser::new();
    let mut buf = vec![0u8; 65_536];
    let mut last = None;
    while Instant::now() < deadline {
        let Ok(Ok(n)) = tokio::time::timeout(Duration::from_secs(1), gcs.recv(&mut buf)).await
        else {
            continue;
        };
        parser.push(&buf[..n]);
        while let Some(frame) = parser.next_frame() {
            if frame.message_id() == SERVO_OUTPUT_RAW && frame.payload_byte(20) == 0 {
                let value = u16::from_le_bytes([
                    frame.payload_byte(offset),
                    frame.payload_byte(offset + 1),
                ]);
                if value == pwm {
                    return;
                }
                last = Some(value);
            }
        }
        parser.end_datagram();
    }
    panic!("SERVO_OUTPUT_RAW output {channel} never showed {pwm} µs (last {last:?})");
}

#[test]
fn imc_actuators_teleoperation_and_buttons_reach_the_vehicle() {
    let rt = runtime();
    // The ground-station socket autopilot-link's router sends to.
    let gcs = rt
        .block_on(UdpSocket::bind(SocketAddr::from(([127, 0, 0, 1], 0))))
        .unwrap();
    let gcs_port = gcs.local_addr().unwrap().port();
    let mut mesh = start(
        MeshOptions {
            imc: true,
            solo: true,
            attitude_hz: 25.0,
            link_endpoints: vec![format!("udpout:127.0.0.1:{gcs_port}")],
            ..Default::default()
        },
        &[
            "vehicle-sim",
            "autopilot-link",
            "hardware",
            "imc-gateway",
            "solo-gateway",
            "shot-engine",
        ],
    );
    rt.block_on(async {
        let bus = mesh.bus("e2e-imc").unwrap();
        let mut v = Vehicle::new(&bus);
        v.wait_ekf().await;
        let peer = peer(&mesh).await;

        // On the ground: SetServoPosition id 0 → output 9; 0.5 rad of ±π/2 over
        // 1000..2000 µs is 1659 µs.
        peer.send(&Message::SetServoPosition { id: 0, value: 0.5 })
            .await
            .unwrap();
        wait_servo_output(&gcs, 9, 1659).await;
        // SetPWM id 0 → output 10, answered PWM once autopilot-link accepted it.
        let m = ask(
            &peer,
            &Message::SetPwm {
                id: 0,
                period: 20_000,
                duty_cycle: 1300,
            },
            "PWM",
            |m| matches!(m, Message::Pwm { .. }),
        )
        .await;
        assert_eq!(
            m,
            Message::Pwm {
                id: 0,
                period: 20_000,
                duty_cycle: 1300
            }
        );
        wait_servo_output(&gcs, 10, 1300).await;

        // In the air the arbiter refuses servo outputs (servo_channels_in_flight = []).
        v.take_off(10.0).await;
        peer.send(&Message::SetServoPosition { id: 0, value: -0.5 })
            .await
            .unwrap();

        // Teleoperation: "Forward" at 10 Hz flies the vehicle along its heading.
        let start = v.now().await;
        let (sin, cos) = start.yaw_rad.sin_cos();
        let deadline = Instant::now() + Duration::from_secs(30);
        let moving = loop {
            peer.send(&Message::RemoteActions {
                actions: "Forward=1;Right=0;Up=0;Yaw=0".into(),
            })
            .await
            .unwrap();
            tokio::time::sleep(Duration::from_millis(100)).await;
            if let Some(s) = v.state.latest().unwrap() {
                if speed(&s) > 1.2 {
                    break s;
                }
            }
            assert!(
                Instant::now() < deadline,
                "remote actions never moved the vehicle"
            );
        };
        let [n, e, _] = moving.vel_ned_mps;
        let along = n * cos + e * sin;
        assert!(
            along > 0.8 * speed(&moving),
            "not moving along the heading: v=({n}, {e}), yaw {}°",
            start.yaw_rad.to_degrees()
        );
        assert!(speed(&moving) < 2.5, "max_speed_mps is 2: {moving:?}");
        // The operator stops sending: the setpoints go stale and the arbiter brakes.
        v.wait_until(
            Duration::from_secs(20),
            "braked after the stream stopped",
            |s| speed(s) < 0.3,
        )
        .await;
        mesh.wait_for(Duration::from_secs(10), "the stale brake", |m| {
            (metric(
                m,
                "skymesh_arbiter_stale_brakes_total{service=\"autopilot-link\",source=\"imc\"}",
            ) >= 1.0)
                .then_some(())
        })
        .unwrap();

        // FLY on the controller: the shot engine (no shot active) switches to LOITER.
        assert_eq!(v.status().await.flight_mode(), FlightMode::Guided);
        peer.send(&Message::ButtonEvent {
            button: 1,
            value: 1,
        })
        .await
        .unwrap();
        let deadline = Instant::now() + REPLY;
        loop {
            let s = v.status.recv_timeout(REPLY).await.unwrap();
            if s.is_some_and(|s| s.flight_mode() == FlightMode::Loiter) {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "FLY never reached the shot engine"
            );
        }
        peer.send(&Message::ButtonEvent {
            button: 1,
            value: 0,
        })
        .await
        .unwrap();
    });
    mesh.wait_for(Duration::from_secs(10), "IMC refusal metrics", |m| {
        (metric(
            m,
            "skymesh_imc_dropped_total{reason=\"refused_in_air\",service=\"imc-gateway\"}",
        ) >= 1.0)
            .then_some(())
    })
    .unwrap();
    assert_eq!(mesh.service("imc-gateway").unwrap()["restarts"], 0);
    mesh.stop(Duration::from_secs(10)).unwrap();
}
