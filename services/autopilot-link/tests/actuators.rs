//! Actuator commands through the real path: bus → arbiter → MAVLink → vehicle-sim,
//! and the servo outputs back to a ground station through the router. In-process:
//! real TCP and UDP on 127.0.0.1, real iceoryx2 shared memory in a domain of its own.

mod common;

use std::net::SocketAddr;
use std::time::Duration;

use common::arbiter::assert_result;
use common::sim::Sim;
use common::{assert_accepted, Mesh, PATIENCE};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA, SERVO_OUTPUT_RAW_DATA,
};
use mavlink::{MavHeader, MessageData};
use mavlink_frame::{FrameParser, RawFrame};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::endpoints::Bound;
use skymesh_autopilot_link::Settings;
use skymesh_ipc_types::{AckResult, Command, CommandSource, RefusalReason, ZoomMode};
use tokio::net::UdpSocket;

fn settings(port: u16) -> Settings {
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    });
    s.reconnect_max = Duration::from_secs(1);
    s
}

fn servo(channel: u8, pwm_us: u16) -> Command {
    Command::Servo { channel, pwm_us }
}

fn motor_test(motor: u8) -> Command {
    Command::MotorTest {
        motor,
        throttle_pct: 20.0,
        duration_s: 1.0,
    }
}

fn refused_in_air(ack: &skymesh_ipc_types::CommandAck, what: &str) {
    assert_result(ack, AckResult::Refused, what);
    assert_eq!(
        ack.reason(),
        Some(RefusalReason::InAir),
        "{what}: {:?}",
        ack.detail
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn actuators_run_on_the_ground_and_in_the_air_only_as_configured() {
    use CommandSource::{Imc, Operator, Safety};
    let sim = Sim::start(0).await;
    let mut s = settings(sim.port);
    s.arbiter.servo_channels_in_flight = vec![10];
    let mut mesh = Mesh::start_with(s).await;
    mesh.wait_link_up().await;
    mesh.wait_status("a healthy EKF and home", |s| {
        s.ekf_healthy == 1 && s.home_valid == 1
    })
    .await;

    // On the ground every actuator command reaches the vehicle.
    assert_accepted(&mesh.command_as(Imc, servo(9, 1900)).await, "servo 9");
    assert_accepted(&mesh.command_as(Imc, servo(10, 1100)).await, "servo 10");
    let zoom = Command::CameraZoom {
        camera: 1,
        mode: ZoomMode::Range,
        value: 40.0,
    };
    assert_accepted(&mesh.command_as(Imc, zoom).await, "zoom");
    // The autopilot refuses a servo on a motor output (the arbiter does not know
    // the airframe): the refusal is the autopilot's.
    let ack = mesh.command_as(Imc, servo(2, 1500)).await;
    assert_eq!(
        ack.reason(),
        Some(RefusalReason::Failed),
        "{:?}",
        ack.detail
    );

    mesh.take_off(2.0).await;
    // In the air: servo 9 is not allowed, servo 10 is, zoom always is.
    refused_in_air(&mesh.command_as(Imc, servo(9, 1000)).await, "servo 9");
    assert_accepted(&mesh.command_as(Imc, servo(10, 1900)).await, "servo 10");
    assert_accepted(&mesh.command_as(Imc, zoom).await, "zoom in the air");
    // A motor test never, from whoever holds flight authority or outranks it.
    refused_in_air(&mesh.command_as(Operator, motor_test(1)).await, "operator");
    refused_in_air(&mesh.command_as(Safety, motor_test(2)).await, "safety");

    // Landed and disarmed (LAND disarms on touch-down), the motor test runs.
    assert_accepted(&mesh.command_as(Operator, Command::Land).await, "land");
    mesh.wait_status("disarmed", |s| !s.is_armed()).await;
    assert_accepted(
        &mesh.command_as(Operator, motor_test(3)).await,
        "motor test on the ground",
    );

    let decisions = "skymesh_arbiter_decisions_total";
    assert_eq!(
        mesh.metric(decisions, "source=imc,decision=refused,reason=in_air"),
        1.0
    );
    assert_eq!(
        mesh.metric(decisions, "source=safety,decision=refused,reason=in_air"),
        1.0
    );
    assert_eq!(
        mesh.metric(decisions, "source=operator,decision=refused,reason=in_air"),
        1.0
    );
    mesh.stop().await;
    sim.stop().await;
}

/// A raw UDP ground station on a `udpin` endpoint, reading frames with the
/// router's own parser.
struct Gcs {
    socket: UdpSocket,
    to: SocketAddr,
    parser: FrameParser,
    buf: Vec<u8>,
    last_hello: tokio::time::Instant,
}

impl Gcs {
    async fn open(to: SocketAddr) -> Gcs {
        let socket = UdpSocket::bind("127.0.0.1:0").await.expect("gcs socket");
        let mut gcs = Gcs {
            socket,
            to,
            parser: FrameParser::new(),
            buf: vec![0; 65536],
            last_hello: tokio::time::Instant::now(),
        };
        gcs.heartbeat().await;
        gcs
    }

    /// The endpoint sends to whoever it heard from in the last 15 s: say hello, as
    /// ground stations do once a second.
    async fn heartbeat(&mut self) {
        self.last_hello = tokio::time::Instant::now();
        let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_GCS,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        });
        let header = MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: 0,
        };
        let frame = RawFrame::encode(header, &heartbeat);
        self.socket
            .send_to(frame.as_bytes(), self.to)
            .await
            .expect("gcs send");
    }

    /// Waits for a SERVO_OUTPUT_RAW whose outputs 1..=16 satisfy `pred`.
    async fn servo_outputs(&mut self, what: &str, pred: impl Fn(&[u16; 16]) -> bool) {
        let deadline = tokio::time::Instant::now() + PATIENCE;
        loop {
            while let Some(f) = self.parser.next_frame() {
                if f.message_id() != SERVO_OUTPUT_RAW_DATA::ID {
                    continue;
                }
                // time_usec (4 bytes), then 16 outputs of 2 bytes; 9..=16 are
                // MAVLink 2 extensions, truncated zeros read as 0.
                let mut out = [0u16; 16];
                for (i, pwm) in out.iter_mut().enumerate() {
                    let at = if i < 8 { 4 + 2 * i } else { 21 + 2 * (i - 8) };
                    *pwm = u16::from_le_bytes([f.payload_byte(at), f.payload_byte(at + 1)]);
                }
                if pred(&out) {
                    return;
                }
            }
            self.parser.end_datagram();
            assert!(
                tokio::time::Instant::now() < deadline,
                "no SERVO_OUTPUT_RAW with {what} within {PATIENCE:?}"
            );
            if self.last_hello.elapsed() >= Duration::from_secs(1) {
                self.heartbeat().await;
            }
            let wait =
                tokio::time::timeout(Duration::from_secs(1), self.socket.recv(&mut self.buf));
            if let Ok(n) = wait.await {
                let n = n.expect("gcs recv");
                self.parser.push(&self.buf[..n]);
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ground_station_sees_the_servo_outputs_without_asking() {
    let sim = Sim::start(0).await;
    let endpoints = vec![Endpoint::UdpIn("127.0.0.1:0".parse().expect("address"))];
    let bound = Bound::bind(&endpoints).await.expect("bind endpoints");
    let gcs_addr = bound.local_addrs()[0].expect("udpin is bound");
    let mut s = settings(sim.port);
    s.endpoints = endpoints;
    let mut mesh = Mesh::start_routed(s, Some(bound)).await;
    mesh.wait_link_up().await;
    let mut gcs = Gcs::open(gcs_addr).await;
    gcs.servo_outputs("idle motors", |o| o[..4] == [1000; 4])
        .await;

    assert_accepted(
        &mesh.command_as(CommandSource::Imc, servo(9, 1900)).await,
        "servo 9",
    );
    gcs.servo_outputs("servo 9 at 1900 µs", |o| o[8] == 1900)
        .await;
    assert_accepted(
        &mesh.command_as(CommandSource::Imc, motor_test(2)).await,
        "motor test",
    );
    gcs.servo_outputs("motor 2 at 20 %", |o| o[..4] == [1000, 1200, 1000, 1000])
        .await;
    gcs.servo_outputs("the test over", |o| o[..4] == [1000; 4])
        .await;
    mesh.stop().await;
    sim.stop().await;
}
