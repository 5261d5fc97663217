//! The event loop's side of the arbiter: the vehicle view it decides on, and what
//! its effects become — `AuthorityState` and `ArbiterEvent` samples, metrics, log
//! lines and the stale-stream brake.

use std::time::{Duration, Instant};

use skymesh_ipc_types::{
    ArbiterEvent, ArbiterEventKind, AuthorityDomain, Command, CommandKind, CommandSource, FixedStr,
    FlightMode, GeofenceSet, RefusalReason, NO_HOLDER,
};
use skymesh_runtime::clock::monotonic_ns;

use super::Service;
use crate::acks::{Answer, Origin};
use crate::arbiter::audit::Record;
use crate::arbiter::{Effect, Home, VehicleView};
use crate::commands::{self, PlanContext};
use crate::Lifecycle;

fn name(source: Option<CommandSource>) -> &'static str {
    source.map_or("nobody", CommandSource::as_str)
}

impl<L: Lifecycle> Service<L> {
    /// When the arbiter next has something to do on its own.
    pub(super) fn arbiter_deadline(&self) -> Option<Instant> {
        let due = self.arbiter.next_deadline_ns()?;
        Some(Instant::now() + Duration::from_nanos(due.saturating_sub(monotonic_ns())))
    }

    pub(super) fn vehicle_view(&self, now_ns: u64) -> VehicleView {
        // The status is refreshed on every autopilot message (HOME_POSITION included).
        let home = self
            .last_status
            .as_ref()
            .filter(|s| s.home_valid == 1)
            .map(|s| Home {
                lat_deg: s.home_lat_deg,
                lon_deg: s.home_lon_deg,
                alt_msl_m: s.home_alt_msl_m,
            });
        VehicleView::new(
            self.telemetry.is_armed(),
            self.telemetry.flight_mode(),
            self.last_state.as_ref(),
            home,
            now_ns,
        )
    }

    /// A refusal before the arbiter (intake): audited like the arbiter's own.
    pub(super) fn refuse(
        &mut self,
        origin: Origin,
        reason: RefusalReason,
        detail: String,
    ) -> anyhow::Result<()> {
        self.audit.decision(Record {
            source: origin.source,
            kind: origin.kind,
            command_id: origin.command_id,
            result: skymesh_ipc_types::AckResult::Refused,
            reason,
            detail: &detail,
        });
        self.publish_answer(Answer::refused(origin, reason, detail))
    }

    pub(super) fn on_geofence(&mut self, set: &GeofenceSet) -> anyhow::Result<()> {
        let effects = self.arbiter.set_geofence(set, self.settings.vehicle_id);
        let applied = self.apply(effects);
        self.save_state(false);
        applied
    }

    /// After a command of wire kind `kind`: the state file is written when the
    /// command could have changed the emergency stops.
    pub(super) fn persist_after(&mut self, kind: u8) {
        if matches!(
            CommandKind::try_from(kind),
            Ok(CommandKind::EmergencyStop
                | CommandKind::ReleaseEmergency
                | CommandKind::ClearEmergency)
        ) {
            self.save_state(false);
        }
    }

    /// Writes the arbiter's stops and fences to the state file if they changed
    /// (`clean_exit` at a clean stop). A failure is logged and counted; the service
    /// goes on with the state in memory.
    pub(super) fn save_state(&mut self, clean_exit: bool) {
        let mut state = self.arbiter.persisted();
        state.clean_exit = clean_exit;
        if let Err(e) = self.store.save(&state) {
            self.audit.state_file_error();
            tracing::error!(
                state_file = %self.store.path().display(),
                error = %e,
                "cannot write the arbiter state file: the emergency stops and fences would not survive a restart"
            );
        }
    }

    /// Does what the arbiter decided besides answering.
    pub(super) fn apply(&mut self, effects: Vec<Effect>) -> anyhow::Result<()> {
        for effect in effects {
            match effect {
                Effect::Authority(c) => {
                    let domain = match c.domain {
                        AuthorityDomain::Flight => "flight",
                        AuthorityDomain::Payload => "payload",
                    };
                    if c.domain == AuthorityDomain::Flight {
                        self.audit.flight_holder(c.to);
                    }
                    let detail = format!(
                        "{domain}: {} -> {} ({})",
                        name(c.from),
                        name(c.to),
                        c.change
                    );
                    tracing::info!(
                        vehicle_id = self.settings.vehicle_id,
                        domain,
                        from = name(c.from),
                        to = name(c.to),
                        change = %c.change,
                        "authority changed"
                    );
                    self.publish_authority()?;
                    // The source that lost authority is the one that must be told.
                    self.publish_event(
                        ArbiterEventKind::AuthorityChanged,
                        c.from.or(c.to),
                        &detail,
                    )?;
                }
                Effect::Event {
                    kind,
                    source,
                    detail,
                } => {
                    let src = name(source);
                    if let (ArbiterEventKind::EmergencyCleared, Some(by)) = (kind, source) {
                        self.audit.emergency_cleared(by, &detail);
                    }
                    match kind {
                        ArbiterEventKind::EmergencyStop | ArbiterEventKind::GeofenceInvalid => {
                            tracing::warn!(event = %kind, source = src, detail, "arbiter event")
                        }
                        // Already in the decision's audit line or the link log.
                        ArbiterEventKind::GeofenceRefused
                        | ArbiterEventKind::GeofenceLimited
                        | ArbiterEventKind::LinkLost
                        | ArbiterEventKind::LinkRestored => {
                            tracing::debug!(event = %kind, source = src, detail, "arbiter event")
                        }
                        _ => tracing::info!(event = %kind, source = src, detail, "arbiter event"),
                    }
                    self.publish_event(kind, source, &detail)?;
                }
                Effect::Fence {
                    kind,
                    source,
                    request_id,
                    detail,
                } => {
                    let src = name(source);
                    if kind == ArbiterEventKind::GeofenceInvalid {
                        tracing::warn!(event = %kind, source = src, request_id, detail, "geofence");
                    } else {
                        tracing::info!(event = %kind, source = src, request_id, detail, "geofence");
                    }
                    self.ports.events.publish(ArbiterEvent {
                        vehicle_id: self.settings.vehicle_id,
                        kind: kind.to_wire(),
                        source: source.map_or(NO_HOLDER, CommandSource::to_wire),
                        request_id,
                        detail: FixedStr::new(&detail),
                        ..ArbiterEvent::default()
                    })?;
                }
                Effect::StaleBrake { source } => self.stale_brake(source, false)?,
                Effect::TargetBrake { source } => self.stale_brake(source, true)?,
            }
        }
        Ok(())
    }

    /// `source`'s setpoint stream stopped while the vehicle was moving on it, or
    /// (`target`) `source` flew to a position target (`GoTo`, `Takeoff`) and lost
    /// flight authority by timeout or pre-emption: hold a hover with a zero-velocity
    /// setpoint. Only in GUIDED, the one mode in which the setpoints or targets had
    /// any effect; in any other mode the autopilot (or the pilot) is already in
    /// charge and switching it to BRAKE would override them.
    fn stale_brake(&mut self, source: CommandSource, target: bool) -> anyhow::Result<()> {
        let mode = self.telemetry.flight_mode();
        let what = if target {
            "position target orphaned"
        } else {
            "setpoint stream stopped"
        };
        let detail = if mode == FlightMode::Guided {
            self.audit.stale_brake(source);
            let ctx = PlanContext {
                target: self.target(),
                mode,
                capture_seq: self.capture_seq,
            };
            let sent = match (commands::plan(&Command::Brake, &ctx), &self.writer) {
                (Ok(plan), Some(writer)) => plan
                    .setpoint
                    .is_some_and(|setpoint| writer.send(setpoint).is_ok()),
                _ => false,
            };
            if sent {
                format!("{what}: braked to a hover")
            } else {
                format!("{what}: brake not sent, link down")
            }
        } else {
            format!("{what}: not GUIDED, nothing to brake")
        };
        tracing::warn!(source = %source, mode = %mode, detail, "braking for a source that stopped commanding");
        self.publish_event(ArbiterEventKind::StaleBrake, Some(source), &detail)
    }

    pub(super) fn publish_authority(&mut self) -> anyhow::Result<()> {
        let state = self.arbiter.authority().state(self.settings.vehicle_id);
        self.ports.authority.publish(state)?;
        Ok(())
    }

    fn publish_event(
        &mut self,
        kind: ArbiterEventKind,
        source: Option<CommandSource>,
        detail: &str,
    ) -> anyhow::Result<()> {
        self.ports.events.publish(ArbiterEvent {
            vehicle_id: self.settings.vehicle_id,
            kind: kind.to_wire(),
            source: source.map_or(NO_HOLDER, CommandSource::to_wire),
            detail: FixedStr::new(detail),
            ..ArbiterEvent::default()
        })?;
        Ok(())
    }
}
