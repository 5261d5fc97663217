//! The event loop: link events, command samples and timers in one task that owns
//! every piece of state (no locks).
//!
//! Command path: intake ([`commands::admit`]) → [`Arbiter::decide`] (authority,
//! freshness, geofence envelope; wiring of its effects in [`safety`]) → dispatch
//! ([`commands::plan`] → link writer → [`AckTracker`]) → `CommandAck`.
//! Gimbal and GoPro telemetry → `PayloadState`, and GoPro answers → [`AckTracker`]:
//! [`payload`].

mod payload;
mod safety;
pub(crate) mod vision;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    AckResult, ArbiterEvent, AuthorityState, Command, CommandAck, CommandKind, CommandSource,
    FixedStr, GeofenceSet, PayloadState, RefusalReason, VehicleCommand, VehicleState,
    VehicleStatus,
};
use skymesh_runtime::timer::until_grid_point;
use skymesh_runtime::{clock::monotonic_ns, IpcError, Publisher, Subscriber};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use crate::acks::{AckPolicy, AckTracker, Action, Answer, Origin};
use crate::arbiter::audit::Audit;
use crate::arbiter::{Arbiter, Outcome};
use crate::commands::{self, PlanContext, Target};
use crate::config::Settings;
use crate::link::{LinkEvent, LinkWriter};
use crate::metrics::Metrics;
use crate::payload::Payload;
use crate::requests;
use crate::telemetry::{LinkChange, LinkMonitor, Telemetry, AUTOPILOT_COMPONENT};
use crate::Lifecycle;

/// Our HEARTBEAT and the periodic VehicleStatus.
const TICK: Duration = Duration::from_secs(1);
/// No ATTITUDE for this long while the link is up → ask for the streams again.
const STREAMS_STALE: Duration = Duration::from_secs(3);
/// ... but not more often than this.
const STREAMS_RETRY: Duration = Duration::from_secs(5);
/// A STATUSTEXT this recent explains a refusal that follows it.
const TEXT_EXPLAINS_ACK: Duration = Duration::from_secs(1);
/// ArduPilot sends a refusal's COMMAND_ACK at once but queues the STATUSTEXT that
/// explains it for its next send cycle: a refusal without an explanation waits this
/// long for one before it is published.
const EXPLANATION_WAIT: Duration = Duration::from_millis(300);

/// What woke the event loop.
enum Wake {
    Command(Result<VehicleCommand, IpcError>),
    /// Boxed: a fence is 4 KiB and arrives rarely.
    Geofence(Result<Box<GeofenceSet>, IpcError>),
    Link(Option<LinkEvent>),
    Vision(vision::VisionWake),
    Timer,
}

/// The bus ports of one vehicle.
pub(crate) struct Ports {
    pub state: Publisher<VehicleState>,
    pub status: Publisher<VehicleStatus>,
    /// Gimbal attitude and GoPro state: on change and at 1 Hz.
    pub payload: Publisher<PayloadState>,
    pub acks: Publisher<CommandAck>,
    pub commands: Subscriber<VehicleCommand>,
    /// Who holds authority: on every change and with each tick.
    pub authority: Publisher<AuthorityState>,
    /// What the arbiter did on its own.
    pub events: Publisher<ArbiterEvent>,
    /// The geofence, from whichever source sets it (history 1).
    pub geofence: Subscriber<GeofenceSet>,
}

/// The virtual gimbals, when `[vision] enabled`.
pub(crate) struct VisionParts {
    pub ports: vision::VisionPorts,
    pub hub: std::sync::Arc<crate::hub::Hub>,
    pub stats: skymesh_runtime::Stats,
}

pub(crate) struct Service<L> {
    settings: Settings,
    lifecycle: L,
    metrics: Metrics,
    arbiter: Arbiter,
    audit: Audit,
    /// Commands the arbiter limited that wait for the autopilot's answer, by
    /// (source, command_id): their `Accepted` is published as `Limited` with this detail.
    limited: HashMap<(u8, u32), String>,
    /// The last VehicleState published (the arbiter's view of the vehicle).
    last_state: Option<VehicleState>,
    ports: Ports,
    telemetry: Telemetry,
    payload: Payload,
    link: LinkMonitor,
    tracker: AckTracker,
    /// Present while a connection is open (between `Connected` and `Disconnected`).
    writer: Option<LinkWriter>,
    /// The last status published, with `heartbeat_age_ms` and header cleared.
    last_status: Option<VehicleStatus>,
    next_tick: Instant,
    capture_seq: u32,
    last_text: Option<(Instant, String)>,
    /// Refusals waiting (until the instant) for the STATUSTEXT that explains them.
    unexplained: Vec<(Instant, Answer)>,
    /// Stream rates must be (re)requested at the next autopilot heartbeat.
    streams_due: bool,
    streams_requested: Option<Instant>,
    /// Re-requests since ATTITUDE last arrived (only the first is logged at info).
    stream_retries: u32,
    last_attitude: Option<Instant>,
    started: Instant,
    /// Gimbal protocol v2 for the vision pipeline's virtual cameras.
    vision: Option<vision::Vision>,
}

impl<L: Lifecycle> Service<L> {
    pub fn new(
        settings: Settings,
        lifecycle: L,
        metrics: Metrics,
        audit: Audit,
        ports: Ports,
        vision_parts: Option<VisionParts>,
    ) -> Self {
        let now = Instant::now();
        let vision = vision_parts.map(|p| {
            vision::Vision::new(
                &settings.vision,
                settings.system_id,
                p.ports,
                p.hub,
                &p.stats,
            )
        });
        Service {
            vision,
            telemetry: Telemetry::new(settings.vehicle_id),
            payload: Payload::new(settings.vehicle_id),
            link: LinkMonitor::new(settings.link_timeout),
            tracker: AckTracker::new(AckPolicy {
                timeout: settings.command_timeout,
                retries: settings.command_retries,
                in_progress_timeout: settings.command_in_progress_timeout,
            }),
            arbiter: Arbiter::new(settings.arbiter.clone()),
            audit,
            limited: HashMap::new(),
            last_state: None,
            settings,
            lifecycle,
            metrics,
            ports,
            writer: None,
            last_status: None,
            next_tick: now,
            capture_seq: 0,
            last_text: None,
            unexplained: Vec::new(),
            streams_due: true,
            streams_requested: None,
            stream_retries: 0,
            last_attitude: None,
            started: now,
        }
    }

    fn target(&self) -> Target {
        Target {
            system: self.settings.vehicle_id,
            component: AUTOPILOT_COMPONENT,
        }
    }

    /// Runs until `shutdown`; then answers whatever is still outstanding.
    pub async fn run(
        &mut self,
        events: &mut mpsc::Receiver<LinkEvent>,
        shutdown: &CancellationToken,
    ) -> anyhow::Result<()> {
        // The first timer pass publishes the initial (link down) status.
        self.metrics.link_up.set(0.0);
        self.lifecycle.link_changed(false);
        let sleep = tokio::time::sleep(Duration::ZERO);
        tokio::pin!(sleep);
        let result = loop {
            if let Err(e) = self.on_timers(Instant::now()) {
                break Err(e);
            }
            sleep
                .as_mut()
                .reset(tokio::time::Instant::from_std(self.next_deadline()));
            let wake = tokio::select! {
                biased;
                _ = shutdown.cancelled() => break Ok(()),
                sample = self.ports.commands.recv() => Wake::Command(sample),
                fence = self.ports.geofence.recv() => Wake::Geofence(fence.map(Box::new)),
                event = events.recv() => Wake::Link(event),
                v = vision::Vision::next(self.vision.as_mut()) => Wake::Vision(v),
                _ = &mut sleep => Wake::Timer,
            };
            let step = match wake {
                Wake::Command(Ok(sample)) => self.on_command(sample),
                Wake::Command(Err(e)) => Err(e.into()),
                Wake::Geofence(Ok(fence)) => self.on_geofence(&fence),
                Wake::Geofence(Err(e)) => Err(e.into()),
                Wake::Link(Some(event)) => self.on_link_event(event),
                Wake::Link(None) => Err(anyhow::anyhow!("the link task ended")),
                Wake::Vision(v) => self.on_vision(v),
                Wake::Timer => Ok(()),
            };
            if let Err(e) = step {
                break Err(e);
            }
        };
        let unexplained = std::mem::take(&mut self.unexplained);
        for answer in unexplained.into_iter().map(|(_, a)| a).chain(
            self.tracker
                .fail_all(RefusalReason::Cancelled, "autopilot-link stopping"),
        ) {
            let _ = self.answer(answer);
        }
        result
    }

    fn next_deadline(&self) -> Instant {
        let unexplained = self.unexplained.iter().map(|(t, _)| *t).min();
        [
            self.link.deadline(),
            self.tracker.next_deadline(),
            unexplained,
            self.arbiter_deadline(),
            Some(self.payload_deadline()),
            self.vision_deadline(),
        ]
        .into_iter()
        .flatten()
        .fold(self.next_tick, Instant::min)
    }

    fn on_timers(&mut self, now: Instant) -> anyhow::Result<()> {
        let effects = self.arbiter.poll(monotonic_ns());
        self.apply(effects)?;
        if let Some(change) = self.link.poll(now) {
            self.link_changed(change, now, "no heartbeat within the link timeout")?;
        }
        for action in self.tracker.poll(now) {
            match action {
                Action::Retransmit(cmd) => {
                    tracing::debug!(command = %cmd.key(), "no COMMAND_ACK yet; retransmitting");
                    self.write(cmd.message());
                }
                Action::Answer(answer) => self.answer(answer)?,
            }
        }
        if self.unexplained.iter().any(|(t, _)| *t <= now) {
            let (due, waiting) = std::mem::take(&mut self.unexplained)
                .into_iter()
                .partition(|(t, _)| *t <= now);
            self.unexplained = waiting;
            for (_, answer) in due {
                self.answer(answer)?;
            }
        }
        self.publish_payload_if_due()?;
        self.poll_vision()?;
        if now >= self.next_tick {
            // On the machine-wide grid (skymesh_runtime::timer), at least half a tick
            // on (a stalled machine skips the missed ticks): the status goes out on
            // the instants of the services' heartbeats, so its listeners do not
            // wake for it alone.
            self.next_tick = now + until_grid_point(TICK);
            self.write(requests::heartbeat());
            self.publish_status(now)?;
            self.publish_authority()?;
            let age = self
                .link
                .heartbeat_age(now)
                .unwrap_or_else(|| now - self.started);
            self.metrics.heartbeat_age.set(age.as_secs_f64());
            let stale = self.last_attitude.is_none_or(|t| now - t >= STREAMS_STALE);
            let may_retry = self
                .streams_requested
                .is_none_or(|t| now - t >= STREAMS_RETRY);
            if self.link.is_up() && stale && may_retry {
                self.stream_retries += 1;
                if self.stream_retries == 1 {
                    tracing::info!("ATTITUDE is not arriving; requesting telemetry rates again");
                } else {
                    tracing::debug!(
                        retries = self.stream_retries,
                        "ATTITUDE still not arriving; requesting telemetry rates again"
                    );
                }
                self.request_streams(now);
            }
        }
        Ok(())
    }

    fn on_link_event(&mut self, event: LinkEvent) -> anyhow::Result<()> {
        let now = Instant::now();
        match event {
            LinkEvent::Connected(writer) => {
                self.writer = Some(writer);
                self.streams_due = true;
                self.write(requests::heartbeat());
            }
            LinkEvent::Disconnected { reason } => {
                self.writer = None;
                for answer in self.tracker.fail_all(
                    RefusalReason::LinkDown,
                    "link lost before the autopilot answered",
                ) {
                    self.answer(answer)?;
                }
                if let Some(change) = self.link.transport_lost() {
                    self.link_changed(change, now, &reason)?;
                }
            }
            LinkEvent::Message(header, msg) => {
                self.check_collision(&header)?;
                self.on_payload_message(&header, &msg, now)?;
                let u = self.telemetry.handle(&header, &msg, monotonic_ns());
                if let Some(system) = u.foreign_autopilot {
                    tracing::warn!(
                        system,
                        vehicle_id = self.settings.vehicle_id,
                        "ignoring an autopilot whose system id is not vehicle_id"
                    );
                }
                if let Some(ap) = u.identified {
                    tracing::info!(
                        system = ap.system_id,
                        autopilot = ap.autopilot,
                        vehicle_type = ap.vehicle_type,
                        "autopilot found"
                    );
                }
                if u.heartbeat {
                    if let Some(change) = self.link.heartbeat(now) {
                        self.link_changed(change, now, "heartbeat")?;
                    }
                    if self.streams_due && self.writer.is_some() {
                        self.request_streams(now);
                    }
                    if u.armed_changed {
                        self.write(requests::request_home(self.target()));
                    }
                }
                if let Some((severity, text)) = u.status_text {
                    if severity <= 4 {
                        tracing::warn!(severity, text = %text, "autopilot says");
                    } else {
                        tracing::info!(severity, text = %text, "autopilot says");
                    }
                    for (_, mut answer) in std::mem::take(&mut self.unexplained) {
                        answer.detail.clone_from(&text);
                        self.answer(answer)?;
                    }
                    self.last_text = Some((now, text));
                }
                if let Some((command, result)) = u.command_ack {
                    let explanation = self
                        .last_text
                        .as_ref()
                        .filter(|(t, _)| now - *t <= TEXT_EXPLAINS_ACK)
                        .map(|(_, text)| text.as_str());
                    let explained = explanation.is_some();
                    match self.tracker.on_ack(command, result, explanation, now) {
                        Some(a) if a.result == AckResult::Refused && !explained => {
                            self.unexplained.push((now + EXPLANATION_WAIT, a));
                        }
                        Some(a) => self.answer(a)?,
                        None => {}
                    }
                }
                if let Some(state) = u.state {
                    self.last_attitude = Some(now);
                    self.stream_retries = 0;
                    self.ports.state.publish(state)?;
                    self.last_state = Some(state);
                }
                self.publish_status_if_changed(now)?;
            }
        }
        Ok(())
    }

    fn link_changed(&mut self, change: LinkChange, now: Instant, why: &str) -> anyhow::Result<()> {
        match change {
            LinkChange::Up => {
                tracing::info!(vehicle_id = self.settings.vehicle_id, "autopilot link up");
                self.metrics.link_up.set(1.0);
                self.lifecycle.link_changed(true);
                // After a reboot or reconnect the autopilot has forgotten our rates.
                self.streams_due = true;
            }
            LinkChange::Down => {
                tracing::warn!(
                    vehicle_id = self.settings.vehicle_id,
                    reason = why,
                    "autopilot link down"
                );
                self.metrics.link_up.set(0.0);
                self.lifecycle.link_changed(false);
                // Nothing sent before the loss may go out after it: a command still
                // waiting for its COMMAND_ACK would otherwise be retransmitted.
                for answer in self.tracker.fail_all(
                    RefusalReason::LinkDown,
                    "link lost before the autopilot answered",
                ) {
                    self.answer(answer)?;
                }
            }
        }
        let effects = self
            .arbiter
            .link_changed(change == LinkChange::Up, monotonic_ns());
        self.apply(effects)?;
        Ok(self.publish_status(now)?)
    }

    fn request_streams(&mut self, now: Instant) {
        tracing::debug!(rates = ?self.settings.rates, "requesting telemetry rates");
        for msg in requests::stream_requests(
            &self.settings.rates,
            self.target(),
            self.settings.request_data_streams,
        ) {
            self.write(msg);
        }
        self.write(requests::request_home(self.target()));
        self.streams_due = false;
        self.streams_requested = Some(now);
    }

    /// Writes a message of our own (heartbeat, requests, retransmissions); a full or
    /// closed link drops it: the next tick or retry sends it again.
    fn write(&self, msg: mavlink::dialects::ardupilotmega::MavMessage) {
        if let Some(writer) = &self.writer {
            if let Err(e) = writer.send(msg) {
                tracing::debug!(error = %e, "message dropped");
            }
        }
    }

    fn current_status(&self, now: Instant) -> VehicleStatus {
        self.telemetry
            .status(self.link.is_up(), self.link.heartbeat_age(now))
    }

    fn publish_status(&mut self, now: Instant) -> Result<(), IpcError> {
        let status = self.current_status(now);
        self.ports.status.publish(status)?;
        self.last_status = Some(VehicleStatus {
            heartbeat_age_ms: 0,
            ..status
        });
        Ok(())
    }

    fn publish_status_if_changed(&mut self, now: Instant) -> Result<(), IpcError> {
        let status = self.current_status(now);
        let comparable = VehicleStatus {
            heartbeat_age_ms: 0,
            ..status
        };
        if self.last_status != Some(comparable) {
            self.publish_status(now)?;
        }
        Ok(())
    }

    fn on_command(&mut self, sample: VehicleCommand) -> anyhow::Result<()> {
        let now = Instant::now();
        let now_ns = monotonic_ns();
        let origin = Origin::of(&sample);
        if let Err(r) = commands::admit(&sample, self.settings.vehicle_id, self.link.is_up()) {
            return self.refuse(origin, r.reason, r.detail);
        }
        let view = self.vehicle_view(now_ns);
        let decision = self.arbiter.decide(now_ns, &sample, &view);
        self.audit.decision(crate::arbiter::audit::Record {
            source: origin.source,
            kind: origin.kind,
            command_id: origin.command_id,
            result: decision.result(),
            reason: decision.reason(),
            detail: decision.detail(),
        });
        // Authority changes are published before the answer, so a source that
        // reads its ack finds AuthorityState already saying so.
        self.apply(decision.effects)?;
        match decision.outcome {
            Outcome::Execute { command, limited } => {
                if let Some(detail) = limited {
                    self.limited
                        .insert((origin.source, origin.command_id), detail);
                }
                self.forward_to_vision(&command)?;
                self.dispatch(origin, &command, now)
            }
            Outcome::Done { detail } => self.publish_answer(Answer {
                detail,
                ..Answer::accepted(origin)
            }),
            Outcome::Refused { reason, detail } => {
                self.publish_answer(Answer::refused(origin, reason, detail))
            }
        }
    }

    fn dispatch(&mut self, origin: Origin, command: &Command, now: Instant) -> anyhow::Result<()> {
        let ctx = PlanContext {
            target: self.target(),
            mode: self.telemetry.flight_mode(),
            capture_seq: self.capture_seq.wrapping_add(1).max(1),
        };
        let plan = match commands::plan(command, &ctx) {
            Ok(p) => p,
            Err(why) => {
                return self.answer(Answer::refused(origin, RefusalReason::Unsupported, why))
            }
        };
        if matches!(command, Command::CameraCapture) {
            self.capture_seq = ctx.capture_seq;
        }
        let Some(writer) = &self.writer else {
            return self.answer(Answer::refused(
                origin,
                RefusalReason::LinkDown,
                "not connected",
            ));
        };
        let sent = plan
            .command
            .as_ref()
            .map_or(Ok(()), |c| writer.send(c.message()))
            .and_then(|()| plan.setpoint.map_or(Ok(()), |s| writer.send(s)));
        if let Err(e) = sent {
            return self.answer(Answer::refused(
                origin,
                RefusalReason::LinkDown,
                e.to_string(),
            ));
        }
        match plan.command {
            Some(cmd) => {
                tracing::debug!(kind = %kind_name(origin.kind), command_id = origin.command_id, answer = %cmd.key(), "command sent");
                if let Some(superseded) = self.tracker.submit(origin, cmd, now, now) {
                    self.answer(superseded)?;
                }
                Ok(())
            }
            None => self.answer(Answer::accepted(origin)),
        }
    }

    /// Publishes, counts and logs the answer to one command.
    fn answer(&mut self, mut a: Answer) -> anyhow::Result<()> {
        let o = a.origin;
        if !self.limited.is_empty() && a.result != AckResult::InProgress {
            if let Some(detail) = self.limited.remove(&(o.source, o.command_id)) {
                if a.result == AckResult::Accepted {
                    a.result = AckResult::Limited;
                    a.detail = detail;
                }
            }
        }
        let kind = kind_name(o.kind);
        let source = CommandSource::try_from(o.source).map_or("unknown", CommandSource::as_str);
        match a.result {
            AckResult::Refused => tracing::warn!(
                kind, source, command_id = o.command_id, reason = %a.reason,
                mav_result = a.mav_result, detail = %a.detail, "command refused"
            ),
            // Velocity setpoints stream at tens of Hz: not worth a line each.
            _ if o.kind == CommandKind::VelocityNed.to_wire() => tracing::debug!(
                kind, source, command_id = o.command_id, result = %a.result, "command accepted"
            ),
            _ => tracing::info!(
                kind, source, command_id = o.command_id, result = %a.result,
                mav_result = a.mav_result, "command answered"
            ),
        }
        self.publish_answer(a)
    }

    /// Publishes and counts the answer to one command (the caller has logged it).
    fn publish_answer(&mut self, a: Answer) -> anyhow::Result<()> {
        let o = a.origin;
        let ack = CommandAck {
            vehicle_id: o.vehicle_id,
            source: o.source,
            kind: o.kind,
            result: a.result.to_wire(),
            command_id: o.command_id,
            reason: a.reason.to_wire(),
            mav_result: a.mav_result,
            command_seq: o.command_seq,
            detail: FixedStr::new(&a.detail),
            ..CommandAck::default()
        };
        self.metrics.command(o.kind, a.result);
        if let Some(latency) = a.latency {
            self.metrics.observe_latency(latency);
        }
        self.ports.acks.publish(ack)?;
        Ok(())
    }
}

fn kind_name(kind: u8) -> &'static str {
    CommandKind::try_from(kind).map_or("unknown", CommandKind::as_str)
}
