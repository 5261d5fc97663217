//! The event loop: one task owns the engine and every port (no locks).
//!
//! App messages, the app's geofence, the app session and buttons wake the loop as
//! they arrive (the engine's answers go out at once, decided on the newest vehicle
//! samples: the vehicle topics are drained first). App messages and geofences come
//! on two topics from the same gateway task: whatever is pending on both is handled
//! in the order of their publish stamps, so a CLEAR sent after a SET_DATA is not
//! undone by it; the interval (`loop_hz`) drains the vehicle's
//! state, status, payload, authority, arbiter events and acks, steps the flying
//! shot and publishes what the engine asks for. A tick that takes longer than the
//! period, or starts more than a period late, counts as an overrun.
//!
//! Idle: while [`Engine::idle_until`] says nothing needs every tick (no shot, the
//! vehicle disarmed, no fence hold), the loop does not tick at `loop_hz`: it sleeps
//! until the engine's next time-driven deadline (the idle `ShotStatus` once a second
//! on the whole second, the app-session timeout) and also wakes for the vehicle's
//! status, authority, arbiter events and acks (a few per second: an arm or an
//! authority change is handled at once, as the periodic tick did within a period). The vehicle state
//! and payload (50 Hz and 10 Hz) are not waited for: only the newest matters and it
//! is read at every tick and before every app message or button. Once something
//! needs ticks the interval restarts, a period after that moment.
//!
//! Event steps: when an app message or button changed a flying shot's guidance
//! (`Engine::take_step_request`), the loop ticks at once instead of draining, and
//! keeps its phase: the next periodic tick comes when it was due anyway (see
//! "Event steps" in `engine/mod.rs` for why).

use std::time::Duration;

use anyhow::Context as _;
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer::{Ticker, Timer};
use skymesh_runtime::{Counter, IpcError};
use tokio_util::sync::CancellationToken;

use skymesh_ipc_types::{
    AppGeofence, ArbiterEvent, AuthorityState, CommandAck, ShotEventSample, ShotRequestSample,
    VehicleStatus,
};

use crate::engine::{Engine, Outputs};
use crate::ipc::Ports;

/// What woke the loop.
enum Wake {
    Tick,
    App(Result<ShotRequestSample, IpcError>),
    Fence(Result<Box<AppGeofence>, IpcError>),
    Session(Result<skymesh_ipc_types::AppSession, IpcError>),
    Button(Result<skymesh_ipc_types::ButtonEvent, IpcError>),
    /// Idle only: a vehicle sample the idle loop waited for; handled in its place
    /// in the drain order, then a tick.
    Vehicle(Result<VehicleInput, IpcError>),
}

/// A vehicle sample the idle loop received while waiting (see the module doc).
enum VehicleInput {
    Status(VehicleStatus),
    Authority(AuthorityState),
    Event(ArbiterEvent),
    Ack(CommandAck),
}

/// Runs until `shutdown`; then ends an active shot and publishes the last outputs.
pub(crate) async fn run_loop(
    mut engine: Engine,
    mut ports: Ports,
    period: Duration,
    shutdown: CancellationToken,
    overruns: Counter,
) -> anyhow::Result<()> {
    // A timerfd, not tokio's wheel (which would add ~16 wake-ups a second to the
    // 25 Hz tick): see skymesh_runtime::timer.
    let mut interval = Ticker::new(period).context("creating the tick timer")?;
    // The idle deadlines too (on the wheel a sleep longer than 64 ms costs two wake-ups).
    let mut idle_timer = Timer::new().context("creating the idle timer")?;
    let period_ns = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX);
    let mut last_tick: Option<u64> = None;
    let mut was_idle = false;
    let result = loop {
        let idle_until = engine.idle_until();
        match idle_until {
            Some(_) => {
                // Slow idle ticks are not overruns.
                last_tick = None;
                was_idle = true;
            }
            None if was_idle => {
                // Ticking again: the first periodic tick a period from now.
                interval.reset();
                was_idle = false;
            }
            None => {}
        }
        let wake = match idle_until {
            None => tokio::select! {
                biased;
                _ = shutdown.cancelled() => break Ok(()),
                t = interval.tick() => match t {
                    Ok(_) => Wake::Tick,
                    Err(e) => break Err(anyhow::Error::new(e).context("the tick timer failed")),
                },
                m = ports.from_app.recv() => Wake::App(m),
                g = ports.app_geofence.recv() => Wake::Fence(g.map(Box::new)),
                s = ports.app_session.recv() => Wake::Session(s),
                b = ports.buttons.recv() => Wake::Button(b),
            },
            Some(until_ns) => {
                let wait = Duration::from_nanos(until_ns.saturating_sub(monotonic_ns()));
                let at = tokio::time::Instant::now() + wait;
                tokio::select! {
                    biased;
                    _ = shutdown.cancelled() => break Ok(()),
                    t = idle_timer.sleep_until(at) => match t {
                        Ok(()) => Wake::Tick,
                        Err(e) => break Err(anyhow::Error::new(e).context("the idle timer failed")),
                    },
                    m = ports.from_app.recv() => Wake::App(m),
                    g = ports.app_geofence.recv() => Wake::Fence(g.map(Box::new)),
                    s = ports.app_session.recv() => Wake::Session(s),
                    b = ports.buttons.recv() => Wake::Button(b),
                    v = ports.status.recv() => Wake::Vehicle(v.map(VehicleInput::Status)),
                    v = ports.authority.recv() => Wake::Vehicle(v.map(VehicleInput::Authority)),
                    v = ports.events.recv() => Wake::Vehicle(v.map(VehicleInput::Event)),
                    v = ports.acks.recv() => Wake::Vehicle(v.map(VehicleInput::Ack)),
                }
            }
        };
        let now = monotonic_ns();
        let step = match wake {
            Wake::Vehicle(v) => v.and_then(|v| {
                drain_vehicle_with(&mut engine, &ports, now, Some(v))
                    .and_then(|()| publish(&mut ports, engine.tick(now)))
            }),
            Wake::Tick => {
                if last_tick.is_some_and(|t| now.saturating_sub(t) > 2 * period_ns) {
                    overruns.inc();
                }
                last_tick = idle_until.is_none().then_some(now);
                let r = drain_vehicle(&mut engine, &ports, now)
                    .and_then(|()| publish(&mut ports, engine.tick(now)));
                if monotonic_ns().saturating_sub(now) > period_ns {
                    overruns.inc();
                }
                r
            }
            Wake::App(m) => m.and_then(|m| {
                drain_vehicle(&mut engine, &ports, now)?;
                handle_inbound(&mut engine, &ports, Inbound::Message(Box::new(m)), now)?;
                let out = event_outputs(&mut engine, now);
                publish(&mut ports, out)
            }),
            Wake::Fence(g) => g.and_then(|g| {
                drain_vehicle(&mut engine, &ports, now)?;
                handle_inbound(&mut engine, &ports, Inbound::Fence(g), now)?;
                publish(&mut ports, engine.drain(now))
            }),
            Wake::Session(s) => s.and_then(|s| {
                engine.handle_app_session(&s, now);
                publish(&mut ports, engine.drain(now))
            }),
            Wake::Button(b) => b.and_then(|b| {
                drain_vehicle(&mut engine, &ports, now)?;
                engine.handle_button(&b, now);
                let out = event_outputs(&mut engine, now);
                publish(&mut ports, out)
            }),
        };
        if let Err(e) = step {
            break Err(anyhow::Error::new(e));
        }
    };
    let last = engine.shutdown(monotonic_ns());
    if let Err(e) = publish(&mut ports, last) {
        tracing::warn!(error = %e, "publishing the final outputs failed");
    }
    result
}

/// After an app message or button: a step now if the engine asks for one, else just
/// what the handlers produced. The loop keeps its phase (see the module doc).
fn event_outputs(engine: &mut Engine, now: u64) -> Outputs {
    if engine.take_step_request() {
        engine.tick(now)
    } else {
        engine.drain(now)
    }
}

/// Everything the vehicle topics hold, oldest first (the newest state wins).
fn drain_vehicle(engine: &mut Engine, ports: &Ports, now: u64) -> Result<(), IpcError> {
    drain_vehicle_with(engine, ports, now, None)
}

/// [`drain_vehicle`], with `first` (already taken from its topic by the idle wait)
/// handled before the rest of its topic, in the same topic order.
fn drain_vehicle_with(
    engine: &mut Engine,
    ports: &Ports,
    now: u64,
    first: Option<VehicleInput>,
) -> Result<(), IpcError> {
    let (mut status, mut authority, mut event, mut ack) = (None, None, None, None);
    match first {
        Some(VehicleInput::Status(s)) => status = Some(s),
        Some(VehicleInput::Authority(a)) => authority = Some(a),
        Some(VehicleInput::Event(e)) => event = Some(e),
        Some(VehicleInput::Ack(a)) => ack = Some(a),
        None => {}
    }
    if let Some(s) = ports.state.latest()? {
        engine.handle_state(&s, now);
    }
    if let Some(s) = status {
        engine.handle_status(&s, now);
    }
    while let Some(s) = ports.status.try_recv()? {
        engine.handle_status(&s, now);
    }
    if let Some(p) = ports.payload.latest()? {
        engine.handle_payload(&p, now);
    }
    if let Some(a) = authority {
        engine.handle_authority(&a, now);
    }
    while let Some(a) = ports.authority.try_recv()? {
        engine.handle_authority(&a, now);
    }
    if let Some(e) = event {
        engine.handle_arbiter_event(&e, now);
    }
    while let Some(e) = ports.events.try_recv()? {
        engine.handle_arbiter_event(&e, now);
    }
    if let Some(a) = ack {
        engine.handle_ack(&a, now);
    }
    while let Some(a) = ports.acks.try_recv()? {
        engine.handle_ack(&a, now);
    }
    Ok(())
}

/// An app request from either app topic.
enum Inbound {
    Message(Box<ShotRequestSample>),
    Fence(Box<AppGeofence>),
}

impl Inbound {
    fn stamp_ns(&self) -> u64 {
        match self {
            Inbound::Message(m) => m.header.stamp_ns,
            Inbound::Fence(g) => g.header.stamp_ns,
        }
    }
}

/// Handles `first` and everything pending on both app topics, oldest first.
fn handle_inbound(
    engine: &mut Engine,
    ports: &Ports,
    first: Inbound,
    now: u64,
) -> Result<(), IpcError> {
    let mut batch = vec![first];
    while let Some(m) = ports.from_app.try_recv()? {
        batch.push(Inbound::Message(Box::new(m)));
    }
    while let Some(g) = ports.app_geofence.try_recv()? {
        batch.push(Inbound::Fence(Box::new(g)));
    }
    // Stable: equal stamps keep their order.
    batch.sort_by_key(Inbound::stamp_ns);
    for request in batch {
        match request {
            Inbound::Message(m) => engine.handle_app(&m, now),
            Inbound::Fence(g) => engine.handle_app_geofence(&g, now),
        }
    }
    Ok(())
}

fn publish(ports: &mut Ports, out: Outputs) -> Result<(), IpcError> {
    // Two wake-ups for a batch of commands, not one per command: the first is
    // notified (autopilot-link, a higher real-time priority on the same CPU, takes
    // it at once), the middle ones go out quietly, and the last one's notification
    // wakes autopilot-link again, which then takes them all in order. Notifying
    // each would switch to autopilot-link and back once per command.
    let last = out.commands.len().saturating_sub(1);
    for (i, c) in out.commands.into_iter().enumerate() {
        if i == 0 || i == last {
            ports.commands.publish(c)?;
        } else {
            ports.commands.publish_quiet(c)?;
        }
    }
    for m in &out.to_app {
        ports.to_app.publish(ShotEventSample::new(0, m))?;
    }
    if let Some(s) = out.status {
        ports.shot_status.publish(s)?;
    }
    if let Some(g) = out.geofence {
        ports.geofence.publish(g)?;
    }
    Ok(())
}
