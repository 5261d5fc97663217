//! Every refused record is counted and logged with the client and the reason, but a
//! flood of bad input must not flood the journal: per reason, at most one warning
//! per [`WARN_EVERY`]; the rest go to debug and the next warning says how many it hid.

use std::collections::HashMap;
use std::fmt::Display;
use std::hash::Hash;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::inbound::RefuseReason;
use crate::metrics::Metrics;

/// At most one warning per kind in this period.
pub const WARN_EVERY: Duration = Duration::from_secs(10);

/// Per-kind warning budget: pure, so the rate limit is tested without a clock.
#[derive(Debug)]
pub struct WarnLimiter<K> {
    /// Kind → (last warning, events logged at debug since).
    last: HashMap<K, (Instant, u64)>,
}

impl<K> Default for WarnLimiter<K> {
    fn default() -> Self {
        WarnLimiter {
            last: HashMap::new(),
        }
    }
}

impl<K: Eq + Hash> WarnLimiter<K> {
    /// `Some(hidden)` if a warning may be logged now (`hidden` = events since the last
    /// warning that were only logged at debug), `None` if this one goes to debug.
    pub fn allow(&mut self, kind: K, now: Instant) -> Option<u64> {
        match self.last.get_mut(&kind) {
            Some((at, hidden)) if now.duration_since(*at) < WARN_EVERY => {
                *hidden += 1;
                None
            }
            Some((at, hidden)) => {
                let n = *hidden;
                (*at, *hidden) = (now, 0);
                Some(n)
            }
            None => {
                self.last.insert(kind, (now, 0));
                Some(0)
            }
        }
    }
}

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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_warning_per_kind_and_period() {
        let mut l = WarnLimiter::default();
        let t0 = Instant::now();
        assert_eq!(l.allow("a", t0), Some(0));
        assert_eq!(l.allow("a", t0 + Duration::from_secs(1)), None);
        assert_eq!(l.allow("a", t0 + Duration::from_secs(2)), None);
        assert_eq!(l.allow("b", t0), Some(0));
        assert_eq!(l.allow("a", t0 + WARN_EVERY), Some(2));
        assert_eq!(l.allow("a", t0 + WARN_EVERY), None);
    }
}
