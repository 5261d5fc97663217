//! A token bucket for per-client message rate limits at the gateways' edges.
//!
//! `rate` tokens per second refill a bucket of `burst` tokens; each message takes
//! one, and a message finding the bucket empty is over the limit (the caller drops
//! and counts it). A new bucket is full, so a client may open with a burst.
//!
//! Pure: time is passed in (`Instant`, e.g. `tokio::time::Instant::into_std()`), so
//! it is tested without a clock. Integer arithmetic (one token is `NANOS` units of
//! credit and a nanosecond adds `rate` units), so there is no rounding drift.

use std::time::{Duration, Instant};

/// Credit units per token: one second of refill at one token per second.
const NANOS: u64 = 1_000_000_000;

/// A token bucket: `rate` messages per second, bursts of up to `burst`.
#[derive(Debug, Clone)]
pub struct TokenBucket {
    rate: u64,
    /// Capacity in credit units (`burst * NANOS`).
    capacity: u64,
    /// Credit now, in units (`NANOS` per token).
    credit: u64,
    last: Instant,
}

impl TokenBucket {
    /// A full bucket at `now`. `rate` and `burst` below 1 are taken as 1 (config
    /// validation keeps them in range; a zero would refuse everything forever).
    pub fn new(rate_per_s: u32, burst: u32, now: Instant) -> Self {
        let capacity = u64::from(burst.max(1)) * NANOS;
        TokenBucket {
            rate: u64::from(rate_per_s.max(1)),
            capacity,
            credit: capacity,
            last: now,
        }
    }

    /// Refills for the time since the last call (time going back adds nothing).
    fn refill(&mut self, now: Instant) {
        let dt = now.saturating_duration_since(self.last);
        self.last = self.last.max(now);
        // Past a full refill the exact time does not matter: cap before multiplying.
        let full = self.capacity / self.rate + 1;
        let ns = u64::try_from(dt.as_nanos()).unwrap_or(u64::MAX).min(full);
        self.credit = self
            .credit
            .saturating_add(ns.saturating_mul(self.rate))
            .min(self.capacity);
    }

    /// `true` if one more message may pass at `now` (and takes its token).
    pub fn take(&mut self, now: Instant) -> bool {
        self.refill(now);
        if self.credit >= NANOS {
            self.credit -= NANOS;
            true
        } else {
            false
        }
    }

    /// Whole tokens available at `now`.
    pub fn available(&mut self, now: Instant) -> u64 {
        self.refill(now);
        self.credit / NANOS
    }

    /// How long from `now` until one token is available (zero if one is).
    pub fn wait(&mut self, now: Instant) -> Duration {
        self.refill(now);
        let missing = NANOS.saturating_sub(self.credit);
        Duration::from_nanos(missing.div_ceil(self.rate))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_burst_then_the_rate() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(10, 5, t0);
        assert!((0..5).all(|_| b.take(t0)), "opens full");
        assert!(!b.take(t0), "burst spent");
        // 10/s: one token per 100 ms.
        assert!(!b.take(t0 + Duration::from_millis(99)));
        assert!(b.take(t0 + Duration::from_millis(100)));
        assert!(!b.take(t0 + Duration::from_millis(100)));
        assert!(b.take(t0 + Duration::from_millis(200)));
        assert_eq!(
            b.wait(t0 + Duration::from_millis(250)),
            Duration::from_millis(50)
        );
    }

    #[test]
    fn refill_stops_at_the_burst() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(100, 3, t0);
        assert!((0..3).all(|_| b.take(t0)));
        let later = t0 + Duration::from_secs(3600);
        assert_eq!(b.available(later), 3);
        assert!((0..3).all(|_| b.take(later)));
        assert!(!b.take(later));
    }

    #[test]
    fn no_drift_over_many_small_steps() {
        // 3/s checked every millisecond for ten seconds after the burst: exactly 30 pass.
        let t0 = Instant::now();
        let mut b = TokenBucket::new(3, 2, t0);
        assert!(b.take(t0) && b.take(t0) && !b.take(t0));
        let passed = (0..10_000)
            .filter(|ms| b.take(t0 + Duration::from_millis(*ms + 1)))
            .count();
        assert_eq!(passed, 30);
    }

    #[test]
    fn time_going_back_adds_nothing_and_zero_is_one() {
        let t0 = Instant::now() + Duration::from_secs(10);
        let mut b = TokenBucket::new(0, 0, t0);
        assert!(b.take(t0));
        assert!(!b.take(t0 - Duration::from_secs(5)));
        assert!(!b.take(t0 + Duration::from_millis(999)));
        assert!(b.take(t0 + Duration::from_secs(1)));
    }

    #[test]
    fn a_sustained_flood_gets_exactly_the_rate() {
        let t0 = Instant::now();
        let mut b = TokenBucket::new(200, 400, t0);
        // 1000 messages per second for 5 s, every millisecond.
        let passed = (0..5000)
            .filter(|ms| b.take(t0 + Duration::from_millis(*ms)))
            .count();
        // 400 at once, then 200/s over the 4.999 s that follow.
        assert_eq!(passed, 400 + 999);
    }
}
