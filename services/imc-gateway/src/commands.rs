//! Vehicle commands in flight (pure, explicit time): every `VehicleCommand` the
//! gateway publishes is remembered until its `CommandAck` (matched by source `imc`
//! and command id), so refusals are counted (`refused_<reason>`) and the `PWM`
//! reply goes out only once the command was accepted.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use imc_proto::Message;
use skymesh_ipc_types::{AckResult, CommandAck, CommandSource, RefusalReason};

use crate::peers::Destination;

/// Most commands waiting for their ack; more are dropped (`command_busy`).
pub const MAX_PENDING: usize = 1024;

/// A command waiting for its ack.
#[derive(Debug, Clone, PartialEq)]
pub struct PendingCommand {
    /// Who asked.
    pub peer: SocketAddr,
    /// The IMC message that asked (for logs).
    pub message: &'static str,
    /// Sent to the peer once the command is accepted (`PWM` for `SetPWM`).
    pub on_accept: Option<(Destination, Message)>,
    pub deadline: Instant,
}

/// What an ack means.
#[derive(Debug, Clone, PartialEq)]
pub enum AckOutcome {
    Accepted,
    /// Refused: the `skymesh_imc_dropped_total` reason and the ack's detail.
    Refused {
        reason: &'static str,
        detail: String,
    },
}

/// `refused_<reason>` for a refusal reason.
pub fn refused_reason(reason: Option<RefusalReason>) -> &'static str {
    match reason {
        Some(RefusalReason::None) => "refused_none",
        Some(RefusalReason::Timeout) => "refused_timeout",
        Some(RefusalReason::Denied) => "refused_denied",
        Some(RefusalReason::Unsupported) => "refused_unsupported",
        Some(RefusalReason::Failed) => "refused_failed",
        Some(RefusalReason::TemporarilyRejected) => "refused_temporarily_rejected",
        Some(RefusalReason::InvalidParameter) => "refused_invalid_parameter",
        Some(RefusalReason::LinkDown) => "refused_link_down",
        Some(RefusalReason::NoAuthority) => "refused_no_authority",
        Some(RefusalReason::Geofence) => "refused_geofence",
        Some(RefusalReason::Stale) => "refused_stale",
        Some(RefusalReason::WrongVehicle) => "refused_wrong_vehicle",
        Some(RefusalReason::WrongState) => "refused_wrong_state",
        Some(RefusalReason::Cancelled) => "refused_cancelled",
        Some(RefusalReason::Emergency) => "refused_emergency",
        Some(RefusalReason::InAir) => "refused_in_air",
        Some(RefusalReason::Preempted) => "refused_preempted",
        Some(RefusalReason::AutopilotFailsafe) => "refused_autopilot_failsafe",
        None => "refused_unknown",
    }
}

/// Commands in flight and the id counter.
#[derive(Debug)]
pub struct Commands {
    pending: HashMap<u32, PendingCommand>,
    next_id: u32,
    timeout: Duration,
}

impl Commands {
    /// `timeout`: how long an ack may take (autopilot-link always answers; this only
    /// bounds memory if it is not running).
    pub fn new(timeout: Duration) -> Self {
        Commands {
            pending: HashMap::new(),
            next_id: 1,
            timeout,
        }
    }

    /// A new command id, remembered with what to do on its ack; `None` when too
    /// many are in flight.
    pub fn start(
        &mut self,
        peer: SocketAddr,
        message: &'static str,
        on_accept: Option<(Destination, Message)>,
        now: Instant,
    ) -> Option<u32> {
        if self.pending.len() >= MAX_PENDING {
            return None;
        }
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        self.pending.insert(
            id,
            PendingCommand {
                peer,
                message,
                on_accept,
                deadline: now + self.timeout,
            },
        );
        Some(id)
    }

    /// The command `ack` finally answers, if it is ours (an in-progress ack keeps it).
    pub fn on_ack(&mut self, ack: &CommandAck) -> Option<(PendingCommand, AckOutcome)> {
        if ack.source != CommandSource::Imc.to_wire() || ack.result() == Some(AckResult::InProgress)
        {
            return None;
        }
        let pending = self.pending.remove(&ack.command_id)?;
        let outcome = if ack.is_accepted() {
            AckOutcome::Accepted
        } else {
            AckOutcome::Refused {
                reason: refused_reason(ack.reason()),
                detail: ack.detail.as_str().to_string(),
            }
        };
        Some((pending, outcome))
    }

    /// Commands whose ack did not come in time.
    /// The earliest reply deadline of the pending requests (what
    /// [`Self::expire`] acts on).
    pub fn next_deadline(&self) -> Option<Instant> {
        self.pending.values().map(|p| p.deadline).min()
    }

    pub fn expire(&mut self, now: Instant) -> Vec<PendingCommand> {
        let late: Vec<u32> = self
            .pending
            .iter()
            .filter(|(_, p)| now >= p.deadline)
            .map(|(id, _)| *id)
            .collect();
        late.into_iter()
            .filter_map(|id| self.pending.remove(&id))
            .collect()
    }

    pub fn len(&self) -> usize {
        self.pending.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::FixedStr;

    fn peer() -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 7000))
    }

    fn ack(id: u32, source: CommandSource, result: AckResult, reason: RefusalReason) -> CommandAck {
        CommandAck {
            source: source.to_wire(),
            command_id: id,
            result: result.to_wire(),
            reason: reason.to_wire(),
            detail: FixedStr::new("held by operator"),
            ..Default::default()
        }
    }

    #[test]
    fn acks_are_matched_by_source_and_id() {
        let t0 = Instant::now();
        let mut c = Commands::new(Duration::from_secs(10));
        let id = c.start(peer(), "SetPWM", None, t0).unwrap();
        let other = c.start(peer(), "SetServoPosition", None, t0).unwrap();
        assert_ne!(id, other);
        let ok = ack(
            id,
            CommandSource::Imc,
            AckResult::Accepted,
            RefusalReason::None,
        );
        let shot = ack(
            id,
            CommandSource::ShotEngine,
            AckResult::Accepted,
            RefusalReason::None,
        );
        assert_eq!(c.on_ack(&shot), None, "another source's command");
        let progress = ack(
            id,
            CommandSource::Imc,
            AckResult::InProgress,
            RefusalReason::None,
        );
        assert_eq!(c.on_ack(&progress), None, "not final");
        let (p, o) = c.on_ack(&ok).unwrap();
        assert_eq!((p.message, o), ("SetPWM", AckOutcome::Accepted));
        assert_eq!(c.on_ack(&ok), None, "answered once");
        let limited = ack(
            other,
            CommandSource::Imc,
            AckResult::Limited,
            RefusalReason::None,
        );
        assert_eq!(c.on_ack(&limited).unwrap().1, AckOutcome::Accepted);
    }

    #[test]
    fn refusals_are_labelled_and_silence_expires() {
        let t0 = Instant::now();
        let mut c = Commands::new(Duration::from_secs(10));
        let id = c.start(peer(), "SetServoPosition", None, t0).unwrap();
        let refused = ack(
            id,
            CommandSource::Imc,
            AckResult::Refused,
            RefusalReason::NoAuthority,
        );
        match c.on_ack(&refused).unwrap().1 {
            AckOutcome::Refused { reason, detail } => {
                assert_eq!(reason, "refused_no_authority");
                assert_eq!(detail, "held by operator");
            }
            other => panic!("{other:?}"),
        }
        for r in RefusalReason::ALL {
            assert_eq!(refused_reason(Some(*r)), format!("refused_{}", r.as_str()));
        }
        c.start(peer(), "SetThrusterActuation", None, t0).unwrap();
        assert!(c.expire(t0 + Duration::from_secs(9)).is_empty());
        assert_eq!(c.expire(t0 + Duration::from_secs(10)).len(), 1);
        assert!(c.is_empty());
    }
}
