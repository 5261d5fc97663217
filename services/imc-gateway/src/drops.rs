//! Every refused input is counted and logged with the peer and the reason, but a
//! flood of bad datagrams must not flood the journal: per peer and reason, at most
//! one warning per [`WARN_EVERY`]; the rest go to debug and the next warning says
//! how many it hid.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use crate::engine::Dropped;
use crate::metrics::Metrics;

/// At most one warning per peer and reason in this period.
pub const WARN_EVERY: Duration = Duration::from_secs(10);
/// (peer, reason) pairs remembered; a flood from many source addresses beyond this
/// is logged at debug only until old entries age out.
const MAX_KEYS: usize = 512;

type Key = (Option<SocketAddr>, &'static str);

/// Per (peer, reason) warning budget: pure, so the rate limit is tested without a clock.
#[derive(Debug, Default)]
pub struct WarnLimiter {
    /// Key → (last warning, drops logged at debug since).
    last: HashMap<Key, (Instant, u64)>,
}

impl WarnLimiter {
    /// `Some(hidden)` if a warning may be logged now (`hidden` = drops since the last
    /// warning that were only logged at debug), `None` if this one goes to debug.
    pub fn allow(&mut self, key: Key, now: Instant) -> Option<u64> {
        match self.last.get_mut(&key) {
            Some((at, hidden)) if now.saturating_duration_since(*at) < WARN_EVERY => {
                *hidden += 1;
                None
            }
            Some((at, hidden)) => {
                let n = *hidden;
                (*at, *hidden) = (now, 0);
                Some(n)
            }
            None => {
                if self.last.len() >= MAX_KEYS {
                    self.last
                        .retain(|_, (at, _)| now.saturating_duration_since(*at) < WARN_EVERY);
                    if self.last.len() >= MAX_KEYS {
                        return None;
                    }
                }
                self.last.insert(key, (now, 0));
                Some(0)
            }
        }
    }
}

/// Counts and logs refused input.
#[derive(Debug)]
pub struct Drops {
    metrics: Metrics,
    limiter: WarnLimiter,
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

#[cfg(test)]
mod tests {
    use super::*;

    fn peer(port: u16) -> Option<SocketAddr> {
        Some(SocketAddr::from(([127, 0, 0, 1], port)))
    }

    #[test]
    fn one_warning_per_peer_reason_and_period() {
        let mut l = WarnLimiter::default();
        let t0 = Instant::now();
        let s = Duration::from_secs(1);
        assert_eq!(l.allow((peer(1), "bad_crc"), t0), Some(0));
        assert_eq!(l.allow((peer(1), "bad_crc"), t0 + s), None);
        assert_eq!(l.allow((peer(1), "bad_crc"), t0 + 2 * s), None);
        assert_eq!(l.allow((peer(2), "bad_crc"), t0), Some(0), "another peer");
        assert_eq!(
            l.allow((peer(1), "bad_sync"), t0),
            Some(0),
            "another reason"
        );
        assert_eq!(l.allow((peer(1), "bad_crc"), t0 + WARN_EVERY), Some(2));
        assert_eq!(l.allow((peer(1), "bad_crc"), t0 + WARN_EVERY), None);
    }

    #[test]
    fn many_source_addresses_cannot_grow_the_table() {
        let mut l = WarnLimiter::default();
        let t0 = Instant::now();
        for p in 0..MAX_KEYS as u16 {
            assert_eq!(l.allow((peer(p), "bad_crc"), t0), Some(0));
        }
        assert_eq!(
            l.allow((peer(60_000), "bad_crc"), t0),
            None,
            "full: debug only"
        );
        assert_eq!(
            l.allow((peer(60_000), "bad_crc"), t0 + WARN_EVERY),
            Some(0),
            "old entries age out"
        );
        assert!(l.last.len() <= MAX_KEYS);
    }
}
