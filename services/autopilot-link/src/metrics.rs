//! The metrics of autopilot-link, exported through the runtime's stats sample.
//!
//! Label sets are bounded: message names outside [`RECEIVED`] / [`SENT`] count as
//! `other`, and command series carry only the `as_str()` names of the ipc-types
//! enums. Labelled series are registered on first use, so an idle link does not
//! spend the stats sample's fixed number of entries on series that stay zero.

use std::time::Duration;

use skymesh_ipc_types::{AckResult, CommandKind};
use skymesh_runtime::stats::LATENCY_BOUNDS_S;
use skymesh_runtime::{Counter, CounterFamily, Gauge, Histogram, Stats};

/// Messages from the autopilot that autopilot-link handles (metric label `msg`).
pub const RECEIVED: &[&str] = &[
    "HEARTBEAT",
    "ATTITUDE",
    "ATTITUDE_QUATERNION",
    "GLOBAL_POSITION_INT",
    "LOCAL_POSITION_NED",
    "SYS_STATUS",
    "BATTERY_STATUS",
    "GPS_RAW_INT",
    "EKF_STATUS_REPORT",
    "HOME_POSITION",
    "STATUSTEXT",
    "COMMAND_ACK",
    "GIMBAL_DEVICE_ATTITUDE_STATUS",
    "GOPRO_HEARTBEAT",
    "GOPRO_SET_RESPONSE",
];

/// Messages autopilot-link sends (metric label `msg`).
pub const SENT: &[&str] = &[
    "HEARTBEAT",
    "COMMAND_LONG",
    "COMMAND_INT",
    "SET_POSITION_TARGET_GLOBAL_INT",
    "SET_POSITION_TARGET_LOCAL_NED",
    "REQUEST_DATA_STREAM",
    "GOPRO_SET_REQUEST",
];

fn label(known: &[&'static str], name: &str) -> &'static str {
    known
        .iter()
        .copied()
        .find(|k| *k == name)
        .unwrap_or("other")
}

/// Every series autopilot-link exports. Cheap to clone; shared with the link threads.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_autopilot_link_up`: 1 while autopilot heartbeats arrive.
    pub link_up: Gauge,
    /// `skymesh_autopilot_heartbeat_age_seconds`: since the last autopilot heartbeat
    /// (since start while none was ever seen).
    pub heartbeat_age: Gauge,
    /// `skymesh_autopilot_mavlink_parse_errors_total`.
    pub parse_errors: Counter,
    /// `skymesh_autopilot_reconnects_total`: connections established after the first.
    pub reconnects: Counter,
    /// `skymesh_autopilot_command_latency_seconds`: command sample → COMMAND_ACK.
    pub command_latency: Histogram,
    /// `skymesh_autopilot_bus_errors_total`: bus samples not taken or not published
    /// (the service carries on).
    pub bus_errors: Counter,
    received: CounterFamily,
    sent: CounterFamily,
    commands: CounterFamily,
    gopro_responses: CounterFamily,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        Metrics {
            link_up: stats.gauge("skymesh_autopilot_link_up", &[]),
            heartbeat_age: stats.gauge("skymesh_autopilot_heartbeat_age_seconds", &[]),
            parse_errors: stats.counter("skymesh_autopilot_mavlink_parse_errors_total", &[]),
            reconnects: stats.counter("skymesh_autopilot_reconnects_total", &[]),
            bus_errors: stats.counter("skymesh_autopilot_bus_errors_total", &[]),
            command_latency: stats.histogram(
                "skymesh_autopilot_command_latency_seconds",
                &[],
                &LATENCY_BOUNDS_S,
            ),
            received: CounterFamily::new(
                stats,
                "skymesh_autopilot_mavlink_messages_received_total",
                ("msg", None),
            ),
            sent: CounterFamily::new(
                stats,
                "skymesh_autopilot_mavlink_messages_sent_total",
                ("msg", None),
            ),
            commands: CounterFamily::new(
                stats,
                "skymesh_autopilot_commands_total",
                ("kind", Some("result")),
            ),
            gopro_responses: CounterFamily::new(
                stats,
                "skymesh_autopilot_gopro_responses_total",
                ("status", None),
            ),
        }
    }

    /// Counts one message from the autopilot by its MAVLink name.
    pub fn received(&self, message_name: &str) {
        self.received.get(label(RECEIVED, message_name), "").inc();
    }

    /// Counts one message written to the link by its MAVLink name.
    pub fn sent(&self, message_name: &str) {
        self.sent.get(label(SENT, message_name), "").inc();
    }

    /// Counts one published CommandAck.
    pub fn command(&self, kind: u8, result: AckResult) {
        let kind = CommandKind::try_from(kind).map_or("unknown", CommandKind::as_str);
        self.commands.get(kind, result.as_str()).inc();
    }

    /// Counts one GOPRO_SET_RESPONSE: `success`/`failed` when it answered one of our
    /// requests, `unmatched` when none was waiting (a ground station's, or too late).
    pub fn gopro_response(&self, matched: bool, success: bool) {
        let status = match (matched, success) {
            (false, _) => "unmatched",
            (true, true) => "success",
            (true, false) => "failed",
        };
        self.gopro_responses.get(status, "").inc();
    }

    pub fn observe_latency(&self, latency: Duration) {
        self.command_latency.observe(latency.as_secs_f64());
    }
}

/// The flight log's series (`[tlog]`), registered only when it is configured.
#[derive(Debug, Clone)]
pub struct TlogMetrics {
    /// `skymesh_autopilot_tlog_recording`: 1 while a log is being written.
    pub recording: Gauge,
    /// `skymesh_autopilot_tlog_frames_total`: frames written to logs.
    pub frames: Counter,
    /// `skymesh_autopilot_tlog_bytes_total`: bytes written to logs (stamps included).
    pub bytes: Counter,
    /// `skymesh_autopilot_tlog_dropped_frames_total`: frames not recorded because
    /// the writer's queue was full (the link never waits for the disk).
    pub dropped: Counter,
    /// `skymesh_autopilot_tlog_errors_total{reason="io"}`: I/O errors (each ends
    /// the recording it hit).
    pub errors: Counter,
    /// `skymesh_autopilot_tlog_errors_total{reason="no_room"}`: recordings not
    /// started or ended because the limits could not hold.
    pub no_room: Counter,
    /// `skymesh_autopilot_tlog_files_deleted_total`: old logs deleted by retention.
    pub deleted: Counter,
}

impl TlogMetrics {
    pub fn new(stats: &Stats) -> Self {
        const ERRORS: &str = "skymesh_autopilot_tlog_errors_total";
        TlogMetrics {
            recording: stats.gauge("skymesh_autopilot_tlog_recording", &[]),
            frames: stats.counter("skymesh_autopilot_tlog_frames_total", &[]),
            bytes: stats.counter("skymesh_autopilot_tlog_bytes_total", &[]),
            dropped: stats.counter("skymesh_autopilot_tlog_dropped_frames_total", &[]),
            errors: stats.counter(ERRORS, &[("reason", "io")]),
            no_room: stats.counter(ERRORS, &[("reason", "no_room")]),
            deleted: stats.counter("skymesh_autopilot_tlog_files_deleted_total", &[]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn labels_are_bounded_and_series_registered_on_use() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.received("ATTITUDE");
        m.received("ATTITUDE");
        m.received("VIBRATION");
        m.received("SCALED_IMU2");
        m.sent("COMMAND_LONG");
        m.command(CommandKind::Arm.to_wire(), AckResult::Accepted);
        m.command(250, AckResult::Refused);
        m.received("GOPRO_HEARTBEAT");
        m.sent("GOPRO_SET_REQUEST");
        m.gopro_response(true, false);
        m.gopro_response(false, true);
        m.gopro_response(false, false);
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        let rx = "skymesh_autopilot_mavlink_messages_received_total";
        assert_eq!(find(rx, "msg=ATTITUDE"), Some(2.0));
        assert_eq!(find(rx, "msg=other"), Some(2.0));
        assert_eq!(find(rx, "msg=HEARTBEAT"), None, "registered on first use");
        assert_eq!(
            find(
                "skymesh_autopilot_mavlink_messages_sent_total",
                "msg=COMMAND_LONG"
            ),
            Some(1.0)
        );
        let cmds = "skymesh_autopilot_commands_total";
        assert_eq!(find(cmds, "kind=arm,result=accepted"), Some(1.0));
        assert_eq!(find(cmds, "kind=unknown,result=refused"), Some(1.0));
        assert_eq!(find("skymesh_autopilot_link_up", ""), Some(0.0));
        assert_eq!(find(rx, "msg=GOPRO_HEARTBEAT"), Some(1.0));
        assert_eq!(
            find(
                "skymesh_autopilot_mavlink_messages_sent_total",
                "msg=GOPRO_SET_REQUEST"
            ),
            Some(1.0)
        );
        let gopro = "skymesh_autopilot_gopro_responses_total";
        assert_eq!(find(gopro, "status=failed"), Some(1.0));
        assert_eq!(find(gopro, "status=unmatched"), Some(2.0));
        assert_eq!(find(gopro, "status=success"), None);
    }
}
