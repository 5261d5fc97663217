//! Ending an emergency stop: an engager withdraws its own (`ReleaseEmergency`),
//! or operator or safety clears it whoever engaged it (`ClearEmergency`).

use skymesh_ipc_types::{ArbiterEventKind, CommandSource, RefusalReason};

use super::authority::Released;
use super::{refused, Arbiter, Effect, Outcome};

/// `a, b, c`.
pub(super) fn names(sources: &[CommandSource]) -> String {
    sources
        .iter()
        .map(|s| s.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl Arbiter {
    /// `source` withdraws its own emergency stop.
    pub(super) fn release_emergency(
        &mut self,
        now_ns: u64,
        source: CommandSource,
        effects: &mut Vec<Effect>,
    ) -> Outcome {
        let detail = match self.authority.release_emergency(source, now_ns) {
            Released::NotEngaged => {
                return Outcome::Done {
                    detail: format!("no emergency stop by {source} in force"),
                }
            }
            Released::Remaining(others) => {
                let detail = format!("{source} released; still held by {}", names(&others));
                effects.push(Effect::Event {
                    kind: ArbiterEventKind::EmergencyReleased,
                    source: Some(source),
                    detail: detail.clone(),
                });
                detail
            }
            Released::Ended(change) => {
                effects.push(Effect::Event {
                    kind: ArbiterEventKind::EmergencyReleased,
                    source: Some(source),
                    detail: format!("{source} released, the last engager"),
                });
                effects.push(Effect::Event {
                    kind: ArbiterEventKind::EmergencyCleared,
                    source: Some(source),
                    detail: format!("emergency stop ended: {source} was the last engager"),
                });
                effects.push(Effect::Authority(change));
                "emergency stop ended".to_string()
            }
        };
        Outcome::Done { detail }
    }

    /// Ends the emergency stop whoever engaged it: operator and safety only.
    pub(super) fn clear_emergency(
        &mut self,
        now_ns: u64,
        source: CommandSource,
        effects: &mut Vec<Effect>,
    ) -> Outcome {
        if !matches!(source, CommandSource::Safety | CommandSource::Operator) {
            return refused(
                RefusalReason::Denied,
                "clear_emergency: operator or safety only",
            );
        }
        let Some((was, change)) = self.authority.clear_emergency(now_ns) else {
            return Outcome::Done {
                detail: "no emergency stop in force".to_string(),
            };
        };
        let engagers: Vec<CommandSource> = was.iter().map(|e| e.source).collect();
        let detail = format!("cleared by {source}; engaged by {}", names(&engagers));
        effects.push(Effect::Event {
            kind: ArbiterEventKind::EmergencyCleared,
            source: Some(source),
            detail: detail.clone(),
        });
        effects.push(Effect::Authority(change));
        Outcome::Done { detail }
    }
}
