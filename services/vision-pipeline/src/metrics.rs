//! The metrics of the vision pipeline, exported through the runtime's stats sample.
//!
//! | series | labels | meaning |
//! |---|---|---|
//! | `skymesh_vision_frames_processed_total` | stream | frames turned into an output frame and a state |
//! | `skymesh_vision_frames_dropped_total` | stream | frames skipped because a newer one was queued, or older than a second when read (the topic's last frame on resuming) |
//! | `skymesh_vision_active` | | 1 while frames are read (the output is used), 0 while the pipeline idles |
//! | `skymesh_vision_frames_bad_total` | stream, reason | frames not usable: `intrinsics`, `pose`, `work_image`, `render`, `publish` |
//! | `skymesh_vision_process_seconds` | stream | one frame: detection to published output and state |
//! | `skymesh_vision_latency_seconds` | stream | capture (`capture_mono_ns`) to published state |
//! | `skymesh_vision_detections` | | tracked objects in the last state |
//! | `skymesh_vision_controls_total` | kind, result | controls answered |
//! | `skymesh_vision_capture_errors_total` | | images or video frames that could not be handed to the writer |

use skymesh_runtime::stats::LATENCY_BOUNDS_S;
use skymesh_runtime::{Counter, CounterFamily, Gauge, Histogram, Stats};

/// Series of one stream.
#[derive(Debug, Clone)]
pub struct StreamMetrics {
    pub processed: Counter,
    pub dropped: Counter,
    pub process_seconds: Histogram,
    pub latency_seconds: Histogram,
    bad: Vec<(&'static str, Counter)>,
}

/// Why a frame was not usable (label `reason`).
pub const BAD_REASONS: [&str; 5] = ["intrinsics", "pose", "work_image", "render", "publish"];

impl StreamMetrics {
    /// Counts one unusable frame (`reason` one of [`BAD_REASONS`]).
    pub fn bad(&self, reason: &'static str) {
        if let Some((_, c)) = self.bad.iter().find(|(r, _)| *r == reason) {
            c.inc();
        }
    }
}

/// Every series the service exports. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Metrics {
    pub streams: Vec<StreamMetrics>,
    pub detections: Gauge,
    pub capture_errors: Counter,
    pub active: Gauge,
    controls: CounterFamily,
}

impl Metrics {
    /// `streams`: the configured stream names (at most two: a bounded label set).
    pub fn new(stats: &Stats, streams: &[String]) -> Self {
        let streams = streams
            .iter()
            .map(|name| {
                let l = [("stream", name.as_str())];
                StreamMetrics {
                    processed: stats.counter("skymesh_vision_frames_processed_total", &l),
                    dropped: stats.counter("skymesh_vision_frames_dropped_total", &l),
                    process_seconds: stats.histogram(
                        "skymesh_vision_process_seconds",
                        &l,
                        &LATENCY_BOUNDS_S,
                    ),
                    latency_seconds: stats.histogram(
                        "skymesh_vision_latency_seconds",
                        &l,
                        &LATENCY_BOUNDS_S,
                    ),
                    bad: BAD_REASONS
                        .iter()
                        .map(|r| {
                            let labels = [("stream", name.as_str()), ("reason", r)];
                            (
                                *r,
                                stats.counter("skymesh_vision_frames_bad_total", &labels),
                            )
                        })
                        .collect(),
                }
            })
            .collect();
        Metrics {
            streams,
            detections: stats.gauge("skymesh_vision_detections", &[]),
            capture_errors: stats.counter("skymesh_vision_capture_errors_total", &[]),
            active: stats.gauge("skymesh_vision_active", &[]),
            controls: CounterFamily::new(
                stats,
                "skymesh_vision_controls_total",
                ("kind", Some("result")),
            ),
        }
    }

    /// Counts one answered control.
    pub fn control(&self, kind: &'static str, result: &'static str) {
        self.controls.get(kind, result).inc();
    }
}
