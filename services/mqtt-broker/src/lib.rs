//! The `mqtt-broker` service: an embedded MQTT 3.1.1 broker ([rumqttd]) on
//! 127.0.0.1:1883 by default, so `skymesh up` has a broker for the DJI Cloud API
//! gateway with nothing installed. It is not on the iceoryx2 bus beyond the
//! runtime's heartbeat and stats. Every client goes through the gate ([`gate`]:
//! logins, per-user topic ACLs, a cap on topics) before rumqttd, which listens only
//! on an internal loopback port. An optional TLS listener ([`tls`]) terminates TLS
//! in this service and hands each connection to the gate.
//!
//! [rumqttd]: https://docs.rs/rumqttd

pub mod acl;
pub mod broker;
pub mod config;
pub mod gate;
pub mod metrics;
pub mod tls;

pub use broker::{serve, BrokerError};
pub use config::{RawConfig, Settings};
use skymesh_runtime::Context;

/// The service entry point for `service_main`.
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let ready = ctx.clone();
    serve(
        settings,
        ctx.stats.clone(),
        ctx.shutdown.clone(),
        move || ready.ready(),
    )
    .await?;
    Ok(())
}
