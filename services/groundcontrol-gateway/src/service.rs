//! The gateway as a skymesh service: config and CLI from the shared runtime; the
//! sockets are bound here (a bind failure is a service failure, not a config error)
//! and handed to [`crate::run`].

use skymesh_runtime::Context;

use crate::config::Settings;
use crate::Sockets;

/// The entry point for `service_main`.
pub async fn run_service(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let sockets = Sockets::bind(&settings).await?;
    crate::run(settings, sockets, ctx).await
}
