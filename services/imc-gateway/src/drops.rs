//! Every refused input is counted and logged with the peer and the reason, but a
//! flood of bad datagrams must not flood the journal: per peer and reason, at most
//! one warning per [`skymesh_runtime::WARN_EVERY`]; the rest go to debug and the next warning says
//! how many it hid.

use std::net::SocketAddr;
use std::time::Instant;

use skymesh_runtime::WarnLimiter;

use crate::engine::Dropped;
use crate::metrics::Metrics;

type Key = (Option<SocketAddr>, &'static str);

/// Counts and logs refused input.
#[derive(Debug)]
pub struct Drops {
    metrics: Metrics,
    limiter: WarnLimiter<Key>,
}

impl Drops {
    pub fn new(metrics: Metrics) -> Self {
        Drops {
            metrics,
            limiter: WarnLimiter::default(),
        }
    }

    /// Counts one drop and logs why (quiet drops only at debug).
    pub fn record(&mut self, d: &Dropped, now: Instant) {
        self.metrics.dropped(d.reason);
        let peer = d
            .peer
            .map(|p| p.to_string())
            .unwrap_or_else(|| "-".to_string());
        if d.quiet {
            tracing::debug!(%peer, reason = d.reason, detail = %d.detail, "IMC input not acted on");
            return;
        }
        match self.limiter.allow((d.peer, d.reason), now) {
            Some(hidden) => tracing::warn!(
                %peer,
                reason = d.reason,
                detail = %d.detail,
                similar_since_last_warning = hidden,
                "IMC input dropped"
            ),
            None => {
                tracing::debug!(%peer, reason = d.reason, detail = %d.detail, "IMC input dropped")
            }
        }
    }
}
