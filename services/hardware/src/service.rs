//! The hardware service as a skymesh service: config and CLI from the shared
//! runtime; the devices are opened here (a device that cannot be opened is a service
//! failure, restarted with backoff, not a config error) and handed to [`crate::run`].

use anyhow::Context as _;
use skymesh_runtime::Context;

use crate::config::{LcdBackend, Settings};
use crate::core::Hardware;
use crate::metrics::Metrics;

/// The entry point for `service_main`.
pub async fn run_service(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let hw = Hardware::start(&settings, Metrics::new(&ctx.stats))
        .context("opening the configured devices")?;
    for l in &settings.leds {
        tracing::info!(led = %l.name, backend = %l.backend, "LED");
    }
    for g in &settings.gpios {
        tracing::info!(line = %g.name, output = g.output, backend = %g.backend, "GPIO line");
    }
    tracing::info!(
        state_dir = %settings.state_dir.display(),
        lcd = match settings.lcd.backend {
            LcdBackend::None => "none",
            LcdBackend::Sim => "sim",
        },
        lcd_width = settings.lcd.width,
        power_down_command = ?settings.power.power_down_command,
        power_up_command = ?settings.power.power_up_command,
        power_down_delay_s = settings.power.power_down_delay.as_secs_f64(),
        "hardware service serving {} LEDs, {} GPIO lines, {} power channels",
        settings.leds.len(),
        settings.gpios.len(),
        settings.channels.len(),
    );
    if settings.power.power_down_command.is_empty() {
        tracing::info!("no power_down_command: companion power-down requests will be refused");
    }
    crate::run(hw, ctx).await
}
