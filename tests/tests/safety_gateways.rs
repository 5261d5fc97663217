//! The gateways' side of the safety rules, end to end (issue 42, findings 1 and 6):
//! real supervisor, vehicle-sim, autopilot-link, swarm queue with its GroundControl
//! gateway, and Solo gateway with the shot engine. Commands go in through the
//! protocols (GroundControl records, Solo TLV); the vehicle's answers are read on
//! the bus.
//!
//! - fences stack: a GroundControl keep-in box (answered ACK_CMD_SUCCESS once the
//!   arbiter took it) and a Solo app's fence (GEOFENCE_SET_ACK valid once the
//!   arbiter took it); the app disconnects, its fence goes, and the box still
//!   refuses a target outside it;
//! - the GroundControl emergency stop is the swarm queue's own: ending it
//!   (EMERGENCY_MODE 0) does not lift a DJI pilot's stop on the same vehicle.

mod solo_common;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use gc_proto::{NetCmdType as T, Record, RECORD_LEN};
use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{
    topics, AckResult, ArbiterEvent, ArbiterEventKind, AuthorityState, Command, CommandAck,
    CommandSource, RefusalReason, VehicleCommand,
};
use skymesh_runtime::ipc::{Publisher, Subscriber};
use solo_common::{app, expect, offset, runtime, start_solo_mesh, Vehicle, STARTUP};
use solo_proto::{GeofenceData, SoloMessage};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Waiting for something that should happen (never a latency claim).
const PATIENCE: Duration = Duration::from_secs(30);

/// Vehicle 1 with the Solo pair and the GroundControl pair (drone 1 = vehicle 1,
/// site origin = its home), once every service runs.
fn mesh() -> Mesh {
    let mut mesh = start_solo_mesh(MeshOptions {
        swarm: true,
        ..MeshOptions::default()
    });
    mesh.expect_running(&["swarm-queue", "groundcontrol-gateway"], STARTUP);
    mesh
}

/// A privileged GroundControl client (from 127.0.0.1) on the state server.
struct Gc {
    stream: TcpStream,
    buf: Vec<u8>,
}

impl Gc {
    async fn connect(port: u16) -> Gc {
        let stream = TcpStream::connect(SocketAddr::from(([127, 0, 0, 1], port)))
            .await
            .unwrap();
        Gc {
            stream,
            buf: Vec::new(),
        }
    }

    async fn send(&mut self, records: &[Record]) {
        let bytes: Vec<u8> = records.iter().flat_map(|r| r.encode()).collect();
        self.stream.write_all(&bytes).await.unwrap();
    }

    /// The ACK_CMD_SUCCESS (true) or ACK_CMD_TIMEOUT (false) of command `t` for
    /// drone 1; other records are skipped.
    async fn ack(&mut self, t: T) -> bool {
        let deadline = Instant::now() + PATIENCE;
        loop {
            while self.buf.len() >= RECORD_LEN {
                let r = Record::from_prefix(&self.buf).unwrap();
                self.buf.drain(..RECORD_LEN);
                let ack = r.kind == T::AckCmdSuccess.id() || r.kind == T::AckCmdTimeout.id();
                if ack && r.context == 1 && r.int1 == t.id() {
                    return r.kind == T::AckCmdSuccess.id();
                }
            }
            let mut chunk = [0u8; 1024];
            let left = deadline.saturating_duration_since(Instant::now());
            let n = tokio::time::timeout(left, self.stream.read(&mut chunk))
                .await
                .unwrap_or_else(|_| panic!("no answer to {} within {PATIENCE:?}", t.name()))
                .unwrap();
            assert!(n > 0, "the state server closed the connection");
            self.buf.extend_from_slice(&chunk[..n]);
        }
    }
}

/// The next arbiter event for which `ok` holds.
async fn event(
    events: &mut Subscriber<ArbiterEvent>,
    what: &str,
    ok: impl Fn(&ArbiterEvent) -> bool,
) -> ArbiterEvent {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let e = events
            .recv_timeout(left)
            .await
            .unwrap()
            .unwrap_or_else(|| panic!("no arbiter event: {what}"));
        if ok(&e) {
            return e;
        }
    }
}

/// An operator GoTo `north_m` north of home at 5 m: its ack.
async fn goto_north(v: &mut Vehicle, id: u32, north_m: f64) -> CommandAck {
    let home = (skymesh_e2e::HOME[0], skymesh_e2e::HOME[1]);
    let p = offset(home, north_m, 0.0);
    let cmd = Command::GoTo {
        lat_deg: p.0,
        lon_deg: p.1,
        alt_rel_m: 5.0,
        yaw_deg: None,
        speed_mps: Some(3.0),
    };
    v.cmds
        .publish(VehicleCommand::new(1, CommandSource::Operator, id, &cmd).unwrap())
        .unwrap();
    let deadline = Instant::now() + PATIENCE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let a = v
            .acks
            .recv_timeout(left)
            .await
            .unwrap()
            .expect("an ack for the GoTo");
        if a.command_id == id && a.source == CommandSource::Operator.to_wire() {
            return a;
        }
    }
}

#[test]
fn a_groundcontrol_box_holds_after_the_solo_app_with_its_fence_leaves() {
    let mesh = mesh();
    runtime().block_on(async {
        let bus = mesh.bus("e2e-safety-gateways").unwrap();
        let mut v = Vehicle::new(&bus);
        let mut events = bus
            .subscriber::<ArbiterEvent>(&topics::vehicle_arbiter_events(1))
            .unwrap();
        v.take_off(5.0).await;

        // The GroundControl box: ±20 m around home, 30 m high (site frame: x east,
        // y north, z up). Answered only once the arbiter took it.
        let mut gc = Gc::connect(mesh.gc_port).await;
        gc.send(&[
            Record::floats(T::ExtParam1, 1, 0, 0, [-20.0, -20.0, -5.0, 0.0]),
            Record::floats(T::CmdSetGeofence, 1, 0, 0, [20.0, 20.0, 30.0, 0.0]),
        ])
        .await;
        assert!(gc.ack(T::CmdSetGeofence).await, "ACK_CMD_SUCCESS");
        event(&mut events, "the swarm queue's fence taken", |e| {
            e.event_kind() == Some(ArbiterEventKind::GeofenceUpdated)
                && e.source == CommandSource::SwarmQueue.to_wire()
                && e.request_id != 0
        })
        .await;

        // The app's fence: a keep-in ±60 m (the box is the tighter one).
        let home = (skymesh_e2e::HOME[0], skymesh_e2e::HOME[1]);
        let corner = |n: f64, e: f64| {
            let p = offset(home, n, e);
            [p.0, p.1]
        };
        let square = |d: f64| vec![corner(-d, -d), corner(-d, d), corner(d, d), corner(d, -d)];
        let mut solo = app(&mesh).await;
        solo.send(&SoloMessage::GeofenceSetData(GeofenceData {
            coord: vec![square(60.0)],
            sub_coord: vec![square(55.0)],
            kinds: vec![0],
        }))
        .await
        .unwrap();
        let ack = expect(&mut solo, "GEOFENCE_SET_ACK", |m| {
            matches!(m, SoloMessage::GeofenceSetAck { .. })
        })
        .await;
        assert_eq!(
            ack,
            SoloMessage::GeofenceSetAck {
                count: 1,
                valid: true
            }
        );

        // Both fences in force: 35 m north is outside the box.
        let out = goto_north(&mut v, 8101, 35.0).await;
        assert_eq!(out.result(), Some(AckResult::Refused), "{out:?}");
        assert_eq!(out.reason(), Some(RefusalReason::Geofence), "{out:?}");

        // The app leaves: the shot engine clears its own fence only.
        drop(solo);
        event(&mut events, "the shot engine's fence cleared", |e| {
            e.event_kind() == Some(ArbiterEventKind::GeofenceUpdated)
                && e.source == CommandSource::ShotEngine.to_wire()
                && e.request_id != 0
                && e.detail.as_str().contains("clear")
        })
        .await;
        // The box still holds; inside it the vehicle may go.
        let out = goto_north(&mut v, 8102, 35.0).await;
        assert_eq!(out.result(), Some(AckResult::Refused), "{out:?}");
        assert_eq!(out.reason(), Some(RefusalReason::Geofence), "{out:?}");
        let inside = goto_north(&mut v, 8103, 8.0).await;
        assert!(inside.is_accepted(), "{inside:?}");
    });
}

#[test]
fn ending_the_groundcontrol_emergency_leaves_a_dji_pilots_stop_in_force() {
    let mesh = mesh();
    runtime().block_on(async {
        let bus = mesh.bus("e2e-safety-gateways").unwrap();
        let mut v = Vehicle::new(&bus);
        let mut authority = bus
            .subscriber::<AuthorityState>(&topics::vehicle_authority(1))
            .unwrap();
        let mut dji: Publisher<VehicleCommand> =
            bus.publisher(&topics::vehicle_command(1)).unwrap();
        v.take_off(5.0).await;
        let mut gc = Gc::connect(mesh.gc_port).await;

        gc.send(&[Record::floats(T::CmdEmergencyMode, 1, 1, 0, [0.0; 4])])
            .await;
        assert!(gc.ack(T::CmdEmergencyMode).await, "the stop engaged");
        // A DJI pilot stops the same vehicle (as dji-gateway's DRC does).
        dji.publish(
            VehicleCommand::new(1, CommandSource::DjiDrc, 8201, &Command::EmergencyStop).unwrap(),
        )
        .unwrap();
        let both = |a: &AuthorityState| {
            a.emergency_by(CommandSource::SwarmQueue) && a.emergency_by(CommandSource::DjiDrc)
        };
        wait_authority(&mut authority, "both engagers", both).await;

        // GroundControl ends its emergency: the queue withdraws only its own stop.
        gc.send(&[Record::floats(T::CmdEmergencyMode, 1, 0, 0, [0.0; 4])])
            .await;
        assert!(
            gc.ack(T::CmdEmergencyMode).await,
            "the queue's stop released"
        );
        let a = wait_authority(&mut authority, "the queue's stop withdrawn", |a| {
            !a.emergency_by(CommandSource::SwarmQueue)
        })
        .await;
        assert!(a.emergency_by(CommandSource::DjiDrc), "{a:?}");
        assert_eq!(a.emergency, 1, "the vehicle stays stopped: {a:?}");
        // Still stopped for everyone below the clear: an operator GoTo is refused.
        let out = goto_north(&mut v, 8202, 8.0).await;
        assert_eq!(out.result(), Some(AckResult::Refused), "{out:?}");
        assert_eq!(out.reason(), Some(RefusalReason::Emergency), "{out:?}");
    });
}

/// The next `AuthorityState` (published on change and once a second) for which
/// `ok` holds.
async fn wait_authority(
    sub: &mut Subscriber<AuthorityState>,
    what: &str,
    ok: impl Fn(&AuthorityState) -> bool,
) -> AuthorityState {
    let deadline = Instant::now() + PATIENCE;
    let mut last = None;
    while Instant::now() < deadline {
        let left = deadline.saturating_duration_since(Instant::now());
        match sub.recv_timeout(left).await.unwrap() {
            Some(a) if ok(&a) => return a,
            Some(a) => last = Some(a),
            None => break,
        }
    }
    panic!("authority never showed {what}; last {last:?}");
}
