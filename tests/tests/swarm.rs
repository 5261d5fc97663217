//! GroundControl swarm end to end (issue 7): five simulated drones (one vehicle-sim
//! in swarm mode, one autopilot-link per vehicle), the swarm queue and the
//! GroundControl gateway, driven by test clients on the real protocol — 32-byte
//! records over TCP to the state server, 84-byte pose records in UDP datagrams from
//! the broadcast.
//!
//! One mesh for everything. The gateway's privileged list is `127.0.0.2` only: the
//! client connecting from 127.0.0.1 is not privileged (its EMERGENCY_MODE is refused
//! and counted, never obeyed); the one connecting from 127.0.0.2 is (its
//! EMERGENCY_MODE is obeyed).
//!
//! Drones 1..=5 fly vehicles 1..=5, homes on a 3 m grid (three per row going east,
//! rows going north) around the site origin = vehicle 1's home; distances flown are a
//! few metres. Waits are generous; nothing asserts a duration.

use std::collections::VecDeque;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

use gc_proto::{NetCmdType as T, Record, RECORD_LEN};
use skymesh_e2e::{Mesh, MeshOptions, HOME};
use skymesh_ipc_types::{
    drone_flags, topics, AckResult, ArbiterEvent, ArbiterEventKind, Command, CommandAck,
    CommandSource, FlightMode, SwarmState, VehicleCommand, VehicleState,
};
use skymesh_runtime::{Bus, Subscriber};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::{TcpSocket, UdpSocket};
use tokio::sync::mpsc;
use tokio::time::Instant;

const N: u8 = 5;
const STARTUP: Duration = Duration::from_secs(60);
/// Any one step: generous, the 2-core machine runs nine processes.
const WAIT: Duration = Duration::from_secs(45);
/// Takeoff height of the swarm queue's default config, m.
const TAKEOFF_ALT: f32 = 2.5;
const SPACING: f32 = 3.0;

/// Drone `id`'s home in the site frame (x east, y north): the sim's grid of
/// ⌈√5⌉ = 3 columns.
fn home_xy(id: u8) -> [f32; 2] {
    let i = usize::from(id - 1);
    [(i % 3) as f32 * SPACING, (i / 3) as f32 * SPACING]
}

// ---------------------------------------------------------------------------
// The state server client: raw 32-byte records.

struct GcClient {
    write: OwnedWriteHalf,
    /// Records as a background task read them, stamped on arrival.
    incoming: mpsc::UnboundedReceiver<(Instant, Record)>,
    /// Records read but not yet consumed, in arrival order.
    inbox: VecDeque<(Instant, Record)>,
    /// Every record ever read (for "this never came" checks).
    seen: Vec<Record>,
}

impl GcClient {
    async fn connect_from(from: Ipv4Addr, port: u16) -> GcClient {
        let socket = TcpSocket::new_v4().unwrap();
        socket.bind(SocketAddr::new(IpAddr::V4(from), 0)).unwrap();
        let stream = socket
            .connect(SocketAddr::from(([127, 0, 0, 1], port)))
            .await
            .unwrap();
        stream.set_nodelay(true).unwrap();
        let (mut read, write) = stream.into_split();
        let (tx, incoming) = mpsc::unbounded_channel();
        // Read all the time, so an arrival time is when the record came, whatever
        // the test was doing then.
        tokio::spawn(async move {
            let mut buf = Vec::new();
            let mut chunk = [0u8; 4096];
            while let Ok(n) = read.read(&mut chunk).await {
                if n == 0 {
                    break;
                }
                let now = Instant::now();
                buf.extend_from_slice(&chunk[..n]);
                while buf.len() >= RECORD_LEN {
                    let rec = Record::from_prefix(&buf).unwrap();
                    buf.drain(..RECORD_LEN);
                    if tx.send((now, rec)).is_err() {
                        return;
                    }
                }
            }
        });
        GcClient {
            write,
            incoming,
            inbox: VecDeque::new(),
            seen: Vec::new(),
        }
    }

    async fn send(&mut self, records: &[Record]) {
        let bytes: Vec<u8> = records.iter().flat_map(|r| r.encode()).collect();
        assert_eq!(bytes.len(), records.len() * RECORD_LEN);
        self.write.write_all(&bytes).await.unwrap();
    }

    fn take(&mut self, r: (Instant, Record)) {
        self.seen.push(r.1);
        self.inbox.push_back(r);
    }

    /// Waits `d`, then moves everything that arrived into the inbox.
    async fn read_for(&mut self, d: Duration) {
        tokio::time::sleep(d).await;
        while let Ok(r) = self.incoming.try_recv() {
            self.take(r);
        }
    }

    /// The first record (oldest first) for which `pred` holds, removed from the
    /// inbox, with its arrival time; the others stay. Panics after `within`.
    async fn expect(
        &mut self,
        within: Duration,
        what: &str,
        mut pred: impl FnMut(&Record) -> bool,
    ) -> (Instant, Record) {
        let deadline = Instant::now() + within;
        loop {
            while let Ok(r) = self.incoming.try_recv() {
                self.take(r);
            }
            if let Some(i) = self.inbox.iter().position(|(_, r)| pred(r)) {
                return self.inbox.remove(i).unwrap();
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, self.incoming.recv()).await {
                Ok(Some(r)) => self.take(r),
                Ok(None) => panic!("the state server closed the connection waiting for {what}"),
                Err(_) => panic!(
                    "timed out waiting for {what}; records not consumed: {:?}",
                    self.inbox
                ),
            }
        }
    }

    /// `ACK_CMD_SUCCESS` for command `t` of drone `drone`; its arrival time.
    async fn ack(&mut self, drone: u8, t: T, within: Duration) -> Instant {
        let what = format!("ACK_CMD_SUCCESS for {} of drone {drone}", t.name());
        let (at, r) = self
            .expect(within, &what, |r| {
                (r.kind == T::AckCmdSuccess.id() || r.kind == T::AckCmdTimeout.id())
                    && r.context == i32::from(drone)
                    && r.int1 == t.id()
            })
            .await;
        assert_eq!(r.kind, T::AckCmdSuccess.id(), "{what}: got a timeout {r:?}");
        at
    }
}

fn cmd(t: T, drone: u8, int1: i32, int2: i32, f: [f32; 4]) -> Record {
    Record::floats(t, i32::from(drone), int1, int2, f)
}

fn waypoint(t: T, drone: u8, p: [f32; 3]) -> Record {
    // Yaw 90° CCW from east = facing north (as the vehicles start, about); speed 0 =
    // the queue's default.
    cmd(t, drone, 9000, 0, [p[0], p[1], p[2], 0.0])
}

// ---------------------------------------------------------------------------
// The pose broadcast: 84-byte records, parsed here by hand from FACTS.md's layout.

const POSE_LEN: usize = 84;

#[derive(Debug, Clone, Copy)]
struct Pose {
    id: u16,
    object_type: u8,
    liveness: u8,
    tracking: [f32; 3],
    target: [f32; 3],
    color: [f32; 3],
    timestamp: f32,
    quaternion: [f32; 4],
    frame_count: u32,
    drone_state: i32,
    flags: u32,
}

impl Pose {
    fn idle(&self) -> bool {
        self.flags & 0x01 != 0
    }
}

fn parse_poses(d: &[u8]) -> Vec<Pose> {
    assert!(
        !d.is_empty() && d.len().is_multiple_of(POSE_LEN),
        "pose datagram of {} bytes is not a whole number of {POSE_LEN}-byte records",
        d.len()
    );
    let out: Vec<Pose> = d
        .chunks_exact(POSE_LEN)
        .map(|b| {
            let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
            let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
            Pose {
                id: u16::from_le_bytes([b[0], b[1]]),
                object_type: b[2],
                liveness: b[3],
                tracking: [f(4), f(8), f(12)],
                target: [f(20), f(24), f(28)],
                color: [f(36), f(40), f(44)],
                timestamp: f(48),
                quaternion: [f(52), f(56), f(60), f(64)],
                frame_count: u(68),
                drone_state: u(72) as i32,
                flags: u(76),
            }
        })
        .collect();
    // The shared codec reads the same bytes the same way.
    let codec = gc_proto::decode_pose_datagram(d).expect("gc-proto parses the datagram");
    for (a, b) in out.iter().zip(&codec) {
        assert_eq!((a.id, a.tracking, a.flags), (b.id, b.tracking, b.flags));
    }
    out
}

/// The pose broadcast, received all the time by a background task; every datagram
/// kept with its arrival time.
struct PoseRx {
    incoming: mpsc::UnboundedReceiver<(Instant, Vec<u8>)>,
    history: Vec<(Instant, Vec<Pose>)>,
}

impl PoseRx {
    fn start(socket: UdpSocket) -> PoseRx {
        let (tx, incoming) = mpsc::unbounded_channel();
        tokio::spawn(async move {
            let mut buf = vec![0u8; 65_536];
            while let Ok(n) = socket.recv(&mut buf).await {
                if tx.send((Instant::now(), buf[..n].to_vec())).is_err() {
                    return;
                }
            }
        });
        PoseRx {
            incoming,
            history: Vec::new(),
        }
    }

    fn push(&mut self, (at, bytes): (Instant, Vec<u8>)) {
        self.history.push((at, parse_poses(&bytes)));
    }

    /// Moves every datagram received so far into the history.
    fn pull(&mut self) {
        while let Ok(d) = self.incoming.try_recv() {
            self.push(d);
        }
    }

    /// Waits for the next datagram into the history.
    async fn wait_one(&mut self) {
        let d = tokio::time::timeout(Duration::from_secs(10), self.incoming.recv())
            .await
            .expect("no pose datagram for 10 s")
            .expect("pose receiver stopped");
        self.push(d);
    }

    /// The first datagram that arrives after this call.
    async fn next(&mut self) -> Vec<Pose> {
        self.until(WAIT, "a pose datagram", |_| true).await
    }

    /// The first datagram arriving after this call for which `pred` holds; panics
    /// after `within`.
    async fn until(
        &mut self,
        within: Duration,
        what: &str,
        pred: impl FnMut(&[Pose]) -> bool,
    ) -> Vec<Pose> {
        self.pull();
        self.until_from(Instant::now(), within, what, pred).await.1
    }

    /// The first datagram that arrived at or after `from` (already received or
    /// still to come) for which `pred` holds, with its arrival time; panics after
    /// `within`.
    async fn until_from(
        &mut self,
        from: Instant,
        within: Duration,
        what: &str,
        mut pred: impl FnMut(&[Pose]) -> bool,
    ) -> (Instant, Vec<Pose>) {
        let deadline = Instant::now() + within;
        let mut i = self.history.partition_point(|(at, _)| *at < from);
        loop {
            while i < self.history.len() {
                let (at, poses) = &self.history[i];
                if pred(poses) {
                    return (*at, poses.clone());
                }
                i += 1;
            }
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {what}; last poses: {:#?}",
                self.history.last()
            );
            self.wait_one().await;
        }
    }

    /// The datagrams that arrived between `from` and `to`.
    fn between(&mut self, from: Instant, to: Instant) -> impl Iterator<Item = &[Pose]> {
        self.pull();
        self.history
            .iter()
            .filter(move |(at, _)| *at >= from && *at <= to)
            .map(|(_, p)| p.as_slice())
    }
}

fn drone(poses: &[Pose], id: u8) -> Pose {
    *poses
        .iter()
        .find(|p| p.id == u16::from(id))
        .unwrap_or_else(|| panic!("no record for drone {id} in {poses:?}"))
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// An operator command to vehicle `vehicle` (above the swarm queue in the arbiter),
/// answered Accepted.
async fn operator(bus: &Bus, vehicle: u8, command_id: u32, cmd: Command) {
    let mut acks = bus
        .subscriber::<CommandAck>(&topics::vehicle_command_ack(vehicle))
        .unwrap();
    let mut cmds = bus
        .publisher::<VehicleCommand>(&topics::vehicle_command(vehicle))
        .unwrap();
    cmds.publish(VehicleCommand::new(vehicle, CommandSource::Operator, command_id, &cmd).unwrap())
        .unwrap();
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        if let Some(a) = acks.recv_timeout(Duration::from_secs(1)).await.unwrap() {
            if a.command_id == command_id && a.source == CommandSource::Operator.to_wire() {
                assert_eq!(a.result(), Some(AckResult::Accepted), "{cmd:?} → {a:?}");
                return;
            }
        }
    }
    panic!("no ack for {cmd:?}");
}

/// `VehicleState` → site frame (x east, y north, z up around vehicle 1's home),
/// flat earth: centimetres of error over these few metres.
fn site_of(s: &VehicleState) -> [f32; 3] {
    const M_PER_DEG: f64 = 111_319.5;
    let x = (s.lon_deg - HOME[1]) * M_PER_DEG * HOME[0].to_radians().cos();
    let y = (s.lat_deg - HOME[0]) * M_PER_DEG;
    [x as f32, y as f32, s.alt_msl_m - HOME[2] as f32]
}

/// Every vehicle's newest `VehicleState`.
struct Vehicles {
    subs: Vec<Subscriber<VehicleState>>,
    last: Vec<Option<VehicleState>>,
}

impl Vehicles {
    async fn fresh(&mut self) -> Vec<VehicleState> {
        for (sub, last) in self.subs.iter_mut().zip(&mut self.last) {
            match sub.latest().unwrap() {
                Some(s) => *last = Some(s),
                None => {
                    let s = sub
                        .recv_timeout(Duration::from_secs(5))
                        .await
                        .unwrap()
                        .expect("VehicleState stream stopped");
                    *last = Some(s);
                }
            }
        }
        self.last.iter().map(|s| s.unwrap()).collect()
    }
}

/// The broadcast's tracking positions agree with the vehicles' own states.
async fn poses_match_vehicles(rx: &mut PoseRx, vehicles: &mut Vehicles, when: &str) {
    let poses = rx.next().await;
    let states = vehicles.fresh().await;
    for (i, s) in states.iter().enumerate() {
        let id = i as u8 + 1;
        assert_eq!(s.vehicle_id, id);
        let p = drone(&poses, id);
        let want = site_of(s);
        assert!(
            dist(p.tracking, want) < 1.0,
            "{when}: drone {id} broadcast at {:?}, its vehicle is at {want:?}",
            p.tracking
        );
    }
}

fn swarm_drone(state: &SwarmState, id: u8) -> skymesh_ipc_types::SwarmDrone {
    *state
        .drones()
        .iter()
        .find(|d| d.drone == u16::from(id))
        .unwrap_or_else(|| panic!("drone {id} not in SwarmState"))
}

/// The next `SwarmState` for which `pred` holds; panics after `within`.
async fn swarm_until(
    sub: &mut Subscriber<SwarmState>,
    within: Duration,
    what: &str,
    mut pred: impl FnMut(&SwarmState) -> bool,
) -> SwarmState {
    let deadline = Instant::now() + within;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let s = sub
            .recv_timeout(left.max(Duration::from_millis(1)))
            .await
            .unwrap();
        match s {
            Some(s) if pred(&s) => return s,
            Some(_) => {}
            None => panic!("timed out waiting for {what}"),
        }
    }
}

const ANIMATION: &str = "\
# drone 4: a 1.5 m square at 2.5 m around its home (0, 3), 4 s a lap
time_s,x,y,z,yaw_deg,r,g,b
0.0,0.0,3.0,2.5,90,1,0,0
1.0,1.5,3.0,2.5,90,0,1,0
2.0,1.5,4.5,2.5,90,0,0,1
3.0,0.0,4.5,2.5,90,1,1,1
4.0,0.0,3.0,2.5,90,1,0,0
";

#[test]
fn five_drones_on_the_groundcontrol_protocol() {
    let opts = MeshOptions {
        vehicles: N,
        sim_swarm: true,
        swarm: true,
        // Not 127.0.0.1: the client from there is the non-privileged one.
        gc_privileged: vec!["127.0.0.2".to_string()],
        // Five links on two cores: positions still arrive at several Hz.
        attitude_hz: 10.0,
        ..Default::default()
    };
    let mut mesh = Mesh::start(opts).unwrap();
    mesh.wait_running("vehicle-sim", STARTUP).unwrap();
    for id in 1..=N {
        mesh.wait_running(&format!("autopilot-link-{id}"), STARTUP)
            .unwrap();
    }
    mesh.wait_running("swarm-queue", STARTUP).unwrap();
    mesh.wait_running("groundcontrol-gateway", STARTUP).unwrap();
    std::fs::write(mesh.animations_dir.join("drone_4.csv"), ANIMATION).unwrap();

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let (gc_port, pose_port) = (mesh.gc_port, mesh.pose_port);
    rt.block_on(async {
        let bus = mesh.bus("e2e-swarm").unwrap();
        let mut vehicles = Vehicles {
            subs: (1..=N)
                .map(|id| {
                    bus.subscriber::<VehicleState>(&topics::vehicle_state(id))
                        .unwrap()
                })
                .collect(),
            last: vec![None; usize::from(N)],
        };
        let mut swarm = bus
            .subscriber::<SwarmState>(&topics::swarm_state())
            .unwrap();
        let mut rx = PoseRx::start(UdpSocket::bind(("127.0.0.1", pose_port)).await.unwrap());

        // --- The broadcast: one record per drone, ids 1..=5, simulated UAVs, on
        // the ground at their grid homes once every vehicle reports a position.
        let poses = rx
            .until(STARTUP, "every drone at its home", |poses| {
                poses.len() == usize::from(N)
                    && (1..=N).all(|id| {
                        let p = drone(poses, id);
                        let h = home_xy(id);
                        // NONE (0) until the queue has the vehicle's state and status.
                        p.drone_state != 0 && dist(p.tracking, [h[0], h[1], 0.0]) < 1.0
                    })
            })
            .await;
        let ids: Vec<u16> = poses.iter().map(|p| p.id).collect();
        assert_eq!(ids, [1, 2, 3, 4, 5], "records in drone order");
        for p in &poses {
            assert_eq!((p.object_type, p.liveness), (0, 2), "{p:?}");
            assert!(p.idle(), "drone {} not idle at start: {p:?}", p.id);
            assert_eq!(p.drone_state, 5, "ON_GROUND: {p:?}");
            let qn: f32 = p.quaternion.iter().map(|q| q * q).sum();
            assert!((qn - 1.0).abs() < 0.01, "unit quaternion: {p:?}");
            assert!(p.timestamp.is_finite(), "{p:?}");
        }
        let frame = poses[0].frame_count;
        let later = rx.next().await;
        assert!(later[0].frame_count > frame, "frame count advances");
        poses_match_vehicles(&mut rx, &mut vehicles, "on the ground").await;

        let mut ext = GcClient::connect_from(Ipv4Addr::LOCALHOST, gc_port).await;
        let mut privileged = GcClient::connect_from(Ipv4Addr::new(127, 0, 0, 2), gc_port).await;

        // --- PING.
        ext.send(&[Record::ping_request(41, 0.0, 0.0)]).await;
        let (_, pong) = ext
            .expect(WAIT, "PING_RESPONSE", |r| r.kind == T::PingResponse.id())
            .await;
        assert_eq!(pong.int1, 41);

        // --- A non-privileged client's privileged command is refused and counted.
        ext.send(&[cmd(T::CmdEmergencyMode, 1, 1, 0, [0.0; 4])])
            .await;
        let refused =
            "skymesh_gc_refused_total{reason=\"not_privileged\",service=\"groundcontrol-gateway\"}";
        mesh.wait_for(WAIT, "the refusal counted", |m| {
            m.metric(refused).ok().flatten().filter(|v| *v >= 1.0)
        })
        .unwrap();
        let s = swarm_until(&mut swarm, WAIT, "a swarm state", |_| true).await;
        assert_eq!(
            swarm_drone(&s, 1).flags & drone_flags::EMERGENCY,
            0,
            "drone 1 must not be in emergency mode"
        );

        // --- Take off all (drone 1 too: the refused emergency had no effect).
        let go: Vec<Record> = (1..=N)
            .map(|id| cmd(T::CmdExtGoExternal, id, 0, 0, [0.0; 4]))
            .collect();
        ext.send(&go).await;
        for id in 1..=N {
            ext.ack(id, T::CmdExtGoExternal, WAIT).await;
        }
        let poses = rx
            .until(WAIT, "every drone at takeoff height", |poses| {
                (1..=N).all(|id| (drone(poses, id).tracking[2] - TAKEOFF_ALT).abs() < 0.6)
            })
            .await;
        for id in 1..=N {
            let p = drone(&poses, id);
            let h = home_xy(id);
            assert!(
                dist(p.tracking, [h[0], h[1], TAKEOFF_ALT]) < 1.0,
                "drone {id} rose above its home: {p:?}"
            );
        }
        ext.read_for(Duration::ZERO).await;
        assert!(
            !ext.seen.iter().any(|r| r.int1 == T::CmdEmergencyMode.id()),
            "a refused command is never answered: {:?}",
            ext.seen
        );

        // --- Waypoints queued and flown in order (drone 1): north 1.5 m, then 3 m
        // west (away from the others). The straight line to the second passes 1.3 m
        // from the first, so being at the first shows the order.
        let wp1 = [0.0, 1.5, TAKEOFF_ALT];
        let wp2 = [-3.0, 1.5, TAKEOFF_ALT];
        let sent = Instant::now();
        ext.send(&[
            waypoint(T::CmdExtWaypoint, 1, wp1),
            waypoint(T::CmdExtWaypoint, 1, wp2),
        ])
        .await;
        let s = swarm_until(&mut swarm, WAIT, "drone 1's second waypoint queued", |s| {
            swarm_drone(s, 1).queue_depth == 1
        })
        .await;
        assert_eq!(swarm_drone(&s, 1).flags & drone_flags::IDLE, 0);
        let ack1 = ext.ack(1, T::CmdExtWaypoint, WAIT).await;
        let ack2 = ext.ack(1, T::CmdExtWaypoint, WAIT).await;
        let (at_wp2, _) = rx
            .until_from(sent, WAIT, "drone 1 at wp2", |poses| {
                dist(drone(poses, 1).tracking, wp2) < 0.6
            })
            .await;
        assert!(
            ack1 < at_wp2,
            "the first waypoint is acknowledged before the drone reaches the second"
        );
        let nearest_wp1 = rx
            .between(sent, ack1)
            .map(|p| dist(drone(p, 1).tracking, wp1))
            .fold(f32::MAX, f32::min);
        assert!(
            nearest_wp1 < 0.6,
            "drone 1 went to wp1 first: nearest {nearest_wp1:.2} m"
        );
        // Between the two acknowledgements the broadcast's target is the second.
        assert!(
            rx.between(ack1, ack2)
                .any(|p| dist(drone(p, 1).target, wp2) < 0.1),
            "the target moves on to wp2"
        );
        rx.until(WAIT, "drone 1 idle, settled at wp2", |poses| {
            let p = drone(poses, 1);
            p.idle() && dist(p.tracking, wp2) < 0.6
        })
        .await;

        // --- The operator switches drone 1 to LOITER and hands authority back; a
        // waypoint follows at once, most likely before a heartbeat has shown LOITER
        // (the status repeats the last heartbeat's GUIDED for up to a second). The
        // queue asks for GUIDED all the same, or the vehicle would ignore the target
        // in LOITER and the waypoint would time out.
        operator(&bus, 1, 9001, Command::SetMode(FlightMode::Loiter)).await;
        operator(&bus, 1, 9002, Command::ReleaseFlightAuthority).await;
        let wp3 = [-3.0, 0.0, TAKEOFF_ALT];
        ext.send(&[waypoint(T::CmdExtWaypoint, 1, wp3)]).await;
        ext.ack(1, T::CmdExtWaypoint, WAIT).await;
        rx.until(
            WAIT,
            "drone 1 at wp3 after the operator's LOITER",
            |poses| dist(drone(poses, 1).tracking, wp3) < 0.6,
        )
        .await;

        // --- WAYPOINT_FOLLOW replaced by a newer one (drone 2): the older is answered
        // when replaced; the drone ends near the newer target and keeps following.
        let f1 = [3.0, 2.0, TAKEOFF_ALT];
        let f2 = [5.0, 0.0, 3.0];
        ext.send(&[waypoint(T::CmdExtWaypointFollow, 2, f1)]).await;
        rx.until(WAIT, "drone 2 heading for f1", |poses| {
            dist(drone(poses, 2).target, f1) < 0.1
        })
        .await;
        ext.send(&[waypoint(T::CmdExtWaypointFollow, 2, f2)]).await;
        ext.ack(2, T::CmdExtWaypointFollow, WAIT).await;
        let p = drone(
            &rx.until(WAIT, "drone 2 near the newer follow target", |poses| {
                let p = drone(poses, 2);
                dist(p.target, f2) < 0.1 && dist(p.tracking, f2) < 0.6
            })
            .await,
            2,
        );
        assert!(!p.idle(), "a follow never finishes by itself: {p:?}");

        // --- HALT empties the queue (drone 3).
        ext.send(&[
            cmd(T::CmdExtPause, 3, 0, 0, [60.0, 0.0, 0.0, 0.0]),
            cmd(T::CmdExtPause, 3, 0, 0, [60.0, 0.0, 0.0, 0.0]),
            waypoint(T::CmdExtWaypoint, 3, [6.0, 2.0, TAKEOFF_ALT]),
        ])
        .await;
        swarm_until(&mut swarm, WAIT, "drone 3 busy with two queued", |s| {
            let d = swarm_drone(s, 3);
            d.queue_depth == 2 && d.flags & drone_flags::IDLE == 0
        })
        .await;
        assert!(!drone(&rx.next().await, 3).idle());
        ext.send(&[cmd(T::CmdExtHalt, 3, 0, 0, [0.0; 4])]).await;
        ext.ack(3, T::CmdExtHalt, WAIT).await;
        let s = swarm_until(&mut swarm, WAIT, "drone 3 idle after HALT", |s| {
            swarm_drone(s, 3).flags & drone_flags::IDLE != 0
        })
        .await;
        assert_eq!(swarm_drone(&s, 3).queue_depth, 0);
        rx.until(WAIT, "drone 3 idle in the broadcast", |poses| {
            drone(poses, 3).idle()
        })
        .await;
        // The halted commands are not acknowledged as done.
        ext.read_for(Duration::from_millis(300)).await;
        assert!(
            !ext.seen.iter().any(|r| r.context == 3
                && (r.int1 == T::CmdExtPause.id() || r.int1 == T::CmdExtWaypoint.id())),
            "{:?}",
            ext.seen
        );

        // --- An animation plays and loops until cancelled (drone 4).
        ext.send(&[cmd(T::CmdExtPlaybackAnim, 4, 0, -1, [1.0, 1.0, 1.0, 1.0])])
            .await;
        // More than one loop: the target passes the far corner (1.5, 4.5) twice,
        // leaving it in between; the drone itself moves along.
        let corner = [1.5, 4.5, 2.5];
        let (mut visits, mut at_corner) = (0, false);
        let mut colours = Vec::new();
        let mut moved: f32 = 0.0;
        let start = drone(&rx.next().await, 4).tracking;
        rx.until(WAIT, "two laps of drone 4's animation", |poses| {
            let p = drone(poses, 4);
            let near = dist(p.target, corner) < 0.3;
            if near && !at_corner {
                visits += 1;
            }
            at_corner = near;
            moved = moved.max(dist(p.tracking, start));
            colours.push(p.color);
            visits >= 2
        })
        .await;
        assert!(moved > 1.0, "drone 4 flew the animation: {moved:.2} m");
        assert!(
            colours.iter().any(|c| c[2] > 0.5) && colours.iter().any(|c| c[0] > 0.5 && c[2] < 0.5),
            "the animation's colours are broadcast: {colours:?}"
        );
        assert!(
            !ext.seen
                .iter()
                .any(|r| r.context == 4 && r.int1 == T::CmdExtPlaybackAnim.id()),
            "a looping animation does not finish by itself"
        );
        ext.send(&[cmd(T::CmdExtAnimCancelLoop, 4, 0, 0, [0.0; 4])])
            .await;
        ext.ack(4, T::CmdExtAnimCancelLoop, WAIT).await;
        ext.ack(4, T::CmdExtPlaybackAnim, WAIT).await;
        rx.until(WAIT, "drone 4 idle after its animation", |poses| {
            drone(poses, 4).idle()
        })
        .await;

        // --- CHECK_ALL_IDLE: one record per drone; drone 2 is still following.
        ext.send(&[cmd(T::CmdExtCheckAllIdle, 0, 0, 0, [0.0; 4])])
            .await;
        let mut idle = Vec::new();
        for _ in 1..=N {
            let (_, r) = ext
                .expect(WAIT, "a CHECK_ALL_IDLE answer", |r| {
                    r.kind == T::CmdExtCheckAllIdle.id()
                })
                .await;
            idle.push((r.context, r.int1));
        }
        idle.sort();
        assert_eq!(idle, [(1, 1), (2, 0), (3, 1), (4, 1), (5, 1)]);
        ext.send(&[cmd(T::CmdExtHalt, 2, 0, 0, [0.0; 4])]).await;
        ext.ack(2, T::CmdExtHalt, WAIT).await;

        // --- The broadcast agrees with the vehicles in flight.
        rx.until(WAIT, "every drone idle", |poses| {
            poses.iter().all(Pose::idle)
        })
        .await;
        tokio::time::sleep(Duration::from_secs(1)).await;
        poses_match_vehicles(&mut rx, &mut vehicles, "hovering").await;

        // --- The privileged client's EMERGENCY_MODE is obeyed (drone 5).
        privileged
            .send(&[cmd(T::CmdEmergencyMode, 5, 1, 0, [0.0; 4])])
            .await;
        privileged.ack(5, T::CmdEmergencyMode, WAIT).await;
        let s = swarm_until(&mut swarm, WAIT, "drone 5 in emergency mode", |s| {
            swarm_drone(s, 5).flags & drone_flags::EMERGENCY != 0
        })
        .await;
        for id in 1..=4 {
            assert_eq!(swarm_drone(&s, id).flags & drone_flags::EMERGENCY, 0);
        }
        let refused_now = mesh.metric(refused).unwrap().unwrap_or(0.0);
        assert_eq!(refused_now, 1.0, "only the one refusal");
    });
}

/// Issue 42 finding 11: the arbiter brakes a position target whose source fell
/// silent for its authority timeout (1.5 s here, 5 s by default). A takeoff to 10 m
/// climbs for about 4 s: the queue keeps its flight authority alive while climbing,
/// so the drone reaches the height, GO_EXTERNAL is acknowledged, and the arbiter
/// never brakes the queue's target (no StaleBrake event). Without the keep-alive the
/// climb stops near 4 m and the command times out.
#[test]
fn a_takeoff_longer_than_the_authority_timeout_is_not_braked() {
    const ALT: f32 = 10.0;
    let opts = MeshOptions {
        swarm: true,
        autopilot_link_extra: "[arbiter]\nauthority_timeout_s = 1.5\n".to_string(),
        swarm_queue_extra: format!("takeoff_alt_m = {ALT}\n"),
        ..Default::default()
    };
    let mut mesh = Mesh::start(opts).unwrap();
    for s in [
        "vehicle-sim",
        "autopilot-link",
        "swarm-queue",
        "groundcontrol-gateway",
    ] {
        mesh.wait_running(s, STARTUP).unwrap();
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let gc_port = mesh.gc_port;
    rt.block_on(async {
        let bus = mesh.bus("e2e-swarm-keepalive").unwrap();
        let events = bus
            .subscriber::<ArbiterEvent>(&topics::vehicle_arbiter_events(1))
            .unwrap();
        let mut swarm = bus
            .subscriber::<SwarmState>(&topics::swarm_state())
            .unwrap();
        swarm_until(&mut swarm, STARTUP, "drone 1 on the ground", |s| {
            let d = swarm_drone(s, 1);
            d.drone_state == 5 && d.flags & drone_flags::POSE_VALID != 0
        })
        .await;
        let mut ext = GcClient::connect_from(Ipv4Addr::LOCALHOST, gc_port).await;
        let sent = Instant::now();
        ext.send(&[cmd(T::CmdExtGoExternal, 1, 0, 0, [0.0; 4])])
            .await;
        let acked = ext.ack(1, T::CmdExtGoExternal, WAIT).await;
        let climb = acked - sent;
        assert!(
            climb > Duration::from_secs(3),
            "the climb outlasts the 1.5 s authority timeout: {climb:?}"
        );
        let s = swarm_until(&mut swarm, WAIT, "drone 1 at the takeoff height", |s| {
            (swarm_drone(s, 1).tracking[2] - ALT).abs() < 0.6
        })
        .await;
        assert_eq!(swarm_drone(&s, 1).flags & drone_flags::EMERGENCY, 0);
        let mut brakes = Vec::new();
        while let Some(e) = events.try_recv().unwrap() {
            if e.event_kind() == Some(ArbiterEventKind::StaleBrake)
                && e.source == CommandSource::SwarmQueue.to_wire()
            {
                brakes.push(e.detail.as_str().to_string());
            }
        }
        assert!(brakes.is_empty(), "the climb was braked: {brakes:?}");
    });
}
