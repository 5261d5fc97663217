//! The metrics of dji-gateway (services/events side), exported through the runtime's
//! stats sample. Label values come from closed sets: topic kinds, the document's
//! method names (anything else is `unknown`), result code names ([`code_name`]),
//! [`dji_proto::Malformed::kind`]. Series are registered on first use.

use dji_proto::{codes, TopicKind};
use skymesh_runtime::{Counter, Gauge, Stats};

/// The label of a topic.
pub fn topic_label(kind: TopicKind) -> &'static str {
    match kind {
        TopicKind::Services => "services",
        TopicKind::ServicesReply => "services_reply",
        TopicKind::Events => "events",
        TopicKind::EventsReply => "events_reply",
        TopicKind::DrcDown => "drc_down",
        TopicKind::DrcUp => "drc_up",
    }
}

/// The `result` label of a result code.
pub fn code_name(code: u32) -> &'static str {
    match code {
        codes::OK => "ok",
        codes::NO_FLIGHT_AUTHORITY => "no_flight_authority",
        codes::SEQ_OUT_OF_ORDER => "seq_out_of_order",
        codes::STICK_STALE => "stick_stale",
        codes::EMERGENCY_STOP_FAILED => "emergency_stop_failed",
        codes::UNKNOWN_METHOD => "unknown_method",
        codes::MISSING_FIELD => "missing_field",
        codes::WRONG_TYPE => "wrong_type",
        codes::OUT_OF_RANGE => "out_of_range",
        codes::NOT_IN_ENUM => "not_in_enum",
        codes::BAD_ARRAY_SIZE => "bad_array_size",
        codes::BAD_TEXT => "bad_text",
        codes::PAYLOAD_AUTHORITY_REQUIRED => "payload_authority_required",
        codes::REFUSED_BY_ARBITER => "refused_by_arbiter",
        codes::VEHICLE_UNAVAILABLE => "vehicle_unavailable",
        codes::WRONG_STATE => "wrong_state",
        codes::PAYLOAD_UNSUPPORTED => "payload_unsupported",
        codes::UNKNOWN_PAYLOAD => "unknown_payload",
        codes::DRC_STATE => "drc_state",
        codes::DRC_BROKER_UNREACHABLE => "drc_broker_unreachable",
        codes::NO_TASK => "no_task",
        codes::INTERNAL => "internal",
        _ => "other",
    }
}

/// The method name as a static label: one of the document's services, else `unknown`.
pub fn method_label(method: &str) -> &'static str {
    dji_proto::SERVICE_METHODS
        .iter()
        .find(|m| **m == method)
        .copied()
        .unwrap_or("unknown")
}

/// Every series of the services/events side. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Metrics {
    stats: Stats,
    /// `skymesh_dji_broker_connected`: 1 while the cloud broker connection is up.
    pub connected: Gauge,
    /// `skymesh_dji_broker_reconnects_total`: connections made after the first.
    pub reconnects: Counter,
    /// `skymesh_dji_broker_connect_failures_total`: attempts that failed or
    /// connections that broke.
    pub connect_failures: Counter,
    /// `skymesh_dji_outbox_queued`: messages waiting for the broker.
    pub queued: Gauge,
    /// `skymesh_dji_outbox_dropped_total`: messages dropped because the queue was full.
    pub outbox_dropped: Counter,
    /// `skymesh_dji_event_resends_total`: need_reply events sent again.
    pub event_resends: Counter,
    /// `skymesh_dji_flight_task_active`: 1 while a takeoff/flyto task runs.
    pub task_active: Gauge,
    /// `skymesh_dji_poi_active`: 1 while POI mode orbits.
    pub poi_active: Gauge,
    /// `skymesh_dji_panorama_active`: 1 while a panorama capture runs.
    pub panorama_active: Gauge,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        Metrics {
            stats: stats.clone(),
            connected: stats.gauge("skymesh_dji_broker_connected", &[]),
            reconnects: stats.counter("skymesh_dji_broker_reconnects_total", &[]),
            connect_failures: stats.counter("skymesh_dji_broker_connect_failures_total", &[]),
            queued: stats.gauge("skymesh_dji_outbox_queued", &[]),
            outbox_dropped: stats.counter("skymesh_dji_outbox_dropped_total", &[]),
            event_resends: stats.counter("skymesh_dji_event_resends_total", &[]),
            task_active: stats.gauge("skymesh_dji_flight_task_active", &[]),
            poi_active: stats.gauge("skymesh_dji_poi_active", &[]),
            panorama_active: stats.gauge("skymesh_dji_panorama_active", &[]),
        }
    }

    /// `skymesh_dji_messages_total{direction,topic}`: MQTT messages received (all,
    /// before any check) and published.
    pub fn message(&self, direction: &'static str, topic: TopicKind) {
        self.counter(
            "skymesh_dji_messages_total",
            &[("direction", direction), ("topic", topic_label(topic))],
        )
        .inc();
    }

    /// `skymesh_dji_requests_total{method,result}`: services requests answered.
    pub fn request(&self, method: &str, result: u32) {
        self.counter(
            "skymesh_dji_requests_total",
            &[
                ("method", method_label(method)),
                ("result", code_name(result)),
            ],
        )
        .inc();
    }

    /// `skymesh_dji_events_total{method}`: events published (first sends).
    pub fn event(&self, method: &'static str) {
        self.counter("skymesh_dji_events_total", &[("method", method)])
            .inc();
    }

    /// `skymesh_dji_event_replies_total{result}`: events_reply received: `matched` an
    /// awaited event, `unmatched` (unknown or already answered), `invalid`.
    pub fn event_reply(&self, result: &'static str) {
        self.counter("skymesh_dji_event_replies_total", &[("result", result)])
            .inc();
    }

    /// `skymesh_dji_event_reply_timeouts_total{method}`: need_reply events never answered.
    pub fn event_reply_timeout(&self, method: &'static str) {
        self.counter(
            "skymesh_dji_event_reply_timeouts_total",
            &[("method", method)],
        )
        .inc();
    }

    /// `skymesh_dji_malformed_total{kind}`: inbound payloads that are no envelope
    /// (no reply possible): oversized, not_json, not_object, missing, wrong_type,
    /// plus unexpected_topic.
    pub fn malformed(&self, kind: &'static str) {
        self.counter("skymesh_dji_malformed_total", &[("kind", kind)])
            .inc();
    }

    /// `skymesh_dji_rate_limited_total{topic}`: inbound messages over the per-topic rate.
    pub fn rate_limited(&self, topic: TopicKind) {
        self.counter(
            "skymesh_dji_rate_limited_total",
            &[("topic", topic_label(topic))],
        )
        .inc();
    }

    /// `skymesh_dji_publish_errors_total`: messages the MQTT client refused.
    pub fn publish_error(&self) {
        self.counter("skymesh_dji_publish_errors_total", &[]).inc();
    }

    fn counter(&self, name: &str, labels: &[(&str, &str)]) -> Counter {
        self.stats.counter(name, labels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_bounded() {
        assert_eq!(method_label("camera_aim"), "camera_aim");
        assert_eq!(method_label("rm -rf"), "unknown");
        assert_eq!(code_name(codes::NO_TASK), "no_task");
        assert_eq!(code_name(42), "other");
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.request("bogus_method", codes::UNKNOWN_METHOD);
        m.request("camera_aim", 0);
        m.malformed("not_json");
        assert_eq!(
            stats.value(
                "skymesh_dji_requests_total",
                "method=unknown,result=unknown_method"
            ),
            Some(1.0)
        );
        assert_eq!(
            stats.value("skymesh_dji_requests_total", "method=camera_aim,result=ok"),
            Some(1.0)
        );
        assert_eq!(
            stats.value("skymesh_dji_malformed_total", "kind=not_json"),
            Some(1.0)
        );
    }
}
