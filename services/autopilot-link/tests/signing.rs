//! MAVLink 2 message signing on router endpoints, in-process: autopilot-link between
//! a scripted fake autopilot (which records every frame it receives) or
//! vehicle-sim and ground stations on `udpin` endpoints, one of which requires
//! signing. The signatures the tests make and check are computed here from the
//! spec (SHA-256 written out), and one vector was produced by pymavlink.

mod common;

use std::cell::Cell;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use common::sim::Sim;
use common::{Mesh, PATIENCE, VEHICLE};
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType, COMMAND_LONG_DATA,
    HEARTBEAT_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use mavlink::{MavHeader, Message};
use mavlink_frame::signing::{sign, timestamp_at, SigningKey};
use mavlink_frame::{FrameParser, RawFrame};
use sha2::{Digest, Sha256};
use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::endpoints::Bound;
use skymesh_autopilot_link::signing::SigningSettings;
use skymesh_autopilot_link::Settings;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::UdpSocket;
use tokio::sync::mpsc;

const KEY: [u8; 32] = {
    let mut k = [0u8; 32];
    let mut i = 0;
    while i < 32 {
        k[i] = i as u8;
        i += 1;
    }
    k
};
const GCS: (u8, u8) = (255, 190);
const COMMAND_LONG: u32 = 76;
const SET_POSITION_TARGET_LOCAL_NED: u32 = 84;

/// COMMAND_LONG(target 1/1, DO_SET_MODE, confirmation 0, param1 1, param2 4) from
/// 255/190, sequence 7, signed with key 00 01 … 1f, link id 3, timestamp
/// 0x0123456789ab, as pymavlink 2.4 packs it (`MAVLink.signing`, MAVLINK20=1).
const PYMAVLINK_VECTOR: &str = "fd20010007ffbe4c00000000803f000080400000000000000000000000000000000000000000b000010142f103ab89674523010141e1eebb24";

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

/// The spec's check, written out independently of the crate: the frame is a signed
/// MAVLink 2 frame of the right length, its checksum covers the new flags, and the
/// last 6 bytes are SHA-256(key ‖ every byte before them)[..6]. Returns
/// (link id, timestamp).
fn verify(key: &[u8; 32], frame: &[u8]) -> Option<(u8, u64)> {
    if frame.len() < 10 || frame[0] != 0xFD || frame[2] & 1 == 0 {
        return None;
    }
    let payload = usize::from(frame[1]);
    if frame.len() != 10 + payload + 2 + 13 {
        return None;
    }
    let id = u32::from_le_bytes([frame[7], frame[8], frame[9], 0]);
    let crc = u16::from_le_bytes([frame[10 + payload], frame[11 + payload]]);
    if mavlink::calculate_crc(&frame[1..10 + payload], MavMessage::extra_crc(id)) != crc {
        return None;
    }
    let mut h = Sha256::new();
    h.update(key);
    h.update(&frame[..frame.len() - 6]);
    let digest = h.finalize();
    if digest[..6] != frame[frame.len() - 6..] {
        return None;
    }
    let block = &frame[12 + payload..];
    let mut ts = [0u8; 8];
    ts[..6].copy_from_slice(&block[1..7]);
    Some((block[0], u64::from_le_bytes(ts)))
}

fn header(from: (u8, u8), sequence: u8) -> MavHeader {
    MavHeader {
        system_id: u32::from(from.0),
        component_id: from.1,
        sequence,
    }
}

fn heartbeat(mavtype: MavType) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 4,
        mavtype,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

/// A COMMAND_LONG whose param3 marks who sent it; `target` (0, 0) = broadcast.
fn marked_command(marker: f32, target: (u8, u8)) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        command: MavCmd::MAV_CMD_DO_SET_MODE,
        target_system: target.0,
        target_component: target.1,
        param1: 1.0,
        param2: 4.0,
        param3: marker,
        ..COMMAND_LONG_DATA::DEFAULT
    })
}

/// param3 of a COMMAND_LONG frame.
fn marker(f: &RawFrame) -> Option<f32> {
    match f.decode() {
        Ok(MavMessage::COMMAND_LONG(c)) => Some(c.param3),
        _ => None,
    }
}

fn unsigned(from: (u8, u8), msg: &MavMessage) -> Vec<u8> {
    RawFrame::encode(header(from, 0), msg).as_bytes().to_vec()
}

fn signed_with(key: [u8; 32], from: (u8, u8), msg: &MavMessage, link: u8, ts: u64) -> Vec<u8> {
    let raw = RawFrame::encode(header(from, 0), msg);
    sign(raw.as_bytes(), &SigningKey::new(key), link, ts)
        .expect("an unsigned MAVLink 2 frame")
        .as_bytes()
        .to_vec()
}

/// A ground station on a raw UDP socket, signing with its own strictly increasing
/// timestamps when it has a key.
struct Peer {
    socket: UdpSocket,
    to: SocketAddr,
    parser: FrameParser,
    buf: Vec<u8>,
    key: Option<[u8; 32]>,
    last_ts: u64,
}

impl Peer {
    async fn open(to: SocketAddr, key: Option<[u8; 32]>) -> Peer {
        Peer {
            socket: UdpSocket::bind("127.0.0.1:0").await.unwrap(),
            to,
            parser: FrameParser::new(),
            buf: vec![0; 65536],
            key,
            last_ts: 0,
        }
    }

    async fn send_raw(&self, bytes: &[u8]) {
        self.socket.send_to(bytes, self.to).await.unwrap();
    }

    /// Sends `msg` from the ground station, signed (link id 7) if the peer has a key;
    /// returns the bytes sent.
    async fn send(&mut self, msg: &MavMessage) -> Vec<u8> {
        let bytes = match self.key {
            Some(key) => {
                self.last_ts = (self.last_ts + 1).max(timestamp_at(SystemTime::now()));
                signed_with(key, GCS, msg, 7, self.last_ts)
            }
            None => unsigned(GCS, msg),
        };
        self.send_raw(&bytes).await;
        bytes
    }

    /// The next frame matching `pred` within [`PATIENCE`]; every frame received on
    /// the way is handed to `seen`.
    async fn recv_match(
        &mut self,
        what: &str,
        mut seen: impl FnMut(&RawFrame),
        pred: impl Fn(&RawFrame) -> bool,
    ) -> RawFrame {
        let deadline = tokio::time::Instant::now() + PATIENCE;
        loop {
            while let Some(f) = self.parser.next_frame() {
                seen(&f);
                if pred(&f) {
                    return f;
                }
            }
            self.parser.end_datagram();
            let n = tokio::time::timeout_at(deadline, self.socket.recv(&mut self.buf))
                .await
                .unwrap_or_else(|_| panic!("no {what} within {PATIENCE:?}"))
                .unwrap();
            self.parser.push(&self.buf[..n]);
        }
    }
}

/// A TCP "autopilot" (system 1, component 1): unsigned HEARTBEATs at 5 Hz, and every
/// frame it receives on `received`.
struct FakeAutopilot {
    port: u16,
    received: mpsc::UnboundedReceiver<RawFrame>,
    stop: Arc<AtomicBool>,
}

impl FakeAutopilot {
    fn start() -> FakeAutopilot {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, received) = mpsc::unbounded_channel();
        let flag = stop.clone();
        std::thread::spawn(move || {
            let (mut stream, _) = listener.accept().unwrap();
            stream
                .set_read_timeout(Some(Duration::from_millis(50)))
                .unwrap();
            let mut parser = FrameParser::new();
            let mut buf = [0u8; 4096];
            let mut last_hb = Instant::now() - Duration::from_secs(1);
            let mut seq = 0u8;
            while !flag.load(Ordering::Relaxed) {
                if last_hb.elapsed() >= Duration::from_millis(200) {
                    last_hb = Instant::now();
                    let hb = RawFrame::encode(
                        header((VEHICLE, 1), seq),
                        &heartbeat(MavType::MAV_TYPE_QUADROTOR),
                    );
                    seq = seq.wrapping_add(1);
                    if stream.write_all(hb.as_bytes()).is_err() {
                        return;
                    }
                }
                match stream.read(&mut buf) {
                    Ok(0) => return,
                    Ok(n) => parser.push(&buf[..n]),
                    Err(_) => continue,
                }
                while let Some(f) = parser.next_frame() {
                    if tx.send(f).is_err() {
                        return;
                    }
                }
            }
        });
        FakeAutopilot {
            port,
            received,
            stop,
        }
    }

    /// Waits for a frame matching `pred`; every frame received on the way goes to `log`.
    async fn expect(
        &mut self,
        what: &str,
        log: &mut Vec<RawFrame>,
        pred: impl Fn(&RawFrame) -> bool,
    ) -> RawFrame {
        let deadline = tokio::time::Instant::now() + PATIENCE;
        loop {
            let f = tokio::time::timeout_at(deadline, self.received.recv())
                .await
                .ok()
                .flatten()
                .unwrap_or_else(|| panic!("the autopilot got no {what} within {PATIENCE:?}"));
            log.push(f);
            if pred(&f) {
                return f;
            }
        }
    }
}

impl Drop for FakeAutopilot {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// autopilot-link on `autopilot_port` with two `udpin` endpoints on free ports:
/// endpoint 0 requires signing, endpoint 1 does not.
async fn signed_mesh(autopilot_port: u16) -> (Mesh, SocketAddr, SocketAddr) {
    let endpoints = vec![Endpoint::UdpIn("127.0.0.1:0".parse().unwrap()); 2];
    let bound = Bound::bind(&endpoints).await.expect("bind endpoints");
    let addrs: Vec<SocketAddr> = bound
        .local_addrs()
        .into_iter()
        .map(|a| a.expect("udpin is bound"))
        .collect();
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port: autopilot_port,
    });
    s.reconnect_max = Duration::from_secs(1);
    s.endpoints = endpoints;
    s.signing = Some(SigningSettings {
        key: SigningKey::new(KEY),
        endpoints: vec![0],
    });
    let mesh = Mesh::start_routed(s, Some(bound)).await;
    (mesh, addrs[0], addrs[1])
}

fn dropped(mesh: &Mesh, at: SocketAddr, reason: &str) -> f64 {
    mesh.metric(
        "skymesh_router_frames_dropped_total",
        &format!("endpoint=udpin:{at},reason={reason}"),
    )
}

/// Our signer reproduces pymavlink's bytes, the written-out check accepts them,
/// and the parsers a forwarded signed frame meets (ours, vehicle-sim's) take it.
#[test]
fn signatures_match_pymavlink_and_the_spec_written_out() {
    let want = hex(PYMAVLINK_VECTOR);
    let raw = RawFrame::encode(header(GCS, 7), &marked_command(0.0, (1, 1)));
    let ours = sign(raw.as_bytes(), &SigningKey::new(KEY), 3, 0x0123_4567_89ab).unwrap();
    assert_eq!(ours.as_bytes(), &want[..]);
    assert_eq!(verify(&KEY, &want), Some((3, 0x0123_4567_89ab)));
    let mut other = KEY;
    other[31] ^= 1;
    assert_eq!(verify(&other, &want), None);
    // A few more, across message ids and lengths, against the written-out check.
    for (i, msg) in [
        heartbeat(MavType::MAV_TYPE_GCS),
        marked_command(2.5, (0, 0)),
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA::DEFAULT),
    ]
    .iter()
    .enumerate()
    {
        let f = signed_with(KEY, (9, 9), msg, i as u8, 1_000 + i as u64);
        assert_eq!(verify(&KEY, &f), Some((i as u8, 1_000 + i as u64)), "{i}");
    }

    let mut parser = FrameParser::new();
    parser.push(&want);
    let f = parser
        .next_frame()
        .expect("our parser takes a signed frame");
    assert!(f.is_signed());
    assert_eq!(marker(&f), Some(0.0));
    let mut decoder = mavlink_frame::FrameDecoder::new();
    decoder.push(&want);
    match decoder.next_frame() {
        Some(Ok(mavlink_frame::Inbound::Message { msg, header, .. })) => {
            assert_eq!(msg.message_id(), COMMAND_LONG);
            assert_eq!((header.system_id, header.component_id), (255, 190));
        }
        other => panic!("vehicle-sim refused a signed frame: {other:?}"),
    }
}

/// On the signing endpoint an unauthorised peer (unsigned, wrong key, MAVLink 1, a
/// replayed frame, a stale timestamp) cannot command the vehicle or reach the other
/// endpoint, and each refusal is counted by reason; the correctly signed ground
/// station's commands reach the autopilot; what we send it verifies with the key;
/// the unsigned endpoint next to it works as before.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_signed_peers_command_the_vehicle_through_a_signing_endpoint() {
    let mut fake = FakeAutopilot::start();
    let (mut mesh, signed_at, open_at) = signed_mesh(fake.port).await;
    mesh.wait_link_up().await;
    let mut log = Vec::new();

    // The signed ground station joins and hears the vehicle, signed by us.
    let mut gcs = Peer::open(signed_at, Some(KEY)).await;
    gcs.send(&heartbeat(MavType::MAV_TYPE_GCS)).await;
    let mut to_gcs: Vec<RawFrame> = Vec::new();
    let heard = [Cell::new(false), Cell::new(false)];
    gcs.recv_match(
        "vehicle and companion heartbeats",
        |f| {
            to_gcs.push(*f);
            if f.message_id() == 0 && f.system_id() == VEHICLE {
                heard[0].set(heard[0].get() || f.component_id() == 1);
                heard[1].set(heard[1].get() || f.component_id() == 191);
            }
        },
        |_| heard[0].get() && heard[1].get(),
    )
    .await;
    // An open ground station on the other endpoint.
    let mut open = Peer::open(open_at, None).await;
    open.send(&heartbeat(MavType::MAV_TYPE_GCS)).await;
    open.recv_match("a vehicle heartbeat", |_| {}, |f| f.message_id() == 0)
        .await;

    // A correctly signed command (broadcast) reaches the autopilot as sent, and
    // the open endpoint.
    let first = gcs.send(&marked_command(1.0, (0, 0))).await;
    let got = fake
        .expect("the signed command", &mut log, |f| marker(f) == Some(1.0))
        .await;
    assert_eq!(got.as_bytes(), &first[..], "forwarded as received");
    open.recv_match("the signed command", |_| {}, |f| marker(f) == Some(1.0))
        .await;

    // The attacker, on the signing endpoint.
    let attacker = Peer::open(signed_at, None).await;
    let now = timestamp_at(SystemTime::now());
    let mut wrong_key = KEY;
    wrong_key[0] ^= 0x80;
    let mut v1 = Vec::new();
    mavlink::write_v1_msg(&mut v1, header(GCS, 0), &marked_command(103.0, (0, 0))).unwrap();
    let setpoint = MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        target_system: VEHICLE,
        target_component: 1,
        vx: 5.0,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::DEFAULT
    });
    for (reason, bytes) in [
        ("unsigned", unsigned(GCS, &marked_command(101.0, (0, 0)))),
        ("unsigned", unsigned(GCS, &setpoint)),
        (
            "bad_signature",
            signed_with(
                wrong_key,
                GCS,
                &marked_command(102.0, (0, 0)),
                7,
                now + 1_000_000,
            ),
        ),
        ("mavlink1", v1),
        // The ground station's own frame, captured and sent again.
        ("replayed", first.clone()),
        // A correctly signed frame of a new stream, more than a minute old.
        (
            "stale_timestamp",
            signed_with(
                KEY,
                (250, 190),
                &marked_command(105.0, (0, 0)),
                7,
                now - 120 * 100_000,
            ),
        ),
    ] {
        let before = dropped(&mesh, signed_at, reason);
        attacker.send_raw(&bytes).await;
        let deadline = Instant::now() + PATIENCE;
        while dropped(&mesh, signed_at, reason) < before + 1.0 {
            assert!(Instant::now() < deadline, "no {reason} drop counted");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }
    for (reason, n) in [
        ("unsigned", 2.0),
        ("bad_signature", 1.0),
        ("mavlink1", 1.0),
        ("replayed", 1.0),
        ("stale_timestamp", 1.0),
    ] {
        assert_eq!(dropped(&mesh, signed_at, reason), n, "{reason}");
    }
    // The attacker did not become a peer of the endpoint (nothing is sent to it).
    assert_eq!(
        mesh.metric(
            "skymesh_router_endpoint_peers",
            &format!("endpoint=udpin:{signed_at}")
        ),
        1.0
    );

    // The ground station's next command arrives; nothing of the attacker's did.
    gcs.send(&marked_command(2.0, (0, 0))).await;
    fake.expect("the second signed command", &mut log, |f| {
        marker(f) == Some(2.0)
    })
    .await;
    let mut at_open = Vec::new();
    open.recv_match(
        "the second signed command",
        |f| at_open.extend(marker(f)),
        |f| marker(f) == Some(2.0),
    )
    .await;
    // (Our own commands to the autopilot come from 1/191.)
    let markers: Vec<f32> = log
        .iter()
        .filter(|f| f.system_id() != VEHICLE)
        .filter_map(marker)
        .collect();
    assert_eq!(
        markers,
        vec![1.0, 2.0],
        "only the signed commands reached the autopilot"
    );
    assert!(
        log.iter()
            .all(|f| f.message_id() != SET_POSITION_TARGET_LOCAL_NED),
        "an unsigned setpoint reached the autopilot"
    );
    assert!(
        at_open.iter().all(|m| *m < 100.0),
        "an attacker's frame reached the open endpoint: {at_open:?}"
    );

    // The open endpoint is unaffected: its unsigned command reaches the autopilot,
    // and the signed ground station gets it signed by us.
    open.send(&marked_command(50.0, (0, 0))).await;
    fake.expect("the open endpoint's command", &mut log, |f| {
        marker(f) == Some(50.0)
    })
    .await;
    gcs.recv_match(
        "the open endpoint's command",
        |f| to_gcs.push(*f),
        |f| marker(f) == Some(50.0),
    )
    .await;
    assert_eq!(dropped(&mesh, open_at, "unsigned"), 0.0);

    // Everything we sent to the signing endpoint verifies with the key, with our
    // link id (endpoint 0) and strictly increasing timestamps.
    assert!(to_gcs.len() >= 3, "{to_gcs:?}");
    let mut last = 0;
    for f in &to_gcs {
        let (link, ts) = verify(&KEY, f.as_bytes())
            .unwrap_or_else(|| panic!("{f:?} does not verify with the key"));
        assert_eq!(link, 0, "{f:?}");
        assert!(ts > last, "timestamps must increase: {ts} after {last}");
        last = ts;
    }
    assert!(to_gcs.iter().any(|f| f.component_id() == 1));
    assert!(to_gcs.iter().any(|f| f.component_id() == 191));
    mesh.stop().await;
}

/// vehicle-sim executes a command from a signed ground station that the router
/// forwards with its signature, and the answer reaches the ground station signed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_signed_ground_station_commands_vehicle_sim() {
    let sim = Sim::start(0).await;
    let (mut mesh, signed_at, _) = signed_mesh(sim.port).await;
    mesh.wait_link_up().await;
    let mut gcs = Peer::open(signed_at, Some(KEY)).await;
    gcs.send(&heartbeat(MavType::MAV_TYPE_GCS)).await;
    gcs.recv_match(
        "a vehicle heartbeat",
        |_| {},
        |f| f.message_id() == 0 && f.component_id() == 1,
    )
    .await;
    gcs.send(&marked_command(0.0, (VEHICLE, 1))).await;
    let ack = gcs
        .recv_match(
            "COMMAND_ACK",
            |_| {},
            |f| {
                f.message_id() == 77
                    && u16::from_le_bytes([f.payload_byte(0), f.payload_byte(1)])
                        == MavCmd::MAV_CMD_DO_SET_MODE as u16
            },
        )
        .await;
    assert_eq!(ack.payload_byte(2), MavResult::MAV_RESULT_ACCEPTED as u8);
    assert!(
        verify(&KEY, ack.as_bytes()).is_some(),
        "ack not signed by us"
    );
    mesh.stop().await;
    sim.stop().await;
}

/// autopilot-link on `autopilot_port` with a signing `udpin` (endpoint 0), a
/// signing `tcpin` (endpoint 1) and an open `udpin` (endpoint 2), on free ports.
async fn signed_tcp_mesh(autopilot_port: u16) -> (Mesh, [SocketAddr; 3]) {
    let any: SocketAddr = "127.0.0.1:0".parse().unwrap();
    let endpoints = vec![
        Endpoint::UdpIn(any),
        Endpoint::TcpIn(any),
        Endpoint::UdpIn(any),
    ];
    let bound = Bound::bind(&endpoints).await.expect("bind endpoints");
    let addrs: Vec<SocketAddr> = bound
        .local_addrs()
        .into_iter()
        .map(|a| a.expect("bound"))
        .collect();
    let mut s = Settings::with_connection(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port: autopilot_port,
    });
    s.reconnect_max = Duration::from_secs(1);
    s.endpoints = endpoints;
    s.signing = Some(SigningSettings {
        key: SigningKey::new(KEY),
        endpoints: vec![0, 1],
    });
    let mesh = Mesh::start_routed(s, Some(bound)).await;
    (mesh, [addrs[0], addrs[1], addrs[2]])
}

/// Waits until `name{labels}` is at least `min`.
async fn until_metric(mesh: &Mesh, name: &str, labels: &str, min: f64) {
    let deadline = Instant::now() + PATIENCE;
    while mesh.metric(name, labels) < min {
        assert!(
            Instant::now() < deadline,
            "{name}{{{labels}}} = {}, expected {min}",
            mesh.metric(name, labels)
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Reads what the TCP client has been sent so far without waiting for more.
fn take_received(client: &tokio::net::TcpStream, into: &mut Vec<u8>) {
    let mut buf = [0u8; 4096];
    loop {
        match client.try_read(&mut buf) {
            Ok(0) => panic!("the endpoint closed the connection"),
            Ok(n) => into.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return,
            Err(e) => panic!("read: {e}"),
        }
    }
}

/// Vehicle HEARTBEATs seen by `peer` from now on: `n` of them prove the router
/// routed at least `n` frames to its endpoints meanwhile (the autopilot sends 5/s).
async fn routed_heartbeats(peer: &mut Peer, n: usize) {
    // What was already received does not count.
    while peer.parser.next_frame().is_some() {}
    peer.parser.end_datagram();
    while peer.socket.try_recv(&mut peer.buf).is_ok() {}
    let count = Cell::new(0);
    peer.recv_match(
        "vehicle heartbeats",
        |f| {
            if f.message_id() == 0 && f.system_id() == VEHICLE && f.component_id() == 1 {
                count.set(count.get() + 1);
            }
        },
        |_| count.get() >= n,
    )
    .await;
}

/// A client of a signing `tcpin` endpoint is sent nothing — while the vehicle's
/// heartbeats flow to the other endpoints — until it delivers a validly signed
/// frame (an unsigned one does not count); then it gets the vehicle's frames,
/// signed. A frame the signed ground station sent on the `udpin` endpoint,
/// replayed on the `tcpin` endpoint, is refused as `replayed` (one replay table
/// for every endpoint) and never reaches the autopilot twice.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tcpin_client_gets_nothing_before_signing_and_replays_cross_no_endpoint() {
    let mut fake = FakeAutopilot::start();
    let (mut mesh, [udp_at, tcp_at, open_at]) = signed_tcp_mesh(fake.port).await;
    mesh.wait_link_up().await;
    let mut log = Vec::new();
    let tcp_label = format!("endpoint=tcpin:{tcp_at}");

    // The open ground station proves frames are routed while we watch the TCP client.
    let mut open = Peer::open(open_at, None).await;
    open.send(&heartbeat(MavType::MAV_TYPE_GCS)).await;
    routed_heartbeats(&mut open, 1).await;

    let mut client = tokio::net::TcpStream::connect(tcp_at).await.unwrap();
    until_metric(&mesh, "skymesh_router_endpoint_peers", &tcp_label, 1.0).await;
    let mut got = Vec::new();
    routed_heartbeats(&mut open, 3).await;
    take_received(&client, &mut got);
    assert!(got.is_empty(), "sent {} bytes before any frame", got.len());

    // An unsigned frame does not open the stream.
    client
        .write_all(&unsigned(GCS, &heartbeat(MavType::MAV_TYPE_GCS)))
        .await
        .unwrap();
    until_metric(
        &mesh,
        "skymesh_router_frames_dropped_total",
        &format!("{tcp_label},reason=unsigned"),
        1.0,
    )
    .await;
    routed_heartbeats(&mut open, 3).await;
    take_received(&client, &mut got);
    assert!(
        got.is_empty(),
        "sent {} bytes after an unsigned frame",
        got.len()
    );

    // The signed ground station on the udpin endpoint sends a command; replayed on
    // the tcpin endpoint it is refused, and the client is still sent nothing.
    let mut gcs = Peer::open(udp_at, Some(KEY)).await;
    let first = gcs.send(&marked_command(1.0, (0, 0))).await;
    fake.expect("the signed command", &mut log, |f| marker(f) == Some(1.0))
        .await;
    client.write_all(&first).await.unwrap();
    until_metric(
        &mesh,
        "skymesh_router_frames_dropped_total",
        &format!("{tcp_label},reason=replayed"),
        1.0,
    )
    .await;
    routed_heartbeats(&mut open, 3).await;
    take_received(&client, &mut got);
    assert!(
        got.is_empty(),
        "sent {} bytes after a replayed frame",
        got.len()
    );

    // A validly signed frame of the client's own: from now on it hears the vehicle,
    // every frame signed by us with the endpoint's link id (1).
    let ts = timestamp_at(SystemTime::now()) + 1;
    let own = signed_with(KEY, (254, 190), &marked_command(2.0, (0, 0)), 9, ts);
    client.write_all(&own).await.unwrap();
    fake.expect("the tcp client's command", &mut log, |f| {
        marker(f) == Some(2.0)
    })
    .await;
    let mut parser = FrameParser::new();
    let mut buf = [0u8; 4096];
    let heartbeat = tokio::time::timeout(PATIENCE, async {
        loop {
            let n = client.read(&mut buf).await.unwrap();
            assert!(n > 0, "closed");
            parser.push(&buf[..n]);
            while let Some(f) = parser.next_frame() {
                let (link, _) = verify(&KEY, f.as_bytes())
                    .unwrap_or_else(|| panic!("{f:?} is not signed with the key"));
                assert_eq!(link, 1);
                // The autopilot's (component 1), not autopilot-link's own
                // heartbeat, which goes out as the same system from component 191.
                if f.message_id() == 0 && f.system_id() == VEHICLE && f.component_id() == 1 {
                    return f;
                }
            }
        }
    })
    .await
    .expect("a vehicle heartbeat on the authenticated tcp client");
    assert_eq!(heartbeat.component_id(), 1);

    // The replayed command reached the autopilot once.
    let markers: Vec<f32> = log
        .iter()
        .filter(|f| f.system_id() != VEHICLE)
        .filter_map(marker)
        .collect();
    assert_eq!(markers, vec![1.0, 2.0]);
    drop(client);
    mesh.stop().await;
}
