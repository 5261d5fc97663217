//! Every refused record is counted and logged with the client and the reason, but a
//! flood of bad input must not flood the journal: per reason, at most one warning
//! per [`skymesh_runtime::WARN_EVERY`]; the rest go to debug and the next warning says how many it hid.

use std::fmt::Display;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use skymesh_runtime::WarnLimiter;

use crate::inbound::RefuseReason;
use crate::metrics::Metrics;

/// Counts and logs refused records and other per-event trouble. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Drops {
    metrics: Metrics,
    limiter: Arc<Mutex<WarnLimiter<&'static str>>>,
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

    /// `Some(hidden)` when a warning about `kind` may be logged now.
    pub fn allow(&self, kind: &'static str) -> Option<u64> {
        self.limiter
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .allow(kind, Instant::now())
    }

    /// Counts one refused record of client `client` at `peer` and logs why.
    pub fn refused(
        &self,
        reason: RefuseReason,
        client: u16,
        peer: SocketAddr,
        detail: &dyn Display,
    ) {
        self.metrics.refused(reason);
        match self.allow(reason.as_str()) {
            Some(hidden) => tracing::warn!(
                %peer,
                client,
                reason = reason.as_str(),
                detail = %detail,
                similar_since_last_warning = hidden,
                "GroundControl record refused"
            ),
            None => tracing::debug!(
                %peer,
                client,
                reason = reason.as_str(),
                detail = %detail,
                "GroundControl record refused"
            ),
        }
    }

    /// Logs a connection closed inside a record that stalled (slow-loris); the
    /// disconnect itself is counted by the hub (`partial_record_timeout`).
    pub fn stalled(&self, client: u16, peer: SocketAddr, buffered: usize) {
        match self.allow("partial_record_timeout") {
            Some(hidden) => tracing::warn!(
                %peer,
                client,
                buffered,
                similar_since_last_warning = hidden,
                "GroundControl client closed: a record stayed incomplete for partial_record_timeout_s"
            ),
            None => tracing::debug!(
                %peer,
                client,
                buffered,
                "GroundControl client closed: a record stayed incomplete"
            ),
        }
    }
}
