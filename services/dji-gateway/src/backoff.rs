//! Reconnect backoff: starts at `initial`, doubles per consecutive failure up to
//! `max`, and each delay is drawn from [delay/2, delay] ("equal jitter") so gateways
//! that lost the same broker do not come back in lockstep. Pure: the random number
//! is passed in.

use std::time::Duration;

#[derive(Debug, Clone)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    /// Consecutive failures so far.
    failures: u32,
}

impl Backoff {
    pub fn new(initial: Duration, max: Duration) -> Self {
        Backoff {
            initial,
            max: max.max(initial),
            failures: 0,
        }
    }

    /// The un-jittered delay before the next attempt.
    pub fn ceiling(&self) -> Duration {
        let factor = 1u32 << self.failures.min(20);
        self.initial.saturating_mul(factor).min(self.max)
    }

    /// One more failure: the delay to wait now. `unit` in [0, 1] picks the jitter
    /// (`fastrand::f64()` in the service).
    pub fn next_delay(&mut self, unit: f64) -> Duration {
        let ceiling = self.ceiling();
        self.failures = self.failures.saturating_add(1);
        let unit = if unit.is_finite() {
            unit.clamp(0.0, 1.0)
        } else {
            1.0
        };
        ceiling.mul_f64(0.5 + 0.5 * unit)
    }

    /// A connection succeeded: the next failure waits `initial` again.
    pub fn reset(&mut self) {
        self.failures = 0;
    }

    pub fn failures(&self) -> u32 {
        self.failures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doubles_up_to_the_cap_with_jitter_and_resets() {
        let mut b = Backoff::new(Duration::from_millis(200), Duration::from_millis(1000));
        assert_eq!(b.next_delay(1.0), Duration::from_millis(200));
        assert_eq!(b.next_delay(1.0), Duration::from_millis(400));
        assert_eq!(b.next_delay(0.0), Duration::from_millis(400), "half of 800");
        assert_eq!(b.next_delay(1.0), Duration::from_millis(1000), "capped");
        for _ in 0..100 {
            let d = b.next_delay(fastrand::f64());
            assert!(d >= Duration::from_millis(500) && d <= Duration::from_millis(1000));
        }
        assert_eq!(b.next_delay(f64::NAN), Duration::from_millis(1000));
        b.reset();
        assert_eq!(b.failures(), 0);
        assert_eq!(b.next_delay(1.0), Duration::from_millis(200));
    }

    #[test]
    fn a_cap_below_the_start_is_the_start() {
        let mut b = Backoff::new(Duration::from_millis(500), Duration::from_millis(100));
        assert_eq!(b.next_delay(1.0), Duration::from_millis(500));
        assert_eq!(b.next_delay(1.0), Duration::from_millis(500));
    }
}
