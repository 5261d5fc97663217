//! The simulation task: owns the vehicles (one, or a swarm's), steps them all at
//! [`PHYSICS_HZ`] against the clock in one tick loop, runs every link's
//! telemetry schedule, and answers inbound frames.
//!
//! One task owns all state, so there are no locks: I/O tasks send it
//! [`LinkEvent`]s and receive encoded frames on their link's queue. The engine
//! never waits on a client: a full queue drops the frame and counts it. A swarm
//! costs one task and one timer however many vehicles it has; each vehicle's
//! endpoint adds only its server task and its clients' tasks.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::{MavMessage, HOME_POSITION_DATA};
use mavlink::{MavHeader, MessageData};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer::{self, Timer};
use tokio::sync::mpsc::{self, error::TrySendError};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;
use tracing::{debug, error, info};

use crate::config::{Settings, StreamDefaults, PHYSICS_HZ};
use crate::handler::{Handler, Outgoing, StreamRequest};
use crate::model::{Event, Vehicle};
use crate::stats::{self, SimStats};
use crate::streams::StreamScheduler;
use crate::telemetry;
use mavlink_frame::Inbound;

/// Identifies one link (a TCP client, or a UDP socket). The upper 32 bits are
/// the index of the vehicle the link belongs to ([`link_id`]).
pub(crate) type LinkId = u64;

/// The id of link `n` (numbered by its server) of vehicle `vehicle`.
pub(crate) fn link_id(vehicle: usize, n: u64) -> LinkId {
    ((vehicle as u64) << 32) | (n & 0xffff_ffff)
}

/// The index of the vehicle link `id` belongs to.
fn vehicle_of(id: LinkId) -> usize {
    (id >> 32) as usize
}

/// Encoded frames queued per link before the engine drops frames for it
/// (about four seconds of default telemetry plus 100 Hz ATTITUDE).
pub(crate) const LINK_QUEUE_FRAMES: usize = 512;

/// After a stall, at most this many physics steps are run at once; the rest of
/// the lost time is skipped rather than simulated in a burst.
const MAX_CATCH_UP_STEPS: u64 = 20;

/// While every vehicle is disarmed the engine runs at least this often (physics
/// steps), even with no telemetry due: 100 ms.
const IDLE_STEPS: u64 = PHYSICS_HZ as u64 / 10;

/// What the I/O tasks tell the engine.
#[derive(Debug)]
// Nearly every value is the large variant (a MavMessage, ~280 bytes); boxing
// it would add an allocation per frame and save nothing.
#[allow(clippy::large_enum_variant)]
pub(crate) enum LinkEvent {
    /// A link came up; its frames go to `tx` (the I/O task holds the receiver).
    Opened {
        id: LinkId,
        peer: String,
        tx: mpsc::Sender<Vec<u8>>,
    },
    /// A frame arrived on a link.
    Frame { id: LinkId, frame: Inbound },
    /// The link is gone.
    Closed { id: LinkId },
}

struct Link {
    peer: String,
    /// Encoded frames for the link's I/O task; bounded, never awaited.
    tx: mpsc::Sender<Vec<u8>>,
    streams: StreamScheduler,
    /// MAVLink sequence numbers per sending component on this link (the
    /// autopilot's and the gimbal's count separately, as two devices would).
    seq: [u8; 256],
}

/// One simulated vehicle and the links of its endpoint.
struct SimVehicle {
    system_id: u8,
    vehicle: Vehicle,
    handler: Handler,
    links: BTreeMap<LinkId, Link>,
    /// The GoPro heartbeat changed; send one to every link after the replies.
    gopro_changed: bool,
}

/// The simulation task's state: every vehicle of the process, stepped together
/// by one tick loop.
pub(crate) struct Engine {
    vehicles: Vec<SimVehicle>,
    stream_defaults: StreamDefaults,
    stats: Arc<SimStats>,
    /// Physics steps taken; sim time is `steps × dt` (the same for every vehicle).
    steps: u64,
    /// Scratch list of the stream ids due on one link (reused every tick).
    due: Vec<u32>,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine")
            .field("vehicles", &self.vehicles.len())
            .field(
                "links",
                &self.vehicles.iter().map(|v| v.links.len()).sum::<usize>(),
            )
            .field("steps", &self.steps)
            .finish_non_exhaustive()
    }
}

/// The physics step, µs.
const DT_US: u64 = 1_000_000 / PHYSICS_HZ as u64;

fn dt() -> Duration {
    Duration::from_micros(DT_US)
}

impl Engine {
    /// Every vehicle of `settings` ([`Settings::vehicles`]), in index order.
    pub(crate) fn new(settings: &Settings, stats: Arc<SimStats>) -> Self {
        let vehicles: Vec<SimVehicle> = settings
            .vehicles()
            .into_iter()
            .map(|spec| SimVehicle {
                system_id: spec.system_id,
                vehicle: Vehicle::new(spec.vehicle),
                handler: Handler::new(spec.system_id),
                links: BTreeMap::new(),
                gopro_changed: false,
            })
            .collect();
        stats::set(&stats.vehicles, vehicles.len() as u64);
        Self {
            vehicles,
            stream_defaults: settings.streams,
            stats,
            steps: 0,
            due: Vec::new(),
        }
    }

    /// Run until `shutdown` or until every event sender is gone.
    pub(crate) async fn run(
        mut self,
        mut events: mpsc::Receiver<LinkEvent>,
        mut timer: Timer,
        shutdown: CancellationToken,
    ) {
        let dt = dt();
        // Steps are counted from the last whole second of CLOCK_MONOTONIC, and sim
        // time starts there too (the vehicle "booted" up to a second earlier): the
        // physics steps and the telemetry falling due on them keep the
        // machine-wide grid of the services' tickers (skymesh_runtime::timer), so
        // a 50 Hz stream goes out on the same instants as their heartbeats and the
        // processes wake together instead of one after another.
        let now_ns = monotonic_ns();
        let start = timer::instant_at(now_ns - now_ns % 1_000_000_000);
        // Wall-clock steps accounted for (simulated or skipped).
        let mut wall_steps = (start.elapsed().as_micros() / u128::from(DT_US)) as u64;
        self.steps = wall_steps;
        loop {
            let wake = start
                + Duration::from_micros(self.next_wake_step(wall_steps).saturating_mul(DT_US));
            tokio::select! {
                biased;
                () = shutdown.cancelled() => break,
                // A timerfd, not tokio's wheel: see skymesh_runtime::timer.
                r = timer.sleep_until(wake) => match r {
                    Ok(()) => self.catch_up(start, &mut wall_steps),
                    Err(e) => {
                        error!(error = %e, "simulation timer failed; stopping");
                        break;
                    }
                },
                ev = events.recv() => match ev {
                    Some(ev) => {
                        // The frame acts on the vehicle as it is now, not as it
                        // was at the last wake.
                        self.catch_up(start, &mut wall_steps);
                        self.on_event(ev);
                    }
                    None => break,
                },
            }
        }
        info!(
            sim_time_s = self.steps as f64 * dt.as_secs_f64(),
            vehicles = self.vehicles.len(),
            links = self.vehicles.iter().map(|v| v.links.len()).sum::<usize>(),
            "simulation stopped"
        );
    }

    /// Step the physics to the wall clock (whole steps), then send what fell due.
    fn catch_up(&mut self, start: Instant, wall_steps: &mut u64) {
        let due = (start.elapsed().as_micros() / u128::from(DT_US)) as u64;
        let n = due.saturating_sub(*wall_steps);
        if n == 0 {
            return;
        }
        if n > MAX_CATCH_UP_STEPS {
            debug!(
                skipped = n - MAX_CATCH_UP_STEPS,
                "simulation fell behind; skipping time"
            );
            stats::add(&self.stats.steps_skipped, n - MAX_CATCH_UP_STEPS);
        }
        *wall_steps = due;
        self.tick(n.min(MAX_CATCH_UP_STEPS));
    }

    /// The wall-clock step at which the engine must next run on its own (frames
    /// from links wake it besides). An armed vehicle is stepped every
    /// [`PHYSICS_HZ`] tick, as before. While every vehicle is disarmed nothing
    /// needs the steps one by one — the model integrates the same whether its
    /// steps are taken together or apart — so the engine sleeps until the next
    /// telemetry falls due on any link, at most [`IDLE_STEPS`] (events the model
    /// raises, e.g. a status text, go out then). An idle simulator wakes at its
    /// telemetry rate (50 a second with autopilot-link's defaults), not at 100 Hz.
    fn next_wake_step(&self, wall_steps: u64) -> u64 {
        let next = wall_steps + 1;
        if self.vehicles.iter().any(|v| v.vehicle.armed()) {
            return next;
        }
        let telemetry = self
            .vehicles
            .iter()
            .flat_map(|v| v.links.values())
            .filter_map(|l| l.streams.next_due())
            .min()
            .map(|due| {
                // Sim time runs behind wall steps by the steps skipped after stalls.
                let ahead = due.saturating_sub(self.sim_now()).as_micros();
                wall_steps + u64::try_from(ahead.div_ceil(u128::from(DT_US))).unwrap_or(u64::MAX)
            });
        telemetry
            .unwrap_or(u64::MAX)
            .clamp(next, wall_steps + IDLE_STEPS)
    }

    fn sim_now(&self) -> Duration {
        Duration::from_micros(self.steps.saturating_mul(DT_US))
    }

    /// Step every vehicle's physics `n` times, then send its events and due telemetry.
    fn tick(&mut self, n: u64) {
        let dt_s = dt().as_secs_f64();
        self.steps += n;
        let now = self.sim_now();
        let (mut armed, mut linked) = (0, 0);
        for v in &mut self.vehicles {
            for _ in 0..n {
                v.vehicle.step(dt_s);
            }
            v.broadcast_events(&self.stats);
            v.flush_gopro_heartbeat(&self.stats);
            v.send_due_telemetry(now, &mut self.due, &self.stats);
            armed += u64::from(v.vehicle.armed());
            linked += u64::from(!v.links.is_empty());
        }
        stats::set(&self.stats.vehicles_armed, armed);
        stats::set(&self.stats.vehicles_linked, linked);
        // The payload gauges are the first vehicle's (one set of series for any swarm size).
        if let Some(first) = self.vehicles.first() {
            self.stats.observe(&first.vehicle);
        }
    }

    fn on_event(&mut self, ev: LinkEvent) {
        let now = self.sim_now();
        let id = match &ev {
            LinkEvent::Opened { id, .. }
            | LinkEvent::Frame { id, .. }
            | LinkEvent::Closed { id } => *id,
        };
        let Some(v) = self.vehicles.get_mut(vehicle_of(id)) else {
            debug!(link = id, "event for a link of no vehicle; ignored");
            return;
        };
        match ev {
            LinkEvent::Opened { id, peer, tx } => {
                info!(link = id, vehicle = v.system_id, %peer, "link opened");
                let streams = StreamScheduler::new(&self.stream_defaults, now);
                v.links.insert(
                    id,
                    Link {
                        peer,
                        tx,
                        streams,
                        seq: [0; 256],
                    },
                );
            }
            LinkEvent::Closed { id } => {
                if let Some(link) = v.links.remove(&id) {
                    info!(link = id, vehicle = v.system_id, peer = %link.peer, "link closed");
                }
            }
            LinkEvent::Frame { id, frame } => v.on_frame(id, &frame, now, &self.stats),
        }
    }
}

impl SimVehicle {
    /// Queue every stream due at `now` on every link.
    fn send_due_telemetry(&mut self, now: Duration, due: &mut Vec<u32>, stats: &SimStats) {
        for link in self.links.values_mut() {
            link.streams.due_into(now, due);
            for id in due.iter() {
                if let Some(out) = telemetry::build_outgoing(*id, &self.vehicle, self.system_id) {
                    send(link, self.system_id, &out, stats);
                }
            }
        }
    }

    fn on_frame(&mut self, id: LinkId, frame: &Inbound, now: Duration, stats: &SimStats) {
        let resp = self.handler.handle(&mut self.vehicle, frame);
        if let Some(result) = resp.ack {
            stats.count_command(result);
        }
        if let Some((request, status)) = resp.gopro {
            stats.count_gopro(request, status);
        }
        // Status texts raised while handling (e.g. the PreArm reason) go out
        // before the COMMAND_ACK, as on ArduPilot.
        self.broadcast_events(stats);
        let Some(link) = self.links.get_mut(&id) else {
            return;
        };
        for req in resp.streams {
            match req {
                StreamRequest::Interval { id, request } => {
                    link.streams.set_interval(id, request, now)
                }
                StreamRequest::DataStream {
                    stream,
                    rate_hz,
                    start,
                } => link
                    .streams
                    .request_data_stream(stream, rate_hz, start, now),
            }
        }
        for reply in &resp.replies {
            send(link, self.system_id, reply, stats);
        }
        // A GoPro change is announced after its GOPRO_SET_RESPONSE.
        self.flush_gopro_heartbeat(stats);
    }

    /// The GoPro's state changed: the gimbal sends a GOPRO_HEARTBEAT at once
    /// (besides its 1 Hz ones) to every link.
    fn flush_gopro_heartbeat(&mut self, stats: &SimStats) {
        if !std::mem::take(&mut self.gopro_changed) {
            return;
        }
        let Some(msg) = telemetry::gopro_heartbeat(&self.vehicle) else {
            return;
        };
        let out = Outgoing::from_gimbal(msg);
        for link in self.links.values_mut() {
            send(link, self.system_id, &out, stats);
        }
    }

    /// Vehicle events go to every link: STATUSTEXT, and HOME_POSITION when
    /// home changes (ArduPilot announces a new home unasked). A GoPro change
    /// only marks the GoPro heartbeat due ([`Self::flush_gopro_heartbeat`]).
    fn broadcast_events(&mut self, stats: &SimStats) {
        for ev in self.vehicle.take_events() {
            let msg: MavMessage = match ev {
                Event::Text { severity, text } => {
                    info!(vehicle = self.system_id, ?severity, %text, "status text");
                    telemetry::statustext(severity, &text)
                }
                Event::HomeChanged => {
                    match telemetry::build(HOME_POSITION_DATA::ID, &self.vehicle, self.system_id) {
                        Some(m) => m,
                        None => continue,
                    }
                }
                Event::GoProChanged => {
                    self.gopro_changed = true;
                    continue;
                }
            };
            let out = Outgoing::Message(msg);
            for link in self.links.values_mut() {
                send(link, self.system_id, &out, stats);
            }
        }
    }
}

/// Encode `out` for `link` and queue it without waiting.
fn send(link: &mut Link, system_id: u8, out: &Outgoing, stats: &SimStats) {
    let component = out.component();
    let seq = &mut link.seq[usize::from(component)];
    let header = MavHeader {
        system_id: u32::from(system_id),
        component_id: component,
        sequence: *seq,
    };
    *seq = seq.wrapping_add(1);
    let mut buf = Vec::with_capacity(64);
    match out {
        Outgoing::Message(msg) | Outgoing::FromComponent { msg, .. } => {
            mavlink_frame::encode(header, msg, &mut buf)
        }
        Outgoing::CommandAckRaw { command, result } => {
            mavlink_frame::encode_command_ack_raw(header, *command, *result, &mut buf)
        }
    }
    match link.tx.try_send(buf) {
        Ok(()) => stats::add(&stats.frames_out, 1),
        Err(TrySendError::Full(_)) => stats::add(&stats.frames_dropped, 1),
        // The I/O task is gone; its Closed event is on the way.
        Err(TrySendError::Closed(_)) => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_ids_carry_their_vehicle() {
        for vehicle in [0usize, 1, 7, 249] {
            for n in [0u64, 1, 2, 0xffff_ffff] {
                assert_eq!(vehicle_of(link_id(vehicle, n)), vehicle);
            }
        }
        assert_ne!(link_id(0, 1), link_id(1, 1));
        assert_eq!(link_id(0, 5), 5, "a single vehicle's ids are unchanged");
    }

    #[test]
    #[allow(deprecated)] // MAV_DATA_STREAM_ALL: see streams.rs
    fn a_disarmed_engine_wakes_for_telemetry_an_armed_one_every_step() {
        let settings = crate::RawConfig::from_toml("")
            .and_then(crate::RawConfig::validate)
            .expect("valid");
        let mut engine = Engine::new(&settings, Arc::new(SimStats::default()));
        // No link: nothing due, so the idle bound.
        assert_eq!(engine.next_wake_step(0), IDLE_STEPS);
        let (tx, mut rx) = mpsc::channel(LINK_QUEUE_FRAMES);
        engine.on_event(LinkEvent::Opened {
            id: link_id(0, 1),
            peer: "test".into(),
            tx,
        });
        let link = engine.vehicles[0].links.get_mut(&link_id(0, 1)).unwrap();
        link.streams.request_data_stream(
            mavlink::dialects::ardupilotmega::MavDataStream::MAV_DATA_STREAM_ALL,
            0,
            false,
            Duration::ZERO,
        );
        link.streams.set_interval(
            mavlink::dialects::ardupilotmega::ATTITUDE_DATA::ID,
            crate::streams::IntervalRequest::Every(Duration::from_millis(40)),
            Duration::ZERO,
        );
        // Everything is due at once on a new link, then ATTITUDE every 4 steps
        // (GoPro heartbeat 1 Hz, HEARTBEAT 1 Hz).
        assert_eq!(engine.next_wake_step(0), 1);
        engine.tick(1);
        while rx.try_recv().is_ok() {}
        assert_eq!(engine.next_wake_step(1), 4, "ATTITUDE at 40 ms");
        engine.tick(3);
        assert!(rx.try_recv().is_ok(), "ATTITUDE sent at step 4");
        assert_eq!(engine.next_wake_step(4), 8);
        // Sim time behind the wall clock after a stall: still the sim time's due step.
        assert_eq!(engine.next_wake_step(10), 14);
        engine.vehicles[0].vehicle.arm(true).expect("force arm");
        assert_eq!(engine.next_wake_step(4), 5, "armed: every physics step");
    }

    #[test]
    fn one_engine_holds_every_vehicle_of_a_swarm() {
        let settings = crate::RawConfig::from_toml("[swarm]\ncount = 4\n")
            .and_then(crate::RawConfig::validate)
            .expect("valid");
        let stats = Arc::new(SimStats::default());
        let mut engine = Engine::new(&settings, stats.clone());
        let ids: Vec<u8> = engine.vehicles.iter().map(|v| v.system_id).collect();
        assert_eq!(ids, [1, 2, 3, 4]);
        assert_eq!(stats.snapshot().vehicles, 4);
        // One tick steps every vehicle (sim time is shared).
        engine.tick(3);
        for v in &engine.vehicles {
            assert!((v.vehicle.time_s() - 0.03).abs() < 1e-9);
        }
        // A link of vehicle 2 gets vehicle 2's telemetry only.
        let (tx, mut rx) = mpsc::channel(64);
        engine.on_event(LinkEvent::Opened {
            id: link_id(2, 1),
            peer: "test".into(),
            tx,
        });
        engine.tick(1);
        let frame = rx.try_recv().expect("telemetry queued at once");
        // MAVLink 2: system id at offset 5.
        assert_eq!((frame[0], frame[5]), (0xFD, 3));
        assert_eq!(stats.snapshot().vehicles_linked, 1);
        assert!(engine
            .vehicles
            .iter()
            .enumerate()
            .all(|(i, v)| v.links.len() == usize::from(i == 2)));
        engine.on_event(LinkEvent::Closed { id: link_id(2, 1) });
        // An id of no vehicle is ignored.
        let (tx, _rx) = mpsc::channel(1);
        engine.on_event(LinkEvent::Opened {
            id: link_id(9, 1),
            peer: "nobody".into(),
            tx,
        });
        engine.tick(1);
        assert_eq!(stats.snapshot().vehicles_linked, 0);
    }
}
