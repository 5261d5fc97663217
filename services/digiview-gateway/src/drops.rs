//! Every refused frame is counted and logged with the client and the reason, but a
//! flood of bad input must not flood the journal: per reason, at most one warning
//! per [`skymesh_runtime::WARN_EVERY`]; the rest go to debug and the next warning
//! says how many it hid.

use std::fmt::Display;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use skymesh_runtime::WarnLimiter;

use crate::metrics::Metrics;
use crate::refusal::Refusal;

/// Counts and logs refusals; keeps the gateway-wide periodic GET count. Cheap to
/// clone.
#[derive(Debug, Clone)]
pub struct Drops {
    metrics: Metrics,
    limiter: Arc<Mutex<WarnLimiter<&'static str>>>,
    periodic: Arc<AtomicI64>,
}

impl Drops {
    pub fn new(metrics: Metrics) -> Self {
        Drops {
            metrics,
            limiter: Arc::default(),
            periodic: Arc::default(),
        }
    }

    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// `Some(hidden)` when a warning about `kind` may be logged now.
    pub fn allow(&self, kind: &'static str) -> Option<u64> {
        self.limiter
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .allow(kind, Instant::now())
    }

    /// Counts one refusal for client `client` at `peer` and logs why.
    pub fn refused(&self, reason: Refusal, client: u64, peer: SocketAddr, detail: &dyn Display) {
        self.metrics.refused(reason);
        match self.allow(reason.as_str()) {
            Some(hidden) => tracing::warn!(
                %peer,
                client,
                reason = reason.as_str(),
                detail = %detail,
                similar_since_last_warning = hidden,
                "DigiView request refused"
            ),
            None => tracing::debug!(
                %peer,
                client,
                reason = reason.as_str(),
                detail = %detail,
                "DigiView request refused"
            ),
        }
    }

    /// Periodic GETs started (`+n`) or stopped (`-n`) by one session.
    pub fn periodic_changed(&self, delta: i64) {
        if delta != 0 {
            let now = self.periodic.fetch_add(delta, Ordering::Relaxed) + delta;
            self.metrics.periodic_gets.set(now.max(0) as f64);
        }
    }
}
