//! The gateway as a skymesh service: config and CLI from the shared runtime; the
//! listener is bound here (a bind failure is a service failure, not a config error)
//! and handed to [`crate::run`].

use skymesh_runtime::Context;

use crate::config::Settings;

/// The entry point for `service_main`.
pub async fn run_service(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let listener = crate::bind(&settings).await?;
    crate::run(settings, listener, ctx).await
}
