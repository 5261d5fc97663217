//! A vehicle-sim served in-process on 127.0.0.1 (port 0 picks a free one).

use std::sync::Arc;

use skymesh_runtime::CancellationToken;
use skymesh_vehicle_sim::SimStats;
use tokio::task::JoinHandle;

use super::{PATIENCE, VEHICLE};

pub struct Sim {
    pub port: u16,
    pub stats: Arc<SimStats>,
    shutdown: CancellationToken,
    task: JoinHandle<anyhow::Result<()>>,
}

impl Sim {
    pub async fn start(port: u16) -> Sim {
        Sim::start_with(skymesh_vehicle_sim::RawConfig {
            endpoint: format!("tcp:127.0.0.1:{port}"),
            system_id: u32::from(VEHICLE),
            ..Default::default()
        })
        .await
    }

    pub async fn start_with(raw: skymesh_vehicle_sim::RawConfig) -> Sim {
        let settings = raw.validate().expect("sim settings");
        let bound = skymesh_vehicle_sim::bind(&settings)
            .await
            .expect("bind sim");
        let port = bound.local_addr().expect("sim address").port();
        let stats = Arc::new(SimStats::default());
        let shutdown = CancellationToken::new();
        let task = tokio::spawn(skymesh_vehicle_sim::run(
            settings,
            bound,
            stats.clone(),
            shutdown.clone(),
        ));
        Sim {
            port,
            stats,
            shutdown,
            task,
        }
    }

    pub async fn stop(self) {
        self.shutdown.cancel();
        tokio::time::timeout(PATIENCE, self.task)
            .await
            .expect("sim stops")
            .expect("sim task")
            .expect("sim result");
    }
}
