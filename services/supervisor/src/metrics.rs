//! `/metrics`: a `prometheus` [`Collector`] that builds metric families from the
//! supervisor's view of the mesh and from every service's latest stats sample, encoded
//! by the crate's `TextEncoder`.
//!
//! Stats entries come from other processes, so they are checked: a name or label that
//! is not a Prometheus identifier, a reserved label (`service`, `le`, `quantile`), a
//! name used with two types, a duplicate series or a malformed histogram is dropped,
//! counted in `skymesh_supervisor_invalid_stats_entries` and logged once. Counters
//! without the `_total` suffix get it (as Prometheus client libraries do); gauges and
//! histograms ending in `_total` are dropped, so the output passes `promtool check metrics`.

use std::collections::{BTreeMap, HashSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use prometheus::core::{Collector, Desc};
use prometheus::proto::{self, LabelPair, Metric, MetricFamily, MetricType};
use prometheus::{Encoder, Registry, TextEncoder};
use skymesh_ipc_types::{StatEntry, StatKind};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::ipc;

use crate::procfs;
use crate::state::{Mesh, Phase, ServiceEntry};

/// Families the supervisor itself exports; a service may not report these names.
const OWN: [(&str, MetricType, &str); 15] = [
    ("skymesh_service_up", MetricType::GAUGE, "1 if the service is running (or degraded), else 0."),
    ("skymesh_service_state", MetricType::GAUGE, "1 for the service's current supervisor state, 0 for the others."),
    ("skymesh_service_restarts_total", MetricType::COUNTER, "Times the service was restarted (by the supervisor, or seen with a new pid in monitor-only mode)."),
    ("skymesh_service_uptime_seconds", MetricType::GAUGE, "Seconds since the service's current process started; 0 when not running."),
    ("skymesh_service_last_exit_code", MetricType::GAUGE, "Exit code of the service's previous process (128 + signal number when killed)."),
    ("skymesh_service_heartbeat_age_seconds", MetricType::GAUGE, "Seconds since the service's last heartbeat was published."),
    ("skymesh_service_cpu_seconds_total", MetricType::COUNTER, "User plus system CPU time of the service's current process."),
    ("skymesh_service_resident_memory_bytes", MetricType::GAUGE, "Resident memory of the service's current process."),
    ("skymesh_service_realtime_priority", MetricType::GAUGE, "SCHED_FIFO/SCHED_RR priority of the service's main thread as the kernel reports it (0: normal scheduling)."),
    ("skymesh_service_stats_dropped_series", MetricType::GAUGE, "Series the service has but could not fit into its stats sample."),
    ("skymesh_supervisor_stale_nodes_cleaned_total", MetricType::COUNTER, "Dead iceoryx2 nodes whose stale resources the supervisor removed."),
    ("skymesh_supervisor_adopted_total", MetricType::COUNTER, "Running processes of the service this supervisor adopted (started by an earlier supervisor that died) instead of starting new ones."),
    ("skymesh_supervisor_invalid_stats_entries", MetricType::GAUGE, "Stats entries dropped at the last scrape because their name, labels or type were unusable."),
    ("skymesh_shm_free_bytes", MetricType::GAUGE, "Bytes still free in /dev/shm, where every iceoryx2 segment lives (a full /dev/shm fails services or ends them with SIGBUS)."),
    ("skymesh_shm_size_bytes", MetricType::GAUGE, "Size of the /dev/shm file system."),
];

/// HELP text of the series the runtime reports for every service.
const KNOWN_HELP: [(&str, &str); 4] = [
    (
        "skymesh_topic_samples_published_total",
        "Samples the service published on the topic.",
    ),
    (
        "skymesh_topic_samples_received_total",
        "Samples the service received from the topic.",
    ),
    (
        "skymesh_topic_samples_lost_total",
        "Samples the service missed on the topic (gaps in sequence numbers).",
    ),
    (
        "skymesh_topic_sample_age_seconds",
        "Age of received samples at reception (publish to receive latency).",
    ),
];

const GENERIC_HELP: &str = "Reported by the service in its stats sample.";

/// Builds the mesh's metric families on every scrape.
#[derive(Debug)]
pub struct MeshCollector {
    mesh: Arc<Mesh>,
    /// `service/metric` pairs already warned about, so a bad entry is logged once.
    warned: Mutex<HashSet<String>>,
    /// `/dev/shm` was below [`ipc::SHM_LOW_FREE_BYTES`] at the last scrape (warned once per dip).
    shm_low: AtomicBool,
}

/// `skymesh_build_info{version, git} 1`.
pub const BUILD_INFO: &str = "skymesh_build_info";

/// A [`Registry`] holding the mesh's collector and `skymesh_build_info`.
pub fn registry(mesh: Arc<Mesh>) -> prometheus::Result<Registry> {
    let registry = Registry::new();
    registry.register(Box::new(MeshCollector::new(mesh)))?;
    let build_info = prometheus::IntGaugeVec::new(
        prometheus::Opts::new(
            BUILD_INFO,
            "Always 1; labels: the skymesh version and the git commit it was built from.",
        ),
        &["version", "git"],
    )?;
    build_info
        .with_label_values(&[crate::VERSION, crate::GIT])
        .set(1);
    registry.register(Box::new(build_info))?;
    Ok(registry)
}

/// The Prometheus text exposition of `registry`.
pub fn render(registry: &Registry) -> prometheus::Result<String> {
    let mut out = Vec::new();
    TextEncoder::new().encode(&registry.gather(), &mut out)?;
    String::from_utf8(out).map_err(|e| prometheus::Error::Msg(e.to_string()))
}

/// Prometheus metric name: `[a-zA-Z_:][a-zA-Z0-9_:]*`.
pub fn is_metric_name(s: &str) -> bool {
    let mut b = s.bytes();
    matches!(b.next(), Some(c) if c.is_ascii_alphabetic() || c == b'_' || c == b':')
        && b.all(|c| c.is_ascii_alphanumeric() || c == b'_' || c == b':')
}

/// Prometheus label name: `[a-zA-Z_][a-zA-Z0-9_]*`, not starting with `__` (reserved).
pub fn is_label_name(s: &str) -> bool {
    let mut b = s.bytes();
    matches!(b.next(), Some(c) if c.is_ascii_alphabetic() || c == b'_')
        && b.all(|c| c.is_ascii_alphanumeric() || c == b'_')
        && !s.starts_with("__")
}

fn label(name: &str, value: &str) -> LabelPair {
    let mut l = LabelPair::default();
    l.set_name(name.to_string());
    l.set_value(value.to_string());
    l
}

fn gauge_metric(labels: Vec<LabelPair>, v: f64) -> Metric {
    let mut g = proto::Gauge::default();
    g.set_value(v);
    let mut m = Metric::from_label(labels);
    m.set_gauge(g);
    m
}

fn counter_metric(labels: Vec<LabelPair>, v: f64) -> Metric {
    let mut c = proto::Counter::default();
    c.set_value(v);
    let mut m = Metric::from_label(labels);
    m.set_counter(c);
    m
}

#[derive(Debug)]
struct Family {
    help: String,
    kind: MetricType,
    metrics: Vec<Metric>,
    /// Label sets already present, to refuse duplicate series.
    series: HashSet<Vec<(String, String)>>,
}

/// Families being assembled for one scrape, keyed by name (so a name reported by
/// several services becomes one family with one HELP and TYPE).
#[derive(Debug, Default)]
struct Families {
    by_name: BTreeMap<String, Family>,
}

impl Families {
    /// Adds `metric` to family `name`; refuses a type conflict or a duplicate series.
    fn push(
        &mut self,
        name: &str,
        kind: MetricType,
        help: &str,
        metric: Metric,
    ) -> Result<(), String> {
        let key: Vec<(String, String)> = metric
            .get_label()
            .iter()
            .map(|l| (l.name().to_string(), l.value().to_string()))
            .collect();
        let fam = self
            .by_name
            .entry(name.to_string())
            .or_insert_with(|| Family {
                help: help.to_string(),
                kind,
                metrics: Vec::new(),
                series: HashSet::new(),
            });
        if fam.kind != kind {
            return Err(format!("already a {:?}, reported as {:?}", fam.kind, kind));
        }
        if !fam.series.insert(key) {
            return Err("duplicate series".to_string());
        }
        fam.metrics.push(metric);
        Ok(())
    }

    fn own(&mut self, name: &str, metric: Metric) {
        let (kind, help) = OWN
            .iter()
            .find(|(n, _, _)| *n == name)
            .map(|(_, k, h)| (*k, *h))
            .unwrap_or((MetricType::GAUGE, GENERIC_HELP));
        // The supervisor's own series are built to be unique and well typed.
        let _ = self.push(name, kind, help, metric);
    }

    fn into_vec(self) -> Vec<MetricFamily> {
        self.by_name
            .into_iter()
            .map(|(name, f)| {
                let mut mf = MetricFamily::default();
                mf.set_name(name);
                mf.set_help(f.help);
                mf.set_field_type(f.kind);
                mf.set_metric(f.metrics);
                mf
            })
            .collect()
    }
}

impl MeshCollector {
    pub fn new(mesh: Arc<Mesh>) -> Self {
        MeshCollector {
            mesh,
            warned: Mutex::new(HashSet::new()),
            shm_low: AtomicBool::new(false),
        }
    }

    /// `skymesh_shm_free_bytes` and `skymesh_shm_size_bytes` (one `statvfs`), and a
    /// warning when the free room first drops below [`ipc::SHM_LOW_FREE_BYTES`].
    fn shm_series(&self, fams: &mut Families) {
        let Ok(space) = ipc::shm_space(std::path::Path::new(ipc::SHM_DIR)) else {
            return;
        };
        fams.own(
            "skymesh_shm_free_bytes",
            gauge_metric(Vec::new(), space.free as f64),
        );
        fams.own(
            "skymesh_shm_size_bytes",
            gauge_metric(Vec::new(), space.size as f64),
        );
        let low = space.free < ipc::SHM_LOW_FREE_BYTES;
        if low && !self.shm_low.swap(true, Ordering::Relaxed) {
            tracing::warn!(
                dir = ipc::SHM_DIR,
                free_bytes = space.free,
                size_bytes = space.size,
                "shared memory is low: services refuse to start below {} bytes free and may die of SIGBUS when a segment cannot grow; size /dev/shm up",
                ipc::SHM_MIN_FREE_BYTES
            );
        } else if !low {
            self.shm_low.store(false, Ordering::Relaxed);
        }
    }

    fn service_series(&self, fams: &mut Families, e: &ServiceEntry, now_ns: u64) {
        let svc = || vec![label("service", &e.name)];
        fams.own(
            "skymesh_service_up",
            gauge_metric(svc(), f64::from(u8::from(e.phase.is_up()))),
        );
        let phases: &[Phase] = if self.mesh.monitor_only {
            &[
                Phase::Starting,
                Phase::Running,
                Phase::Degraded,
                Phase::Stopping,
                Phase::Stale,
                Phase::Down,
            ]
        } else {
            &Phase::ALL[..8]
        };
        for p in phases {
            let labels = vec![label("service", &e.name), label("state", p.as_str())];
            fams.own(
                "skymesh_service_state",
                gauge_metric(labels, f64::from(u8::from(*p == e.phase))),
            );
        }
        fams.own(
            "skymesh_service_restarts_total",
            counter_metric(svc(), e.restarts as f64),
        );
        if !self.mesh.monitor_only {
            fams.own(
                "skymesh_supervisor_adopted_total",
                counter_metric(svc(), e.adopted_total as f64),
            );
        }
        fams.own(
            "skymesh_service_uptime_seconds",
            gauge_metric(svc(), e.uptime_s(now_ns)),
        );
        if let Some(code) = e.last_exit_code {
            fams.own(
                "skymesh_service_last_exit_code",
                gauge_metric(svc(), f64::from(code)),
            );
        }
        if let Some(age) = e.heartbeat_age_s(now_ns) {
            fams.own(
                "skymesh_service_heartbeat_age_seconds",
                gauge_metric(svc(), age),
            );
        }
        if let Some(u) = e.pid.and_then(procfs::usage) {
            fams.own(
                "skymesh_service_cpu_seconds_total",
                counter_metric(svc(), u.cpu_seconds),
            );
            fams.own(
                "skymesh_service_resident_memory_bytes",
                gauge_metric(svc(), u.resident_bytes as f64),
            );
            fams.own(
                "skymesh_service_realtime_priority",
                gauge_metric(svc(), f64::from(u.realtime_priority)),
            );
        }
        if let Some(stats) = &e.stats {
            fams.own(
                "skymesh_service_stats_dropped_series",
                gauge_metric(svc(), f64::from(stats.dropped)),
            );
        }
    }

    /// Adds one stats entry of `service`; `Err` says why it was dropped.
    fn stat_entry(
        fams: &mut Families,
        service: &str,
        entry: &StatEntry,
    ) -> Result<(), (String, String)> {
        let raw_name = entry
            .name
            .try_as_str()
            .unwrap_or("<invalid utf-8>")
            .to_string();
        let fail = |why: &str| Err((raw_name.clone(), why.to_string()));
        if entry.name.try_as_str().is_none() || !is_metric_name(&raw_name) {
            return fail("not a Prometheus metric name");
        }
        let Some(kind) = entry.stat_kind() else {
            return fail("unknown metric kind");
        };
        let name = match kind {
            StatKind::Counter if !raw_name.ends_with("_total") => format!("{raw_name}_total"),
            StatKind::Gauge | StatKind::Histogram if raw_name.ends_with("_total") => {
                return fail("only counters may end in _total")
            }
            _ => raw_name.clone(),
        };
        if name == BUILD_INFO
            || OWN.iter().any(|(n, _, _)| *n == name)
            || name.starts_with(crate::vehicles::PREFIX)
        {
            return fail("name reserved for the supervisor's own metrics");
        }
        if entry.labels.try_as_str().is_none() {
            return fail("labels are not UTF-8");
        }
        let mut labels = vec![label("service", service)];
        for (k, v) in entry.label_pairs() {
            if !is_label_name(k) || matches!(k, "service" | "le" | "quantile") {
                return fail(&format!("label `{k}` is invalid or reserved"));
            }
            if labels.iter().any(|l| l.name() == k) {
                return fail(&format!("label `{k}` given twice"));
            }
            labels.push(label(k, v));
        }
        let help = KNOWN_HELP
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(GENERIC_HELP, |(_, h)| h);
        let (metric, mtype) = match kind {
            StatKind::Counter => (counter_metric(labels, entry.value), MetricType::COUNTER),
            StatKind::Gauge => (gauge_metric(labels, entry.value), MetricType::GAUGE),
            StatKind::Histogram => {
                let n = usize::from(entry.bucket_count).min(entry.bounds.len());
                let mut buckets = Vec::with_capacity(n);
                let (mut prev_bound, mut prev_count) = (f64::NEG_INFINITY, 0u64);
                for (&bound, &count) in entry.bounds[..n].iter().zip(&entry.buckets[..n]) {
                    if bound.is_nan()
                        || bound <= prev_bound
                        || count < prev_count
                        || count > entry.count
                    {
                        return fail("histogram buckets are not ascending and cumulative");
                    }
                    (prev_bound, prev_count) = (bound, count);
                    if bound.is_infinite() {
                        continue; // the encoder writes +Inf from the sample count
                    }
                    let mut b = proto::Bucket::default();
                    b.set_upper_bound(bound);
                    b.set_cumulative_count(count);
                    buckets.push(b);
                }
                let mut h = proto::Histogram::default();
                h.set_bucket(buckets);
                h.set_sample_count(entry.count);
                h.set_sample_sum(entry.value);
                let mut m = Metric::from_label(labels);
                m.set_histogram(h);
                (m, MetricType::HISTOGRAM)
            }
        };
        fams.push(&name, mtype, help, metric)
            .map_err(|why| (name.clone(), why))
    }
}

impl Collector for MeshCollector {
    /// The families depend on what the services report, so none are declared up front.
    fn desc(&self) -> Vec<&Desc> {
        Vec::new()
    }

    fn collect(&self) -> Vec<MetricFamily> {
        let now_ns = monotonic_ns();
        let mut fams = Families::default();
        let mut dropped: Vec<(String, String, String)> = Vec::new();
        self.mesh.with_all(|entries| {
            for e in entries {
                self.service_series(&mut fams, e, now_ns);
            }
            for e in entries {
                let Some(stats) = &e.stats else { continue };
                for entry in stats.entries() {
                    if let Err((metric, why)) = Self::stat_entry(&mut fams, &e.name, entry) {
                        dropped.push((e.name.clone(), metric, why));
                    }
                }
            }
        });
        fams.own(
            "skymesh_supervisor_stale_nodes_cleaned_total",
            counter_metric(
                Vec::new(),
                self.mesh.stale_nodes_cleaned.load(Ordering::Relaxed) as f64,
            ),
        );
        fams.own(
            "skymesh_supervisor_invalid_stats_entries",
            gauge_metric(Vec::new(), dropped.len() as f64),
        );
        self.shm_series(&mut fams);
        if !dropped.is_empty() {
            let mut warned = self.warned.lock().unwrap_or_else(|p| p.into_inner());
            for (service, metric, why) in dropped {
                if warned.insert(format!("{service}/{metric}")) {
                    tracing::warn!(service = %service, metric = %metric, reason = %why, "stats entry not exported");
                }
            }
        }
        fams.into_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{FixedStr, ServiceStats};

    fn entry(kind: StatKind, name: &str, labels: &str, value: f64) -> StatEntry {
        StatEntry {
            kind: kind.to_wire(),
            name: FixedStr::new(name),
            labels: FixedStr::new(labels),
            value,
            ..Default::default()
        }
    }

    fn stats(entries: &[StatEntry]) -> Box<ServiceStats> {
        let mut s = Box::<ServiceStats>::default();
        s.entries[..entries.len()].copy_from_slice(entries);
        s.len = entries.len() as u32;
        s
    }

    fn mesh_with_stats() -> Arc<Mesh> {
        let mesh = Arc::new(Mesh::new(&[("a".into(), true), ("b".into(), false)], false));
        let mut hist = entry(
            StatKind::Histogram,
            "skymesh_topic_sample_age_seconds",
            "topic=x",
            0.5,
        );
        hist.bucket_count = 3;
        hist.bounds[..3].copy_from_slice(&[0.1, 1.0, f64::INFINITY]);
        hist.buckets[..3].copy_from_slice(&[1, 3, 4]);
        hist.count = 4;
        let common = [
            entry(
                StatKind::Counter,
                "skymesh_topic_samples_published_total",
                "topic=skymesh/vehicle/1/state",
                10.0,
            ),
            entry(
                StatKind::Counter,
                "skymesh_topic_samples_received_total",
                "topic=x",
                3.0,
            ),
            hist,
        ];
        let a_only = [
            entry(StatKind::Gauge, "skymesh_link_up", "", 1.0),
            entry(StatKind::Counter, "frames", "dir=in", 2.0), // gets _total
            entry(StatKind::Gauge, "bad-name", "", 1.0),       // invalid name
            entry(StatKind::Gauge, "x_gauge", "service=evil", 1.0), // reserved label
            entry(StatKind::Gauge, "y_gauge", "9bad=1", 1.0),  // invalid label
            entry(StatKind::Gauge, "skymesh_service_up", "", 1.0), // supervisor's name
            entry(StatKind::Gauge, "skymesh_vehicle_armed", "", 1.0), // supervisor's prefix
            entry(StatKind::Gauge, "g_total", "", 1.0),        // gauge named like a counter
        ];
        let b_only = [entry(StatKind::Gauge, "frames_total", "dir=in", 1.0)]; // type conflict with a's counter
        mesh.update(0, |e| {
            e.phase = Phase::Running;
            e.pid = Some(std::process::id());
            e.started_at = Some(std::time::Instant::now());
            let mut all = common.to_vec();
            all.extend_from_slice(&a_only);
            e.stats = Some(stats(&all));
        });
        mesh.update(1, |e| {
            e.phase = Phase::Backoff;
            e.restarts = 2;
            e.last_exit_code = Some(1);
            let mut all = common.to_vec();
            all.extend_from_slice(&b_only);
            e.stats = Some(stats(&all));
        });
        mesh
    }

    /// Minimal structural check of the text format: every sample line belongs to a
    /// family announced by exactly one HELP and one TYPE line, names and label names
    /// are identifiers, values parse.
    pub(crate) fn check_exposition(text: &str) -> BTreeMap<String, String> {
        let mut types = BTreeMap::new();
        let mut helps = HashSet::new();
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("# HELP ") {
                let name = rest.split(' ').next().unwrap();
                assert!(helps.insert(name.to_string()), "HELP twice for {name}");
            } else if let Some(rest) = line.strip_prefix("# TYPE ") {
                let (name, kind) = rest.split_once(' ').unwrap();
                assert!(helps.contains(name), "TYPE without HELP for {name}");
                assert!(
                    types.insert(name.to_string(), kind.to_string()).is_none(),
                    "TYPE twice for {name}"
                );
            } else if !line.is_empty() {
                let (series, value) = line.rsplit_once(' ').unwrap();
                assert!(
                    value.parse::<f64>().is_ok() || value == "+Inf",
                    "value in {line}"
                );
                let name = series.split('{').next().unwrap();
                assert!(is_metric_name(name), "{line}");
                let family = types
                    .keys()
                    .find(|f| {
                        name == f.as_str()
                            || ["_bucket", "_sum", "_count"]
                                .iter()
                                .any(|s| name == format!("{f}{s}"))
                    })
                    .unwrap_or_else(|| panic!("sample before its TYPE: {line}"));
                if types[family] == "counter" {
                    assert!(family.ends_with("_total"), "{family}");
                }
                if let Some(labels) = series.split_once('{').map(|(_, l)| l.trim_end_matches('}')) {
                    for pair in labels.split("\",").filter(|p| !p.is_empty()) {
                        let (k, _) = pair.split_once('=').unwrap();
                        assert!(is_label_name(k), "{line}");
                    }
                }
            }
        }
        types
    }

    #[test]
    fn exposition_merges_families_and_drops_invalid_entries() {
        let mesh = mesh_with_stats();
        let text = render(&registry(mesh).unwrap()).unwrap();
        let types = check_exposition(&text);
        for (name, kind) in [
            ("skymesh_service_up", "gauge"),
            ("skymesh_service_restarts_total", "counter"),
            ("skymesh_service_uptime_seconds", "gauge"),
            ("skymesh_service_last_exit_code", "gauge"),
            ("skymesh_service_cpu_seconds_total", "counter"),
            ("skymesh_service_resident_memory_bytes", "gauge"),
            ("skymesh_supervisor_stale_nodes_cleaned_total", "counter"),
            ("skymesh_topic_samples_published_total", "counter"),
            ("skymesh_topic_samples_received_total", "counter"),
            ("skymesh_topic_sample_age_seconds", "histogram"),
            ("frames_total", "counter"),
            ("skymesh_link_up", "gauge"),
        ] {
            assert_eq!(
                types.get(name).map(String::as_str),
                Some(kind),
                "{name}\n{text}"
            );
        }
        assert!(
            text.contains(r#"skymesh_service_up{service="a"} 1"#),
            "{text}"
        );
        assert!(
            text.contains(r#"skymesh_service_up{service="b"} 0"#),
            "{text}"
        );
        assert!(
            text.contains(r#"skymesh_service_restarts_total{service="b"} 2"#),
            "{text}"
        );
        assert!(
            text.contains(r#"skymesh_service_state{service="b",state="backoff"} 1"#),
            "{text}"
        );
        assert!(text.contains(
            r#"skymesh_topic_samples_published_total{service="a",topic="skymesh/vehicle/1/state"} 10"#
        ));
        assert!(
            text.contains(
                r#"skymesh_topic_sample_age_seconds_bucket{service="b",topic="x",le="1"} 3"#
            ),
            "{text}"
        );
        assert!(
            text.contains(
                r#"skymesh_topic_sample_age_seconds_bucket{service="b",topic="x",le="+Inf"} 4"#
            ),
            "{text}"
        );
        assert!(
            text.contains(r#"skymesh_topic_sample_age_seconds_count{service="a",topic="x"} 4"#),
            "{text}"
        );
        // Dropped: bad name, reserved label, bad label, supervisor name, supervisor
        // prefix, gauge *_total, type conflict.
        assert!(
            text.contains("skymesh_supervisor_invalid_stats_entries 7"),
            "{text}"
        );
        assert!(!text.contains("bad-name") && !text.contains("evil") && !text.contains("g_total"));
        assert!(!text.contains("skymesh_vehicle_armed"), "{text}");
        assert_eq!(
            text.matches(r#"skymesh_service_up{service="a"}"#).count(),
            1
        );
    }

    #[test]
    fn build_info_is_exported_once_with_version_and_commit() {
        let mesh = Arc::new(Mesh::new(&[("a".into(), false)], false));
        // A service cannot shadow it.
        mesh.update(0, |e| {
            e.phase = Phase::Running;
            e.pid = Some(std::process::id());
            e.stats = Some(stats(&[entry(
                StatKind::Gauge,
                "skymesh_build_info",
                "",
                7.0,
            )]));
        });
        let text = render(&registry(mesh).unwrap()).unwrap();
        check_exposition(&text);
        let line = format!(
            r#"skymesh_build_info{{git="{}",version="{}"}} 1"#,
            crate::GIT,
            crate::VERSION
        );
        assert!(text.contains(&line), "{line} missing in\n{text}");
        assert_eq!(text.matches("skymesh_build_info{").count(), 1, "{text}");
        assert!(!crate::GIT.is_empty() && !crate::VERSION.is_empty());
    }

    #[test]
    fn identifiers_are_checked() {
        assert!(is_metric_name("skymesh_x:y_total"));
        assert!(!is_metric_name("9x") && !is_metric_name("") && !is_metric_name("a-b"));
        assert!(is_label_name("topic") && is_label_name("_x"));
        assert!(!is_label_name("__name__") && !is_label_name("a:b") && !is_label_name(""));
    }

    #[test]
    fn empty_mesh_still_renders_supervisor_metrics() {
        let mesh = Arc::new(Mesh::new(&[], false));
        let text = render(&registry(mesh).unwrap()).unwrap();
        check_exposition(&text);
        assert!(
            text.contains("skymesh_supervisor_stale_nodes_cleaned_total 0"),
            "{text}"
        );
        let free = find_value(&text, "skymesh_shm_free_bytes").expect("shm free exported");
        let size = find_value(&text, "skymesh_shm_size_bytes").expect("shm size exported");
        assert!(size > 0.0 && free <= size, "{text}");
    }

    fn find_value(text: &str, series: &str) -> Option<f64> {
        text.lines()
            .find_map(|l| l.strip_prefix(series)?.strip_prefix(' ')?.parse().ok())
    }
}
