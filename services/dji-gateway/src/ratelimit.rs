//! Inbound rate limit: at most `max_per_s` messages per topic in each one-second
//! window; the excess is dropped (and counted by the caller). Pure, explicit time.

use std::collections::HashMap;
use std::hash::Hash;
use std::time::{Duration, Instant};

const WINDOW: Duration = Duration::from_secs(1);

#[derive(Debug)]
pub struct RateLimiter<K> {
    max_per_s: u32,
    /// Key → (window start, messages admitted in it).
    windows: HashMap<K, (Instant, u32)>,
}

impl<K: Eq + Hash> RateLimiter<K> {
    pub fn new(max_per_s: u32) -> Self {
        RateLimiter {
            max_per_s,
            windows: HashMap::new(),
        }
    }

    /// `true` if one more message of `key` may be handled at `now`.
    pub fn admit(&mut self, key: K, now: Instant) -> bool {
        let (start, count) = self.windows.entry(key).or_insert((now, 0));
        if now.saturating_duration_since(*start) >= WINDOW {
            (*start, *count) = (now, 0);
        }
        if *count >= self.max_per_s {
            return false;
        }
        *count += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_key_budget_per_second() {
        let t0 = Instant::now();
        let mut r = RateLimiter::new(3);
        assert!((0..3).all(|_| r.admit("services", t0)));
        assert!(!r.admit("services", t0 + Duration::from_millis(500)));
        assert!(
            r.admit("events_reply", t0 + Duration::from_millis(500)),
            "own budget"
        );
        assert!(!r.admit("services", t0 + Duration::from_millis(999)));
        assert!(r.admit("services", t0 + WINDOW), "a new window");
        assert!(r.admit("services", t0 + WINDOW));
        assert!(r.admit("services", t0 + WINDOW));
        assert!(!r.admit("services", t0 + WINDOW));
    }
}
