//! Runtime glue for `service_main`.

use skymesh_runtime::Context;

use crate::config::Settings;

/// The entry point for `service_main`.
pub async fn run_service(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    crate::run(settings, ctx).await
}
