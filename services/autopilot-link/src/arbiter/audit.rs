//! Audit: every decision is counted and logged as one structured line (the
//! `CommandAck` is published by the service), plus the arbiter's other series.
//!
//! Series. The label sets known at start exist at 0 from the first scrape
//! (Prometheus convention: a dashboard sees 0, not "no data"): every source's
//! `accepted` and `limited` decisions, its authority-holder gauge and its stale-brake
//! counter (32 series). Refusals are registered on first use: source × reason would
//! spend 144 of the stats sample's 384 entries on series that mostly stay zero.
//! - `skymesh_arbiter_decisions_total{source,decision,reason}` — decision is
//!   `accepted`, `limited` or `refused`; reason is a `RefusalReason` name (`none`
//!   when accepted or limited).
//! - `skymesh_arbiter_authority_holder{vehicle,source}` — 1 for the flight-authority
//!   holder, 0 for every other source.
//! - `skymesh_arbiter_stale_brakes_total{source}` — brakes because the source's
//!   setpoint stream stopped (or its position target lost authority).
//! - `skymesh_arbiter_emergency_ends_total{source}` — emergency stops ended by that
//!   source: its `ReleaseEmergency` as the last engager, or its `ClearEmergency`
//!   whoever engaged them (on use).
//! - `skymesh_arbiter_state_file_errors_total` — failed writes of the state file
//!   (on use).
//!
//! Log levels: refusals `warn`, other decisions `info`; a setpoint stream (tens of
//! Hz) logs at `info`/`warn` only when its outcome changes and at `debug` otherwise.

use std::collections::HashMap;

use skymesh_ipc_types::{AckResult, CommandKind, CommandSource, RefusalReason};
use skymesh_runtime::{Counter, Gauge, Stats};

/// One decision as the audit sees it (raw wire values: refusals of undecodable
/// samples are audited too).
#[derive(Debug, Clone, Copy)]
pub struct Record<'a> {
    pub source: u8,
    pub kind: u8,
    pub command_id: u32,
    pub result: AckResult,
    pub reason: RefusalReason,
    pub detail: &'a str,
}

/// The arbiter's metrics and log lines.
#[derive(Debug)]
pub struct Audit {
    stats: Stats,
    vehicle: String,
    decisions: HashMap<(&'static str, AckResult, RefusalReason), Counter>,
    holders: Vec<(CommandSource, Gauge)>,
    stale_brakes: HashMap<CommandSource, Counter>,
    /// Outcome of the last setpoint per source (wire value as index).
    last_setpoint: [Option<(AckResult, RefusalReason)>; CommandSource::ALL.len()],
    /// `skymesh_arbiter_emergency_ends_total{source}`: stops ended by that source
    /// (registered on use).
    clears: HashMap<CommandSource, Counter>,
    /// `skymesh_arbiter_state_file_errors_total` (registered on use).
    state_file_errors: Option<Counter>,
}

fn source_name(raw: u8) -> &'static str {
    CommandSource::try_from(raw).map_or("unknown", CommandSource::as_str)
}

impl Audit {
    pub fn new(stats: &Stats, vehicle_id: u8) -> Self {
        let mut audit = Audit {
            stats: stats.clone(),
            vehicle: vehicle_id.to_string(),
            decisions: HashMap::new(),
            holders: Vec::new(),
            stale_brakes: HashMap::new(),
            last_setpoint: [None; CommandSource::ALL.len()],
            clears: HashMap::new(),
            state_file_errors: None,
        };
        for &source in CommandSource::ALL {
            for result in [AckResult::Accepted, AckResult::Limited] {
                audit.decision_counter(source.as_str(), result, RefusalReason::None);
            }
            audit.stale_brake_counter(source);
            let gauge = audit.stats.gauge(
                "skymesh_arbiter_authority_holder",
                &[("vehicle", &audit.vehicle), ("source", source.as_str())],
            );
            gauge.set(0.0);
            audit.holders.push((source, gauge));
        }
        audit
    }

    fn decision_counter(
        &mut self,
        source: &'static str,
        result: AckResult,
        reason: RefusalReason,
    ) -> &Counter {
        let stats = &self.stats;
        self.decisions
            .entry((source, result, reason))
            .or_insert_with(|| {
                stats.counter(
                    "skymesh_arbiter_decisions_total",
                    &[
                        ("source", source),
                        ("decision", result.as_str()),
                        ("reason", reason.as_str()),
                    ],
                )
            })
    }

    fn stale_brake_counter(&mut self, source: CommandSource) -> &Counter {
        let stats = &self.stats;
        self.stale_brakes.entry(source).or_insert_with(|| {
            stats.counter(
                "skymesh_arbiter_stale_brakes_total",
                &[("source", source.as_str())],
            )
        })
    }

    /// Counts and logs one decision.
    pub fn decision(&mut self, r: Record<'_>) {
        let source = source_name(r.source);
        self.decision_counter(source, r.result, r.reason).inc();
        let kind_known = CommandKind::try_from(r.kind).ok();
        let kind = kind_known.map_or("unknown", CommandKind::as_str);
        let repeat = match kind_known {
            Some(k) if k.is_setpoint() => self
                .last_setpoint
                .get_mut(usize::from(r.source))
                .is_some_and(|last| {
                    last.replace((r.result, r.reason)) == Some((r.result, r.reason))
                }),
            _ => false,
        };
        let (decision, reason, command_id, detail) =
            (r.result.as_str(), r.reason.as_str(), r.command_id, r.detail);
        if repeat {
            tracing::debug!(
                source,
                kind,
                decision,
                reason,
                command_id,
                detail,
                "arbiter decision"
            );
        } else if r.result == AckResult::Refused {
            tracing::warn!(
                source,
                kind,
                decision,
                reason,
                command_id,
                detail,
                "arbiter decision"
            );
        } else {
            tracing::info!(
                source,
                kind,
                decision,
                reason,
                command_id,
                detail,
                "arbiter decision"
            );
        }
    }

    /// Flight authority now belongs to `holder` (or nobody).
    pub fn flight_holder(&mut self, holder: Option<CommandSource>) {
        if let Some(h) = holder {
            if !self.holders.iter().any(|(s, _)| *s == h) {
                let gauge = self.stats.gauge(
                    "skymesh_arbiter_authority_holder",
                    &[("vehicle", &self.vehicle), ("source", h.as_str())],
                );
                self.holders.push((h, gauge));
            }
        }
        for (s, gauge) in &self.holders {
            gauge.set(if Some(*s) == holder { 1.0 } else { 0.0 });
        }
    }

    /// The arbiter braked because `source`'s setpoint stream stopped.
    pub fn stale_brake(&mut self, source: CommandSource) {
        self.stale_brake_counter(source).inc();
    }

    /// `by` ended the emergency stop (the last engager released it, or a
    /// `ClearEmergency` whoever engaged it): counted and logged at `warn` with the
    /// arbiter's detail (who cleared, who had engaged).
    pub fn emergency_cleared(&mut self, by: CommandSource, detail: &str) {
        let stats = &self.stats;
        self.clears
            .entry(by)
            .or_insert_with(|| {
                stats.counter(
                    "skymesh_arbiter_emergency_ends_total",
                    &[("source", by.as_str())],
                )
            })
            .inc();
        tracing::warn!(source = by.as_str(), detail, "emergency stop ended");
    }

    /// The state file could not be written.
    pub fn state_file_error(&mut self) {
        let stats = &self.stats;
        self.state_file_errors
            .get_or_insert_with(|| stats.counter("skymesh_arbiter_state_file_errors_total", &[]))
            .inc();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    fn value(stats: &Stats, name: &str, labels: &str) -> Option<f64> {
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        out.entries()
            .iter()
            .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
            .map(|e| e.value)
    }

    #[test]
    fn known_series_exist_at_zero_refusals_on_use() {
        let stats = Stats::new();
        let mut a = Audit::new(&stats, 3);
        let d = "skymesh_arbiter_decisions_total";
        let h = "skymesh_arbiter_authority_holder";
        let b = "skymesh_arbiter_stale_brakes_total";
        for s in CommandSource::ALL.iter().map(|s| s.as_str()) {
            for decision in ["accepted", "limited"] {
                let labels = format!("source={s},decision={decision},reason=none");
                assert_eq!(value(&stats, d, &labels), Some(0.0), "{labels}");
            }
            assert_eq!(
                value(&stats, h, &format!("vehicle=3,source={s}")),
                Some(0.0)
            );
            assert_eq!(value(&stats, b, &format!("source={s}")), Some(0.0));
        }
        assert_eq!(
            value(&stats, d, "source=vision,decision=refused,reason=stale"),
            None,
            "refusals are registered on first use"
        );
        let rec = |source: u8, result, reason| Record {
            source,
            kind: CommandKind::VelocityNed.to_wire(),
            command_id: 1,
            result,
            reason,
            detail: "",
        };
        a.decision(rec(
            CommandSource::Vision.to_wire(),
            AckResult::Refused,
            RefusalReason::Stale,
        ));
        a.decision(rec(
            CommandSource::Vision.to_wire(),
            AckResult::Refused,
            RefusalReason::Stale,
        ));
        a.decision(rec(
            200,
            AckResult::Refused,
            RefusalReason::InvalidParameter,
        ));
        a.decision(rec(
            CommandSource::Operator.to_wire(),
            AckResult::Limited,
            RefusalReason::None,
        ));
        assert_eq!(
            value(&stats, d, "source=vision,decision=refused,reason=stale"),
            Some(2.0)
        );
        assert_eq!(
            value(
                &stats,
                d,
                "source=unknown,decision=refused,reason=invalid_parameter"
            ),
            Some(1.0)
        );
        assert_eq!(
            value(&stats, d, "source=operator,decision=limited,reason=none"),
            Some(1.0)
        );
        assert_eq!(
            value(&stats, d, "source=operator,decision=accepted,reason=none"),
            Some(0.0)
        );

        a.flight_holder(Some(CommandSource::ShotEngine));
        a.flight_holder(Some(CommandSource::ManualRc));
        assert_eq!(value(&stats, h, "vehicle=3,source=shot_engine"), Some(0.0));
        assert_eq!(value(&stats, h, "vehicle=3,source=manual_rc"), Some(1.0));
        a.flight_holder(None);
        assert_eq!(value(&stats, h, "vehicle=3,source=manual_rc"), Some(0.0));
        assert_eq!(value(&stats, h, "vehicle=3,source=vision"), Some(0.0));

        a.stale_brake(CommandSource::Imc);
        assert_eq!(value(&stats, b, "source=imc"), Some(1.0));
        assert_eq!(value(&stats, b, "source=dji_drc"), Some(0.0));
    }
}
