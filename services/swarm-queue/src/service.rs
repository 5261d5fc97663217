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
//!
//! **At rest** the queue ticks once a second ([`REST_TICK`]) instead: when a tick
//! leaves nothing for the next one to do ([`Swarm::at_rest`]: no drone has a
//! command running, queued or waiting for its vehicle, no reply or output waits)
//! and no reader watches its `SwarmState` (`skymesh/swarm/watch`: the pose
//! broadcast says it watches while somebody may listen to the poses, and renews
//! the word every second; a word lapses after `SWARM_WATCH_LEASE_NS`). With
//! nothing to fly, a 30 Hz tick would be the queue's whole work and 30 wake-ups a
//! second. A swarm command ends the rest as it arrives (the vehicles' topics are
//! drained first, so it sees their current state), and so does a word that starts
//! watching: the queue ticks at once, so the reader has a fresh state within a
//! tick's work. `skymesh_swarm_resting` is 1 while it rests. The rest ticks fall
//! on the machine-wide whole seconds (skymesh_runtime::timer), the instants of the
//! services' heartbeats, so neither the queue nor the GroundControl gateway, which
//! listens to its state, wakes for them alone.

use std::time::Duration;

use skymesh_ipc_types::{SwarmWatch, SWARM_WATCH_LEASE_NS};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer::{until_grid_point, Ticker};
use skymesh_runtime::{CancellationToken, IpcError};
use tokio::time::Instant;

use crate::core::Swarm;
use crate::ipc::Ports;
use crate::metrics::Metrics;

/// The tick period while the queue rests (see the module docs).
pub const REST_TICK: Duration = Duration::from_secs(1);

/// The readers that watch the state: each publisher's (header service, instance)
/// word that it watches, and when that lapses (monotonic ns).
#[derive(Debug, Default)]
struct Watches(Vec<((u16, u16), u64)>);

impl Watches {
    /// A publisher's newest word, received at `now`.
    fn word(&mut self, w: &SwarmWatch, now: u64) {
        let key = (w.header.service, w.header.instance);
        self.0.retain(|(k, _)| *k != key);
        if w.watching != 0 {
            self.0.push((key, now.saturating_add(SWARM_WATCH_LEASE_NS)));
        }
    }

    /// Whether any reader watches at `now` (lapsed words are forgotten).
    fn any(&mut self, now: u64) -> bool {
        self.0.retain(|&(_, until)| until > now);
        !self.0.is_empty()
    }
}

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
    let mut resting = false;
    let mut watches = Watches::default();
    loop {
        let (step, ticked) = tokio::select! {
            biased;
            _ = shutdown.cancelled() => return Ok(()),
            c = ports.swarm_commands.recv() => (c.and_then(|c| {
                let now = monotonic_ns();
                if resting {
                    // The last drain may be a second old: a command that needs a
                    // position must see the vehicle's current one.
                    drain_vehicles(&mut swarm, &mut ports, now)?;
                }
                swarm.handle_command(&c, now);
                while let Some(c) = ports.swarm_commands.try_recv()? {
                    swarm.handle_command(&c, now);
                }
                publish(&mut swarm, &mut ports, &mut budget)
            }), false),
            w = ports.watch.recv() => (w.and_then(|w| {
                let now = monotonic_ns();
                watches.word(&w, now);
                while let Some(w) = ports.watch.try_recv()? {
                    watches.word(&w, now);
                }
                Ok(())
            }), false),
            t = interval.tick() => {
                if let Err(e) = t {
                    return Err(anyhow::Error::new(e).context("the tick timer failed"));
                }
                let now = monotonic_ns();
                if !resting && last_tick.is_some_and(|t| now.saturating_sub(t) > 2 * period_ns) {
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
                (r, true)
            }
        };
        if let Err(e) = step {
            return Err(anyhow::Error::new(e));
        }
        let rest = swarm.at_rest() && !watches.any(monotonic_ns());
        if rest && (ticked || !resting) {
            // After a tick, or on coming to rest: the next tick on the first whole
            // second of the grid at least half a rest period on. A command or word
            // that leaves the queue at rest does not move it.
            interval.skip_to(Instant::now() + until_grid_point(REST_TICK));
        } else if !rest && resting {
            // At once: a reader that starts watching waits for a fresh state.
            interval.reset_immediately();
            last_tick = None;
        }
        if rest != resting {
            tracing::debug!(resting = rest, "swarm queue tick rate");
            metrics.resting.set(if rest { 1.0 } else { 0.0 });
            resting = rest;
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
    drain_vehicles(swarm, ports, now)?;
    swarm.tick(now);
    publish(swarm, ports, budget)?;
    // Written in place in shared memory: the sample is ~20 KiB.
    ports.state.publish_with(|out| swarm.fill_state(now, out))?;
    Ok(())
}

/// Hands the queue every drone's newest state and status, every acknowledgement and
/// every arbiter event.
fn drain_vehicles(swarm: &mut Swarm, ports: &mut Ports, now: u64) -> Result<(), IpcError> {
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
        while let Some(e) = d.events.try_recv()? {
            swarm.handle_event(idx, &e, now);
        }
    }
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
