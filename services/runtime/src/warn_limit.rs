//! Rate-limited warnings for hostile input: every dropped input is counted and
//! logged, but a flood must not flood the journal. Per key (a reason, or a peer and a
//! reason), at most one warning per [`WARN_EVERY`]; the rest go to debug and the next
//! warning says how many it hid. Used by every gateway's drop accounting.

use std::collections::HashMap;
use std::hash::Hash;
use std::time::{Duration, Instant};

/// At most one warning per key in this period.
pub const WARN_EVERY: Duration = Duration::from_secs(10);
/// Keys remembered: a flood from many source addresses beyond this is logged at
/// debug only until old entries age out, so the table cannot grow without bound.
pub const MAX_KEYS: usize = 512;

/// Per-key warning budget: pure (time is passed in), so it is tested without a clock.
#[derive(Debug)]
pub struct WarnLimiter<K> {
    /// Key → (last warning, events logged at debug since).
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
    pub fn allow(&mut self, key: K, now: Instant) -> Option<u64> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_warning_per_key_and_period() {
        let mut l = WarnLimiter::default();
        let t0 = Instant::now();
        assert_eq!(l.allow("a", t0), Some(0));
        assert_eq!(l.allow("a", t0 + Duration::from_secs(1)), None);
        assert_eq!(l.allow("b", t0 + Duration::from_secs(1)), Some(0));
        assert_eq!(l.allow("a", t0 + Duration::from_secs(2)), None);
        assert_eq!(l.allow("a", t0 + WARN_EVERY), Some(2));
        assert_eq!(l.allow("a", t0 + WARN_EVERY), None);
    }

    #[test]
    fn many_keys_cannot_grow_the_table() {
        let mut l = WarnLimiter::default();
        let t0 = Instant::now();
        for k in 0..MAX_KEYS {
            assert_eq!(l.allow(k, t0), Some(0));
        }
        assert_eq!(l.allow(MAX_KEYS, t0), None, "table full: debug only");
        assert_eq!(
            l.allow(MAX_KEYS, t0 + WARN_EVERY),
            Some(0),
            "old keys age out"
        );
    }
}
