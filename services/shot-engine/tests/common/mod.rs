//! Shared by the in-process tests: a domain of their own, settings with a temporary
//! state file, app messages as the gateway would publish them, and the engine
//! running `run_with` in a task.
#![allow(dead_code)] // each test crate uses its own subset

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_ipc_types::{ServiceId, ShotRequest, ShotRequestSample};
use skymesh_runtime::{Bus, CancellationToken, Domain, Stats};
use skymesh_shot_engine::{RawConfig, Settings};
use tokio::task::JoinHandle;

pub const VEHICLE: u8 = 1;
/// Generous bound for anything that should take a second or two.
pub const PATIENCE: Duration = Duration::from_secs(30);

pub fn unique_domain() -> Domain {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "se{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    Domain::load(&name, None).expect("domain")
}

pub fn settings(dir: &std::path::Path) -> Settings {
    let mut s = RawConfig::default()
        .validate_with_env(None, None)
        .expect("defaults");
    s.state_file = dir.join("shot-engine.json");
    s
}

/// `msg` as a gateway publishes it for app session 1.
pub fn app_msg(msg: &ShotRequest) -> ShotRequestSample {
    ShotRequestSample::new(1, msg)
}

/// The engine running in-process on `domain`.
pub struct Engine {
    pub shutdown: CancellationToken,
    pub task: JoinHandle<anyhow::Result<()>>,
    pub stats: Stats,
}

impl Engine {
    /// Starts the engine and waits until its ports are open.
    pub async fn start(domain: &Domain, settings: Settings) -> Engine {
        let stats = Stats::new();
        let bus = Bus::open(
            domain,
            "shot-engine",
            ServiceId::ShotEngine,
            0,
            stats.clone(),
        )
        .expect("engine bus");
        let shutdown = CancellationToken::new();
        let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(skymesh_shot_engine::run_with(
            settings,
            bus,
            stats.clone(),
            shutdown.clone(),
            move || {
                let _ = ready_tx.send(());
            },
        ));
        tokio::time::timeout(PATIENCE, ready_rx)
            .await
            .expect("engine ready in time")
            .expect("engine ready");
        Engine {
            shutdown,
            task,
            stats,
        }
    }

    /// Stops the engine; it must return `Ok` within the runtime's grace period.
    pub async fn stop(self) {
        self.shutdown.cancel();
        tokio::time::timeout(Duration::from_secs(5), self.task)
            .await
            .expect("engine stops within 5 s")
            .expect("engine task")
            .expect("engine result");
    }
}
