//! The event loop: one task owns the queue and every port (no locks, no thread per
//! subscriber).
//!
//! - A swarm command wakes the loop at once (the command topic's event, awaited):
//!   everything pending on it is handled, in order, and what that produced is
//!   published right away (a queued command that can start, starts).
//! - The tick (`tick_hz`) drains every drone's vehicle topics without waiting
//!   (newest state and status, every acknowledgement), steps every drone, publishes
//!   the vehicle commands, geofences and hardware requests, up to
//!   `max_replies_per_tick` replies, and the `SwarmState`.
//!
//! So a command is acted on within microseconds of its arrival, a vehicle's answer
//! is seen within one tick (33 ms at 30 Hz), and the state is at most one tick old.
//! Replies beyond the per-tick budget (`max_replies_per_tick`, within the reply
//! topic's buffer of 1024) wait for the next tick, so bursts of answers never
//! overrun the gateway's subscriber buffer.

use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer::Ticker;
use skymesh_runtime::{CancellationToken, IpcError};

use crate::core::Swarm;
use crate::ipc::Ports;
use crate::metrics::Metrics;

/// Runs until `shutdown`.
pub(crate) async fn run_loop(
    mut swarm: Swarm,
    mut ports: Ports,
    metrics: Metrics,
    shutdown: CancellationToken,
) -> anyhow::Result<()> {
    let period = swarm.settings().tick_period;
    let budget_per_tick = swarm.settings().max_replies_per_tick;
    // A timerfd, not tokio's wheel (which would add ~16 wake-ups a second to a
    // 30 Hz tick): see skymesh_runtime::timer.
    let mut interval = Ticker::new(period)?;
    let period_ns = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX);
    let mut last_tick: Option<u64> = None;
    let mut budget = budget_per_tick;
    loop {
        let step = tokio::select! {
            biased;
            _ = shutdown.cancelled() => return Ok(()),
            c = ports.swarm_commands.recv() => c.and_then(|c| {
                let now = monotonic_ns();
                swarm.handle_command(&c, now);
                while let Some(c) = ports.swarm_commands.try_recv()? {
                    swarm.handle_command(&c, now);
                }
                publish(&mut swarm, &mut ports, &mut budget)
            }),
            t = interval.tick() => {
                if let Err(e) = t {
                    return Err(anyhow::Error::new(e).context("the tick timer failed"));
                }
                let now = monotonic_ns();
                if last_tick.is_some_and(|t| now.saturating_sub(t) > 2 * period_ns) {
                    metrics.overruns.inc();
                }
                last_tick = Some(now);
                budget = budget_per_tick;
                let r = tick(&mut swarm, &mut ports, &mut budget, now);
                let took = monotonic_ns().saturating_sub(now);
                metrics.tick_seconds.observe(took as f64 / 1e9);
                if took > period_ns {
                    metrics.overruns.inc();
                }
                r
            }
        };
        if let Err(e) = step {
            return Err(anyhow::Error::new(e));
        }
    }
}

/// Drains the vehicle topics, steps the queue, publishes everything.
fn tick(
    swarm: &mut Swarm,
    ports: &mut Ports,
    budget: &mut usize,
    now: u64,
) -> Result<(), IpcError> {
    for (idx, d) in ports.drones.iter().enumerate() {
        if let Some(s) = d.state.latest()? {
            swarm.handle_state(idx, &s, now);
        }
        if let Some(s) = d.status.latest()? {
            swarm.handle_status(idx, &s, now);
        }
        while let Some(a) = d.acks.try_recv()? {
            swarm.handle_ack(idx, &a, now);
        }
    }
    swarm.tick(now);
    publish(swarm, ports, budget)?;
    // Written in place in shared memory: the sample is ~20 KiB.
    ports.state.publish_with(|out| swarm.fill_state(now, out))?;
    Ok(())
}

/// Publishes the queue's outputs and as many replies as the budget allows.
fn publish(swarm: &mut Swarm, ports: &mut Ports, budget: &mut usize) -> Result<(), IpcError> {
    let out = swarm.take_outputs();
    for c in out.commands {
        match swarm.index_of_vehicle(c.vehicle_id) {
            Some(idx) => {
                ports.drones[idx].commands.publish(c)?;
            }
            None => tracing::error!(
                vehicle = c.vehicle_id,
                "command for a vehicle without ports"
            ),
        }
    }
    for g in out.geofences {
        if let Some(idx) = swarm.index_of_vehicle(g.vehicle_id) {
            ports.publish_geofence(idx, *g)?;
        }
    }
    if let Some(hw) = &mut ports.hardware {
        for r in out.hardware {
            hw.publish(r)?;
        }
    }
    while *budget > 0 {
        let Some(r) = swarm.pop_reply() else { break };
        ports.replies.publish(r)?;
        *budget -= 1;
    }
    Ok(())
}
