//! Timers for periodic loops that wake exactly when due: a `timerfd` in tokio's
//! reactor instead of tokio's timer wheel.
//!
//! Why: tokio's hierarchical wheel keeps only the current, aligned 64 ms block in
//! its finest level. A timer due in the next block sits one level up, and the
//! runtime wakes at the block boundary to move it down — so a service that
//! always has a timer pending a few tens of milliseconds ahead (a 30 Hz tick, a
//! 50 Hz simulator step) wakes ~15.6 times a second more than its work needs
//! (measured: a lone 30 Hz `tokio::time::interval` parks 45 times a second, not 30).
//! A `timerfd` armed with an absolute `CLOCK_MONOTONIC` deadline wakes once, on
//! time. For the periodic loops of the mesh (services' ticks); one-off and long
//! timeouts stay on tokio's timers.
//!
//! Deadlines are tokio `Instant`s (`CLOCK_MONOTONIC` on Linux, converted through
//! one monotonic reading). Under a paused test clock (tokio's `test-util`, e.g.
//! `#[tokio::test(start_paused = true)]`) a timer falls back to tokio's own
//! sleep, so tests that fast-forward time keep working; the check is made once,
//! when the timer is created.

use std::io;
use std::os::fd::{AsFd, AsRawFd, RawFd};
use std::time::Duration;

use nix::sys::time::TimeSpec;
use nix::sys::timerfd::{ClockId, Expiration, TimerFd, TimerFlags, TimerSetTimeFlags};
use tokio::io::unix::AsyncFd;
use tokio::time::Instant;

use crate::clock::monotonic_ns;

/// A one-shot timer re-armed for each wait. Cancel-safe: dropping a pending
/// [`Timer::sleep_until`] leaves the timer armed, and the next call re-arms it
/// (which also discards an expiry not yet read).
#[derive(Debug)]
pub struct Timer {
    /// `None` under a paused test clock: tokio's sleep instead.
    fd: Option<AsyncFd<Fd>>,
}

/// `AsyncFd` wants `AsRawFd`; nix's `TimerFd` offers `AsFd`.
#[derive(Debug)]
struct Fd(TimerFd);

impl AsRawFd for Fd {
    fn as_raw_fd(&self) -> RawFd {
        self.0.as_fd().as_raw_fd()
    }
}

impl Timer {
    /// A timer registered with the current tokio runtime's reactor.
    pub fn new() -> io::Result<Self> {
        if clock_is_paused() {
            return Ok(Timer { fd: None });
        }
        let fd = TimerFd::new(
            ClockId::CLOCK_MONOTONIC,
            TimerFlags::TFD_NONBLOCK | TimerFlags::TFD_CLOEXEC,
        )?;
        // `AsyncFd::new` is deprecated because it cannot prove the descriptor stays
        // open while registered; here the `AsyncFd` owns the timer, so it does. Its
        // replacement is `unsafe` for that reason only.
        #[allow(deprecated)]
        let fd = AsyncFd::with_interest(Fd(fd), tokio::io::Interest::READABLE)?;
        Ok(Timer { fd: Some(fd) })
    }

    /// Waits until `at` (returns at once if it has passed).
    pub async fn sleep_until(&mut self, at: Instant) -> io::Result<()> {
        let Some(fd) = &self.fd else {
            tokio::time::sleep_until(at).await;
            return Ok(());
        };
        let now = Instant::now();
        if at <= now {
            return Ok(());
        }
        let at_ns = monotonic_ns().saturating_add(nanos(at - now));
        fd.get_ref().0.set(
            Expiration::OneShot(TimeSpec::from_duration(Duration::from_nanos(at_ns))),
            TimerSetTimeFlags::TFD_TIMER_ABSTIME,
        )?;
        loop {
            let mut ready = fd.readable().await?;
            // Reads the expiry count; WouldBlock when the readiness was stale (an
            // expiry of an earlier arming that the re-arm above discarded).
            if let Ok(read) = ready.try_io(|fd| fd.get_ref().0.wait().map_err(io::Error::from)) {
                // The one-shot is spent until re-armed: clearing the readiness now
                // saves the next wait a read that would only find it stale.
                ready.clear_ready();
                return read;
            }
        }
    }
}

/// True under tokio's paused test clock: it does not move while this thread
/// spins (the real clock always does).
fn clock_is_paused() -> bool {
    let tokio_then = Instant::now();
    let real = std::time::Instant::now();
    while real.elapsed() < Duration::from_micros(20) {
        std::hint::spin_loop();
    }
    Instant::now() == tokio_then
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// A periodic tick on a [`Timer`]: the first [`Ticker::tick`] returns at once,
/// then one every `period`, on a fixed grid from the start. Ticks missed while the
/// loop was busy are skipped, not burst (tokio's `MissedTickBehavior::Skip`).
#[derive(Debug)]
pub struct Ticker {
    timer: Timer,
    period: Duration,
    next: Instant,
}

impl Ticker {
    /// `period` must not be zero.
    pub fn new(period: Duration) -> io::Result<Self> {
        if period.is_zero() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "a ticker's period must not be zero",
            ));
        }
        Ok(Ticker {
            timer: Timer::new()?,
            period,
            next: Instant::now(),
        })
    }

    /// The tick period.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Waits for the next tick and returns its scheduled time. Cancel-safe: a
    /// dropped call loses no tick.
    pub async fn tick(&mut self) -> io::Result<Instant> {
        self.timer.sleep_until(self.next).await?;
        let due = self.next;
        let now = Instant::now();
        self.next = due + self.period;
        if self.next <= now {
            // Behind by more than a period: the next tick on the grid after now.
            let behind = nanos(now - due) / nanos(self.period).max(1);
            self.next = due + self.period * u32::try_from(behind + 1).unwrap_or(u32::MAX);
        }
        Ok(due)
    }

    /// The next tick comes a period from now (then every period from it).
    pub fn reset(&mut self) {
        self.next = Instant::now() + self.period;
    }

    /// The next tick comes at once (then every period from it).
    pub fn reset_immediately(&mut self) {
        self.next = Instant::now();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn sleep_until_waits_until_the_deadline_and_not_for_a_past_one() {
        let mut t = Timer::new().unwrap();
        assert!(t.fd.is_some(), "a real clock uses the timerfd");
        let start = Instant::now();
        t.sleep_until(start + Duration::from_millis(30))
            .await
            .unwrap();
        assert!(start.elapsed() >= Duration::from_millis(30));
        let past = Instant::now() - Duration::from_millis(5);
        let before = Instant::now();
        t.sleep_until(past).await.unwrap();
        assert!(before.elapsed() < Duration::from_secs(1));
    }

    #[tokio::test]
    async fn a_dropped_sleep_leaves_no_stale_expiry_for_the_next() {
        let mut t = Timer::new().unwrap();
        // Armed for 5 ms, abandoned, and left to expire unread.
        let _ = tokio::time::timeout(
            Duration::from_millis(1),
            t.sleep_until(Instant::now() + Duration::from_millis(5)),
        )
        .await;
        std::thread::sleep(Duration::from_millis(10));
        let start = Instant::now();
        t.sleep_until(start + Duration::from_millis(40))
            .await
            .unwrap();
        assert!(
            start.elapsed() >= Duration::from_millis(40),
            "woke after {:?} on the abandoned expiry",
            start.elapsed()
        );
    }

    #[tokio::test(start_paused = true)]
    async fn a_paused_test_clock_is_followed() {
        let mut t = Timer::new().unwrap();
        assert!(t.fd.is_none(), "paused clock detected");
        let real = std::time::Instant::now();
        let start = Instant::now();
        t.sleep_until(start + Duration::from_secs(3600))
            .await
            .unwrap();
        assert!(Instant::now() >= start + Duration::from_secs(3600));
        assert!(
            real.elapsed() < Duration::from_secs(60),
            "fast-forwarded, not slept"
        );
        assert!(Timer::new().unwrap().fd.is_none());
    }

    #[tokio::test]
    async fn ticks_keep_a_grid_and_skip_what_was_missed() {
        let period = Duration::from_millis(20);
        let mut ticker = Ticker::new(period).unwrap();
        let first = ticker.tick().await.unwrap();
        let second = ticker.tick().await.unwrap();
        assert_eq!(second - first, period);
        assert!(Instant::now() >= second);
        // Busy for five periods: the next tick is the first grid point after now.
        std::thread::sleep(period * 5 + Duration::from_millis(5));
        let late = ticker.tick().await.unwrap();
        assert_eq!(late, second + period, "the missed tick is due at once");
        let next = ticker.tick().await.unwrap();
        let gap = next - second;
        assert!(
            gap >= period * 6 && gap <= period * 7 && (gap.as_nanos() % period.as_nanos()) == 0,
            "{gap:?}"
        );
        assert!(Ticker::new(Duration::ZERO).is_err());
        let before = Instant::now();
        ticker.reset();
        let after_reset = ticker.tick().await.unwrap();
        assert!(after_reset >= before + period && Instant::now() >= after_reset);
        ticker.reset_immediately();
        let at_once = Instant::now();
        assert!(ticker.tick().await.unwrap() <= at_once);
    }
}
