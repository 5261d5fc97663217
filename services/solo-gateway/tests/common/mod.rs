//! The in-process harness: solo-gateway on loopback port 0 in its own iceoryx2
//! domain, plus a "tool" node that plays the shot engine (reads `from_app` and
//! `app_session`, writes `to_app`).
#![allow(dead_code)] // each test crate uses its own subset

use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_ipc_types::{
    topics, AppGeofence, AppSession, ServiceId, ShotEvent, ShotEventSample, ShotRequestSample,
};
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, Publisher, Stats, Subscriber};
use skymesh_solo_gateway::{run, Settings, Sockets};
use solo_proto::SoloMessage;
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// Generous bound for anything that should take a moment.
pub const PATIENCE: Duration = Duration::from_secs(30);

pub fn localhost() -> IpAddr {
    [127, 0, 0, 1].into()
}

/// Another loopback address: "a second phone" on the same machine.
pub fn other_host() -> IpAddr {
    [127, 0, 0, 2].into()
}

fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "solo{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

/// The value bytes of a message, as the gateway must forward them.
pub fn value_of(m: &SoloMessage) -> Vec<u8> {
    let mut b = bytes::BytesMut::new();
    m.encode_value(&mut b);
    b.to_vec()
}

/// A request the gateway published, read back as the Solo message it stands for
/// (`msg_type` and `value` as the app sent them).
#[derive(Debug, Clone, PartialEq)]
pub struct FromApp {
    pub header: skymesh_ipc_types::SampleHeader,
    pub session: u32,
    /// Bytes of the Solo value.
    pub len: u32,
    pub msg_type: u32,
    pub flags: u32,
    value: Vec<u8>,
}

impl FromApp {
    pub fn new(sample: &ShotRequestSample) -> FromApp {
        let request = sample
            .request()
            .expect("the gateway publishes valid requests");
        let m = skymesh_solo_gateway::translate::solo_request(&request);
        let value = value_of(&m);
        FromApp {
            header: sample.header,
            session: sample.session,
            len: value.len() as u32,
            msg_type: m.msg_type(),
            flags: sample.flags,
            value,
        }
    }

    pub fn value(&self) -> &[u8] {
        &self.value
    }

    pub fn is_follow_stream(&self) -> bool {
        self.flags & skymesh_ipc_types::shot_api::request_flags::FOLLOW_STREAM != 0
    }
}

/// solo-gateway running in-process, and the engine side of the bus.
pub struct Gateway {
    pub domain: Domain,
    pub stats: Stats,
    pub tcp: SocketAddr,
    pub udp: SocketAddr,
    pub from_app: Subscriber<ShotRequestSample>,
    /// GEOFENCE_SET_DATA, translated.
    pub geofence: Subscriber<AppGeofence>,
    pub sessions: Subscriber<AppSession>,
    pub to_app: Publisher<ShotEventSample>,
    shutdown: CancellationToken,
    task: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Gateway {
    pub async fn start() -> Gateway {
        Gateway::start_with(Settings::loopback_any_port()).await
    }

    /// Starts with `settings` (the sockets must be on port 0).
    pub async fn start_with(settings: Settings) -> Gateway {
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "solo-gateway",
            ServiceId::SoloGateway,
            0,
            stats.clone(),
        )
        .expect("gateway bus");
        let tool = Bus::open(
            &domain,
            "shot-engine-fake",
            ServiceId::Tool,
            0,
            Stats::new(),
        )
        .expect("tool bus");
        // Before the gateway runs: from_app has no history.
        let from_app = tool
            .subscriber::<ShotRequestSample>(&topics::shot_requests())
            .expect("shot requests subscriber");
        let geofence = tool
            .subscriber::<AppGeofence>(&topics::shot_app_geofence())
            .expect("app_geofence subscriber");
        let sessions = tool
            .subscriber::<AppSession>(&topics::shot_app_session())
            .expect("app_session subscriber");
        let to_app = tool
            .publisher::<ShotEventSample>(&topics::shot_events())
            .expect("shot events publisher");
        let sockets = Sockets::bind(&settings).await.expect("bind");
        let (tcp, udp) = sockets.local_addrs().expect("addresses");
        let shutdown = CancellationToken::new();
        let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "solo-gateway");
        let task = tokio::spawn(run(settings, sockets, ctx));
        Gateway {
            domain,
            stats,
            tcp,
            udp,
            from_app,
            geofence,
            sessions,
            to_app,
            shutdown,
            task: Some(task),
        }
    }

    /// Stops the gateway (it must return `Ok` within the runtime's grace period) and
    /// cleans the domain.
    pub async fn stop(mut self) {
        self.halt().await;
        let Gateway {
            domain,
            from_app,
            geofence,
            sessions,
            to_app,
            ..
        } = self;
        drop((from_app, geofence, sessions, to_app));
        domain.remove_leftover_files();
    }

    /// Stops the gateway but keeps the engine side open (to read what it said last).
    pub async fn halt(&mut self) {
        self.shutdown.cancel();
        if let Some(task) = self.task.take() {
            tokio::time::timeout(Duration::from_secs(5), task)
                .await
                .expect("solo-gateway stops within 5 s")
                .expect("solo-gateway task")
                .expect("solo-gateway result");
        }
    }

    /// The next message the gateway publishes for the engine.
    pub async fn next_from_app(&mut self) -> FromApp {
        let sample = self
            .from_app
            .recv_timeout(PATIENCE)
            .await
            .expect("shot requests")
            .unwrap_or_else(|| panic!("no ShotRequestSample within {PATIENCE:?}"));
        FromApp::new(&sample)
    }

    /// The next geofence the gateway publishes for the engine.
    pub async fn next_geofence(&mut self) -> AppGeofence {
        self.geofence
            .recv_timeout(PATIENCE)
            .await
            .expect("app_geofence")
            .unwrap_or_else(|| panic!("no AppGeofence within {PATIENCE:?}"))
    }

    /// Waits for an `AppSession` sample matching `pred`.
    pub async fn wait_session(
        &mut self,
        what: &str,
        pred: impl Fn(&AppSession) -> bool,
    ) -> AppSession {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.sessions.recv_timeout(left).await.expect("app_session") {
                Some(s) if pred(&s) => return s,
                Some(_) => {}
                None => panic!("no AppSession with {what} within {PATIENCE:?}"),
            }
        }
    }

    /// Waits until session `n` is connected.
    pub async fn wait_connected(&mut self, n: u32) -> AppSession {
        self.wait_session(&format!("session {n} connected"), |s| {
            s.session == n && s.connected == 1
        })
        .await
    }

    /// Sends an event to the app as the engine does (session 0 = whoever is connected).
    pub fn send_to_app(&mut self, session: u32, e: &ShotEvent) {
        self.to_app
            .publish(ShotEventSample::new(session, e))
            .expect("publish shot event");
    }

    /// The current value of a series (`labels` as `k=v,k=v`), if registered.
    pub fn metric(&self, name: &str, labels: &str) -> Option<f64> {
        self.stats.value(name, labels)
    }

    /// Waits until a series reaches `value` (counters are updated by other tasks).
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

    /// Waits until `skymesh_solo_malformed_total{kind}` reaches `value`.
    pub async fn wait_malformed(&self, kind: &str, value: f64) {
        self.wait_metric(
            "skymesh_solo_malformed_total",
            &format!("kind={kind}"),
            value,
        )
        .await;
    }
}
