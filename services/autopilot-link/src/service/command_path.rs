//! The command path of the event loop: a sample's intake and arbiter decision,
//! the emergency stop's drive, dispatch to the link and the `CommandAck` answers.

use std::time::Instant;

use skymesh_ipc_types::{
    AckResult, Command, CommandAck, CommandKind, CommandSource, FixedStr, RefusalReason,
    VehicleCommand,
};
use skymesh_runtime::clock::monotonic_ns;

use crate::acks::{Answer, Origin};
use crate::arbiter::{Effect, Outcome};
use crate::commands::{self, PlanContext};
use crate::Lifecycle;

use super::{stop, Service};

impl<L: Lifecycle> Service<L> {
    pub(super) fn on_command(&mut self, sample: VehicleCommand) -> anyhow::Result<()> {
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
        let overridden = overridden(&decision.effects);
        self.apply(decision.effects)?;
        self.cancel_overridden(&overridden)?;
        let answered = match decision.outcome {
            Outcome::Execute {
                command: Command::EmergencyStop,
                ..
            } => self.engage_stop(origin, now),
            Outcome::Execute { command, limited } => {
                if let Some(detail) = limited {
                    self.limited
                        .insert((origin.source, origin.command_id), detail);
                }
                self.forward_to_vision(&command)?;
                self.dispatch(&sample, &command, now)
            }
            Outcome::Done { detail } => self.publish_answer(Answer {
                detail,
                ..Answer::accepted(origin)
            }),
            Outcome::Refused { reason, detail } => {
                self.publish_answer(Answer::refused(origin, reason, detail))
            }
        };
        self.persist_after(origin.kind);
        answered
    }

    /// An emergency stop the arbiter let through: every flight command still
    /// waiting for its answer is cancelled (none is retransmitted over the stop),
    /// then the stop is driven until the autopilot confirms it ([`stop`]).
    pub(super) fn engage_stop(&mut self, origin: Origin, now: Instant) -> anyhow::Result<()> {
        let source =
            CommandSource::try_from(origin.source).map_or("unknown", CommandSource::as_str);
        for answer in self.tracker.cancel_where(
            |o| is_flight(o.kind),
            RefusalReason::Cancelled,
            &format!("cancelled by {source}'s emergency stop"),
        ) {
            self.answer(answer)?;
        }
        let mode = self.telemetry.flight_mode();
        let joins = self.stop.is_active();
        tracing::warn!(source, command_id = origin.command_id, mode = %mode, joins, "emergency stop: braking until the autopilot confirms");
        let actions = self.stop.engage(origin, now, mode);
        self.run_stop(actions)
    }

    /// The link is up (first time since start, with a latch restored from the
    /// state file, or again after a loss) while an emergency latch is in force:
    /// the drive that braked the vehicle, if any, ended with the link or the
    /// process, so brake again as for a fresh stop ([`stop::StopTracker::rebrake`];
    /// a failsafe descent is held, a disarmed vehicle left alone).
    pub(super) fn rebrake(&mut self, now: Instant) -> anyhow::Result<()> {
        let mode = self.telemetry.flight_mode();
        let armed = self.telemetry.is_armed();
        let engagers = self.arbiter.authority().engagements();
        tracing::warn!(mode = %mode, armed, engagers = ?engagers, "emergency stop in force at link up: braking an armed vehicle until the autopilot confirms");
        let actions = self.stop.rebrake(now, mode, armed);
        self.run_stop(actions)
    }

    /// Writes the stop's frames and publishes its answers.
    pub(super) fn run_stop(&mut self, actions: Vec<stop::StopAction>) -> anyhow::Result<()> {
        for action in actions {
            match action {
                stop::StopAction::BrakeMode { confirmation } => {
                    match commands::brake_mode(self.target(), confirmation) {
                        Ok(cmd) => {
                            if confirmation > 0 {
                                tracing::info!(
                                    confirmation,
                                    "BRAKE not reported yet; sending DO_SET_MODE BRAKE again"
                                );
                            }
                            self.write(cmd.message());
                        }
                        Err(why) => tracing::error!(why, "emergency stop: no BRAKE mode"),
                    }
                }
                stop::StopAction::ZeroSetpoint => {
                    self.write(commands::zero_velocity(self.target()))
                }
                stop::StopAction::Answer(answer) => self.answer(answer)?,
            }
        }
        Ok(())
    }

    /// Ends the stop's drive (link lost, emergency cleared): nothing more is sent.
    pub(super) fn end_stop(&mut self, reason: RefusalReason, detail: &str) -> anyhow::Result<()> {
        for answer in self.stop.end(reason, detail) {
            self.answer(answer)?;
        }
        Ok(())
    }

    /// Cancels what the arbiter's effects override: the commands still waiting for
    /// an answer of a pre-empted source (in that domain), and the stop's drive when
    /// the emergency ended.
    pub(super) fn cancel_overridden(&mut self, overridden: &[Overridden]) -> anyhow::Result<()> {
        for o in overridden {
            match *o {
                Overridden::Preempted { source, by, domain } => {
                    let detail = format!(
                        "pre-empted by {}",
                        by.map_or("nobody", CommandSource::as_str)
                    );
                    for answer in self.tracker.cancel_where(
                        |p| {
                            p.source == source.to_wire()
                                && CommandKind::try_from(p.kind)
                                    .ok()
                                    .and_then(CommandKind::authority)
                                    == Some(domain)
                        },
                        RefusalReason::Preempted,
                        &detail,
                    ) {
                        self.answer(answer)?;
                    }
                }
                Overridden::EmergencyEnded => {
                    self.end_stop(
                        RefusalReason::Cancelled,
                        "emergency ended before confirmation",
                    )?;
                }
            }
        }
        Ok(())
    }

    /// What the arbiter would decide about `sample` now, without changing it (a
    /// retransmission is not a new command: it takes no authority and its age is
    /// the first decision's business). `Some` if it would refuse it.
    pub(super) fn redecide(&self, sample: &VehicleCommand) -> Option<(RefusalReason, String)> {
        let now_ns = monotonic_ns();
        let mut again = *sample;
        again.header.stamp_ns = now_ns;
        let view = self.vehicle_view(now_ns);
        let mut dry = self.arbiter.clone();
        match dry.decide(now_ns, &again, &view).outcome {
            Outcome::Refused { reason, detail } => Some((reason, detail)),
            Outcome::Execute { .. } | Outcome::Done { .. } => None,
        }
    }

    pub(super) fn dispatch(
        &mut self,
        sample: &VehicleCommand,
        command: &Command,
        now: Instant,
    ) -> anyhow::Result<()> {
        let origin = Origin::of(sample);
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
                if let Some(superseded) = self.tracker.submit_sample(sample, cmd, now, now) {
                    self.answer(superseded)?;
                }
                Ok(())
            }
            None => self.answer(Answer::accepted(origin)),
        }
    }

    /// Publishes, counts and logs the answer to one command.
    pub(super) fn answer(&mut self, mut a: Answer) -> anyhow::Result<()> {
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
    pub(super) fn publish_answer(&mut self, a: Answer) -> anyhow::Result<()> {
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
        // A lost answer is counted and logged, not fatal, and does not keep the
        // answers after it (a stop's, a cancellation's) from going out.
        if let Err(e) = self.ports.acks.publish(ack) {
            self.metrics.bus_errors.inc();
            tracing::warn!(error = %e, kind = %kind_name(o.kind), command_id = o.command_id, "command ack not published");
        }
        Ok(())
    }
}

pub(super) fn kind_name(kind: u8) -> &'static str {
    CommandKind::try_from(kind).map_or("unknown", CommandKind::as_str)
}

pub(super) fn is_flight(kind: u8) -> bool {
    CommandKind::try_from(kind)
        .ok()
        .and_then(CommandKind::authority)
        == Some(skymesh_ipc_types::AuthorityDomain::Flight)
}

/// What an arbiter decision overrides, besides what it answers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Overridden {
    /// `source` lost `domain` to `by`: its commands still waiting are cancelled.
    Preempted {
        source: CommandSource,
        by: Option<CommandSource>,
        domain: skymesh_ipc_types::AuthorityDomain,
    },
    /// The emergency stop ended: its drive stops.
    EmergencyEnded,
}

pub(super) fn overridden(effects: &[Effect]) -> Vec<Overridden> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Authority(c) if c.change == skymesh_ipc_types::AuthorityChange::Preempted => {
                c.from.map(|source| Overridden::Preempted {
                    source,
                    by: c.to,
                    domain: c.domain,
                })
            }
            Effect::Event {
                kind: skymesh_ipc_types::ArbiterEventKind::EmergencyCleared,
                ..
            } => Some(Overridden::EmergencyEnded),
            _ => None,
        })
        .collect()
}
