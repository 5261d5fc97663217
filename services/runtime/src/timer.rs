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
//!
//! **One grid for the whole machine.** A [`Ticker`] does not tick at multiples of
//! its period from whenever it was created but on a grid of `CLOCK_MONOTONIC`
//! itself ([`grid_at_or_after`]): every 500 ms heartbeat of every service falls on
//! the same instants, and so do two 30 Hz loops in two processes, and a 50 Hz loop
//! and a 500 ms one meet every 500 ms. The processes then wake together, and one
//! exit from idle serves them all: on this 2-core VM four processes sleeping to the
//! same 50 Hz deadlines cost 25–27 µs of CPU per wake-up each, staggered 38–45 µs
//! (docs/benchmarks.md, "One grid for every clock"). Periods of a whole fraction
//! of a second (1/n s: 30 Hz, 50 Hz, 2 Hz) lie on an exact grid of `n` points per
//! second, so 33 333 333 ns does not drift away from the 100 ms points.

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

    /// False under a paused test clock (tokio's own sleep is used instead, and
    /// instants are not on the `CLOCK_MONOTONIC` grid).
    fn on_real_clock(&self) -> bool {
        self.fd.is_some()
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

const SECOND_NS: u128 = 1_000_000_000;

/// The first instant at or after `t_ns` (`CLOCK_MONOTONIC` ns) of the grid of
/// `period` shifted by `phase` (taken modulo the period). The grid is the same in
/// every process of the machine. A period of a whole fraction of a second (1/n s
/// to the nanosecond, e.g. 33 333 333 ns for 30 Hz) has exactly `n` points a
/// second, at ⌈k·10⁹/n⌉ ns, so its points meet those of 10 Hz, 2 Hz or 1 Hz
/// forever instead of drifting a nanosecond every few ticks; any other period's
/// points are its whole multiples.
pub fn grid_at_or_after(t_ns: u64, period: Duration, phase: Duration) -> u64 {
    let p = period.as_nanos().max(1);
    let offset = phase.as_nanos() % p;
    let t = u128::from(t_ns).saturating_sub(offset);
    let n = (SECOND_NS + p / 2) / p;
    let at = if p <= SECOND_NS && n > 0 && SECOND_NS.abs_diff(n * p) <= n {
        // The smallest k with ⌈k·10⁹/n⌉ ≥ t.
        let k = if t == 0 {
            0
        } else {
            (t - 1) * n / SECOND_NS + 1
        };
        (k * SECOND_NS).div_ceil(n)
    } else {
        t.div_ceil(p) * p
    };
    u64::try_from(at + offset).unwrap_or(u64::MAX)
}

/// How long from now to the first point of the grid of `period` (phase zero) at
/// least half a period on: for a once-in-a-while job that should fall on the
/// instants every other process's ticker shares (a once-a-second status on the
/// heartbeats' whole seconds). Between half a period and a period and a half.
pub fn until_grid_point(period: Duration) -> Duration {
    let now_ns = monotonic_ns();
    let at_ns = grid_at_or_after(
        now_ns.saturating_add(nanos(period) / 2),
        period,
        Duration::ZERO,
    );
    Duration::from_nanos(at_ns.saturating_sub(now_ns))
}

/// `at` as `CLOCK_MONOTONIC` ns (through one reading of each clock).
fn monotonic_ns_of(at: Instant) -> u64 {
    let (now, now_ns) = (Instant::now(), monotonic_ns());
    if at >= now {
        now_ns.saturating_add(nanos(at - now))
    } else {
        now_ns.saturating_sub(nanos(now - at))
    }
}

/// The tokio instant of a `CLOCK_MONOTONIC` time in ns.
pub fn instant_at(at_ns: u64) -> Instant {
    let (now, now_ns) = (Instant::now(), monotonic_ns());
    if at_ns >= now_ns {
        now + Duration::from_nanos(at_ns - now_ns)
    } else {
        now.checked_sub(Duration::from_nanos(now_ns - at_ns))
            .unwrap_or(now)
    }
}

/// A periodic tick on a [`Timer`]: the first [`Ticker::tick`] returns at once,
/// then one every `period` on the machine-wide grid ([`grid_at_or_after`]; the
/// first of them at least half a period after the start). Ticks missed while the
/// loop was busy are skipped, not burst (tokio's `MissedTickBehavior::Skip`).
/// Under a paused test clock the grid starts at the first tick instead.
#[derive(Debug)]
pub struct Ticker {
    timer: Timer,
    period: Duration,
    phase: Duration,
    next: Instant,
}

impl Ticker {
    /// Ticks on the grid's points. `period` must not be zero.
    pub fn new(period: Duration) -> io::Result<Self> {
        Self::with_phase(period, Duration::ZERO)
    }

    /// Ticks `phase` after the grid's points (modulo the period): for a loop that
    /// must run after another process's tick on the same grid, e.g. one that reads
    /// what that tick publishes. `period` must not be zero.
    pub fn with_phase(period: Duration, phase: Duration) -> io::Result<Self> {
        if period.is_zero() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "a ticker's period must not be zero",
            ));
        }
        Ok(Ticker {
            timer: Timer::new()?,
            period,
            phase,
            next: Instant::now(),
        })
    }

    /// The first tick time at or after `at`: on the grid, or `at` itself under a
    /// paused test clock.
    fn at_or_after(&self, at: Instant) -> Instant {
        if !self.timer.on_real_clock() {
            return at;
        }
        instant_at(grid_at_or_after(
            monotonic_ns_of(at),
            self.period,
            self.phase,
        ))
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
        if !self.timer.on_real_clock() {
            self.next = due + self.period;
            if self.next <= now {
                // Behind by more than a period: the next tick of the grid after now.
                let behind = nanos(now - due) / nanos(self.period).max(1);
                self.next = due + self.period * u32::try_from(behind + 1).unwrap_or(u32::MAX);
            }
            return Ok(due);
        }
        // Half a period on from a tick is past its grid point (whatever the
        // conversion between the clocks rounded) and before the next one.
        self.next = self.at_or_after(due + self.period / 2);
        if self.next <= now {
            // Behind by more than a period: the next grid point after now.
            self.next = self.at_or_after(now + Duration::from_nanos(1));
        }
        Ok(due)
    }

    /// The next tick is the first grid point at least half a period from now
    /// (a period from now under a paused test clock).
    pub fn reset(&mut self) {
        let now = Instant::now();
        self.next = if self.timer.on_real_clock() {
            self.at_or_after(now + self.period / 2)
        } else {
            now + self.period
        };
    }

    /// No tick before `at`: the next is the first grid point at or after it (`at`
    /// itself under a paused test clock). For a loop that knows it has nothing to
    /// do until then.
    pub fn skip_to(&mut self, at: Instant) {
        self.next = self.at_or_after(at);
    }

    /// The next tick comes at once (then on the grid).
    pub fn reset_immediately(&mut self) {
        self.next = Instant::now();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn until_grid_point_lands_on_the_grid_half_a_period_on_or_more() {
        for period in [Duration::from_secs(1), Duration::from_millis(500)] {
            let before = monotonic_ns();
            let d = until_grid_point(period);
            let after = monotonic_ns();
            assert!(d <= period * 3 / 2, "{d:?} for {period:?}");
            // The target, read against either clock reading, is a grid point.
            let lo = before + nanos(d);
            let hi = after + nanos(d);
            let at = grid_at_or_after(lo, period, Duration::ZERO);
            assert!(
                at <= hi,
                "{lo}..={hi} holds no point of the {period:?} grid"
            );
            assert!(
                at >= before + nanos(period) / 2,
                "less than half a period on"
            );
        }
    }

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

    /// Instants converted through two clock readings: equal within this.
    const SLOP: Duration = Duration::from_micros(200);

    fn close(a: Duration, b: Duration) -> bool {
        a.abs_diff(b) <= SLOP
    }

    /// Distance of an instant from the nearest point of `period`'s grid.
    fn off_grid(at: Instant, period: Duration) -> Duration {
        let ns = monotonic_ns_of(at);
        let up = grid_at_or_after(ns, period, Duration::ZERO) - ns;
        let down =
            ns - grid_at_or_after(ns.saturating_sub(nanos(period)) + 1, period, Duration::ZERO);
        Duration::from_nanos(up.min(down))
    }

    #[tokio::test]
    async fn ticks_keep_the_machine_grid_and_skip_what_was_missed() {
        let period = Duration::from_millis(20);
        let start = Instant::now();
        let mut ticker = Ticker::new(period).unwrap();
        let first = ticker.tick().await.unwrap();
        assert!(
            first <= Instant::now() && first >= start,
            "the first tick at once"
        );
        let second = ticker.tick().await.unwrap();
        assert!(second - first >= period / 2 && second - first <= period * 3 / 2 + SLOP);
        assert!(
            off_grid(second, period) <= SLOP,
            "{:?}",
            off_grid(second, period)
        );
        let third = ticker.tick().await.unwrap();
        assert!(close(third - second, period), "{:?}", third - second);
        assert!(Instant::now() >= third);
        // Busy for five periods: the missed tick is due at once, then the first
        // grid point after now.
        std::thread::sleep(period * 5 + Duration::from_millis(5));
        let late = ticker.tick().await.unwrap();
        assert!(close(late - third, period), "{:?}", late - third);
        let next = ticker.tick().await.unwrap();
        let gap = next - third;
        assert!(
            gap >= period * 6 - SLOP && gap <= period * 7 + SLOP,
            "{gap:?}"
        );
        assert!(off_grid(next, period) <= SLOP);
        assert!(Ticker::new(Duration::ZERO).is_err());
        let before = Instant::now();
        ticker.reset();
        let after_reset = ticker.tick().await.unwrap();
        assert!(after_reset + SLOP >= before + period / 2 && Instant::now() >= after_reset);
        assert!(off_grid(after_reset, period) <= SLOP);
        ticker.reset_immediately();
        let at_once = Instant::now();
        assert!(ticker.tick().await.unwrap() <= at_once);
    }

    #[tokio::test]
    async fn a_phase_shifts_the_ticks_off_the_grid_by_that_much() {
        let period = Duration::from_millis(20);
        let phase = Duration::from_millis(3);
        let mut ticker = Ticker::with_phase(period, phase).unwrap();
        ticker.tick().await.unwrap();
        let t = ticker.tick().await.unwrap();
        assert!(close(off_grid(t - phase, period), Duration::ZERO));
    }

    #[test]
    fn grid_points_are_whole_multiples_or_exact_fractions_of_a_second() {
        const MS: u64 = 1_000_000;
        const S: u64 = 1_000 * MS;
        let ms = Duration::from_millis;
        // Plain multiples.
        assert_eq!(grid_at_or_after(0, ms(20), Duration::ZERO), 0);
        assert_eq!(grid_at_or_after(1, ms(20), Duration::ZERO), 20 * MS);
        assert_eq!(grid_at_or_after(20 * MS, ms(20), Duration::ZERO), 20 * MS);
        assert_eq!(grid_at_or_after(S + 1, ms(300), Duration::ZERO), 1200 * MS);
        assert_eq!(grid_at_or_after(3 * S + 1, ms(2000), Duration::ZERO), 4 * S);
        // A phase, and a phase of more than a period wraps.
        assert_eq!(grid_at_or_after(1, ms(20), ms(3)), 3 * MS);
        assert_eq!(grid_at_or_after(4 * MS, ms(20), ms(23)), 23 * MS);
        // 30 Hz: 33 333 333 ns, thirty points a second, meeting every whole second
        // and every 100 ms however long the machine has been up.
        let hz30 = Duration::from_secs(1) / 30;
        assert_eq!(hz30.as_nanos(), 33_333_333);
        let day = 86_400 * S;
        assert_eq!(
            grid_at_or_after(day + 1, hz30, Duration::ZERO),
            day + 33_333_334
        );
        assert_eq!(grid_at_or_after(day - 1, hz30, Duration::ZERO), day);
        assert_eq!(
            grid_at_or_after(day + 99 * MS, hz30, Duration::ZERO),
            day + 100 * MS
        );
        let mut t = day;
        for _ in 0..90 {
            let next = grid_at_or_after(t + 1, hz30, Duration::ZERO);
            assert!(
                next - t == 33_333_333 || next - t == 33_333_334,
                "{}",
                next - t
            );
            t = next;
        }
        assert_eq!(t, day + 3 * S);
    }

    #[tokio::test]
    async fn a_ticker_skipped_ahead_ticks_next_on_the_grid_at_or_after_that_time() {
        let period = Duration::from_millis(10);
        let mut t = Ticker::new(period).unwrap();
        t.tick().await.unwrap();
        let at = Instant::now() + Duration::from_millis(95);
        t.skip_to(at);
        let due = t.tick().await.unwrap();
        assert!(due >= at, "ticked before the time skipped to");
        assert!(Instant::now() >= at);
        // On the grid, up to the conversion between the two clocks (ns to µs).
        let on_grid = |at: Instant| {
            let off = monotonic_ns_of(at) % nanos(period);
            assert!(
                off < 100_000 || off > nanos(period) - 100_000,
                "{off} ns off the grid"
            );
        };
        on_grid(due);
        // And the grid's ticks after it (a loaded machine may skip one).
        let next = t.tick().await.unwrap();
        on_grid(next);
        assert!(next - due >= period - Duration::from_micros(100));
    }
}
