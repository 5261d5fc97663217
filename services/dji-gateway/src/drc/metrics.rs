//! The DRC link's series (`skymesh_dji_drc_*`), exported through the gateway's stats
//! sample. Every label value is a `&'static str` from a closed set (methods of the
//! document plus `unknown`, result names of [`result_name`], `Malformed::kind`,
//! `CommandAck` outcomes), so the series count is bounded. Labelled series are
//! registered on first use.

use skymesh_runtime::stats::LATENCY_BOUNDS_S;
use skymesh_runtime::{Counter, CounterFamily, Gauge, Histogram, Stats};

/// Every DRC series. Cheap to clone.
#[derive(Debug, Clone)]
pub struct DrcMetrics {
    /// `skymesh_dji_drc_state`: 0 not connected, 1 connecting, 2 connected.
    pub state: Gauge,
    /// `skymesh_dji_drc_messages_total{method,result}`: drc/down messages answered (or
    /// not: heart_beat has no result, it is counted `ok`).
    messages: CounterFamily,
    /// `skymesh_dji_drc_stick_commands_total{result}`: what the arbiter answered to the
    /// setpoints drone_control produced (accepted, limited, refused, no_ack, bus_error).
    sticks: CounterFamily,
    /// `skymesh_dji_drc_heartbeats_total`.
    pub heartbeats: Counter,
    /// `skymesh_dji_drc_pushes_total{method}`: osd/hsi/delay pushes published.
    pushes: CounterFamily,
    /// `skymesh_dji_drc_push_dropped_total{method}`: pushes not published (not
    /// connected, client queue full, no vehicle state yet).
    push_dropped: CounterFamily,
    /// `skymesh_dji_drc_reconnects_total`: the DRC broker accepted us again after a drop.
    pub reconnects: Counter,
    /// `skymesh_dji_drc_connection_errors_total`: drops and failed reconnects.
    pub connection_errors: Counter,
    /// `skymesh_dji_drc_malformed_total{reason}`: drc/down payloads that are no envelope,
    /// or refused before parsing (`oversized`, `rate_limited`).
    malformed: CounterFamily,
    /// `skymesh_dji_drc_brakes_total{reason}`: brakes the link sent itself
    /// (stale, exit, heartbeat_timeout, credentials_expired, shutdown, replaced).
    brakes: CounterFamily,
    /// `skymesh_dji_drc_exits_total{reason}`: how DRC mode ended.
    exits: CounterFamily,
    /// `skymesh_dji_drc_joystick_invalid_total{reason}`.
    joystick_invalid: CounterFamily,
    /// `skymesh_dji_drc_reply_dropped_total`: drc/up replies the client would not queue.
    pub reply_dropped: Counter,
    /// `skymesh_dji_drc_command_latency_seconds`: drone_control arrival → CommandAck.
    pub latency: Histogram,
}

impl DrcMetrics {
    pub fn new(stats: &Stats) -> Self {
        let one =
            |name: &'static str, key: &'static str| CounterFamily::new(stats, name, (key, None));
        let plain = |name: &str| stats.counter(name, &[]);
        DrcMetrics {
            state: stats.gauge("skymesh_dji_drc_state", &[]),
            messages: CounterFamily::new(
                stats,
                "skymesh_dji_drc_messages_total",
                ("method", Some("result")),
            ),
            sticks: one("skymesh_dji_drc_stick_commands_total", "result"),
            heartbeats: plain("skymesh_dji_drc_heartbeats_total"),
            pushes: one("skymesh_dji_drc_pushes_total", "method"),
            push_dropped: one("skymesh_dji_drc_push_dropped_total", "method"),
            reconnects: plain("skymesh_dji_drc_reconnects_total"),
            connection_errors: plain("skymesh_dji_drc_connection_errors_total"),
            malformed: one("skymesh_dji_drc_malformed_total", "reason"),
            brakes: one("skymesh_dji_drc_brakes_total", "reason"),
            exits: one("skymesh_dji_drc_exits_total", "reason"),
            joystick_invalid: one("skymesh_dji_drc_joystick_invalid_total", "reason"),
            reply_dropped: plain("skymesh_dji_drc_reply_dropped_total"),
            latency: stats.histogram(
                "skymesh_dji_drc_command_latency_seconds",
                &[],
                &LATENCY_BOUNDS_S,
            ),
        }
    }

    pub fn message(&self, method: &'static str, result: u32) {
        self.messages.get(method, result_name(result)).inc();
    }

    pub fn stick(&self, result: &'static str) {
        self.sticks.inc(result);
    }

    pub fn push(&self, method: &'static str) {
        self.pushes.inc(method);
    }

    pub fn push_dropped(&self, method: &'static str) {
        self.push_dropped.inc(method);
    }

    pub fn malformed(&self, reason: &'static str) {
        self.malformed.inc(reason);
    }

    pub fn brake(&self, reason: &'static str) {
        self.brakes.inc(reason);
    }

    pub fn exit(&self, reason: &'static str) {
        self.exits.inc(reason);
    }

    pub fn joystick_invalid(&self, reason: &'static str) {
        self.joystick_invalid.inc(reason);
    }
}

/// The `result` label of a `data.result` code (a closed set; unknown codes → `other`).
pub fn result_name(code: u32) -> &'static str {
    use dji_proto::codes as c;
    match code {
        c::OK => "ok",
        c::NO_FLIGHT_AUTHORITY => "no_flight_authority",
        c::SEQ_OUT_OF_ORDER => "seq_out_of_order",
        c::STICK_STALE => "stick_stale",
        c::EMERGENCY_STOP_FAILED => "emergency_stop_failed",
        c::UNKNOWN_METHOD => "unknown_method",
        c::MISSING_FIELD => "missing_field",
        c::WRONG_TYPE => "wrong_type",
        c::OUT_OF_RANGE => "out_of_range",
        c::NOT_IN_ENUM => "not_in_enum",
        c::BAD_ARRAY_SIZE => "bad_array_size",
        c::BAD_TEXT => "bad_text",
        c::WRONG_STATE => "wrong_state",
        c::VEHICLE_UNAVAILABLE => "vehicle_unavailable",
        c::INTERNAL => "internal",
        _ => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labelled_series_appear_on_first_use() {
        let stats = Stats::new();
        let m = DrcMetrics::new(&stats);
        m.message("drone_control", dji_proto::codes::SEQ_OUT_OF_ORDER);
        m.message("drone_control", dji_proto::codes::SEQ_OUT_OF_ORDER);
        m.malformed("not_json");
        m.state.set(2.0);
        assert_eq!(
            stats.value(
                "skymesh_dji_drc_messages_total",
                "method=drone_control,result=seq_out_of_order"
            ),
            Some(2.0)
        );
        assert_eq!(
            stats.value("skymesh_dji_drc_malformed_total", "reason=not_json"),
            Some(1.0)
        );
        assert_eq!(stats.value("skymesh_dji_drc_state", ""), Some(2.0));
        assert_eq!(
            stats.value("skymesh_dji_drc_malformed_total", "reason=oversized"),
            None
        );
    }

    #[test]
    fn unknown_codes_share_one_label() {
        assert_eq!(result_name(999_999), "other");
        assert_eq!(result_name(0), "ok");
    }
}
