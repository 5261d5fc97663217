//! Counters, gauges and histograms a service exports through its stats sample.
//!
//! Handles are cheap clones around atomics; taking one with the same name and
//! labels twice returns the same series. Once a second the runtime copies every
//! series into a [`ServiceStats`] sample and the supervisor turns it into Prometheus
//! text with a `service` label added.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use skymesh_ipc_types::service::{HISTOGRAM_BUCKETS, MAX_STAT_ENTRIES};
use skymesh_ipc_types::{FixedStr, ServiceStats, StatEntry, StatKind};

/// A monotonically increasing count.
#[derive(Debug, Clone)]
pub struct Counter(Arc<AtomicU64>);

impl Counter {
    pub fn inc(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
    pub fn add(&self, n: u64) {
        self.0.fetch_add(n, Ordering::Relaxed);
    }
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// A value that goes up and down (stored as f64 bits).
#[derive(Debug, Clone)]
pub struct Gauge(Arc<AtomicU64>);

impl Gauge {
    pub fn set(&self, v: f64) {
        self.0.store(v.to_bits(), Ordering::Relaxed);
    }
    pub fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::Relaxed))
    }
}

/// Inline arrays, not vectors: an observation (every received sample's age) touches
/// one allocation — the lock, the sum, the count and the first buckets share its
/// first cache line — where three allocations cost a receive after an idle period
/// a cache and TLB miss each.
#[derive(Debug)]
#[repr(C)]
struct HistogramState {
    sum: f64,
    count: u64,
    /// How many of `bounds` are used.
    len: usize,
    /// Per-bucket (non-cumulative) counts; index `len` is the +Inf bucket.
    counts: [u64; HISTOGRAM_BUCKETS],
    /// Ascending finite upper bounds, `len` of them.
    bounds: [f64; HISTOGRAM_BUCKETS - 1],
}

impl HistogramState {
    fn bounds(&self) -> &[f64] {
        &self.bounds[..self.len]
    }

    fn counts(&self) -> &[u64] {
        &self.counts[..=self.len]
    }
}

/// A distribution with fixed bucket bounds (at most `HISTOGRAM_BUCKETS - 1` finite ones).
#[derive(Debug, Clone)]
pub struct Histogram(Arc<Mutex<HistogramState>>);

impl Histogram {
    pub fn observe(&self, v: f64) {
        if !v.is_finite() {
            return;
        }
        let mut h = lock(&self.0);
        let idx = h.bounds().iter().position(|b| v <= *b).unwrap_or(h.len);
        h.counts[idx] += 1;
        h.sum += v;
        h.count += 1;
    }

    pub fn count(&self) -> u64 {
        lock(&self.0).count
    }
}

/// Bucket bounds for latencies and sample ages, in seconds (100 µs … 5 s).
pub const LATENCY_BOUNDS_S: [f64; 11] = [
    0.0001, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.5, 5.0,
];

#[derive(Debug, Clone)]
enum Series {
    Counter(Counter),
    Gauge(Gauge),
    Histogram(Histogram),
}

#[derive(Debug)]
struct Entry {
    name: String,
    labels: String,
    series: Series,
}

/// A counter family with one or two bounded labels whose series are registered on
/// first use (a service exports at most `MAX_STAT_ENTRIES` series, so families whose
/// label values are known but mostly unused should not register them all up front).
/// Cheap to clone; clones share the series.
#[derive(Debug, Clone)]
pub struct CounterFamily {
    stats: Stats,
    name: &'static str,
    keys: (&'static str, Option<&'static str>),
    cache: Arc<Mutex<std::collections::HashMap<(&'static str, &'static str), Counter>>>,
}

impl CounterFamily {
    /// `name{first_key=…}`, or `name{first_key=…,second_key=…}` with a second key.
    pub fn new(
        stats: &Stats,
        name: &'static str,
        keys: (&'static str, Option<&'static str>),
    ) -> Self {
        CounterFamily {
            stats: stats.clone(),
            name,
            keys,
            cache: Arc::default(),
        }
    }

    /// The series for these label values (`second` is ignored by one-label families).
    pub fn get(&self, first: &'static str, second: &'static str) -> Counter {
        lock(&self.cache)
            .entry((first, second))
            .or_insert_with(|| match self.keys {
                (k1, None) => self.stats.counter(self.name, &[(k1, first)]),
                (k1, Some(k2)) => self.stats.counter(self.name, &[(k1, first), (k2, second)]),
            })
            .clone()
    }

    /// Increments the series of a one-label family.
    pub fn inc(&self, value: &'static str) {
        self.get(value, "").inc();
    }

    /// Adds `n` to the series of a one-label family.
    pub fn add(&self, value: &'static str, n: u64) {
        self.get(value, "").add(n);
    }
}

/// The registry of one service's series.
#[derive(Debug, Clone, Default)]
pub struct Stats {
    entries: Arc<Mutex<Vec<Entry>>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding a stats lock cannot leave the data inconsistent in a way
    // that matters for metrics; keep exporting.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// `key=value,...` with characters that would break the encoding replaced.
fn encode_labels(labels: &[(&str, &str)]) -> String {
    let clean = |s: &str| s.replace([',', '=', '"', '\\', '\n'], "_");
    labels
        .iter()
        .map(|(k, v)| format!("{}={}", clean(k), clean(v)))
        .collect::<Vec<_>>()
        .join(",")
}

impl Stats {
    pub fn new() -> Self {
        Self::default()
    }

    fn get_or_insert(
        &self,
        name: &str,
        labels: &[(&str, &str)],
        make: impl FnOnce() -> Series,
    ) -> Series {
        let labels = encode_labels(labels);
        let mut entries = lock(&self.entries);
        if let Some(e) = entries
            .iter()
            .find(|e| e.name == name && e.labels == labels)
        {
            return e.series.clone();
        }
        let series = make();
        entries.push(Entry {
            name: name.to_string(),
            labels,
            series: series.clone(),
        });
        series
    }

    /// The counter `name{labels}`; names end in `_total` by convention.
    pub fn counter(&self, name: &str, labels: &[(&str, &str)]) -> Counter {
        match self.get_or_insert(name, labels, || Series::Counter(Counter(Arc::default()))) {
            Series::Counter(c) => c,
            other => panic!("metric {name} registered as {other:?}, requested as counter"),
        }
    }

    pub fn gauge(&self, name: &str, labels: &[(&str, &str)]) -> Gauge {
        match self.get_or_insert(name, labels, || Series::Gauge(Gauge(Arc::default()))) {
            Series::Gauge(g) => g,
            other => panic!("metric {name} registered as {other:?}, requested as gauge"),
        }
    }

    /// A histogram with ascending finite `bounds` (at most `HISTOGRAM_BUCKETS - 1`; more are ignored).
    pub fn histogram(&self, name: &str, labels: &[(&str, &str)], bounds: &[f64]) -> Histogram {
        let make = || {
            let mut state = HistogramState {
                sum: 0.0,
                count: 0,
                len: bounds.len().min(HISTOGRAM_BUCKETS - 1),
                counts: [0; HISTOGRAM_BUCKETS],
                bounds: [f64::INFINITY; HISTOGRAM_BUCKETS - 1],
            };
            state.bounds[..state.len].copy_from_slice(&bounds[..state.len]);
            Series::Histogram(Histogram(Arc::new(Mutex::new(state))))
        };
        match self.get_or_insert(name, labels, make) {
            Series::Histogram(h) => h,
            other => panic!("metric {name} registered as {other:?}, requested as histogram"),
        }
    }

    /// The current value of one series (`labels` as exported: `k=v,k=v`), the same
    /// number [`Stats::snapshot_into`] would export (a histogram's sum); `None` if not
    /// registered. For tests and tools.
    pub fn value(&self, name: &str, labels: &str) -> Option<f64> {
        let entries = lock(&self.entries);
        let e = entries
            .iter()
            .find(|e| e.name == name && e.labels == labels)?;
        Some(match &e.series {
            Series::Counter(c) => c.get() as f64,
            Series::Gauge(g) => g.get(),
            Series::Histogram(h) => lock(&h.0).sum,
        })
    }

    /// Copies every series into `out` (entries beyond its capacity are counted in `dropped`).
    pub fn snapshot_into(&self, out: &mut ServiceStats) {
        let entries = lock(&self.entries);
        out.len = 0;
        out.dropped = entries.len().saturating_sub(MAX_STAT_ENTRIES) as u32;
        for (slot, e) in out.entries.iter_mut().zip(entries.iter()) {
            *slot = StatEntry {
                name: FixedStr::new(&e.name),
                labels: FixedStr::new(&e.labels),
                ..StatEntry::default()
            };
            match &e.series {
                Series::Counter(c) => {
                    slot.kind = StatKind::Counter.to_wire();
                    slot.value = c.get() as f64;
                }
                Series::Gauge(g) => {
                    slot.kind = StatKind::Gauge.to_wire();
                    slot.value = g.get();
                }
                Series::Histogram(h) => {
                    let h = lock(&h.0);
                    slot.kind = StatKind::Histogram.to_wire();
                    slot.value = h.sum;
                    slot.count = h.count;
                    let mut cumulative = 0;
                    for (i, c) in h.counts().iter().enumerate() {
                        cumulative += c;
                        slot.bounds[i] = h.bounds().get(i).copied().unwrap_or(f64::INFINITY);
                        slot.buckets[i] = cumulative;
                    }
                    slot.bucket_count = h.counts().len() as u8;
                }
            }
            out.len += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_reads_one_series() {
        let s = Stats::new();
        s.counter("x_total", &[("topic", "a"), ("dir", "in")])
            .add(3);
        s.gauge("g", &[]).set(1.5);
        assert_eq!(s.value("x_total", "topic=a,dir=in"), Some(3.0));
        assert_eq!(s.value("g", ""), Some(1.5));
        assert_eq!(s.value("x_total", "topic=b,dir=in"), None);
    }

    #[test]
    fn same_name_and_labels_is_the_same_series() {
        let s = Stats::new();
        s.counter("x_total", &[("topic", "a")]).inc();
        s.counter("x_total", &[("topic", "a")]).add(2);
        s.counter("x_total", &[("topic", "b")]).inc();
        let mut out = ServiceStats::default();
        s.snapshot_into(&mut out);
        assert_eq!(out.entries().len(), 2);
        assert_eq!(out.entries()[0].value, 3.0);
        assert_eq!(out.entries()[0].labels.as_str(), "topic=a");
    }

    #[test]
    fn histogram_buckets_are_cumulative_with_inf() {
        let s = Stats::new();
        let h = s.histogram("age_seconds", &[], &[0.1, 1.0]);
        for v in [0.05, 0.5, 0.5, 7.0, f64::NAN] {
            h.observe(v);
        }
        let mut out = ServiceStats::default();
        s.snapshot_into(&mut out);
        let e = &out.entries()[0];
        assert_eq!(e.bucket_count, 3);
        assert_eq!(&e.buckets[..3], &[1, 3, 4]);
        assert!(e.bounds[2].is_infinite());
        assert_eq!(e.count, 4);
    }

    #[test]
    fn label_values_cannot_break_the_encoding() {
        assert_eq!(encode_labels(&[("k", "a,b=c\"")]), "k=a_b_c_");
    }

    #[test]
    fn overflow_is_counted_not_lost_silently() {
        let s = Stats::new();
        for i in 0..MAX_STAT_ENTRIES + 5 {
            s.counter("c_total", &[("i", &i.to_string())]);
        }
        let mut out = ServiceStats::default();
        s.snapshot_into(&mut out);
        assert_eq!(out.len as usize, MAX_STAT_ENTRIES);
        assert_eq!(out.dropped, 5);
    }
}
