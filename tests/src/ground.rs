//! A test's own ground station on the bus for vehicle 1: commands from any source,
//! their acks matched by command id, and the vehicle's state, status and authority.

use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    topics, AckResult, AuthorityState, Command, CommandAck, CommandSource, FlightMode,
    VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Publisher, Subscriber};

use crate::{Mesh, MeshBus};

/// How long the `wait_*` helpers wait for something that should happen (a deadline
/// for a loaded machine, never a latency claim).
pub const PATIENCE: Duration = Duration::from_secs(30);

/// A multi-threaded tokio runtime for one end-to-end test.
pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// The bus ports of a test acting as a ground station for vehicle 1.
#[derive(Debug)]
pub struct Ground {
    _bus: MeshBus,
    cmds: Publisher<VehicleCommand>,
    pub acks: Subscriber<CommandAck>,
    pub state: Subscriber<VehicleState>,
    pub status: Subscriber<VehicleStatus>,
    pub authority: Subscriber<AuthorityState>,
    next_id: u32,
    /// Acks read while waiting for another, with when they were read.
    pub early: Vec<(Instant, CommandAck)>,
    /// When [`Ground::keep_authority`] last grabbed flight authority.
    last_grab: Option<Instant>,
}

impl Ground {
    /// Opens the ports as bus node `name`.
    pub fn new(mesh: &Mesh, name: &str) -> Ground {
        let bus = mesh.bus(name).unwrap();
        Ground {
            cmds: bus.publisher(&topics::vehicle_command(1)).unwrap(),
            acks: bus.subscriber(&topics::vehicle_command_ack(1)).unwrap(),
            state: bus.subscriber(&topics::vehicle_state(1)).unwrap(),
            status: bus.subscriber(&topics::vehicle_status(1)).unwrap(),
            authority: bus.subscriber(&topics::vehicle_authority(1)).unwrap(),
            _bus: bus,
            next_id: 100,
            early: Vec::new(),
            last_grab: None,
        }
    }

    /// Publishes `cmd` from `source`; returns its command id.
    pub fn send(&mut self, source: CommandSource, cmd: &Command) -> u32 {
        self.next_id += 1;
        let id = self.next_id;
        self.cmds
            .publish(VehicleCommand::new(1, source, id, cmd).unwrap())
            .unwrap();
        id
    }

    /// The ack of command `id` and when it was read (acks of other commands read
    /// meanwhile are kept for their own `ack`).
    pub async fn ack_within(&mut self, id: u32, within: Duration) -> (Instant, CommandAck) {
        if let Some(i) = self.early.iter().position(|(_, a)| a.command_id == id) {
            return self.early.remove(i);
        }
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let a = self
                .acks
                .recv_timeout(left)
                .await
                .unwrap()
                .unwrap_or_else(|| panic!("no ack for command {id} within {within:?}"));
            let at = Instant::now();
            if a.command_id == id {
                return (at, a);
            }
            self.early.push((at, a));
        }
    }

    /// The ack of command `id`; an emergency stop's waits for the autopilot's
    /// confirmation (≤ 5 s), so up to 10 s.
    pub async fn ack(&mut self, id: u32) -> CommandAck {
        self.ack_within(id, Duration::from_secs(10)).await.1
    }

    /// Sends `cmd` from `source` and waits for its ack.
    pub async fn command(&mut self, source: CommandSource, cmd: &Command) -> CommandAck {
        let id = self.send(source, cmd);
        self.ack(id).await
    }

    /// Sends `cmd` as the operator and asserts that the arbiter accepted it.
    pub async fn operator_accepted(&mut self, cmd: &Command) {
        let ack = self.command(CommandSource::Operator, cmd).await;
        assert_eq!(ack.result(), Some(AckResult::Accepted), "{cmd:?} → {ack:?}");
    }

    /// The operator's take-off: guided, arm, take off to `alt_rel_m`, each accepted.
    /// While the take-off flies, call [`Ground::keep_authority`] in the watch loop.
    pub async fn take_off(&mut self, alt_rel_m: f32) {
        self.operator_accepted(&Command::SetMode(FlightMode::Guided))
            .await;
        self.operator_accepted(&Command::Arm { force: false }).await;
        self.operator_accepted(&Command::Takeoff { alt_rel_m })
            .await;
    }

    /// Renews the operator's flight authority once its last grab is a second old, as
    /// a source flying a position target must (the acks are not awaited).
    pub fn keep_authority(&mut self) {
        if self
            .last_grab
            .is_some_and(|t| t.elapsed() < Duration::from_secs(1))
        {
            return;
        }
        self.last_grab = Some(Instant::now());
        self.send(CommandSource::Operator, &Command::GrabFlightAuthority);
    }

    /// The next VehicleState that satisfies `ok`.
    pub async fn wait_state(
        &mut self,
        what: &str,
        ok: impl Fn(&VehicleState) -> bool,
    ) -> VehicleState {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let s = self.state.recv_timeout(PATIENCE).await.unwrap();
            let s = s.unwrap_or_else(|| panic!("{what}: no VehicleState"));
            if ok(&s) {
                return s;
            }
            assert!(Instant::now() < deadline, "{what}: last {s:?}");
        }
    }

    /// The next VehicleStatus that satisfies `ok` (published on change and at 1 Hz).
    pub async fn wait_status(
        &mut self,
        what: &str,
        ok: impl Fn(&VehicleStatus) -> bool,
    ) -> VehicleStatus {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let s = self.status.recv_timeout(PATIENCE).await.unwrap();
            let s = s.unwrap_or_else(|| panic!("{what}: no VehicleStatus"));
            if ok(&s) {
                return s;
            }
            assert!(Instant::now() < deadline, "{what}: last {s:?}");
        }
    }

    /// The next AuthorityState that satisfies `ok` (published on every change and
    /// once a second).
    pub async fn wait_authority(
        &mut self,
        what: &str,
        ok: impl Fn(&AuthorityState) -> bool,
    ) -> AuthorityState {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let s = self.authority.recv_timeout(PATIENCE).await.unwrap();
            let s = s.unwrap_or_else(|| panic!("{what}: no AuthorityState"));
            if ok(&s) {
                return s;
            }
            assert!(Instant::now() < deadline, "{what}: last {s:?}");
        }
    }
}
