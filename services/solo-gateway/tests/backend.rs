//! The gateway without its backend: a request the shot engine answers waits up to
//! `backend_wait_ms` for one to read the bus, then is answered by the gateway with
//! the protocol's error (issue 43, "Ready means able to serve": never silence).

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_ipc_types::{topics, ServiceId, ShotRequest, ShotRequestSample};
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, Stats};
use skymesh_solo_gateway::client::AppClient;
use skymesh_solo_gateway::{run, Settings, Sockets};
use solo_proto::{ButtonSetting, SoloMessage};
use tokio::task::JoinHandle;
use tokio::time::Instant;

const PATIENCE: Duration = Duration::from_secs(30);

/// solo-gateway in its own domain, with no shot engine on the bus.
struct Alone {
    domain: Domain,
    stats: Stats,
    app: AppClient,
    shutdown: CancellationToken,
    task: JoinHandle<anyhow::Result<()>>,
}

impl Alone {
    async fn start(backend_wait: Duration) -> Alone {
        static N: AtomicU32 = AtomicU32::new(0);
        let name = format!(
            "solobk{}x{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        );
        let domain = Domain::load(&name, None).expect("domain");
        let stats = Stats::new();
        let bus = Bus::open(
            &domain,
            "solo-gateway",
            ServiceId::SoloGateway,
            0,
            stats.clone(),
        )
        .expect("gateway bus");
        let settings = Settings {
            backend_wait,
            ..Settings::loopback_any_port()
        };
        let sockets = Sockets::bind(&settings).await.expect("bind");
        let (tcp, _) = sockets.local_addrs().expect("addresses");
        let shutdown = CancellationToken::new();
        let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "solo-gateway");
        let task = tokio::spawn(run(settings, sockets, ctx));
        let app = AppClient::connect(tcp).await.expect("connect");
        Alone {
            domain,
            stats,
            app,
            shutdown,
            task,
        }
    }

    fn backend_missing(&self) -> Option<f64> {
        self.stats
            .value("skymesh_solo_malformed_total", "kind=backend_missing")
    }

    async fn stop(self) {
        self.shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), self.task)
            .await
            .expect("solo-gateway stops within 5 s")
            .expect("solo-gateway task")
            .expect("solo-gateway result");
        self.domain.remove_leftover_files();
    }
}

fn get_button() -> SoloMessage {
    SoloMessage::GetButtonSetting(ButtonSetting {
        button: 4,
        event: 0,
        shot: -1,
        mode: -1,
    })
}

#[tokio::test]
async fn without_a_shot_engine_requests_are_answered_with_the_protocol_error() {
    let wait = Duration::from_millis(300);
    let mut gw = Alone::start(wait).await;
    let sent = Instant::now();
    gw.app
        .send(&SoloMessage::GeofenceClear)
        .await
        .expect("send");
    assert_eq!(
        gw.app.recv(PATIENCE).await,
        Some(SoloMessage::GeofenceSetAck {
            count: 0,
            valid: false
        })
    );
    let waited = sent.elapsed();
    match gw.app.recv(PATIENCE).await {
        Some(SoloMessage::ShotManagerError(text)) => {
            assert!(text.contains("shot engine is not running"), "{text}");
        }
        other => panic!("expected SHOTMANAGER_ERROR, got {other:?}"),
    }
    assert!(waited >= wait, "answered after {waited:?}, before the wait");
    // The wait ran out: the next request is answered at once, not after another.
    let sent = Instant::now();
    gw.app.send(&get_button()).await.expect("send");
    assert!(matches!(
        gw.app.recv(PATIENCE).await,
        Some(SoloMessage::ShotManagerError(_))
    ));
    assert!(
        sent.elapsed() < wait,
        "second answer took {:?}",
        sent.elapsed()
    );
    assert_eq!(gw.backend_missing(), Some(2.0));
    // A message without a reply gets none (forwarded as always).
    gw.app.send(&SoloMessage::Pause).await.expect("send");
    assert_eq!(gw.app.recv(Duration::from_millis(200)).await, None);
    assert_eq!(gw.backend_missing(), Some(2.0));
    gw.stop().await;
}

#[tokio::test]
async fn a_shot_engine_that_appears_within_the_wait_gets_the_request() {
    let mut gw = Alone::start(Duration::from_secs(10)).await;
    gw.app.send(&get_button()).await.expect("send");
    tokio::time::sleep(Duration::from_millis(300)).await;
    let engine = Bus::open(
        &gw.domain,
        "shot-engine-fake",
        ServiceId::Tool,
        0,
        Stats::new(),
    )
    .expect("engine bus");
    let mut from_app = engine
        .subscriber::<ShotRequestSample>(&topics::shot_requests())
        .expect("shot requests subscriber");
    let m = from_app
        .recv_timeout(PATIENCE)
        .await
        .expect("from_app")
        .expect("the request, forwarded once the engine reads");
    assert!(matches!(m.request(), Ok(ShotRequest::GetButtonSetting(_))));
    assert_eq!(gw.backend_missing().unwrap_or(0.0), 0.0);
    drop(from_app);
    drop(engine);
    gw.stop().await;
}
