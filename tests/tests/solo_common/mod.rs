//! Shared by the Solo end-to-end tests: a mesh with the Solo gateway and shot engine,
//! the test's view of the vehicle (bus subscriptions and operator commands), and a
//! test app speaking TLV to the gateway.
#![allow(dead_code)] // each test file uses a different part

use std::time::{Duration, Instant};

use skymesh_e2e::{Mesh, MeshOptions};
use skymesh_ipc_types::{
    topics, AckResult, Command, CommandAck, CommandSource, FlightMode, PayloadState,
    VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::ipc::{Bus, Subscriber};
use skymesh_solo_gateway::client::AppClient;
use solo_proto::{shots, Location, SoloMessage};

pub const STARTUP: Duration = Duration::from_secs(40);
pub const REPLY: Duration = Duration::from_secs(5);
pub const M_PER_DEG_LAT: f64 = 111_320.0;

pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

pub fn start_mesh() -> Mesh {
    start_mesh_with("")
}

/// A mesh with `shot_engine_extra` appended to the shot engine's config.
pub fn start_mesh_with(shot_engine_extra: &str) -> Mesh {
    start_solo_mesh(MeshOptions {
        shot_engine_extra: shot_engine_extra.to_string(),
        ..Default::default()
    })
}

/// The Solo mesh (vehicle-sim, autopilot-link, solo-gateway, shot-engine at 25 Hz
/// attitude) with `opts` otherwise, once every service runs.
pub fn start_solo_mesh(opts: MeshOptions) -> Mesh {
    let mut mesh = Mesh::start(MeshOptions {
        solo: true,
        attitude_hz: 25.0,
        ..opts
    })
    .unwrap();
    mesh.expect_running(
        &[
            "vehicle-sim",
            "autopilot-link",
            "solo-gateway",
            "shot-engine",
        ],
        STARTUP,
    );
    mesh
}

/// North/east metres of `p` from `o`.
pub fn ne(o: (f64, f64), p: (f64, f64)) -> (f64, f64) {
    (
        (p.0 - o.0) * M_PER_DEG_LAT,
        (p.1 - o.1) * M_PER_DEG_LAT * o.0.to_radians().cos(),
    )
}

pub fn offset(o: (f64, f64), north_m: f64, east_m: f64) -> (f64, f64) {
    (
        o.0 + north_m / M_PER_DEG_LAT,
        o.1 + east_m / (M_PER_DEG_LAT * o.0.to_radians().cos()),
    )
}

pub fn loc(p: (f64, f64), alt_m: f32) -> Location {
    Location {
        lat_deg: p.0,
        lon_deg: p.1,
        alt_m,
    }
}

/// The test's view of the vehicle and its operator controls.
pub struct Vehicle {
    pub state: Subscriber<VehicleState>,
    pub status: Subscriber<VehicleStatus>,
    pub payload: Subscriber<PayloadState>,
    pub acks: Subscriber<CommandAck>,
    pub cmds: skymesh_runtime::ipc::Publisher<VehicleCommand>,
    next_id: u32,
}

impl Vehicle {
    pub fn new(bus: &Bus) -> Vehicle {
        Vehicle {
            state: bus.subscriber(&topics::vehicle_state(1)).unwrap(),
            status: bus.subscriber(&topics::vehicle_status(1)).unwrap(),
            payload: bus.subscriber(&topics::vehicle_payload(1)).unwrap(),
            acks: bus.subscriber(&topics::vehicle_command_ack(1)).unwrap(),
            cmds: bus.publisher(&topics::vehicle_command(1)).unwrap(),
            next_id: 7000,
        }
    }

    pub async fn now(&mut self) -> VehicleState {
        self.state
            .recv_timeout(REPLY)
            .await
            .unwrap()
            .expect("vehicle state stream stopped")
    }

    pub async fn status(&mut self) -> VehicleStatus {
        if let Some(s) = self.status.latest().unwrap() {
            return s;
        }
        self.status
            .recv_timeout(REPLY)
            .await
            .unwrap()
            .expect("no vehicle status")
    }

    pub async fn wait_ekf(&mut self) {
        let deadline = Instant::now() + STARTUP;
        while Instant::now() < deadline {
            if let Some(s) = self.status.recv_timeout(REPLY).await.unwrap() {
                if s.ekf_healthy != 0 && s.is_link_up() {
                    return;
                }
            }
        }
        panic!("EKF never became healthy");
    }

    /// An operator command (priority above the shot engine), answered Accepted.
    pub async fn operator(&mut self, cmd: Command) {
        self.next_id += 1;
        let id = self.next_id;
        self.cmds
            .publish(VehicleCommand::new(1, CommandSource::Operator, id, &cmd).unwrap())
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Some(a) = self.acks.recv_timeout(REPLY).await.unwrap() {
                if a.command_id == id && a.source == CommandSource::Operator.to_wire() {
                    assert_eq!(a.result(), Some(AckResult::Accepted), "{cmd:?} → {a:?}");
                    return;
                }
            }
        }
        panic!("no ack for {cmd:?}");
    }

    /// GUIDED, armed, hovering at `alt` m; the operator then gives authority back.
    pub async fn take_off(&mut self, alt: f32) {
        self.wait_ekf().await;
        self.operator(Command::SetMode(FlightMode::Guided)).await;
        self.operator(Command::Arm { force: false }).await;
        self.operator(Command::Takeoff { alt_rel_m: alt }).await;
        self.fly_until(Duration::from_secs(30), "take-off", |s| {
            s.alt_rel_m > alt - 0.5
        })
        .await;
        self.operator(Command::ReleaseFlightAuthority).await;
    }

    /// Operator flies to `p` at `alt`, waits to arrive, then releases authority.
    pub async fn fly_to(&mut self, p: (f64, f64), alt: f32) {
        // Leaving a shot hands the vehicle back in LOITER; GoTo needs GUIDED.
        self.operator(Command::SetMode(FlightMode::Guided)).await;
        self.operator(Command::GoTo {
            lat_deg: p.0,
            lon_deg: p.1,
            alt_rel_m: alt,
            yaw_deg: None,
            speed_mps: Some(6.0),
        })
        .await;
        self.fly_until(Duration::from_secs(30), "arrival", |s| {
            let (n, e) = ne(p, (s.lat_deg, s.lon_deg));
            n.hypot(e) < 1.0 && (s.alt_rel_m - alt).abs() < 0.7 && speed(s) < 0.3
        })
        .await;
        self.operator(Command::ReleaseFlightAuthority).await;
    }

    /// [`Vehicle::wait_until`] while the operator flies a position target: as any
    /// source flying one must, it keeps its flight authority (a grab each second),
    /// else the arbiter brakes the target when the authority times out.
    pub async fn fly_until(
        &mut self,
        timeout: Duration,
        what: &str,
        mut f: impl FnMut(&VehicleState) -> bool,
    ) -> VehicleState {
        let deadline = Instant::now() + timeout;
        let mut grab = Instant::now();
        let mut last = None;
        while Instant::now() < deadline {
            if Instant::now() >= grab {
                grab += Duration::from_secs(1);
                self.next_id += 1;
                let keep = VehicleCommand::new(
                    1,
                    CommandSource::Operator,
                    self.next_id,
                    &Command::GrabFlightAuthority,
                );
                self.cmds.publish(keep.unwrap()).unwrap();
            }
            let s = self.now().await;
            if f(&s) {
                return s;
            }
            last = Some(s);
        }
        panic!("{what}: not reached within {timeout:?}; last state {last:?}");
    }

    pub async fn wait_until(
        &mut self,
        timeout: Duration,
        what: &str,
        mut f: impl FnMut(&VehicleState) -> bool,
    ) -> VehicleState {
        let deadline = Instant::now() + timeout;
        let mut last = None;
        while Instant::now() < deadline {
            let s = self.now().await;
            if f(&s) {
                return s;
            }
            last = Some(s);
        }
        panic!("{what}: not reached within {timeout:?}; last state {last:?}");
    }
}

pub fn speed(s: &VehicleState) -> f32 {
    s.vel_ned_mps[0].hypot(s.vel_ned_mps[1])
}

pub fn pos(s: &VehicleState) -> (f64, f64) {
    (s.lat_deg, s.lon_deg)
}

pub async fn app(mesh: &Mesh) -> AppClient {
    let mut app = AppClient::connect(([127, 0, 0, 1], mesh.solo_port).into())
        .await
        .expect("connect to the solo gateway");
    // On connect the engine tells the app the current shot and the GoPro state.
    app.recv_until(REPLY, |m| matches!(m, SoloMessage::GetCurrentShot(_)))
        .await
        .expect("no current shot on connect");
    app
}

pub async fn expect(
    app: &mut AppClient,
    what: &str,
    f: impl FnMut(&SoloMessage) -> bool,
) -> SoloMessage {
    expect_within(app, Duration::from_secs(8), what, f).await
}

pub async fn expect_within(
    app: &mut AppClient,
    timeout: Duration,
    what: &str,
    f: impl FnMut(&SoloMessage) -> bool,
) -> SoloMessage {
    match app.recv_until(timeout, f).await {
        Some(m) => m,
        None => panic!("the app never received {what}"),
    }
}

pub async fn enter(app: &mut AppClient, shot: i32) {
    app.send(&SoloMessage::SetCurrentShot(shot)).await.unwrap();
    expect(app, "GET_CURRENT_SHOT for the shot", |m| {
        *m == SoloMessage::GetCurrentShot(shot)
    })
    .await;
}

pub async fn leave(app: &mut AppClient) {
    app.send(&SoloMessage::SetCurrentShot(shots::NONE))
        .await
        .unwrap();
    expect(app, "GET_CURRENT_SHOT -1", |m| {
        *m == SoloMessage::GetCurrentShot(shots::NONE)
    })
    .await;
}

pub fn metric(mesh: &Mesh, series: &str) -> f64 {
    mesh.metric(series).unwrap().unwrap_or(0.0)
}
