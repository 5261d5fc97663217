//! The hardware service in-process on the real bus (its own iceoryx2 domain) with
//! the sim backend in a temp dir: requests in, replies and state out.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_hardware::config::RawConfig;
use skymesh_hardware::service::run_service;
use skymesh_ipc_types::hardware::{PowerChannelOp, SystemPowerOp};
use skymesh_ipc_types::{
    topics, HardwareOp, HardwareReply, HardwareRequest, HardwareResult, HardwareState, HwName,
    ServiceId,
};
use skymesh_runtime::{
    Bus, CancellationToken, Context, Domain, Publisher, ServiceConfig, Stats, Subscriber,
};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// Generous bound for anything that should take a moment.
const PATIENCE: Duration = Duration::from_secs(30);

fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "hw{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

/// The service running in-process, and a gateway's side of the bus.
struct Rig {
    domain: Domain,
    dir: tempfile::TempDir,
    stats: Stats,
    requests: Publisher<HardwareRequest>,
    replies: Subscriber<HardwareReply>,
    state: Subscriber<HardwareState>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
    next_id: u32,
}

impl Rig {
    /// Starts the service on the shipped config with each `(from, to)` replaced
    /// (`@DIR@` in `to` is the state directory).
    async fn start(edits: &[(&str, &str)]) -> Rig {
        let dir = tempfile::tempdir().expect("temp dir");
        let dir_s = dir.path().display().to_string();
        let mut text = RawConfig::DEFAULT_TOML.to_string();
        for (from, to) in [("state_dir = \"\"", "state_dir = \"@DIR@\"")]
            .iter()
            .chain(edits)
        {
            assert!(text.contains(from), "the shipped config has no `{from}`");
            text = text.replace(from, &to.replace("@DIR@", &dir_s));
        }
        let settings = skymesh_runtime::config::parse::<RawConfig>(&text, "test").expect("config");
        assert_eq!(settings.state_dir, dir.path());
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(&domain, "hardware", ServiceId::Hardware, 0, stats.clone())
            .expect("service bus");
        let tool =
            Bus::open(&domain, "gateway-fake", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
        let requests = tool
            .publisher::<HardwareRequest>(&topics::hardware_request())
            .expect("request publisher");
        let replies = tool
            .subscriber::<HardwareReply>(&topics::hardware_reply())
            .expect("reply subscriber");
        let state = tool
            .subscriber::<HardwareState>(&topics::hardware_state())
            .expect("state subscriber");
        let shutdown = CancellationToken::new();
        let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "hardware");
        let task = tokio::spawn(run_service(settings, ctx));
        let mut rig = Rig {
            domain,
            dir,
            stats,
            requests,
            replies,
            state,
            shutdown,
            task: Some(task),
            next_id: 0,
        };
        // The first state is published once the request subscriber exists.
        rig.wait_state("the first state", |_| true).await;
        rig
    }

    fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    async fn stop(mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            tokio::time::timeout(Duration::from_secs(5), task)
                .await
                .expect("the service stops within 5 s")
                .expect("service task")
                .expect("service result");
        }
        let Rig {
            domain,
            requests,
            replies,
            state,
            ..
        } = self;
        drop((requests, replies, state));
        domain.remove_leftover_files();
    }

    /// Publishes `req` and returns its reply.
    async fn ask(&mut self, mut req: HardwareRequest) -> HardwareReply {
        self.next_id += 1;
        req.request_id = self.next_id;
        self.requests.publish(req).expect("publish request");
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.replies.recv_timeout(left).await.expect("reply topic") {
                Some(r)
                    if r.request_id == self.next_id
                        && r.requester_service == ServiceId::Tool.to_wire() =>
                {
                    assert_eq!(r.header.service_id(), Ok(ServiceId::Hardware));
                    return r;
                }
                Some(_) => {}
                None => panic!("no reply to request {} within {PATIENCE:?}", self.next_id),
            }
        }
    }

    /// Waits for a state sample matching `pred`.
    async fn wait_state(
        &mut self,
        what: &str,
        pred: impl Fn(&HardwareState) -> bool,
    ) -> HardwareState {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.state.recv_timeout(left).await.expect("state topic") {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None => panic!("no state with {what} within {PATIENCE:?}"),
            }
        }
    }

    fn metric(&self, name: &str, labels: &str) -> Option<f64> {
        self.stats.value(name, labels)
    }
}

fn req(op: HardwareOp, name: &str) -> HardwareRequest {
    HardwareRequest {
        name: HwName::new(name),
        ..HardwareRequest::new(0, op)
    }
}

async fn wait_for_file(path: &Path, content: &str) {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if std::fs::read_to_string(path).is_ok_and(|c| c.trim() == content) {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{} did not hold `{content}` within {PATIENCE:?}",
            path.display()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test]
async fn an_led_set_is_answered_and_published() {
    let mut rig = Rig::start(&[]).await;
    let reply = rig
        .ask(HardwareRequest {
            value: 180,
            ..req(HardwareOp::LedSet, "red")
        })
        .await;
    assert_eq!(reply.result(), Ok(HardwareResult::Ok));
    assert_eq!(reply.value, 180);
    assert_eq!(reply.name.as_str(), "red");
    assert_eq!(reply.op, HardwareOp::LedSet.to_wire());
    let s = rig
        .wait_state("red at 180", |s| {
            s.led("red").is_some_and(|l| l.value == 180)
        })
        .await;
    assert_eq!(s.n_leds, 4);
    assert_eq!(s.led("green").map(|l| l.value), Some(0));
    assert_eq!(
        std::fs::read_to_string(rig.path("led/red")).unwrap(),
        "180\n"
    );
    let reply = rig.ask(req(HardwareOp::LedQuery, "ultraviolet")).await;
    assert_eq!(reply.result(), Ok(HardwareResult::UnknownName));
    assert_eq!(
        rig.metric("skymesh_hardware_requests_total", "op=led_set,result=ok"),
        Some(1.0)
    );
    rig.stop().await;
}

#[tokio::test]
async fn a_scheduled_power_channel_turns_on() {
    let mut rig = Rig::start(&[]).await;
    let reply = rig
        .ask(HardwareRequest {
            sub_op: PowerChannelOp::ScheduleOn.to_wire(),
            sched_s: 0.3,
            ..req(HardwareOp::PowerChannel, "lights")
        })
        .await;
    assert_eq!(reply.result(), Ok(HardwareResult::Ok));
    assert_eq!(reply.value, 0, "not yet");
    assert!(reply.time_remaining_s > 0.0 && reply.time_remaining_s <= 0.3);
    rig.wait_state("lights on", |s| {
        s.channel("lights")
            .is_some_and(|c| c.on == 1 && c.sched_on_in_s < 0.0)
    })
    .await;
    wait_for_file(&rig.path("power/lights"), "1").await;
    assert_eq!(
        rig.metric("skymesh_hardware_power_channel_on", "channel=lights"),
        Some(1.0)
    );
    rig.stop().await;
}

#[tokio::test]
async fn an_input_line_is_read_from_its_file() {
    let mut rig = Rig::start(&[]).await;
    let reply = rig.ask(req(HardwareOp::GpioGet, "button_a")).await;
    assert_eq!((reply.result(), reply.value), (Ok(HardwareResult::Ok), 0));
    std::fs::write(rig.path("gpio/button_a"), "1\n").unwrap();
    let reply = rig.ask(req(HardwareOp::GpioGet, "button_a")).await;
    assert_eq!((reply.result(), reply.value), (Ok(HardwareResult::Ok), 1));
    // Released: the once-a-second poll publishes it without a request.
    std::fs::write(rig.path("gpio/button_a"), "0\n").unwrap();
    rig.wait_state("button_a released", |s| {
        s.gpio("button_a").is_some_and(|g| g.value == 0)
    })
    .await;
    let reply = rig
        .ask(HardwareRequest {
            value: 1,
            ..req(HardwareOp::GpioSet, "button_a")
        })
        .await;
    assert_eq!(reply.result(), Ok(HardwareResult::NotSupported));
    rig.stop().await;
}

#[tokio::test]
async fn power_down_is_refused_by_default_and_bad_requests_are_answered() {
    let mut rig = Rig::start(&[]).await;
    let reply = rig
        .ask(HardwareRequest {
            sub_op: SystemPowerOp::PowerDown.to_wire(),
            ..req(HardwareOp::SystemPower, "")
        })
        .await;
    assert_eq!(reply.result(), Ok(HardwareResult::Refused));
    assert_eq!(reply.sub_op, SystemPowerOp::PowerDownAborted.to_wire());
    assert!(reply.message.as_str().contains("no power_down_command"));
    let mut bad = req(HardwareOp::LedSet, "red");
    bad.op = 200;
    let reply = rig.ask(bad).await;
    assert_eq!(reply.result(), Ok(HardwareResult::InvalidValue));
    assert_eq!(reply.op, 200);
    // Still serving.
    let reply = rig.ask(req(HardwareOp::LedQuery, "status")).await;
    assert_eq!(reply.result(), Ok(HardwareResult::Ok));
    assert_eq!(
        rig.metric(
            "skymesh_hardware_requests_total",
            "op=unknown,result=invalid_value"
        ),
        Some(1.0)
    );
    rig.stop().await;
}

#[tokio::test]
async fn power_down_runs_the_configured_command_when_due() {
    let mut rig = Rig::start(&[
        (
            "power_down_command = []",
            "power_down_command = [\"touch\", \"@DIR@/powered-down\"]",
        ),
        ("power_down_delay_s = 10", "power_down_delay_s = 0.3"),
    ])
    .await;
    let reply = rig
        .ask(HardwareRequest {
            sub_op: SystemPowerOp::PowerDown.to_wire(),
            ..req(HardwareOp::SystemPower, "")
        })
        .await;
    assert_eq!(reply.result(), Ok(HardwareResult::Ok));
    assert_eq!(reply.sub_op, SystemPowerOp::PowerDownInProgress.to_wire());
    assert!(reply.time_remaining_s > 0.0 && reply.time_remaining_s <= 0.3);
    let deadline = Instant::now() + PATIENCE;
    while !rig.path("powered-down").exists() {
        assert!(Instant::now() < deadline, "the command did not run");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    rig.wait_state("nothing pending", |s| {
        s.system_power == SystemPowerOp::PowerDownAborted.to_wire()
    })
    .await;
    let deadline = Instant::now() + PATIENCE;
    while rig.metric(
        "skymesh_hardware_power_commands_total",
        "op=power_down,result=ok",
    ) != Some(1.0)
    {
        assert!(
            Instant::now() < deadline,
            "the command's end was not counted"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    rig.stop().await;
}
