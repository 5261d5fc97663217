//! Service heartbeats and statistics, read by the supervisor.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

wire_enum! {
    /// What a service says about itself in its heartbeat.
    pub enum ServiceState: u8 {
        Starting = 0 => "starting",
        Running = 1 => "running",
        /// Running but an external dependency is missing (e.g. autopilot link down).
        Degraded = 2 => "degraded",
        Stopping = 3 => "stopping",
    }
}

/// Heartbeat, published every `period_ms` on `skymesh/service/{name}/health`.
///
/// The supervisor kills and restarts a service whose heartbeats stop for N periods,
/// which catches hangs (deadlock, SIGSTOP) that a live pid does not reveal.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ServiceHealth.v1")]
#[repr(C)]
pub struct ServiceHealth {
    pub header: SampleHeader,
    /// Instance name, as given by the supervisor (e.g. `vehicle-sim-2`).
    pub name: FixedStr<32>,
    pub pid: u32,
    /// [`ServiceState`] as stored on the wire.
    pub state: u8,
    pub reserved: [u8; 3],
    pub uptime_ms: u64,
    /// The period the service promises to publish at.
    pub period_ms: u32,
    pub reserved2: u32,
}
crate::assert_layout!(ServiceHealth, size = 80, align = 8);

impl ServiceHealth {
    pub fn service_state(&self) -> Option<ServiceState> {
        ServiceState::try_from(self.state).ok()
    }
}

wire_enum! {
    /// Prometheus metric type of a [`StatEntry`].
    pub enum StatKind: u8 {
        Counter = 0 => "counter",
        Gauge = 1 => "gauge",
        Histogram = 2 => "histogram",
    }
}

/// Number of histogram buckets a [`StatEntry`] carries (the last is usually +Inf).
pub const HISTOGRAM_BUCKETS: usize = 12;
/// Number of entries one [`ServiceStats`] sample carries.
pub const MAX_STAT_ENTRIES: usize = 384;

/// One metric series: a name, its labels and its value.
///
/// `labels` is `key=value` pairs separated by `,`; keys are Prometheus label names
/// and values never contain `,` or `=` (the runtime enforces it). The supervisor adds
/// `service="<name>"`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct StatEntry {
    /// [`StatKind`] as stored on the wire.
    pub kind: u8,
    /// Number of valid buckets for a histogram.
    pub bucket_count: u8,
    pub reserved: [u8; 6],
    pub name: FixedStr<56>,
    pub labels: FixedStr<72>,
    /// Counter or gauge value; the sum of observations for a histogram.
    pub value: f64,
    /// Number of observations (histogram).
    pub count: u64,
    /// Upper bounds of the buckets (histogram), ascending; +Inf allowed.
    pub bounds: [f64; HISTOGRAM_BUCKETS],
    /// Cumulative count of observations ≤ each bound (histogram).
    pub buckets: [u64; HISTOGRAM_BUCKETS],
}
crate::assert_layout!(StatEntry, size = 344, align = 8);

impl Default for StatEntry {
    fn default() -> Self {
        Self {
            kind: 0,
            bucket_count: 0,
            reserved: [0; 6],
            name: FixedStr::EMPTY,
            labels: FixedStr::EMPTY,
            value: 0.0,
            count: 0,
            bounds: [0.0; HISTOGRAM_BUCKETS],
            buckets: [0; HISTOGRAM_BUCKETS],
        }
    }
}

impl StatEntry {
    pub fn stat_kind(&self) -> Option<StatKind> {
        StatKind::try_from(self.kind).ok()
    }

    /// The label pairs, skipping malformed ones.
    pub fn label_pairs(&self) -> impl Iterator<Item = (&str, &str)> {
        self.labels
            .as_str()
            .split(',')
            .filter_map(|kv| kv.split_once('='))
            .filter(|(k, _)| !k.is_empty())
    }
}

/// Everything a service wants exported, published once a second on
/// `skymesh/service/{name}/stats`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ServiceStats.v3")]
#[repr(C)]
pub struct ServiceStats {
    pub header: SampleHeader,
    pub name: FixedStr<32>,
    /// Valid entries in `entries`.
    pub len: u32,
    /// Series the service has but could not fit in this sample.
    pub dropped: u32,
    pub entries: [StatEntry; MAX_STAT_ENTRIES],
}
crate::assert_layout!(
    ServiceStats,
    size = 24 + 32 + 8 + 344 * MAX_STAT_ENTRIES,
    align = 8
);

impl Default for ServiceStats {
    fn default() -> Self {
        Self {
            header: SampleHeader::default(),
            name: FixedStr::EMPTY,
            len: 0,
            dropped: 0,
            entries: [StatEntry::default(); MAX_STAT_ENTRIES],
        }
    }
}

impl ServiceStats {
    /// The valid entries (a corrupt `len` is clamped).
    pub fn entries(&self) -> &[StatEntry] {
        let n = (self.len as usize).min(MAX_STAT_ENTRIES);
        &self.entries[..n]
    }
}

crate::impl_sample!(ServiceHealth, ServiceStats);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_parse_and_skip_garbage() {
        let e = StatEntry {
            labels: FixedStr::new("topic=a/b,,=x,dir=in"),
            ..Default::default()
        };
        let pairs: Vec<_> = e.label_pairs().collect();
        assert_eq!(pairs, vec![("topic", "a/b"), ("dir", "in")]);
    }

    #[test]
    fn corrupt_len_is_clamped() {
        let s = ServiceStats {
            len: 10_000,
            ..Default::default()
        };
        assert_eq!(s.entries().len(), MAX_STAT_ENTRIES);
    }
}
