//! The metrics of the shot engine (`skymesh_shot_*`), exported through the runtime's
//! stats sample.
//!
//! Label sets are bounded: shot names come from `shot_api::shots::name`, message
//! names from `ShotRequest::name` and `ShotEvent::name`, command kinds and refusal
//! reasons from the ipc-types enums, exit reasons and entry errors from fixed lists
//! in `engine`.
//! Labelled series are registered on first use so an idle engine does not spend the
//! stats sample's fixed number of entries on series that stay zero.

use skymesh_runtime::{Counter, CounterFamily, Gauge, Stats};

/// Every series the engine exports.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_shot_current`: the Solo shot index being flown or set up, −1 idle.
    pub current_shot: Gauge,
    entered: CounterFamily,
    exits: CounterFamily,
    refusals: CounterFamily,
    app_in: CounterFamily,
    app_out: CounterFamily,
    /// `skymesh_shot_unimplemented_requests_total`: requests answered "not implemented".
    pub unimplemented: Counter,
    commands: CounterFamily,
    refused: CounterFamily,
    /// `skymesh_shot_loop_overruns_total`: ticks that took longer than the loop period
    /// or came late by more than one period.
    pub overruns: Counter,
    /// `skymesh_shot_app_decode_errors_total`: bus messages whose value did not decode.
    pub decode_errors: Counter,
    /// `skymesh_shot_state_file_errors_total`: failed writes of the state file.
    pub state_file_errors: Counter,
    /// `skymesh_shot_geofence_polygons`: polygons of the app's geofence now (0 = none).
    pub geofence_polygons: Gauge,
    /// `skymesh_shot_geofence_activations_total`: times the predictive check held the
    /// vehicle at the fence.
    pub geofence_activations: Counter,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        let current_shot = stats.gauge("skymesh_shot_current", &[]);
        current_shot.set(-1.0);
        Metrics {
            current_shot,
            entered: CounterFamily::new(stats, "skymesh_shot_entered_total", ("shot", None)),
            exits: CounterFamily::new(stats, "skymesh_shot_exits_total", ("reason", None)),
            refusals: CounterFamily::new(
                stats,
                "skymesh_shot_entry_refusals_total",
                ("error", None),
            ),
            app_in: CounterFamily::new(stats, "skymesh_shot_app_messages_in_total", ("msg", None)),
            app_out: CounterFamily::new(
                stats,
                "skymesh_shot_app_messages_out_total",
                ("msg", None),
            ),
            unimplemented: stats.counter("skymesh_shot_unimplemented_requests_total", &[]),
            commands: CounterFamily::new(stats, "skymesh_shot_commands_sent_total", ("kind", None)),
            refused: CounterFamily::new(
                stats,
                "skymesh_shot_commands_refused_total",
                ("reason", None),
            ),
            overruns: stats.counter("skymesh_shot_loop_overruns_total", &[]),
            decode_errors: stats.counter("skymesh_shot_app_decode_errors_total", &[]),
            state_file_errors: stats.counter("skymesh_shot_state_file_errors_total", &[]),
            geofence_polygons: stats.gauge("skymesh_shot_geofence_polygons", &[]),
            geofence_activations: stats.counter("skymesh_shot_geofence_activations_total", &[]),
        }
    }

    pub fn entered(&self, shot: &'static str) {
        self.entered.inc(shot);
    }
    pub fn exited(&self, reason: &'static str) {
        self.exits.inc(reason);
    }
    pub fn refused_entry(&self, error: &'static str) {
        self.refusals.inc(error);
    }
    pub fn app_in(&self, msg: &'static str) {
        self.app_in.inc(msg);
    }
    pub fn app_out(&self, msg: &'static str) {
        self.app_out.inc(msg);
    }
    pub fn command_sent(&self, kind: &'static str) {
        self.commands.inc(kind);
    }
    pub fn command_refused(&self, reason: &'static str) {
        self.refused.inc(reason);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn labelled_series_appear_on_first_use() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        let count = |s: &Stats| {
            let mut out = ServiceStats::default();
            s.snapshot_into(&mut out);
            out.len
        };
        let idle = count(&stats);
        m.entered("orbit");
        m.entered("orbit");
        assert_eq!(count(&stats), idle + 1);
        m.exited("fly_button");
        assert_eq!(count(&stats), idle + 2);
        assert_eq!(
            stats
                .counter("skymesh_shot_entered_total", &[("shot", "orbit")])
                .get(),
            2
        );
    }
}
