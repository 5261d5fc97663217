//! The MAVLink router in-process: autopilot-link between vehicle-sim (or a scripted
//! fake autopilot) and ground stations on `udpin` endpoints. The ground stations
//! are built on the `mavlink` crate's own UDP connection (an implementation
//! independent of the router's framing) or on raw sockets where byte-exactness is
//! the point.

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::sim::Sim;
use common::{assert_accepted, Mesh, PATIENCE, VEHICLE};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType, ATTITUDE_DATA,
    COMMAND_LONG_DATA, HEARTBEAT_DATA, SYSTEM_TIME_DATA,
};
use mavlink::{Connectable, Connection, MavConnection, MavHeader, Message, UdpConfig, UdpMode};
use mavlink_frame::{FrameParser, RawFrame};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::endpoints::Bound;
use skymesh_autopilot_link::Settings;
use skymesh_ipc_types::{AckResult, Command, FlightMode};
use tokio::net::UdpSocket;

const GCS: (u8, u8) = (255, 190);

fn settings(autopilot_port: u16, endpoints: Vec<Endpoint>) -> Settings {
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port: autopilot_port,
    });
    s.reconnect_max = Duration::from_secs(1);
    s.endpoints = endpoints;
    s
}

/// autopilot-link on `autopilot_port` with `n` `udpin` endpoints on free ports.
async fn routed(autopilot_port: u16, n: usize) -> (Mesh, Vec<SocketAddr>) {
    let endpoints = vec![Endpoint::UdpIn("127.0.0.1:0".parse().unwrap()); n];
    let bound = Bound::bind(&endpoints).await.expect("bind endpoints");
    let addrs = bound
        .local_addrs()
        .into_iter()
        .map(|a| a.expect("udpin is bound"))
        .collect();
    let mesh = Mesh::start_routed(settings(autopilot_port, endpoints), Some(bound)).await;
    (mesh, addrs)
}

fn header((system, component): (u8, u8)) -> MavHeader {
    MavHeader {
        system_id: u32::from(system),
        component_id: component,
        sequence: 0,
    }
}

fn heartbeat(mavtype: MavType, custom_mode: u32) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode,
        mavtype,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

fn set_mode(target: (u8, u8), flags: f32, custom_mode: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        command: MavCmd::MAV_CMD_DO_SET_MODE,
        target_system: target.0,
        target_component: target.1,
        param1: flags,
        param2: custom_mode,
        ..COMMAND_LONG_DATA::DEFAULT
    })
}

const CUSTOM_MODE: f32 = 1.0; // MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
const GUIDED: u32 = 4;

/// A ground station on the `mavlink` crate's blocking UDP connection (`udpout` to
/// the router's `udpin`). Use from `spawn_blocking`.
struct Gcs {
    conn: Connection<MavMessage>,
    header: MavHeader,
    last_heartbeat: Option<Instant>,
}

impl Gcs {
    fn open(to: SocketAddr) -> Gcs {
        let mut conn = UdpConfig::new(to.to_string(), UdpMode::Udpout)
            .read_timeout(Duration::from_millis(100))
            .connect::<MavMessage>()
            .expect("gcs socket");
        conn.set_protocol_version(mavlink::MavlinkVersion::V2);
        Gcs {
            conn,
            header: header(GCS),
            last_heartbeat: None,
        }
    }

    fn send(&mut self, msg: &MavMessage) {
        self.conn.send(&self.header, msg).expect("gcs send");
        self.header.sequence = self.header.sequence.wrapping_add(1);
    }

    /// Receives until `f` returns `Some`, sending a HEARTBEAT every second as ground
    /// stations do (which is also how the router's `udpin` learns about us).
    fn wait<T>(&mut self, what: &str, mut f: impl FnMut(MavHeader, MavMessage) -> Option<T>) -> T {
        let deadline = Instant::now() + PATIENCE;
        loop {
            if self
                .last_heartbeat
                .is_none_or(|t| t.elapsed() >= Duration::from_secs(1))
            {
                self.last_heartbeat = Some(Instant::now());
                self.send(&heartbeat(MavType::MAV_TYPE_GCS, 0));
            }
            if let Ok((h, m)) = self.conn.recv() {
                if let Some(t) = f(h, m) {
                    return t;
                }
            }
            assert!(
                Instant::now() < deadline,
                "gcs: no {what} within {PATIENCE:?}"
            );
        }
    }
}

/// A ground station flies vehicle-sim through the router while autopilot-link
/// keeps publishing VehicleState and executing its own commands; a ground
/// station's COMMAND_ACK never answers one of ours.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_ground_station_flies_the_vehicle_through_the_router() {
    let sim = Sim::start(0).await;
    let (mut mesh, addrs) = routed(sim.port, 1).await;
    mesh.wait_link_up().await;
    let gcs_addr = addrs[0];

    let mut gcs = tokio::task::spawn_blocking(move || {
        let mut gcs = Gcs::open(gcs_addr);
        // The vehicle's heartbeat is forwarded, and so is ours (component 191).
        let (mut vehicle, mut companion) = (false, false);
        gcs.wait("vehicle and companion heartbeats", |h, m| {
            if let MavMessage::HEARTBEAT(hb) = m {
                let from = (h.system_id, h.component_id);
                vehicle |=
                    from == (u32::from(VEHICLE), 1) && hb.mavtype == MavType::MAV_TYPE_QUADROTOR;
                companion |= from == (u32::from(VEHICLE), 191)
                    && hb.mavtype == MavType::MAV_TYPE_ONBOARD_CONTROLLER;
            }
            (vehicle && companion).then_some(())
        });
        // GUIDED through the router: the vehicle answers and its heartbeat says so.
        gcs.send(&set_mode((VEHICLE, 1), CUSTOM_MODE, GUIDED as f32));
        let result = gcs.wait("COMMAND_ACK for DO_SET_MODE", |_, m| match m {
            MavMessage::COMMAND_ACK(a) if a.command == MavCmd::MAV_CMD_DO_SET_MODE => {
                Some(a.result)
            }
            _ => None,
        });
        assert_eq!(result, MavResult::MAV_RESULT_ACCEPTED);
        gcs.wait("a GUIDED heartbeat", |h, m| match m {
            MavMessage::HEARTBEAT(hb) if h.component_id == 1 && hb.custom_mode == GUIDED => {
                Some(())
            }
            _ => None,
        });
        gcs
    })
    .await
    .expect("gcs");
    let state = mesh
        .wait_state("state after the ground station's command", PATIENCE, |_| {
            true
        })
        .await;
    assert_eq!(state.vehicle_id, VEHICLE);

    // The same MAV_CMD from both at once: the ground station's is refused by the
    // vehicle (no custom-mode flag), ours is accepted. Each gets its own answer.
    gcs.send(&set_mode((VEHICLE, 1), 0.0, GUIDED as f32));
    let ours = mesh.command(Command::SetMode(FlightMode::Guided));
    let theirs = tokio::task::spawn_blocking(move || {
        gcs.wait("the refusal of its DO_SET_MODE", |_, m| match m {
            MavMessage::COMMAND_ACK(a)
                if a.command == MavCmd::MAV_CMD_DO_SET_MODE
                    && a.result != MavResult::MAV_RESULT_ACCEPTED =>
            {
                Some(a.result)
            }
            _ => None,
        })
    });
    assert_accepted(&ours.await, "our SetMode beside the ground station's");
    assert_eq!(theirs.await.expect("gcs"), MavResult::MAV_RESULT_DENIED);

    let label = format!("udpin:{gcs_addr}");
    assert!(
        mesh.metric(
            "skymesh_router_frames_total",
            &format!("endpoint={label},direction=in")
        ) >= 3.0
    );
    assert!(
        mesh.metric(
            "skymesh_router_frames_total",
            &format!("endpoint={label},direction=out")
        ) > 10.0
    );
    assert!(
        mesh.metric(
            "skymesh_router_frames_total",
            "endpoint=autopilot,direction=out"
        ) >= 3.0
    );
    assert_eq!(
        mesh.metric(
            "skymesh_router_endpoint_peers",
            &format!("endpoint={label}")
        ),
        1.0
    );
    mesh.stop().await;
    sim.stop().await;
}

/// Raw UDP peer of a `udpin` endpoint, reading whole frames with the router's parser.
struct Peer {
    socket: UdpSocket,
    to: SocketAddr,
    parser: FrameParser,
    buf: Vec<u8>,
}

impl Peer {
    async fn open(to: SocketAddr) -> Peer {
        Peer {
            socket: UdpSocket::bind("127.0.0.1:0").await.unwrap(),
            to,
            parser: FrameParser::new(),
            buf: vec![0; 65536],
        }
    }

    async fn send(&self, bytes: &[u8]) {
        self.socket.send_to(bytes, self.to).await.unwrap();
    }

    /// The next frame matching `pred` within `timeout`.
    async fn recv_match(
        &mut self,
        timeout: Duration,
        pred: impl Fn(&RawFrame) -> bool,
    ) -> Option<RawFrame> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            while let Some(f) = self.parser.next_frame() {
                if pred(&f) {
                    return Some(f);
                }
            }
            self.parser.end_datagram();
            let n = tokio::time::timeout_at(deadline, self.socket.recv(&mut self.buf))
                .await
                .ok()?
                .unwrap();
            self.parser.push(&self.buf[..n]);
        }
    }
}

fn encode(from: (u8, u8), msg: &MavMessage) -> Vec<u8> {
    RawFrame::encode(header(from), msg).as_bytes().to_vec()
}

/// A MAVLink 2 frame with a message id no dialect knows (the router cannot check
/// its checksum and must pass it on unchanged).
fn unknown_id_frame(from: (u8, u8)) -> Vec<u8> {
    vec![
        0xFD, 4, 0, 0, 0, from.0, from.1, 0x39, 0x30, 0x01, 9, 8, 7, 6, 0x12, 0x34,
    ]
}

/// A signed MAVLink 2 HEARTBEAT (the router neither checks nor strips signatures).
fn signed_heartbeat(from: (u8, u8)) -> Vec<u8> {
    let mut f = encode(from, &heartbeat(MavType::MAV_TYPE_GCS, 0));
    f[2] |= 0x01;
    let end = f.len() - 2;
    let crc = mavlink::calculate_crc(&f[1..end], 50);
    f[end..].copy_from_slice(&crc.to_le_bytes());
    f.extend_from_slice(&[0, 1, 2, 3, 4, 5, 6, 0xA, 0xB, 0xC, 0xD, 0xE, 0xF]);
    f
}

/// Targeted frames go where the target was last heard and nowhere else; broadcast,
/// unknown-id and signed frames go everywhere but back, byte for byte; a frame that
/// claims the vehicle's id from an endpoint is dropped as a loop.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_between_endpoints_follow_their_targets() {
    let sim = Sim::start(0).await;
    let (mut mesh, addrs) = routed(sim.port, 2).await;
    mesh.wait_link_up().await;
    let mut a = Peer::open(addrs[0]).await;
    let mut b = Peer::open(addrs[1]).await;
    let companion = (7, 1);
    let ap_out = || {
        mesh.metric(
            "skymesh_router_frames_total",
            "endpoint=autopilot,direction=out",
        )
    };

    // A introduces the ground station, B system 7 (a udpin endpoint learns its
    // peers from what they send). Each hears the other.
    let from = |f: &RawFrame, who: (u8, u8)| (f.system_id(), f.component_id()) == who;
    let hb_a = encode(GCS, &heartbeat(MavType::MAV_TYPE_GCS, 0));
    let hb_b = encode(
        companion,
        &heartbeat(MavType::MAV_TYPE_ONBOARD_CONTROLLER, 0),
    );
    let deadline = Instant::now() + PATIENCE;
    let (mut a_heard, mut b_heard) = (false, false);
    while !(a_heard && b_heard) {
        assert!(Instant::now() < deadline, "A and B do not hear each other");
        a.send(&hb_a).await;
        b.send(&hb_b).await;
        let wait = Duration::from_millis(200);
        a_heard |= a.recv_match(wait, |f| from(f, companion)).await.is_some();
        b_heard |= b.recv_match(wait, |f| from(f, GCS)).await.is_some();
    }
    // The heartbeats (broadcast) also reached the vehicle.
    let deadline = Instant::now() + PATIENCE;
    while ap_out() < 2.0 {
        assert!(
            Instant::now() < deadline,
            "heartbeats not forwarded to the autopilot"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // Let the last heartbeats reach the vehicle before counting.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let before = ap_out();

    // A → system 7 (only seen on B): B gets it byte for byte, the vehicle does not.
    let targeted = encode(GCS, &set_mode(companion, CUSTOM_MODE, 4.0));
    a.send(&targeted).await;
    let got = b
        .recv_match(PATIENCE, |f| f.message_id() == 76)
        .await
        .expect("B gets the command");
    assert_eq!(got.as_bytes(), &targeted[..]);
    // Unknown ids and signed frames are broadcast unchanged (to B and the vehicle).
    let unknown = unknown_id_frame(GCS);
    let signed = signed_heartbeat(GCS);
    a.send(&unknown).await;
    a.send(&signed).await;
    let got = b
        .recv_match(PATIENCE, |f| f.message_id() == 0x013039)
        .await
        .expect("unknown id");
    assert_eq!(got.as_bytes(), &unknown[..]);
    let got = b
        .recv_match(PATIENCE, |f| f.is_signed())
        .await
        .expect("signed frame");
    assert_eq!(got.as_bytes(), &signed[..]);
    // A frame from an endpoint that claims to be the vehicle: a loop, dropped.
    a.send(&encode(
        (VEHICLE, 1),
        &heartbeat(MavType::MAV_TYPE_QUADROTOR, 99),
    ))
    .await;
    let label_a = format!("udpin:{}", addrs[0]);
    let deadline = Instant::now() + PATIENCE;
    while mesh.metric(
        "skymesh_router_frames_dropped_total",
        &format!("endpoint={label_a},reason=loop"),
    ) < 1.0
    {
        assert!(Instant::now() < deadline, "loop not counted");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // The vehicle got the two broadcasts and not the targeted frame.
    let deadline = Instant::now() + PATIENCE;
    while ap_out() < before + 2.0 {
        assert!(
            Instant::now() < deadline,
            "broadcasts not forwarded to the autopilot"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        ap_out(),
        before + 2.0,
        "the targeted frame went to the autopilot"
    );
    // Nothing of A's ever came back to A, and the spoofed heartbeat reached nobody.
    assert!(a
        .recv_match(Duration::from_millis(300), |f| from(f, GCS))
        .await
        .is_none());
    assert!(b
        .recv_match(Duration::from_millis(300), |f| from(f, (VEHICLE, 1))
            && f.payload_byte(0) == 99)
        .await
        .is_none());
    mesh.stop().await;
    sim.stop().await;
}

/// A scripted TCP autopilot for what vehicle-sim does not send: raw frames of
/// unknown ids, signed frames, COMMAND_ACKs with target fields (as ArduPilot sends).
struct FakeAutopilot {
    port: u16,
    stop: Arc<AtomicBool>,
    /// Raw bytes for the writer thread, written as soon as they arrive.
    raw: std::sync::mpsc::Sender<Vec<u8>>,
}

type SharedStream = Arc<Mutex<std::net::TcpStream>>;

fn write(stream: &SharedStream, bytes: &[u8]) -> std::io::Result<()> {
    stream.lock().unwrap().write_all(bytes)
}

impl FakeAutopilot {
    fn start(acks: AckStyle) -> FakeAutopilot {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let stop = Arc::new(AtomicBool::new(false));
        let (raw, raw_rx) = std::sync::mpsc::channel::<Vec<u8>>();
        let flag = stop.clone();
        std::thread::spawn(move || {
            let (mut reader, _) = listener.accept().unwrap();
            reader
                .set_read_timeout(Some(Duration::from_millis(50)))
                .unwrap();
            reader.set_nodelay(true).unwrap();
            let out: SharedStream = Arc::new(Mutex::new(reader.try_clone().unwrap()));
            let writer = out.clone();
            std::thread::spawn(move || {
                for bytes in raw_rx {
                    if write(&writer, &bytes).is_err() {
                        return;
                    }
                }
            });
            let mut parser = FrameParser::new();
            let mut buf = [0u8; 4096];
            let mut last_hb = Instant::now() - Duration::from_secs(1);
            let mut seq = 0u8;
            let mut in_order: Vec<(u8, u8)> = Vec::new();
            let mut send = |msg: &MavMessage| {
                let h = MavHeader {
                    sequence: seq,
                    ..header((VEHICLE, 1))
                };
                seq = seq.wrapping_add(1);
                write(&out, RawFrame::encode(h, msg).as_bytes())
            };
            while !flag.load(Ordering::Relaxed) {
                if last_hb.elapsed() >= Duration::from_millis(200) {
                    last_hb = Instant::now();
                    let mut hb = heartbeat(MavType::MAV_TYPE_QUADROTOR, GUIDED);
                    if let MavMessage::HEARTBEAT(h) = &mut hb {
                        h.autopilot = MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA;
                        h.base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
                    }
                    let att = MavMessage::ATTITUDE(ATTITUDE_DATA::DEFAULT);
                    if send(&hb).and_then(|_| send(&att)).is_err() {
                        return;
                    }
                }
                match reader.read(&mut buf) {
                    Ok(0) => return,
                    Ok(n) => parser.push(&buf[..n]),
                    Err(_) => continue,
                }
                while let Some(f) = parser.next_frame() {
                    if f.command() != Some(MavCmd::MAV_CMD_DO_SET_MODE as u16) {
                        continue;
                    }
                    let sender = (f.system_id(), f.component_id());
                    let result = |who: (u8, u8)| {
                        if who == GCS {
                            MavResult::MAV_RESULT_DENIED
                        } else {
                            MavResult::MAV_RESULT_ACCEPTED
                        }
                    };
                    let answer = match acks {
                        // An ack addressed to a ground station (refused), then the
                        // sender's (accepted), targets filled as ArduPilot does.
                        AckStyle::Targeted => [
                            ack(MavResult::MAV_RESULT_DENIED, Some(GCS)),
                            ack(MavResult::MAV_RESULT_ACCEPTED, Some(sender)),
                        ]
                        .concat(),
                        // No targets; both answers once two commands are in flight,
                        // in the order they came.
                        AckStyle::InOrder => {
                            in_order.push(sender);
                            if in_order.len() < 2 {
                                continue;
                            }
                            std::mem::take(&mut in_order)
                                .into_iter()
                                .flat_map(|who| ack(result(who), None))
                                .collect()
                        }
                    };
                    if write(&out, &answer).is_err() {
                        return;
                    }
                }
            }
        });
        FakeAutopilot { port, stop, raw }
    }

    fn send_raw(&self, frame: Vec<u8>) {
        self.raw.send(frame).unwrap();
    }
}

impl Drop for FakeAutopilot {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// How the fake autopilot answers DO_SET_MODE.
#[derive(Debug, Clone, Copy)]
enum AckStyle {
    /// COMMAND_ACK with target fields (ArduPilot).
    Targeted,
    /// Without them (older firmware, vehicle-sim), in order of arrival.
    InOrder,
}

/// COMMAND_ACK for DO_SET_MODE; with a target, carrying the MAVLink 2 extension
/// fields ArduPilot sends (progress, result_param2, target_system, target_component).
fn ack(result: MavResult, target: Option<(u8, u8)>) -> Vec<u8> {
    let mut f = vec![0xFD, 3, 0, 0, 0, VEHICLE, 1, 77, 0, 0];
    f.extend_from_slice(&(MavCmd::MAV_CMD_DO_SET_MODE as u16).to_le_bytes());
    f.push(result as u8);
    if let Some(target) = target {
        f[1] = 10;
        f.extend_from_slice(&[0, 0, 0, 0, 0, target.0, target.1]);
    }
    let crc = mavlink::calculate_crc(&f[1..], MavMessage::extra_crc(77));
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// Frames from the autopilot reach the endpoints byte for byte whatever they are,
/// and a COMMAND_ACK addressed to a ground station never answers our command.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn autopilot_frames_pass_unchanged_and_foreign_acks_are_not_ours() {
    let fake = FakeAutopilot::start(AckStyle::Targeted);
    let (mut mesh, addrs) = routed(fake.port, 1).await;
    mesh.wait_link_up().await;
    let mut gcs = Peer::open(addrs[0]).await;
    gcs.send(&encode(GCS, &heartbeat(MavType::MAV_TYPE_GCS, 0)))
        .await;
    assert!(gcs
        .recv_match(PATIENCE, |f| f.message_id() == 0)
        .await
        .is_some());

    let unknown = unknown_id_frame((VEHICLE, 1));
    let signed = signed_heartbeat((VEHICLE, 1));
    let mut v1 = Vec::new();
    mavlink::write_v1_msg(
        &mut v1,
        header((VEHICLE, 1)),
        &MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA::DEFAULT),
    )
    .unwrap();
    fake.send_raw([unknown.clone(), signed.clone(), v1.clone()].concat());
    for (what, want) in [
        ("unknown id", &unknown),
        ("signed", &signed),
        ("MAVLink 1", &v1),
    ] {
        let got = gcs
            .recv_match(PATIENCE, |f| f.as_bytes() == &want[..])
            .await;
        assert!(got.is_some(), "{what} frame not forwarded unchanged");
    }

    let ack = mesh.command(Command::SetMode(FlightMode::Guided)).await;
    assert_eq!(
        ack.result(),
        Some(AckResult::Accepted),
        "the ground station's DENIED was taken for ours: {:?}",
        ack.detail
    );
    // The ground station still got both acks.
    let acks = [MavResult::MAV_RESULT_DENIED, MavResult::MAV_RESULT_ACCEPTED];
    for result in acks {
        let got = gcs
            .recv_match(PATIENCE, |f| {
                f.message_id() == 77 && f.payload_byte(2) == result as u8
            })
            .await;
        assert!(got.is_some(), "{result:?} ack not forwarded");
    }
    mesh.stop().await;
}

/// Without target fields in COMMAND_ACK, acks are attributed in the order the
/// commands were written: a ground station's refusal that arrives while our own
/// command with the same MAV_CMD is in flight is not taken for ours.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn untargeted_acks_are_attributed_in_command_order() {
    let fake = FakeAutopilot::start(AckStyle::InOrder);
    let (mut mesh, addrs) = routed(fake.port, 1).await;
    mesh.wait_link_up().await;
    let ap_out = |mesh: &Mesh| {
        mesh.metric(
            "skymesh_router_frames_total",
            "endpoint=autopilot,direction=out",
        )
    };
    let gcs = Peer::open(addrs[0]).await;
    // The ground station's command reaches the autopilot first…
    let before = ap_out(&mesh);
    gcs.send(&encode(GCS, &set_mode((VEHICLE, 1), 0.0, GUIDED as f32)))
        .await;
    let deadline = Instant::now() + PATIENCE;
    while ap_out(&mesh) < before + 1.0 {
        assert!(
            Instant::now() < deadline,
            "ground station command not forwarded"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // …then ours; the fake answers both in order: DENIED (theirs), ACCEPTED (ours).
    assert_accepted(
        &mesh.command(Command::SetMode(FlightMode::Guided)).await,
        "our SetMode after the ground station's",
    );
    mesh.stop().await;
}

/// Not a test: forwarding latency autopilot → endpoint (p50/p99) and throughput.
/// `cargo test -p skymesh-autopilot-link --test router -- --ignored --nocapture`
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore]
async fn bench_forwarding_latency_and_throughput() {
    let fake = FakeAutopilot::start(AckStyle::Targeted);
    let (mut mesh, addrs) = routed(fake.port, 1).await;
    mesh.wait_link_up().await;
    let mut gcs = Peer::open(addrs[0]).await;
    gcs.send(&encode(GCS, &heartbeat(MavType::MAV_TYPE_GCS, 0)))
        .await;
    assert!(gcs
        .recv_match(PATIENCE, |f| f.message_id() == 0)
        .await
        .is_some());
    let t0 = Instant::now();
    let stamp = |i: u32| {
        let msg = MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
            time_unix_usec: t0.elapsed().as_nanos() as u64,
            time_boot_ms: i,
        });
        encode((VEHICLE, 1), &msg)
    };
    let decode_stamp = |f: &RawFrame| match f.decode() {
        Ok(MavMessage::SYSTEM_TIME(s)) => Some(s),
        _ => None,
    };

    // Latency: one frame every 2 ms.
    let n = 2000u32;
    let mut latencies = Vec::new();
    for i in 0..n {
        fake.send_raw(stamp(i));
        if let Some(f) = gcs
            .recv_match(Duration::from_millis(200), |f| f.message_id() == 2)
            .await
        {
            if let Some(s) = decode_stamp(&f) {
                latencies.push(t0.elapsed().as_nanos() as u64 - s.time_unix_usec);
            }
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    latencies.sort_unstable();
    let pct = |p: f64| latencies[((latencies.len() as f64 - 1.0) * p) as usize] as f64 / 1000.0;
    println!(
        "autopilot → endpoint latency over {} frames: p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs (fake autopilot write → TCP → link → hub → udpin → test socket)",
        latencies.len(),
        pct(0.5),
        pct(0.99),
        pct(1.0)
    );

    // Throughput: paced streams at rising rates (1 s each, a chunk every 10 ms),
    // then one burst of 20 000 frames written at once.
    let drops = |mesh: &Mesh| {
        mesh.metric(
            "skymesh_router_frames_dropped_total",
            &format!("endpoint=udpin:{},reason=queue_full", addrs[0]),
        )
    };
    for rate in [1_000u32, 5_000, 10_000, 20_000] {
        let per_chunk = rate / 100;
        let drops_before = drops(&mesh);
        let start = Instant::now();
        let sender = {
            let raw = fake.raw.clone();
            let chunks: Vec<Vec<u8>> = (0..100)
                .map(|c| {
                    (0..per_chunk)
                        .flat_map(|i| stamp(c * per_chunk + i))
                        .collect()
                })
                .collect();
            std::thread::spawn(move || {
                for (c, chunk) in chunks.into_iter().enumerate() {
                    let due = start + Duration::from_millis(10 * c as u64);
                    std::thread::sleep(due.saturating_duration_since(Instant::now()));
                    if raw.send(chunk).is_err() {
                        return;
                    }
                }
            })
        };
        let mut got = 0u32;
        while gcs
            .recv_match(Duration::from_millis(300), |f| f.message_id() == 2)
            .await
            .is_some()
        {
            got += 1;
        }
        sender.join().unwrap();
        println!(
            "paced {rate} frames/s for 1 s: {got}/{rate} reached the endpoint, router queue drops {}",
            drops(&mesh) - drops_before
        );
    }
    let burst = 20_000u32;
    let frames: Vec<u8> = (0..burst).flat_map(stamp).collect();
    let drops_before = drops(&mesh);
    let start = Instant::now();
    fake.send_raw(frames);
    let mut got = 0u32;
    let mut last = start;
    while gcs
        .recv_match(Duration::from_millis(300), |f| f.message_id() == 2)
        .await
        .is_some()
    {
        got += 1;
        last = Instant::now();
    }
    let secs = (last - start).as_secs_f64();
    println!(
        "burst of {burst} frames at once: {got} reached the endpoint in {secs:.2} s = {:.0} frames/s (router queue drops: {})",
        f64::from(got) / secs,
        drops(&mesh) - drops_before
    );
    mesh.stop().await;
}

/// Context switches of every thread of this process (`/proc/self/task/*/status`),
/// by thread id: (name, voluntary + involuntary).
fn context_switches() -> std::collections::BTreeMap<u32, (String, u64)> {
    let mut out = std::collections::BTreeMap::new();
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return out;
    };
    for task in tasks.flatten() {
        let Ok(tid) = task.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(status) = std::fs::read_to_string(task.path().join("status")) else {
            continue;
        };
        let mut name = String::new();
        let mut switches = 0;
        for line in status.lines() {
            if let Some(n) = line.strip_prefix("Name:") {
                name = n.trim().to_string();
            } else if let Some(v) = line
                .strip_prefix("voluntary_ctxt_switches:")
                .or_else(|| line.strip_prefix("nonvoluntary_ctxt_switches:"))
            {
                switches += v.trim().parse::<u64>().unwrap_or(0);
            }
        }
        out.insert(tid, (name, switches));
    }
    out
}

/// Not a test: the context switches of autopilot-link (and this test's helper
/// threads) while a fake autopilot sends ~85 frames/s and the one `udpout`
/// endpoint's ground station does not listen (the default deployment, idle).
/// `cargo test -p skymesh-autopilot-link --test router -- --ignored --nocapture idle_wakeups`
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore]
async fn bench_idle_wakeups_with_a_udpout_endpoint() {
    let fake = FakeAutopilot::start(AckStyle::Targeted);
    // A port nobody listens on (as a ground station that is not running).
    let gcs_port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let endpoints = vec![Endpoint::UdpOut {
        host: "127.0.0.1".into(),
        port: gcs_port,
    }];
    let bound = Bound::bind(&endpoints).await.expect("bind endpoints");
    let mut mesh = Mesh::start_routed(settings(fake.port, endpoints), Some(bound)).await;
    mesh.wait_link_up().await;
    // The fake sends HEARTBEAT + ATTITUDE at 5 Hz; 75 more frames/s make ~85.
    let stop = Arc::new(AtomicBool::new(false));
    let pacer = {
        let (raw, stop) = (fake.raw.clone(), stop.clone());
        let frame = encode((VEHICLE, 1), &MavMessage::ATTITUDE(ATTITUDE_DATA::DEFAULT));
        std::thread::spawn(move || {
            let start = Instant::now();
            let mut i = 0u32;
            while !stop.load(Ordering::Relaxed) {
                i += 1;
                let due = start + Duration::from_secs(1) * i / 75;
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
                if raw.send(frame.clone()).is_err() {
                    return;
                }
            }
        })
    };
    let out = || {
        mesh.metric(
            "skymesh_router_frames_total",
            &format!("endpoint=udpout:127.0.0.1:{gcs_port},direction=out"),
        )
    };
    tokio::time::sleep(Duration::from_secs(2)).await;
    let window = Duration::from_secs(10);
    let (before, sent_before) = (context_switches(), out());
    // Not on a runtime worker: the test itself must not add wake-ups.
    tokio::task::block_in_place(|| std::thread::sleep(window));
    let (after, sent_after) = (context_switches(), out());
    stop.store(true, Ordering::Relaxed);
    pacer.join().unwrap();
    let secs = window.as_secs_f64();
    let mut total = 0;
    let mut rows = Vec::new();
    for (tid, (name, n)) in &after {
        let d = n - before.get(tid).map_or(0, |b| b.1);
        total += d;
        if d > 0 {
            rows.push((d, *tid, name.clone()));
        }
    }
    rows.sort_unstable_by(|a, b| b.cmp(a));
    println!(
        "{:.0} frames/s sent to the udpout endpoint; whole test process: {:.0} context switches/s",
        (sent_after - sent_before) / secs,
        total as f64 / secs
    );
    for (d, tid, name) in rows {
        println!("  {tid:>7} {name:<24} {:>6.1}/s", d as f64 / secs);
    }
    mesh.stop().await;
}
