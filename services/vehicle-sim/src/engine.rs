//! The simulation task: owns the vehicle, steps it at [`PHYSICS_HZ`] against
//! the clock, runs every link's telemetry schedule, and answers inbound frames.
//!
//! One task owns all state, so there are no locks: I/O tasks send it
//! [`LinkEvent`]s and receive encoded frames on their link's queue. The engine
//! never waits on a client: a full queue drops the frame and counts it.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::{MavMessage, HOME_POSITION_DATA};
use mavlink::{MavHeader, MessageData};
use tokio::sync::mpsc::{self, error::TrySendError};
use tokio::time::{Instant, MissedTickBehavior};
use tokio_util::sync::CancellationToken;
use tracing::{debug, info};

use crate::codec::{self, Inbound};
use crate::config::{Settings, StreamDefaults, PHYSICS_HZ};
use crate::handler::{Handler, Outgoing, StreamRequest};
use crate::model::{Event, Vehicle};
use crate::stats::{self, SimStats};
use crate::streams::StreamScheduler;
use crate::telemetry;

/// Identifies one link (a TCP client, or the UDP socket).
pub(crate) type LinkId = u64;

/// Encoded frames queued per link before the engine drops frames for it
/// (about four seconds of default telemetry plus 100 Hz ATTITUDE).
pub(crate) const LINK_QUEUE_FRAMES: usize = 512;

/// After a stall, at most this many physics steps are run at once; the rest of
/// the lost time is skipped rather than simulated in a burst.
const MAX_CATCH_UP_STEPS: u64 = 20;

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

/// The simulation task's state.
pub(crate) struct Engine {
    system_id: u8,
    vehicle: Vehicle,
    handler: Handler,
    links: BTreeMap<LinkId, Link>,
    stream_defaults: StreamDefaults,
    stats: Arc<SimStats>,
    /// Physics steps taken; sim time is `steps × dt`.
    steps: u64,
    /// The GoPro heartbeat changed; send one to every link after the replies.
    gopro_changed: bool,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Engine")
            .field("system_id", &self.system_id)
            .field("links", &self.links.len())
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
    pub(crate) fn new(settings: &Settings, stats: Arc<SimStats>) -> Self {
        Self {
            system_id: settings.system_id,
            vehicle: Vehicle::new(settings.vehicle.clone()),
            handler: Handler::new(settings.system_id),
            links: BTreeMap::new(),
            stream_defaults: settings.streams,
            stats,
            steps: 0,
            gopro_changed: false,
        }
    }

    /// Run until `shutdown` or until every event sender is gone.
    pub(crate) async fn run(
        mut self,
        mut events: mpsc::Receiver<LinkEvent>,
        shutdown: CancellationToken,
    ) {
        let dt = dt();
        let mut ticker = tokio::time::interval(dt);
        ticker.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let start = Instant::now();
        // Wall-clock ticks accounted for (simulated or skipped).
        let mut wall_steps: u64 = 0;
        loop {
            tokio::select! {
                biased;
                () = shutdown.cancelled() => break,
                _ = ticker.tick() => {
                    let due = (start.elapsed().as_micros() / dt.as_micros()) as u64;
                    let n = due.saturating_sub(wall_steps);
                    if n > MAX_CATCH_UP_STEPS {
                        debug!(skipped = n - MAX_CATCH_UP_STEPS, "simulation fell behind; skipping time");
                    }
                    wall_steps = due;
                    self.tick(n.min(MAX_CATCH_UP_STEPS));
                }
                ev = events.recv() => match ev {
                    Some(ev) => self.on_event(ev),
                    None => break,
                },
            }
        }
        info!(
            sim_time_s = self.vehicle.time_s(),
            links = self.links.len(),
            "simulation stopped"
        );
    }

    fn sim_now(&self) -> Duration {
        Duration::from_micros(self.steps.saturating_mul(DT_US))
    }

    /// Step the physics `n` times, then send events and due telemetry.
    fn tick(&mut self, n: u64) {
        let dt_s = dt().as_secs_f64();
        for _ in 0..n {
            self.vehicle.step(dt_s);
            self.steps += 1;
        }
        self.broadcast_events();
        self.flush_gopro_heartbeat();
        let now = self.sim_now();
        for link in self.links.values_mut() {
            for id in link.streams.due(now) {
                if let Some(out) = telemetry::build_outgoing(id, &self.vehicle, self.system_id) {
                    send(link, self.system_id, &out, &self.stats);
                }
            }
        }
        self.stats.observe(&self.vehicle);
    }

    fn on_event(&mut self, ev: LinkEvent) {
        match ev {
            LinkEvent::Opened { id, peer, tx } => {
                info!(link = id, %peer, "link opened");
                let streams = StreamScheduler::new(&self.stream_defaults, self.sim_now());
                self.links.insert(
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
                if let Some(link) = self.links.remove(&id) {
                    info!(link = id, peer = %link.peer, "link closed");
                }
            }
            LinkEvent::Frame { id, frame } => self.on_frame(id, &frame),
        }
    }

    fn on_frame(&mut self, id: LinkId, frame: &Inbound) {
        let resp = self.handler.handle(&mut self.vehicle, frame);
        if let Some(result) = resp.ack {
            self.stats.count_command(result);
        }
        if let Some((request, status)) = resp.gopro {
            self.stats.count_gopro(request, status);
        }
        // Status texts raised while handling (e.g. the PreArm reason) go out
        // before the COMMAND_ACK, as on ArduPilot.
        self.broadcast_events();
        let now = self.sim_now();
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
            send(link, self.system_id, reply, &self.stats);
        }
        // A GoPro change is announced after its GOPRO_SET_RESPONSE.
        self.flush_gopro_heartbeat();
    }

    /// The GoPro's state changed: the gimbal sends a GOPRO_HEARTBEAT at once
    /// (besides its 1 Hz ones) to every link.
    fn flush_gopro_heartbeat(&mut self) {
        if !std::mem::take(&mut self.gopro_changed) {
            return;
        }
        let Some(msg) = telemetry::gopro_heartbeat(&self.vehicle) else {
            return;
        };
        let out = Outgoing::from_gimbal(msg);
        for link in self.links.values_mut() {
            send(link, self.system_id, &out, &self.stats);
        }
    }

    /// Vehicle events go to every link: STATUSTEXT, and HOME_POSITION when
    /// home changes (ArduPilot announces a new home unasked). A GoPro change
    /// only marks the GoPro heartbeat due ([`Self::flush_gopro_heartbeat`]).
    fn broadcast_events(&mut self) {
        for ev in self.vehicle.take_events() {
            let msg: MavMessage = match ev {
                Event::Text { severity, text } => {
                    info!(?severity, %text, "status text");
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
                send(link, self.system_id, &out, &self.stats);
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
            codec::encode(header, msg, &mut buf)
        }
        Outgoing::CommandAckRaw { command, result } => {
            codec::encode_command_ack_raw(header, *command, *result, &mut buf)
        }
        Outgoing::GimbalStatus(status) => {
            codec::encode_gimbal_device_attitude_status(header, status, &mut buf)
        }
    }
    match link.tx.try_send(buf) {
        Ok(()) => stats::add(&stats.frames_out, 1),
        Err(TrySendError::Full(_)) => stats::add(&stats.frames_dropped, 1),
        // The I/O task is gone; its Closed event is on the way.
        Err(TrySendError::Closed(_)) => {}
    }
}
