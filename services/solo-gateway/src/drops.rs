//! Every dropped input is counted and logged with the peer and the reason, but a
//! flood of bad input must not flood the journal: per kind, at most one warning per
//! [`WARN_EVERY`]; the rest go to debug and the next warning says how many it hid.

use std::collections::HashMap;
use std::fmt::Display;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::metrics::{Malformed, Metrics};

/// At most one warning per kind in this period.
pub const WARN_EVERY: Duration = Duration::from_secs(10);

/// Per-kind warning budget: pure, so the rate limit is tested without a clock.
#[derive(Debug, Default)]
pub struct WarnLimiter {
    /// Kind → (last warning, drops logged at debug since).
    last: HashMap<Malformed, (Instant, u64)>,
}

impl WarnLimiter {
    /// `Some(hidden)` if a warning may be logged now (`hidden` = drops since the last
    /// warning that were only logged at debug), `None` if this one goes to debug.
    pub fn allow(&mut self, kind: Malformed, now: Instant) -> Option<u64> {
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

/// Counts and logs dropped input. Cheap to clone; shared by every task.
#[derive(Debug, Clone)]
pub struct Drops {
    metrics: Metrics,
    limiter: Arc<Mutex<WarnLimiter>>,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_warning_per_kind_and_period() {
        let mut l = WarnLimiter::default();
        let t0 = Instant::now();
        assert_eq!(l.allow(Malformed::Stalled, t0), Some(0));
        assert_eq!(
            l.allow(Malformed::Stalled, t0 + Duration::from_secs(1)),
            None
        );
        assert_eq!(
            l.allow(Malformed::Stalled, t0 + Duration::from_secs(2)),
            None
        );
        // Another kind has its own budget.
        assert_eq!(l.allow(Malformed::TooLong, t0), Some(0));
        assert_eq!(l.allow(Malformed::Stalled, t0 + WARN_EVERY), Some(2));
        assert_eq!(l.allow(Malformed::Stalled, t0 + WARN_EVERY), None);
    }
}
