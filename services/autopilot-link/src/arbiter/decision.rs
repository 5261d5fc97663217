//! What the arbiter answers: the [`Outcome`] for the command, the [`Effect`]s the
//! service publishes besides, together a [`Decision`].

use skymesh_ipc_types::{AckResult, ArbiterEventKind, Command, CommandSource, RefusalReason};

use super::authority::Change;
#[cfg(doc)]
use super::Arbiter;

/// What to do with a command.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Execute `command` (as the arbiter left it); `limited` says what it reduced.
    Execute {
        command: Command,
        limited: Option<String>,
    },
    /// Decided by the arbiter alone (authority requests): answer accepted.
    Done { detail: String },
    Refused {
        reason: RefusalReason,
        detail: String,
    },
}

/// Something the service must publish or do besides answering.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// Publish `AuthorityState` (and an `AuthorityChanged` event).
    Authority(Change),
    Event {
        kind: ArbiterEventKind,
        source: Option<CommandSource>,
        detail: String,
    },
    /// A geofence decision ([`Arbiter::set_geofence`]): an `ArbiterEvent` that echoes
    /// the `GeofenceSet`'s `request_id`.
    Fence {
        kind: ArbiterEventKind,
        source: Option<CommandSource>,
        request_id: u32,
        detail: String,
    },
    /// `source`'s setpoint stream stopped while moving: brake to a hover.
    StaleBrake { source: CommandSource },
    /// `source` flew to a position target (`GoTo`, `Takeoff`) and lost flight
    /// authority by timeout or pre-emption: brake to a hover, as for a stopped stream.
    TargetBrake { source: CommandSource },
}

/// The arbiter's answer to one command.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub outcome: Outcome,
    pub effects: Vec<Effect>,
}

impl Decision {
    pub fn result(&self) -> AckResult {
        match &self.outcome {
            Outcome::Execute {
                limited: Some(_), ..
            } => AckResult::Limited,
            Outcome::Execute { .. } | Outcome::Done { .. } => AckResult::Accepted,
            Outcome::Refused { .. } => AckResult::Refused,
        }
    }

    pub fn reason(&self) -> RefusalReason {
        match &self.outcome {
            Outcome::Refused { reason, .. } => *reason,
            _ => RefusalReason::None,
        }
    }

    pub fn detail(&self) -> &str {
        match &self.outcome {
            Outcome::Execute { limited, .. } => limited.as_deref().unwrap_or(""),
            Outcome::Done { detail } | Outcome::Refused { detail, .. } => detail,
        }
    }
}

pub(super) fn refused(reason: RefusalReason, detail: impl Into<String>) -> Outcome {
    Outcome::Refused {
        reason,
        detail: detail.into(),
    }
}
