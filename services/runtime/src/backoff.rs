//! Retry pacing shared by every service that reconnects or restarts something: the
//! supervisor's restarts, the DJI gateway's broker links, autopilot-link's MAVLink
//! connection.
//!
//! The delay before retry `n` (1-based) of a streak doubles from `initial`:
//! `d(n) = min(initial · 2^(n−1), max / (1 + jitter))`, and the delay waited is drawn
//! uniformly from `[d(n)·(1 − jitter), d(n)·(1 + jitter)]` by a number `unit` in
//! `[0, 1]` that the caller passes in (`fastrand::f64()` in the services, fixed values
//! in tests). That is the one jitter rule: relative, symmetric around the doubled
//! delay, and never above `max`. Capping the centre at `max / (1 + jitter)` rather
//! than clamping the drawn delay keeps retries that reached the cap spread over
//! `[max·(1 − jitter)/(1 + jitter), max]` instead of piling up on exactly `max`,
//! so peers that failed together stay apart. With `jitter = 0` the delays are
//! exactly `initial, 2·initial, …, max`.
//!
//! The type is synchronous and pure (no clock, no random source inside): callers
//! ask for the next delay and sleep however they sleep.

use std::time::Duration;

/// Exponential, capped, jittered retry delays (see the module docs for the rule).
#[derive(Debug, Clone, PartialEq)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    /// Relative jitter in `[0, 1]` (0.2 = ±20 %).
    jitter: f64,
    /// Consecutive failures so far.
    failures: u32,
}

impl Backoff {
    /// Doubling from `initial` up to `max`, no jitter. A `max` below `initial` is
    /// `initial`.
    pub fn new(initial: Duration, max: Duration) -> Self {
        Backoff {
            initial,
            max: max.max(initial),
            jitter: 0.0,
            failures: 0,
        }
    }

    /// With relative jitter `jitter` (0.2 = ±20 %), clamped to `[0, 1]`; a
    /// non-finite value means no jitter.
    pub fn with_jitter(mut self, jitter: f64) -> Self {
        self.jitter = if jitter.is_finite() {
            jitter.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self
    }

    /// The delay before retry `attempt` (1-based; 0 counts as 1) of a streak, with
    /// `unit` in `[0, 1]` picking the point in the jitter band (0 the shortest, 1 the
    /// longest; a non-finite `unit` is the band's centre). Never more than `max`.
    pub fn delay(&self, attempt: u32, unit: f64) -> Duration {
        let top = if self.jitter == 0.0 {
            self.max
        } else {
            self.max.div_f64(1.0 + self.jitter)
        };
        let doublings = attempt.saturating_sub(1);
        let centre = if doublings >= 32 {
            top
        } else {
            self.initial.saturating_mul(1u32 << doublings).min(top)
        };
        if self.jitter == 0.0 {
            return centre;
        }
        let unit = if unit.is_finite() {
            unit.clamp(0.0, 1.0)
        } else {
            0.5
        };
        centre
            .mul_f64(1.0 + self.jitter * (2.0 * unit - 1.0))
            .min(self.max)
    }

    /// One more failure: the delay to wait before the next attempt.
    pub fn next_delay(&mut self, unit: f64) -> Duration {
        self.failures = self.failures.saturating_add(1);
        self.delay(self.failures, unit)
    }

    /// A success: the next failure waits about `initial` again.
    pub fn reset(&mut self) {
        self.failures = 0;
    }

    /// Consecutive failures since the last [`reset`](Self::reset).
    pub fn failures(&self) -> u32 {
        self.failures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn without_jitter_it_doubles_from_initial_to_max() {
        // The supervisor's default pacing: 100 ms doubling to 30 s.
        let b = Backoff::new(ms(100), Duration::from_secs(30));
        let got: Vec<u128> = (1..=11).map(|n| b.delay(n, 0.5).as_millis()).collect();
        assert_eq!(
            got,
            [100, 200, 400, 800, 1600, 3200, 6400, 12800, 25600, 30000, 30000]
        );
        assert_eq!(b.delay(u32::MAX, 0.5), Duration::from_secs(30));
        assert_eq!(b.delay(0, 0.5), ms(100), "attempt 0 counts as the first");
        // Without jitter the unit does not matter.
        assert_eq!(b.delay(3, 0.0), b.delay(3, 1.0));
    }

    #[test]
    fn jitter_is_symmetric_around_the_doubled_delay() {
        let b = Backoff::new(ms(100), Duration::from_secs(30)).with_jitter(0.2);
        assert_eq!(b.delay(1, 0.0), ms(80));
        assert_eq!(b.delay(1, 1.0), ms(120));
        assert_eq!(b.delay(3, 0.5), ms(400));
        assert_eq!(b.delay(3, f64::NAN), ms(400), "non-finite unit: the centre");
        assert_eq!(b.delay(3, -3.0), ms(320), "unit clamped to 0");
        for r in [0.0, 0.25, 0.5, 0.75, 0.999, 1.0] {
            let d = b.delay(4, r);
            assert!(d >= ms(640) && d <= ms(960), "{d:?}");
        }
    }

    #[test]
    fn at_the_cap_retries_stay_spread_and_never_exceed_max() {
        let max = Duration::from_secs(30);
        let b = Backoff::new(ms(100), max).with_jitter(0.2);
        // Centre max / 1.2 = 25 s: the band is [20 s, 30 s].
        assert_eq!(b.delay(30, 0.5), Duration::from_secs(25));
        assert_eq!(b.delay(30, 0.0), Duration::from_secs(20));
        assert_eq!(b.delay(30, 1.0), max);
        let mut at_max = 0;
        for i in 0..=1000 {
            let d = b.delay(40, f64::from(i) / 1000.0);
            assert!(d >= Duration::from_secs(20) && d <= max, "{d:?}");
            at_max += usize::from(d == max);
        }
        assert!(at_max <= 1, "{at_max} of 1001 retries on exactly max");
    }

    #[test]
    fn next_delay_counts_failures_and_reset_starts_over() {
        let mut b = Backoff::new(ms(200), ms(1000)).with_jitter(0.5);
        assert_eq!(b.next_delay(0.5), ms(200));
        assert_eq!(b.next_delay(0.0), ms(200), "half of 400");
        let d = b.next_delay(1.0);
        assert!(
            d > ms(999) && d <= ms(1000),
            "1.5 × 666.7 ms, the cap: {d:?}"
        );
        assert_eq!(b.failures(), 3);
        for i in 0..100 {
            let d = b.next_delay(f64::from(i) / 99.0);
            assert!(d >= ms(333) && d <= ms(1000), "{d:?}");
        }
        b.reset();
        assert_eq!(b.failures(), 0);
        assert_eq!(b.next_delay(0.5), ms(200));
    }

    #[test]
    fn a_cap_below_the_start_is_the_start() {
        let mut b = Backoff::new(ms(500), ms(100));
        assert_eq!(b.next_delay(1.0), ms(500));
        assert_eq!(b.next_delay(1.0), ms(500));
    }

    #[test]
    fn jitter_is_clamped_and_non_finite_jitter_is_none() {
        let b = Backoff::new(ms(100), ms(1000)).with_jitter(5.0);
        assert_eq!(b.delay(1, 0.0), Duration::ZERO);
        assert_eq!(b.delay(1, 1.0), ms(200));
        let b = Backoff::new(ms(100), ms(1000)).with_jitter(f64::NAN);
        assert_eq!(b.delay(1, 0.0), ms(100));
        let b = Backoff::new(ms(100), ms(1000)).with_jitter(-1.0);
        assert_eq!(b.delay(2, 1.0), ms(200));
    }
}
