//! The in-process harness: imc-gateway on loopback port 0 in its own iceoryx2
//! domain, a "tool" node that plays the other end of every topic (a fake hardware
//! service, a fake autopilot-link that acks commands and publishes the vehicle, the
//! shot engine reading buttons), and IMC test peers built on the same codec.
#![allow(dead_code)] // each test crate uses its own subset

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use imc_proto::Message;
use skymesh_imc_gateway::client::ImcClient;
use skymesh_imc_gateway::{bind, run, Settings};
use skymesh_ipc_types::{
    topics, AckResult, ButtonEvent, CommandAck, HardwareReply, HardwareRequest, HardwareResult,
    HardwareState, RefusalReason, ServiceId, VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, Publisher, Stats, Subscriber};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// Generous bound for anything that should take a moment.
pub const PATIENCE: Duration = Duration::from_secs(30);
/// The gateway's IMC address in the default settings.
pub const GATEWAY_ID: u16 = 0x2c01;

fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "imc{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

/// The defaults on loopback port 0, no Announce.
pub fn settings() -> Settings {
    Settings::loopback_any_port().expect("default settings")
}

/// imc-gateway running in-process, and the other end of its topics.
pub struct Gateway {
    pub domain: Domain,
    pub stats: Stats,
    /// The gateway's UDP address.
    pub addr: SocketAddr,
    pub tool: Bus,
    pub hw_requests: Subscriber<HardwareRequest>,
    pub hw_replies: Publisher<HardwareReply>,
    pub hw_state: Publisher<HardwareState>,
    pub commands: Subscriber<VehicleCommand>,
    pub acks: Publisher<CommandAck>,
    pub vehicle_state: Publisher<VehicleState>,
    pub vehicle_status: Publisher<VehicleStatus>,
    pub buttons: Subscriber<ButtonEvent>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Gateway {
    pub async fn start() -> Gateway {
        Gateway::start_with(settings()).await
    }

    /// Starts with `settings` (`listen` must be on port 0).
    pub async fn start_with(settings: Settings) -> Gateway {
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "imc-gateway",
            ServiceId::ImcGateway,
            0,
            stats.clone(),
        )
        .expect("gateway bus");
        let tool = Bus::open(&domain, "imc-test-tool", ServiceId::Tool, 0, Stats::new())
            .expect("tool bus");
        let v = settings.vehicle_id;
        // Before the gateway runs: the command-like topics keep no history.
        let hw_requests = tool
            .subscriber(&topics::hardware_request())
            .expect("hardware request subscriber");
        let commands = tool
            .subscriber(&topics::vehicle_command(v))
            .expect("command subscriber");
        let buttons = tool
            .subscriber(&topics::input_buttons())
            .expect("buttons subscriber");
        let hw_replies = tool
            .publisher(&topics::hardware_reply())
            .expect("hardware reply publisher");
        let hw_state = tool
            .publisher(&topics::hardware_state())
            .expect("hardware state publisher");
        let acks = tool
            .publisher(&topics::vehicle_command_ack(v))
            .expect("ack publisher");
        let vehicle_state = tool
            .publisher(&topics::vehicle_state(v))
            .expect("vehicle state publisher");
        let vehicle_status = tool
            .publisher(&topics::vehicle_status(v))
            .expect("vehicle status publisher");
        let socket = bind(&settings).await.expect("bind");
        let addr = socket.local_addr().expect("address");
        let shutdown = CancellationToken::new();
        let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "imc-gateway");
        let task = tokio::spawn(run(settings, socket, ctx));
        Gateway {
            domain,
            stats,
            addr,
            tool,
            hw_requests,
            hw_replies,
            hw_state,
            commands,
            acks,
            vehicle_state,
            vehicle_status,
            buttons,
            shutdown,
            task: Some(task),
        }
    }

    /// A test peer addressed to the gateway's IMC address.
    pub async fn peer(&self) -> ImcClient {
        let mut c = ImcClient::connect(self.addr).await.expect("peer socket");
        c.identity.dst = GATEWAY_ID;
        c
    }

    /// Stops the gateway (it must return `Ok` promptly) and cleans the domain.
    pub async fn stop(mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            tokio::time::timeout(Duration::from_secs(5), task)
                .await
                .expect("imc-gateway stops within 5 s")
                .expect("imc-gateway task")
                .expect("imc-gateway result");
        }
        let Gateway {
            domain,
            hw_requests,
            hw_replies,
            hw_state,
            commands,
            acks,
            vehicle_state,
            vehicle_status,
            buttons,
            tool,
            ..
        } = self;
        drop((
            hw_requests,
            hw_replies,
            hw_state,
            commands,
            acks,
            vehicle_state,
            vehicle_status,
            buttons,
            tool,
        ));
        domain.remove_leftover_files();
    }

    pub async fn next_hw_request(&mut self) -> HardwareRequest {
        self.hw_requests
            .recv_timeout(PATIENCE)
            .await
            .expect("hardware_request")
            .unwrap_or_else(|| panic!("no HardwareRequest within {PATIENCE:?}"))
    }

    /// Answers `req` as the hardware service does.
    pub fn hw_reply(&mut self, req: &HardwareRequest, result: HardwareResult, value: u8) {
        self.hw_reply_with(req, result, value, req.sub_op, -1.0);
    }

    pub fn hw_reply_with(
        &mut self,
        req: &HardwareRequest,
        result: HardwareResult,
        value: u8,
        sub_op: u8,
        time_remaining_s: f32,
    ) {
        let reply = HardwareReply {
            request_id: req.request_id,
            requester_service: req.header.service,
            requester_instance: req.header.instance,
            op: req.op,
            sub_op,
            result: result.to_wire(),
            value,
            time_remaining_s,
            name: req.name,
            ..Default::default()
        };
        self.hw_replies.publish(reply).expect("publish reply");
    }

    pub async fn next_command(&mut self) -> VehicleCommand {
        self.commands
            .recv_timeout(PATIENCE)
            .await
            .expect("vehicle_command")
            .unwrap_or_else(|| panic!("no VehicleCommand within {PATIENCE:?}"))
    }

    /// Answers `cmd` as autopilot-link does.
    pub fn ack(&mut self, cmd: &VehicleCommand, result: AckResult, reason: RefusalReason) {
        let ack = CommandAck {
            vehicle_id: cmd.vehicle_id,
            source: cmd.source,
            kind: cmd.kind,
            result: result.to_wire(),
            command_id: cmd.command_id,
            reason: reason.to_wire(),
            mav_result: CommandAck::NO_MAV_RESULT,
            command_seq: cmd.header.seq as u32,
            ..Default::default()
        };
        self.acks.publish(ack).expect("publish ack");
    }

    pub async fn next_button(&mut self) -> ButtonEvent {
        self.buttons
            .recv_timeout(PATIENCE)
            .await
            .expect("buttons")
            .unwrap_or_else(|| panic!("no ButtonEvent within {PATIENCE:?}"))
    }

    /// The current value of a series (`labels` as `k=v,k=v`), if registered.
    pub fn metric(&self, name: &str, labels: &str) -> Option<f64> {
        self.stats.value(name, labels)
    }

    /// Waits until a series reaches `value` (counters are updated by the gateway's task).
    pub async fn wait_metric(&self, name: &str, labels: &str, value: f64) {
        let deadline = Instant::now() + PATIENCE;
        while self.metric(name, labels) != Some(value) {
            assert!(
                Instant::now() < deadline,
                "{name}{{{labels}}} is {:?}, expected {value}",
                self.metric(name, labels)
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Waits until a series is at least `value`.
    pub async fn wait_metric_at_least(&self, name: &str, labels: &str, value: f64) {
        let deadline = Instant::now() + PATIENCE;
        while self.metric(name, labels).unwrap_or(0.0) < value {
            assert!(
                Instant::now() < deadline,
                "{name}{{{labels}}} is {:?}, expected at least {value}",
                self.metric(name, labels)
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Waits until `skymesh_imc_dropped_total{reason}` reaches `value`.
    pub async fn wait_dropped(&self, reason: &str, value: f64) {
        self.wait_metric(
            "skymesh_imc_dropped_total",
            &format!("reason={reason}"),
            value,
        )
        .await;
    }
}

/// The first message within [`PATIENCE`] matching `pred` (heartbeats and others skipped).
pub async fn expect(peer: &ImcClient, what: &str, pred: impl FnMut(&Message) -> bool) -> Message {
    peer.recv_message(PATIENCE, pred)
        .await
        .unwrap_or_else(|| panic!("the peer never received {what}"))
}

/// The next message that is not a Heartbeat or Announce.
pub async fn next_reply(peer: &ImcClient) -> Message {
    expect(peer, "a reply", |m| {
        !matches!(m, Message::Heartbeat | Message::Announce(_))
    })
    .await
}

/// A marker request whose REPORT reply proves the gateway has handled everything
/// sent before it (one loop, in order) and answered nothing else meanwhile.
pub async fn barrier(peer: &ImcClient) {
    peer.send(&Message::RemoteActionsRequest {
        op: imc_proto::RemoteActionsOp::Query,
        actions: String::new(),
    })
    .await
    .expect("send query");
    let m = next_reply(peer).await;
    assert!(
        matches!(
            m,
            Message::RemoteActionsRequest {
                op: imc_proto::RemoteActionsOp::Report,
                ..
            }
        ),
        "expected only the REPORT, got {m:?}"
    );
}
