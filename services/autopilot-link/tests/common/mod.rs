//! The in-process harness shared by the integration tests: autopilot-link on its
//! own iceoryx2 domain plus a "tool" node that sends commands and reads samples.
#![allow(dead_code)] // each test crate uses its own subset

pub mod arbiter;
pub mod sim;

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use skymesh_autopilot_link::config::Endpoint;
use skymesh_autopilot_link::{run_with, Detached, Settings};
use skymesh_ipc_types::{
    topics, AckResult, Command, CommandAck, CommandSource, PayloadState, RefusalReason, ServiceId,
    VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, CancellationToken, Domain, Publisher, Stats, Subscriber};
use tokio::task::JoinHandle;

pub const VEHICLE: u8 = 1;
/// Generous bound for anything that should take a second or two.
pub const PATIENCE: Duration = Duration::from_secs(30);

pub fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "apl{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

/// autopilot-link running in-process, plus a "tool" node that talks to it.
pub struct Mesh {
    pub domain: Domain,
    pub stats: Stats,
    pub shutdown: CancellationToken,
    pub link: JoinHandle<anyhow::Result<()>>,
    pub commands: Publisher<VehicleCommand>,
    pub acks: Subscriber<CommandAck>,
    pub state: Subscriber<VehicleState>,
    pub status: Subscriber<VehicleStatus>,
    pub payload: Subscriber<PayloadState>,
    pub next_command_id: u32,
    /// Holds the test's own arbiter state file (see [`Mesh::start_routed`]).
    pub state_dir: Option<tempfile::TempDir>,
}

impl Mesh {
    pub async fn start(port: u16) -> Mesh {
        let mut settings = Settings::with_connection(Endpoint::TcpOut {
            host: "127.0.0.1".into(),
            port,
        });
        settings.reconnect_max = Duration::from_secs(1);
        // These tests measure the telemetry of a disarmed simulator at the flight
        // rate; the ground rate has tests of its own (`requests`, `fake_autopilot`,
        // and tests/tests/ground_rates.rs end to end).
        settings.rates.ground_attitude_hz = None;
        Mesh::start_with(settings).await
    }

    pub async fn start_with(settings: Settings) -> Mesh {
        Mesh::start_routed(settings, None).await
    }

    /// Like [`Mesh::start_with`], with router endpoints already bound (port 0 →
    /// read the ports from `Bound::local_addrs` before handing them over).
    ///
    /// The arbiter persists its emergency latch and fences: a test whose settings
    /// still name the default state file (shared by every test of every crate on
    /// this machine, `/tmp/skymesh-skymesh/autopilot-link-1.json`) gets a file in a
    /// temp dir of its own instead, so a test that ends latched cannot latch the
    /// next one. A test that sets `state_file` itself keeps it.
    pub async fn start_routed(
        mut settings: Settings,
        endpoints: Option<skymesh_autopilot_link::endpoints::Bound>,
    ) -> Mesh {
        let default_state_file = Settings::with_connection(settings.connection.clone()).state_file;
        let state_dir = if settings.state_file == default_state_file {
            let dir = tempfile::tempdir().expect("state dir");
            settings.state_file = dir.path().join(format!("autopilot-link-{VEHICLE}.json"));
            Some(dir)
        } else {
            None
        };
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "autopilot-link",
            ServiceId::AutopilotLink,
            0,
            stats.clone(),
        )
        .expect("autopilot-link bus");
        let tool =
            Bus::open(&domain, "test-tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
        // Subscribe before anything is published: acks have no history.
        let acks = tool
            .subscriber::<CommandAck>(&topics::vehicle_command_ack(VEHICLE))
            .expect("ack subscriber");
        let state = tool
            .subscriber::<VehicleState>(&topics::vehicle_state(VEHICLE))
            .expect("state subscriber");
        let status = tool
            .subscriber::<VehicleStatus>(&topics::vehicle_status(VEHICLE))
            .expect("status subscriber");
        let payload = tool
            .subscriber::<PayloadState>(&topics::vehicle_payload(VEHICLE))
            .expect("payload subscriber");
        let commands = tool
            .publisher::<VehicleCommand>(&topics::vehicle_command(VEHICLE))
            .expect("command publisher");
        let shutdown = CancellationToken::new();
        let link = match endpoints {
            None => tokio::spawn(run_with(
                settings,
                bus,
                stats.clone(),
                shutdown.clone(),
                Detached,
            )),
            Some(endpoints) => tokio::spawn(skymesh_autopilot_link::run_with_endpoints(
                settings,
                endpoints,
                bus,
                stats.clone(),
                shutdown.clone(),
                Detached,
            )),
        };
        Mesh {
            domain,
            stats,
            shutdown,
            link,
            commands,
            acks,
            state,
            status,
            payload,
            next_command_id: 1,
            state_dir,
        }
    }

    /// Stops autopilot-link (it must return `Ok` promptly) and cleans the domain.
    pub async fn stop(self) {
        self.shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), self.link)
            .await
            .expect("autopilot-link stops within the 5 s grace period")
            .expect("autopilot-link task")
            .expect("autopilot-link result");
        let domain = self.domain.clone();
        drop((
            self.commands,
            self.acks,
            self.state,
            self.status,
            self.payload,
        ));
        domain.remove_leftover_files();
    }

    /// Waits for a status matching `pred` (statuses are published on change and at 1 Hz).
    pub async fn wait_status(
        &mut self,
        what: &str,
        pred: impl Fn(&VehicleStatus) -> bool,
    ) -> VehicleStatus {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.status.recv_timeout(left).await.expect("status") {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None => panic!("no VehicleStatus with {what} within {PATIENCE:?}"),
            }
        }
    }

    /// Waits for a payload sample matching `pred` (on change and at 1 Hz).
    pub async fn wait_payload(
        &mut self,
        what: &str,
        pred: impl Fn(&PayloadState) -> bool,
    ) -> PayloadState {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.payload.recv_timeout(left).await.expect("payload") {
                Some(p) if pred(&p) => return p,
                Some(_) => {}
                None => panic!("no PayloadState with {what} within {PATIENCE:?}"),
            }
        }
    }

    pub async fn wait_link_up(&mut self) -> VehicleStatus {
        self.wait_status("link up", VehicleStatus::is_link_up).await
    }

    /// Waits for a state matching `pred`.
    pub async fn wait_state(
        &mut self,
        what: &str,
        timeout: Duration,
        pred: impl Fn(&VehicleState) -> bool,
    ) -> VehicleState {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.state.recv_timeout(left).await.expect("state") {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None => panic!("no VehicleState with {what} within {timeout:?}"),
            }
        }
    }

    pub fn send(&mut self, mut sample: VehicleCommand) -> u32 {
        let id = self.next_command_id;
        self.next_command_id += 1;
        sample.command_id = id;
        self.commands.publish(sample).expect("publish command");
        id
    }

    /// Publishes `cmd` and returns its final answer (skipping in-progress acks).
    pub async fn command(&mut self, cmd: Command) -> CommandAck {
        let sample =
            VehicleCommand::new(VEHICLE, CommandSource::Operator, 0, &cmd).expect("valid command");
        let id = self.send(sample);
        self.answer_to(id).await
    }

    pub async fn answer_to(&mut self, command_id: u32) -> CommandAck {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.acks.recv_timeout(left).await.expect("ack") {
                Some(a)
                    if a.command_id == command_id && a.result() != Some(AckResult::InProgress) =>
                {
                    return a
                }
                Some(_) => {}
                None => panic!("no CommandAck for command {command_id} within {PATIENCE:?}"),
            }
        }
    }

    pub fn metric(&self, name: &str, labels: &str) -> f64 {
        self.stats.value(name, labels).unwrap_or(0.0)
    }
}

pub fn assert_accepted(ack: &CommandAck, what: &str) {
    assert_eq!(
        ack.result(),
        Some(AckResult::Accepted),
        "{what}: {:?} {:?}",
        ack.reason(),
        ack.detail
    );
    assert_eq!(ack.reason(), Some(RefusalReason::None), "{what}");
    assert_eq!(ack.vehicle_id, VEHICLE);
}
