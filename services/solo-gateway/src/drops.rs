//! Every dropped input is counted and logged with the peer and the reason, but a
//! flood of bad input must not flood the journal: per kind, at most one warning per
//! [`skymesh_runtime::WARN_EVERY`]; the rest go to debug and the next warning says how many it hid.

use std::fmt::Display;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use skymesh_runtime::WarnLimiter;

use crate::metrics::{Malformed, Metrics};

/// Counts and logs dropped input. Cheap to clone; shared by every task.
#[derive(Debug, Clone)]
pub struct Drops {
    metrics: Metrics,
    limiter: Arc<Mutex<WarnLimiter<Malformed>>>,
}

impl Drops {
    pub fn new(metrics: Metrics) -> Self {
        Drops {
            metrics,
            limiter: Arc::default(),
        }
    }

    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// Counts one drop of `kind` from `peer` and logs why.
    pub fn record(&self, kind: Malformed, peer: SocketAddr, reason: &dyn Display) {
        self.metrics.malformed(kind);
        let allowed = self
            .limiter
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .allow(kind, Instant::now());
        match allowed {
            Some(hidden) => tracing::warn!(
                %peer,
                kind = kind.as_str(),
                reason = %reason,
                similar_since_last_warning = hidden,
                "dropped input from the Solo app side"
            ),
            None => tracing::debug!(
                %peer,
                kind = kind.as_str(),
                reason = %reason,
                "dropped input from the Solo app side"
            ),
        }
    }
}
