//! Inbound rate limit: a token bucket per topic (the runtime's
//! [`skymesh_runtime::TokenBucket`]), `max_per_s` messages per second with bursts of
//! as many; the excess is dropped (and counted by the caller). Pure, explicit time.

use std::collections::HashMap;
use std::hash::Hash;
use std::time::Instant;

use skymesh_runtime::TokenBucket;

#[derive(Debug)]
pub struct RateLimiter<K> {
    max_per_s: u32,
    /// Key → its bucket (keys are topic kinds: a bounded set).
    buckets: HashMap<K, TokenBucket>,
}

impl<K: Eq + Hash> RateLimiter<K> {
    pub fn new(max_per_s: u32) -> Self {
        RateLimiter {
            max_per_s,
            buckets: HashMap::new(),
        }
    }

    /// `true` if one more message of `key` may be handled at `now`.
    pub fn admit(&mut self, key: K, now: Instant) -> bool {
        let per_s = self.max_per_s;
        self.buckets
            .entry(key)
            .or_insert_with(|| TokenBucket::new(per_s, per_s, now))
            .take(now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn per_key_budget_per_second() {
        let t0 = Instant::now();
        let mut r = RateLimiter::new(3);
        assert!((0..3).all(|_| r.admit("services", t0)));
        assert!(!r.admit("services", t0 + Duration::from_millis(300)));
        assert!(
            r.admit("events_reply", t0 + Duration::from_millis(300)),
            "own budget"
        );
        // One token per 333 ms refills.
        assert!(r.admit("services", t0 + Duration::from_millis(334)));
        assert!(!r.admit("services", t0 + Duration::from_millis(600)));
        let later = t0 + Duration::from_secs(5);
        assert!(
            (0..3).all(|_| r.admit("services", later)),
            "a full burst again"
        );
        assert!(!r.admit("services", later));
    }
}
