//! The metrics of the camera service, exported through the runtime's stats sample.
//!
//! | series | labels | meaning |
//! |---|---|---|
//! | `skymesh_camera_frames_published_total` | | frames published |
//! | `skymesh_camera_frames_skipped_total` | reason | frame ticks without a frame: `late` (rendering slower than the frame rate), `no_pose` (no vehicle pose and no configured origin), `publish_error` (the bus refused the frame) |
//! | `skymesh_camera_render_seconds` | | time to render (synthetic) or convert (file) and publish one frame |
//! | `skymesh_camera_file_errors_total` | | Y4M file read errors (truncated or corrupt frame, I/O): handled as the end of the file |
//! | `skymesh_camera_file_rewinds_total` | | times a Y4M file source started again from its first frame (`loop = true`) |
//! | `skymesh_camera_active` | | 1 while frames are made (a reader's demand word holds, the frame topic has a subscriber, or `always_on`), 0 while the camera idles |

use skymesh_runtime::stats::LATENCY_BOUNDS_S;
use skymesh_runtime::{Counter, Gauge, Histogram, Stats};

/// Why a frame tick produced no frame (label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Skip {
    Late,
    NoPose,
    PublishError,
}

/// Every series the service exports. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Metrics {
    pub published: Counter,
    late: Counter,
    no_pose: Counter,
    publish_error: Counter,
    pub render_seconds: Histogram,
    pub file_errors: Counter,
    pub file_rewinds: Counter,
    pub active: Gauge,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        let skipped =
            |reason| stats.counter("skymesh_camera_frames_skipped_total", &[("reason", reason)]);
        Metrics {
            published: stats.counter("skymesh_camera_frames_published_total", &[]),
            late: skipped("late"),
            no_pose: skipped("no_pose"),
            publish_error: skipped("publish_error"),
            render_seconds: stats.histogram(
                "skymesh_camera_render_seconds",
                &[],
                &LATENCY_BOUNDS_S,
            ),
            file_errors: stats.counter("skymesh_camera_file_errors_total", &[]),
            file_rewinds: stats.counter("skymesh_camera_file_rewinds_total", &[]),
            active: stats.gauge("skymesh_camera_active", &[]),
        }
    }

    pub fn skipped(&self, reason: Skip, n: u64) {
        match reason {
            Skip::Late => self.late.add(n),
            Skip::NoPose => self.no_pose.add(n),
            Skip::PublishError => self.publish_error.add(n),
        }
    }
}
