//! The event loop: link events, command samples and timers in one task that owns
//! every piece of state (no locks).
//!
//! Command path: intake ([`commands::admit`]) → [`Arbiter::decide`] (authority,
//! freshness, geofence envelope; wiring of its effects in [`safety`]) → dispatch
//! ([`commands::plan`] → link writer → [`AckTracker`]) → `CommandAck`: [`command_path`].
//! Gimbal and GoPro telemetry → `PayloadState`, and GoPro answers → [`AckTracker`]:
//! [`payload`]. An emergency stop is driven until the autopilot confirms it:
//! [`stop`]. A retransmission is decided again by the arbiter before it goes out,
//! and an emergency stop or a pre-emption cancels what it overrides ([`crate::acks`]).
//!
//! A bus error (a sample that could not be taken or published) is logged, counted
//! (`skymesh_autopilot_bus_errors_total`) and survived: the loop goes on, a failing
//! subscription is retried every [`BUS_RETRY`]. Only a command subscription that
//! keeps failing for [`BUS_FATAL`], or the link task ending, ends the service with
//! an error (a non-zero exit: the supervisor restarts it).

mod command_path;
mod payload;
mod safety;
pub(crate) mod stop;
pub(crate) mod vision;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    AckResult, ArbiterEvent, AuthorityState, CommandAck, GeofenceSet, PayloadState, RefusalReason,
    VehicleCommand, VehicleState, VehicleStatus,
};
use skymesh_runtime::timer::until_grid_point;
use skymesh_runtime::{clock::monotonic_ns, IpcError, Publisher, Subscriber};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use crate::acks::{AckPolicy, AckTracker, Action, Answer};
use crate::arbiter::audit::Audit;
use crate::arbiter::{persist, Arbiter, Effect};
use crate::commands::Target;
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
/// A subscription whose `recv` failed is tried again after this long (not at once:
/// a broken port would spin the loop).
const BUS_RETRY: Duration = Duration::from_millis(100);
/// The command subscription failing this long without a sample in between is
/// fatal: the service exits with an error and the supervisor restarts it.
const BUS_FATAL: Duration = Duration::from_secs(10);
/// MAV_CMD_DO_SET_MODE: a COMMAND_ACK for it nobody else waits for may answer the
/// emergency stop's BRAKE.
const DO_SET_MODE: u32 = mavlink::dialects::ardupilotmega::MavCmd::MAV_CMD_DO_SET_MODE as u32;

/// A subscription's recent failures.
#[derive(Debug, Default)]
struct BusHealth {
    /// The first failure since the last sample.
    failing_since: Option<Instant>,
    /// Not polled before this instant.
    resume_at: Option<Instant>,
}

impl BusHealth {
    fn ready(&self, now: Instant) -> bool {
        self.resume_at.is_none_or(|t| now >= t)
    }

    fn ok(&mut self) {
        self.failing_since = None;
        self.resume_at = None;
    }

    /// A failure at `now`: returns how long it has been failing.
    fn failed(&mut self, now: Instant) -> Duration {
        let since = *self.failing_since.get_or_insert(now);
        self.resume_at = Some(now + BUS_RETRY);
        now - since
    }
}

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
    /// The arbiter's state file ([`crate::arbiter::persist`]).
    store: persist::Store,
    /// What restoring the arbiter changed, published once the loop runs.
    restored: Vec<Effect>,
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
    /// The emergency stop being driven until the autopilot confirms it.
    stop: stop::StopTracker,
    /// `position_stamp_ns` of the last velocity the stop tracker was given.
    stop_fed_stamp: u64,
    commands_health: BusHealth,
    geofence_health: BusHealth,
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
        let settings_stop_timeout = settings.stop_confirm_timeout;
        // Before the first command: the stops and fences of the last run.
        let (store, loaded) = persist::Store::open(&settings.state_file, settings.vehicle_id);
        let (arbiter, restored) = persist::start(
            settings.arbiter.clone(),
            loaded,
            store.path(),
            settings.vehicle_id,
            monotonic_ns(),
        );
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
            arbiter,
            store,
            restored,
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
            stop: stop::StopTracker::new(stop::StopPolicy {
                confirm_timeout: settings_stop_timeout,
                ..stop::StopPolicy::DEFAULT
            }),
            stop_fed_stamp: 0,
            commands_health: BusHealth::default(),
            geofence_health: BusHealth::default(),
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
        // The restored stops and fences are in force before the first command.
        let restored = std::mem::take(&mut self.restored);
        self.apply(restored)?;
        self.save_state(false);
        let sleep = tokio::time::sleep(Duration::ZERO);
        tokio::pin!(sleep);
        let result = loop {
            let now = Instant::now();
            if let Err(e) = self.on_timers(now) {
                if let Err(fatal) = self.survive(e, "timers") {
                    break Err(fatal);
                }
            }
            let commands_ready = self.commands_health.ready(now);
            let geofence_ready = self.geofence_health.ready(now);
            sleep
                .as_mut()
                .reset(tokio::time::Instant::from_std(self.next_deadline()));
            let wake = tokio::select! {
                biased;
                _ = shutdown.cancelled() => break Ok(()),
                sample = self.ports.commands.recv(), if commands_ready => Wake::Command(sample),
                fence = self.ports.geofence.recv(), if geofence_ready => Wake::Geofence(fence.map(Box::new)),
                event = events.recv() => Wake::Link(event),
                v = vision::Vision::next(self.vision.as_mut()) => Wake::Vision(v),
                _ = &mut sleep => Wake::Timer,
            };
            let step = match wake {
                Wake::Command(Ok(sample)) => {
                    self.commands_health.ok();
                    self.on_command(sample)
                }
                Wake::Command(Err(e)) => {
                    let failing = self.commands_health.failed(Instant::now());
                    if failing >= BUS_FATAL {
                        break Err(anyhow::Error::new(e).context(format!(
                            "the command subscription failed for {:.0} s",
                            failing.as_secs_f64()
                        )));
                    }
                    Err(e.into())
                }
                Wake::Geofence(Ok(fence)) => {
                    self.geofence_health.ok();
                    self.on_geofence(&fence)
                }
                Wake::Geofence(Err(e)) => {
                    self.geofence_health.failed(Instant::now());
                    Err(e.into())
                }
                Wake::Link(Some(event)) => self.on_link_event(event),
                Wake::Link(None) => break Err(anyhow::anyhow!("the link task ended")),
                Wake::Vision(v) => self.on_vision(v),
                Wake::Timer => Ok(()),
            };
            if let Err(e) = step {
                if let Err(fatal) = self.survive(e, "event") {
                    break Err(fatal);
                }
            }
        };
        let unexplained = std::mem::take(&mut self.unexplained);
        let stops = self
            .stop
            .end(RefusalReason::Cancelled, "autopilot-link stopping");
        for answer in unexplained.into_iter().map(|(_, a)| a).chain(stops).chain(
            self.tracker
                .fail_all(RefusalReason::Cancelled, "autopilot-link stopping"),
        ) {
            let _ = self.answer(answer);
        }
        self.save_state(result.is_ok());
        result
    }

    /// A step failed: a bus error is logged and counted and the loop goes on;
    /// anything else is returned (fatal).
    fn survive(&mut self, e: anyhow::Error, during: &'static str) -> anyhow::Result<()> {
        if e.downcast_ref::<IpcError>().is_none() {
            return Err(e);
        }
        self.metrics.bus_errors.inc();
        tracing::warn!(error = format!("{e:#}"), during, "bus error; carrying on");
        Ok(())
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
            self.stop.next_deadline(),
            self.commands_health.resume_at,
            self.geofence_health.resume_at,
        ]
        .into_iter()
        .flatten()
        .fold(self.next_tick, Instant::min)
    }

    /// Everything due at `now`. Each part runs even if one before it failed (a
    /// bus error must not hold back the heartbeat, a retransmission or the stop);
    /// the first error is returned.
    fn on_timers(&mut self, now: Instant) -> anyhow::Result<()> {
        let results = [
            self.poll_arbiter(),
            self.poll_link(now),
            self.poll_commands(now),
            self.publish_payload_if_due(),
            self.poll_vision(),
            self.tick(now),
        ];
        results.into_iter().find(Result::is_err).unwrap_or(Ok(()))
    }

    fn poll_arbiter(&mut self) -> anyhow::Result<()> {
        let effects = self.arbiter.poll(monotonic_ns());
        self.apply(effects)
    }

    fn poll_link(&mut self, now: Instant) -> anyhow::Result<()> {
        if let Some(change) = self.link.poll(now) {
            self.link_changed(change, now, "no heartbeat within the link timeout")?;
        }
        Ok(())
    }

    /// Retransmissions (decided again), timeouts, the stop's repeats and
    /// deadlines, refusals whose explanation did not come.
    fn poll_commands(&mut self, now: Instant) -> anyhow::Result<()> {
        for action in self.tracker.poll(now) {
            match action {
                Action::Retransmit {
                    origin,
                    sample,
                    command,
                } => {
                    if let Some((reason, detail)) = sample.and_then(|s| self.redecide(&s)) {
                        tracing::info!(command = %command.key(), reason = %reason, detail, "retransmission refused by the arbiter; cancelled");
                        let detail = format!("not retransmitted: {detail}");
                        if let Some(answer) = self.tracker.cancel(&origin, reason, &detail) {
                            self.answer(answer)?;
                        }
                        continue;
                    }
                    tracing::debug!(command = %command.key(), "no COMMAND_ACK yet; retransmitting");
                    self.write(command.message());
                }
                Action::Answer(answer) => self.answer(answer)?,
            }
        }
        let actions = self.stop.poll(now);
        self.run_stop(actions)?;
        if self.unexplained.iter().any(|(t, _)| *t <= now) {
            let (due, waiting) = std::mem::take(&mut self.unexplained)
                .into_iter()
                .partition(|(t, _)| *t <= now);
            self.unexplained = waiting;
            for (_, answer) in due {
                self.answer(answer)?;
            }
        }
        Ok(())
    }

    /// Our HEARTBEAT, the periodic status and authority, stream re-requests.
    fn tick(&mut self, now: Instant) -> anyhow::Result<()> {
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
                self.end_stop(
                    RefusalReason::LinkDown,
                    "link lost before the stop was confirmed",
                )?;
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
                    // The ATTITUDE rate follows the armed state (flight rate armed,
                    // ground rate disarmed), and the home is asked for again at
                    // arming (ArduPilot sets it then).
                    if (self.streams_due || u.armed_changed) && self.writer.is_some() {
                        self.request_streams(now);
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
                        None if command == DO_SET_MODE => {
                            self.stop.on_mode_ack(now, result, explanation);
                        }
                        None => {}
                    }
                }
                if let Some(state) = u.state {
                    self.last_attitude = Some(now);
                    self.stream_retries = 0;
                    self.ports.state.publish(state)?;
                    self.last_state = Some(state);
                    // A position target reached is over (its source may go quiet).
                    let view = self.vehicle_view(monotonic_ns());
                    self.arbiter.observe(&view);
                }
                self.publish_status_if_changed(now)?;
                // After the samples: a source that reads the stop's answer finds
                // VehicleStatus / VehicleState already showing what confirmed it.
                if u.heartbeat {
                    let actions = self.stop.on_heartbeat(now, self.telemetry.flight_mode());
                    self.run_stop(actions)?;
                }
                // A new velocity measurement (not the same one republished with the
                // next ATTITUDE).
                if let Some(state) = u
                    .state
                    .filter(|s| s.position_valid == 1 && s.position_stamp_ns != self.stop_fed_stamp)
                {
                    self.stop_fed_stamp = state.position_stamp_ns;
                    let actions = self.stop.on_velocity(now, state.vel_ned_mps);
                    self.run_stop(actions)?;
                }
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
                self.end_stop(
                    RefusalReason::LinkDown,
                    "link lost before the stop was confirmed",
                )?;
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
        if change == LinkChange::Up && self.arbiter.authority().in_emergency() {
            self.rebrake(now)?;
        }
        Ok(self.publish_status(now)?)
    }

    fn request_streams(&mut self, now: Instant) {
        tracing::debug!(rates = ?self.settings.rates, "requesting telemetry rates");
        for msg in requests::stream_requests(
            &self.settings.rates,
            self.target(),
            self.settings.request_data_streams,
            self.telemetry.is_armed(),
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
}

#[cfg(test)]
mod tests {
    use super::command_path::{is_flight, overridden, Overridden};
    use super::*;
    use crate::arbiter::authority::Change;
    use skymesh_ipc_types::{
        ArbiterEventKind, AuthorityChange, AuthorityDomain, CommandKind, CommandSource,
    };

    #[test]
    fn a_failing_subscription_is_paused_then_retried_and_its_failure_measured() {
        let t0 = Instant::now();
        let mut h = BusHealth::default();
        assert!(h.ready(t0));
        assert_eq!(h.failed(t0), Duration::ZERO);
        assert!(!h.ready(t0 + BUS_RETRY / 2), "not polled at once again");
        assert!(h.ready(t0 + BUS_RETRY));
        assert_eq!(
            h.failed(t0 + Duration::from_secs(3)),
            Duration::from_secs(3)
        );
        h.ok();
        assert!(h.ready(t0));
        assert_eq!(
            h.failed(t0 + Duration::from_secs(4)),
            Duration::ZERO,
            "a sample in between starts the count again"
        );
    }

    #[test]
    fn preemptions_and_the_end_of_the_emergency_are_what_is_overridden() {
        let change = |change, from, to| {
            Effect::Authority(Change {
                domain: AuthorityDomain::Flight,
                from,
                to,
                change,
            })
        };
        let effects = [
            change(
                AuthorityChange::Preempted,
                Some(CommandSource::SwarmQueue),
                Some(CommandSource::Operator),
            ),
            change(AuthorityChange::Granted, None, Some(CommandSource::Imc)),
            change(
                AuthorityChange::Preempted,
                None,
                Some(CommandSource::Operator),
            ),
            Effect::Event {
                kind: ArbiterEventKind::EmergencyCleared,
                source: Some(CommandSource::Operator),
                detail: String::new(),
            },
            Effect::Event {
                kind: ArbiterEventKind::EmergencyReleased,
                source: Some(CommandSource::DjiDrc),
                detail: String::new(),
            },
        ];
        assert_eq!(
            overridden(&effects),
            vec![
                Overridden::Preempted {
                    source: CommandSource::SwarmQueue,
                    by: Some(CommandSource::Operator),
                    domain: AuthorityDomain::Flight,
                },
                Overridden::EmergencyEnded,
            ]
        );
        assert!(is_flight(CommandKind::Arm.to_wire()));
        assert!(!is_flight(CommandKind::Servo.to_wire()));
        assert!(!is_flight(CommandKind::EmergencyStop.to_wire()));
    }
}
