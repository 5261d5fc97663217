//! skymesh hardware: the companion computer's own I/O — LEDs, GPIO lines, power
//! channels, a two-line LCD, and the computer's power — on the bus.
//!
//! Gateways never touch a device. They publish a `HardwareRequest`; this service
//! executes it on its backend (simulated files, `/sys/class/leds`, the Linux GPIO
//! character device) and answers with one `HardwareReply` carrying the state after
//! the operation; it publishes the whole `HardwareState` on every change and once a
//! second, so the IMC and GroundControl gateways read the same truth.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`backend`] | the device traits and their sim, sysfs and cdev implementations |
//! | [`core`] | the pure core: request → reply + state, schedules on explicit time |
//! | [`persist`] | saved power-channel states |
//! | [`metrics`] | counters and gauges |
//! | `ipc` | every bus call |
//! | [`service`] | runtime glue for `service_main` |
//!
//! Entry points: [`Hardware::start`] then [`run`] (or [`service::run_service`]).
#![forbid(unsafe_code)]

pub mod backend;
pub mod config;
pub mod core;
mod ipc;
pub mod metrics;
pub mod persist;
pub mod service;

use std::process::Stdio;
use std::time::Duration;

use anyhow::Context as _;
use skymesh_runtime::timer::Ticker;
use skymesh_runtime::{Context, IpcError};
use tokio_util::task::TaskTracker;

pub use crate::config::{RawConfig, Settings};
pub use crate::core::{Effect, Hardware, Now, PowerCommand};
use crate::metrics::Metrics;

/// How often the whole state is republished (and input lines re-read).
pub const STATE_PERIOD: Duration = Duration::from_secs(1);

/// How long a stopping service waits for a companion power command it started.
const COMMAND_GRACE: Duration = Duration::from_secs(2);

/// What woke the loop.
enum Wake {
    Request(Result<skymesh_ipc_types::HardwareRequest, IpcError>),
    Due,
    Period,
}

/// Serves requests on an already-started [`Hardware`] until `ctx.shutdown` is
/// cancelled (then `Ok`) or the bus fails (then `Err`). Marks the service ready once
/// its bus ports exist and the first state is published.
///
/// One task owns the devices: requests are answered in order (everything pending is
/// handled per wake-up, the state is published once, then the replies); the loop sleeps until
/// the next scheduled operation or the next second, whichever comes first.
pub async fn run(mut hw: Hardware, ctx: Context) -> anyhow::Result<()> {
    let metrics = hw.metrics().clone();
    let mut ports = ipc::Ports::open(&ctx.bus)?;
    ports.state(hw.state(Now::current()))?;
    // On the machine-wide grid (skymesh_runtime::timer), not tokio's wheel: the
    // second's state falls on the instant of this process's own heartbeat (and every
    // other service's), one wake-up for both, where tokio's interval woke the
    // process twice more a second (its own instant, and the wheel's move of it).
    let mut period = Ticker::new(STATE_PERIOD).context("creating the state timer")?;
    period.tick().await?; // the first tick is immediate: the state was just published
    let commands = TaskTracker::new();
    ctx.ready();
    let result: anyhow::Result<()> = loop {
        let due = hw.next_due(Now::current());
        let wake = tokio::select! {
            biased;
            _ = ctx.shutdown.cancelled() => break Ok(()),
            r = ports.requests.recv() => Wake::Request(r),
            _ = tokio::time::sleep(due.unwrap_or_default()), if due.is_some() => Wake::Due,
            r = period.tick() => match r {
                Ok(_) => Wake::Period,
                Err(e) => break Err(anyhow::Error::new(e).context("the state timer")),
            },
        };
        let now = Now::current();
        let step = match wake {
            Wake::Request(first) => first.and_then(|first| {
                let mut changed = false;
                let mut replies = Vec::new();
                let mut next = Some(first);
                while let Some(req) = next {
                    let answer = hw.handle(&req, now);
                    replies.push(answer.reply);
                    changed |= answer.changed;
                    run_effects(answer.effects, &metrics, &commands);
                    next = ports.requests.try_recv()?;
                }
                // The state before the replies: whoever holds a reply can read the
                // state that contains its change (a query right after it is answered
                // from that state, not the one before).
                if changed {
                    ports.state(hw.state(now))?;
                }
                for reply in replies {
                    ports.reply(reply)?;
                }
                Ok(())
            }),
            Wake::Due => {
                let t = hw.tick(now);
                run_effects(t.effects, &metrics, &commands);
                if t.changed {
                    ports.state(hw.state(now))
                } else {
                    Ok(())
                }
            }
            Wake::Period => {
                let t = hw.tick(now);
                hw.poll_inputs();
                run_effects(t.effects, &metrics, &commands);
                ports.state(hw.state(now))
            }
        };
        if let Err(e) = step {
            break Err(anyhow::Error::new(e).context("hardware bus ports"));
        }
    };
    commands.close();
    if tokio::time::timeout(COMMAND_GRACE, commands.wait())
        .await
        .is_err()
    {
        tracing::warn!("a companion power command is still running; leaving it");
    }
    tracing::info!("hardware service stopped");
    result
}

fn run_effects(effects: Vec<Effect>, metrics: &Metrics, tracker: &TaskTracker) {
    for Effect::RunCommand { op, argv } in effects {
        run_command(op, argv, metrics.clone(), tracker);
    }
}

/// Starts a companion power command (no shell) and logs how it ends.
fn run_command(op: PowerCommand, argv: Vec<String>, metrics: Metrics, tracker: &TaskTracker) {
    let Some((program, args)) = argv.split_first() else {
        return;
    };
    tracing::warn!(operation = op.as_str(), command = ?argv, "running the companion power command");
    let spawned = tokio::process::Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .spawn();
    let mut child = match spawned {
        Ok(c) => c,
        Err(e) => {
            tracing::error!(operation = op.as_str(), command = ?argv, error = %e, "the companion power command could not be started");
            metrics.power_command(op.as_str(), "not_started");
            return;
        }
    };
    tracker.spawn(async move {
        match child.wait().await {
            Ok(status) if status.success() => {
                tracing::info!(operation = op.as_str(), "the companion power command succeeded");
                metrics.power_command(op.as_str(), "ok");
            }
            Ok(status) => {
                tracing::error!(operation = op.as_str(), %status, "the companion power command failed");
                metrics.power_command(op.as_str(), "failed");
            }
            Err(e) => {
                tracing::error!(operation = op.as_str(), error = %e, "waiting for the companion power command failed");
                metrics.power_command(op.as_str(), "failed");
            }
        }
    });
}
