//! The broker's metrics (`skymesh_mqtt_*`), exported through the runtime's stats
//! sample.
//!
//! They come from rumqttd's meters (its public monitoring API), pushed by its router
//! every `meters_interval_s`. rumqttd only pushes a router meter for an interval in
//! which something was published, so the connection and subscription gauges are
//! refreshed when there is traffic and keep their last value while the broker is
//! idle. rumqttd has no per-connection events in its public API (its alerts only
//! report cursor jumps and bad publishes, counted in `skymesh_mqtt_alerts_total`);
//! refused logins, ACL refusals, the topic cap and bad packets are counted by the
//! gate (`skymesh_mqtt_refused_total{reason}`, `skymesh_mqtt_topics`, see
//! [`crate::gate`]).

use rumqttd::{Alert, Meter};
use skymesh_runtime::{Counter, CounterFamily, Gauge, Stats};

/// Every series the broker exports.
#[derive(Debug, Clone)]
pub struct Metrics {
    /// `skymesh_mqtt_connections`: client connections (last meter with traffic).
    pub connections: Gauge,
    /// `skymesh_mqtt_subscriptions`: subscriptions (last meter with traffic).
    pub subscriptions: Gauge,
    /// `skymesh_mqtt_publishes_total`: PUBLISH packets the router accepted.
    pub publishes: Counter,
    /// `skymesh_mqtt_failed_publishes_total`: PUBLISH packets the router refused.
    pub failed_publishes: Counter,
    /// `skymesh_mqtt_meters_total`: router meters received (proves the link works).
    pub meters: Counter,
    /// `skymesh_mqtt_alerts_total{kind}`: rumqttd alerts (`cursor_jump`: a slow
    /// subscriber lost messages; `bad_publish`; `other`).
    alerts: CounterFamily,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        Metrics {
            connections: stats.gauge("skymesh_mqtt_connections", &[]),
            subscriptions: stats.gauge("skymesh_mqtt_subscriptions", &[]),
            publishes: stats.counter("skymesh_mqtt_publishes_total", &[]),
            failed_publishes: stats.counter("skymesh_mqtt_failed_publishes_total", &[]),
            meters: stats.counter("skymesh_mqtt_meters_total", &[]),
            alerts: CounterFamily::new(stats, "skymesh_mqtt_alerts_total", ("kind", None)),
        }
    }

    /// Folds one push of rumqttd meters into the series. Router meters carry the
    /// publishes since the previous push (rumqttd resets them after each push).
    pub fn record(&self, meters: &[Meter]) {
        for m in meters {
            if let Meter::Router(_, r) = m {
                self.meters.inc();
                self.connections.set(r.total_connections as f64);
                self.subscriptions.set(r.total_subscriptions as f64);
                self.publishes.add(r.total_publishes as u64);
                self.failed_publishes.add(r.failed_publishes as u64);
            }
        }
    }

    /// Counts and logs one push of rumqttd alerts.
    pub fn record_alerts(&self, alerts: &[Alert]) {
        for a in alerts {
            let name = a.kind.name();
            let kind = match name.as_str() {
                "cursor_jump" => "cursor_jump",
                "bad_publish" => "bad_publish",
                _ => "other",
            };
            self.alerts.inc(kind);
            tracing::warn!(client = %a.client_id, kind = %name, "MQTT broker alert");
        }
    }
}
