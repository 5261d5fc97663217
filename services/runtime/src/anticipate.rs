//! Anticipating a periodic stream: waking *before* the next sample instead of
//! *because of* it.
//!
//! A blocking receive pays one process wake-up after the sample is published: on
//! the project's VM 60–80 µs after a 10–33 ms sleep (docs/benchmarks.md, "Small
//! samples" and "Camera frames"), more than the whole shared-memory transfer. A
//! consumer of a periodic stream (a camera's frames, a fixed-rate telemetry topic)
//! knows roughly when the next sample comes: the publisher stamps every sample with
//! its `CLOCK_MONOTONIC` send time, so the period and its jitter can be learnt from
//! the stamps. [`Anticipation`] does that and plans each wait:
//!
//! - long before the next sample is due: sleep on a timer (and on the topic's event,
//!   so an early sample still wakes the receiver at once) until shortly before it;
//! - inside the window around the expected time: poll shared memory (no syscall), so
//!   the sample is taken within a microsecond of its publication;
//! - after the window (a late or lost sample): block on the event as usual.
//!
//! The expected time comes from tracking the stamps as a clock (an alpha-beta
//! filter: phase and period), so one sample's late send does not move the next
//! prediction by as much. The window is `expected ± margin`, with
//! `margin = 50 µs + 4 × the mean absolute prediction error`, its timer set earlier
//! by how late this thread's timer wake-ups have been, and never longer than the
//! configured maximum spin. The cost is the spin: up to one window of CPU per sample
//! (`frames-bench` reports it). Pure logic here; the waits are in [`crate::ipc`]
//! and [`crate::frames`].
//!
//! Meant for one periodic publisher per topic. A stamp whole periods late (lost
//! samples) keeps the estimate; stamps that fit no period (a pause, a second
//! publisher) are ignored; after four such stamps or gaps in a row the estimate
//! starts over from the newest interval, so a rate change is followed.

use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

/// Weight of a new observation in the running averages.
const GAIN: f64 = 1.0 / 8.0;
/// The tracking filter's gains: how much of a prediction error moves the phase,
/// and the period.
const ALPHA: f64 = 1.0 / 4.0;
const BETA: f64 = 1.0 / 32.0;
/// The smallest half-window around the expected time.
const MIN_MARGIN_NS: f64 = 50_000.0;
/// Intervals longer than this are not a period (a paused stream).
const MAX_PERIOD_NS: f64 = 2e9;
/// Consecutive intervals outside the period's band before the estimate restarts.
const OUTLIERS_TO_RESET: u32 = 4;

/// What a receiver should do now to take the next sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Plan {
    /// No estimate yet, or the window has passed: block on the topic's event.
    Block,
    /// Block on the topic's event and on a timer at this `CLOCK_MONOTONIC` time (ns).
    SleepUntil(u64),
    /// Poll shared memory until this time (ns), then block.
    SpinUntil(u64),
}

/// Period, jitter and wake-up lateness learnt from one stream's send stamps.
#[derive(Debug, Clone)]
pub(crate) struct Anticipation {
    max_spin_ns: f64,
    last_stamp: Option<u64>,
    /// Estimated period, ns.
    period: Option<f64>,
    /// Predicted stamp of the next sample, ns.
    next: Option<f64>,
    /// Mean absolute deviation of the intervals from the period, ns.
    jitter: f64,
    /// How late this thread's timer wake-ups came, ns (running average).
    lateness: f64,
    outliers: u32,
    /// Receives that polled a window, and those that took their sample in it.
    pub(crate) windows: u64,
    pub(crate) hits: u64,
}

/// How an anticipating subscriber has done (see `Subscriber::set_anticipate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnticipationStats {
    /// The period learnt from the send stamps; `None` while unknown.
    pub period: Option<Duration>,
    /// Receives that polled shared memory around an expected sample.
    pub windows: u64,
    /// Of those, the receives that took their sample while polling (no wake-up).
    pub hits: u64,
    /// Half the polling window now (from the stamps' jitter).
    pub margin: Duration,
    /// How late the timer wake-ups have come (the window opens that much earlier).
    pub lateness: Duration,
}

/// A subscriber's anticipation: off until [`Anticipating::set`]. Shared by
/// `Subscriber` and `FrameSubscriber`; behind a mutex because their receives take
/// `&self` (never contended: one receiving thread).
#[derive(Debug, Default)]
pub(crate) struct Anticipating(Option<Mutex<Anticipation>>);

impl Anticipating {
    /// On with `max_spin`; zero turns it off.
    pub(crate) fn set(&mut self, max_spin: Duration) {
        self.0 = (!max_spin.is_zero()).then(|| Mutex::new(Anticipation::new(max_spin)));
    }

    /// The state, if on.
    pub(crate) fn get(&self) -> Option<&Mutex<Anticipation>> {
        self.0.as_ref()
    }

    /// Feeds a received sample's send stamp, if on.
    pub(crate) fn observe(&self, stamp_ns: u64) {
        if let Some(a) = &self.0 {
            lock(a).observe(stamp_ns);
        }
    }

    /// What it has done, if on.
    pub(crate) fn stats(&self) -> Option<AnticipationStats> {
        self.0.as_ref().map(|a| lock(a).stats())
    }
}

/// The anticipation state, also after a panic elsewhere (it holds only estimates).
pub(crate) fn lock(a: &Mutex<Anticipation>) -> MutexGuard<'_, Anticipation> {
    a.lock().unwrap_or_else(|p| p.into_inner())
}

impl Anticipation {
    /// `max_spin`: the most CPU time one receive may spend polling.
    pub(crate) fn new(max_spin: Duration) -> Self {
        Anticipation {
            max_spin_ns: max_spin.as_nanos() as f64,
            last_stamp: None,
            period: None,
            next: None,
            jitter: 0.0,
            lateness: 0.0,
            outliers: 0,
            windows: 0,
            hits: 0,
        }
    }

    /// A sample sent at `stamp_ns` (the publisher's `CLOCK_MONOTONIC`) was received.
    ///
    /// The stamps are tracked as a clock (an alpha-beta filter on the predicted
    /// stamp), not interval by interval: a source paced against absolute times
    /// (a camera, a fixed-rate loop) stays on its grid however each sample's own
    /// send time wobbles, and predicting from the previous stamp would add that
    /// sample's wobble to the next prediction.
    pub(crate) fn observe(&mut self, stamp_ns: u64) {
        let last = self.last_stamp.replace(stamp_ns);
        let Some(last) = last else {
            return;
        };
        if stamp_ns <= last {
            // The publisher restarted (or a second one interleaves): start over.
            self.period = None;
            self.outliers = 0;
            return;
        }
        let s = stamp_ns as f64;
        let (Some(period), Some(next)) = (self.period, self.next) else {
            let interval = s - last as f64;
            if interval < MAX_PERIOD_NS {
                self.period = Some(interval);
                self.next = Some(s + interval);
                self.jitter = 0.0;
            }
            return;
        };
        // Samples lost since the last one put this stamp whole periods later.
        let skipped = ((s - next) / period).round().max(0.0);
        let err = s - (next + skipped * period);
        let plausible = err.abs() < 0.5 * period && s - (last as f64) < MAX_PERIOD_NS;
        if plausible && (skipped == 0.0 || self.outliers + 1 < OUTLIERS_TO_RESET) {
            let estimate = next + skipped * period + ALPHA * err;
            let period = period + BETA * err / (skipped + 1.0);
            self.period = Some(period);
            self.next = Some(estimate + period);
            self.jitter += GAIN * (err.abs() - self.jitter);
            // A lost sample now and then is not a new rate; four gaps in a row are.
            self.outliers = if skipped == 0.0 { 0 } else { self.outliers + 1 };
            return;
        }
        self.outliers += 1;
        if self.outliers >= OUTLIERS_TO_RESET {
            let interval = s - last as f64;
            let fits = interval < MAX_PERIOD_NS;
            self.period = fits.then_some(interval);
            self.next = fits.then_some(s + interval);
            self.jitter = 0.0;
            self.outliers = 0;
        }
    }

    /// A timer wake-up planned for `planned_ns` came at `now_ns`.
    pub(crate) fn woke(&mut self, planned_ns: u64, now_ns: u64) {
        let late = now_ns.saturating_sub(planned_ns) as f64;
        self.lateness += GAIN * (late - self.lateness);
    }

    /// The estimated period, if there is one.
    pub(crate) fn period(&self) -> Option<Duration> {
        self.period.map(|p| Duration::from_nanos(p as u64))
    }

    /// What the anticipation has done so far.
    pub(crate) fn stats(&self) -> AnticipationStats {
        AnticipationStats {
            period: self.period(),
            windows: self.windows,
            hits: self.hits,
            margin: Duration::from_nanos(self.margin() as u64),
            lateness: Duration::from_nanos(self.lateness as u64),
        }
    }

    fn margin(&self) -> f64 {
        (MIN_MARGIN_NS + 4.0 * self.jitter).min(self.max_spin_ns / 2.0)
    }

    /// What to do at `now_ns` to take the next sample.
    pub(crate) fn plan(&self, now_ns: u64) -> Plan {
        let (Some(_), Some(expected)) = (self.period, self.next) else {
            return Plan::Block;
        };
        if self.max_spin_ns <= 0.0 {
            return Plan::Block;
        }
        let margin = self.margin();
        let until = expected + margin;
        // The timer is set `lateness` early so that the thread is awake when the
        // window opens; the poll itself never lasts longer than `max_spin`.
        let from = expected - margin - self.lateness;
        // Whole nanoseconds from here on, so that planning again at the planned
        // wake-up time gives the spin.
        let (from, until) = (from.max(0.0) as u64, until as u64);
        if now_ns < from {
            Plan::SleepUntil(from)
        } else if now_ns < until {
            Plan::SpinUntil(until.min(now_ns + self.max_spin_ns as u64))
        } else {
            Plan::Block
        }
    }
}

/// How often a polling receive gives its CPU to another runnable thread, ns.
const YIELD_EVERY_NS: u64 = 25_000;

/// The pause between two looks at shared memory while an anticipating receive
/// polls its window: a CPU spin hint, and every [`YIELD_EVERY_NS`] a `sched_yield`.
/// (`Subscriber::set_spin` keeps a pure spin: its polls are microseconds, and a
/// yield there handed the CPU to the other side of a spinning ping-pong.)
///
/// Why the yield: a poll can last milliseconds, and the thread it waits for (the
/// publisher) may be woken on the polling thread's CPU. The scheduler then need not
/// preempt the poll at once (a thread that slept until just now has its slice), so
/// the publisher waited up to a whole slice, ~1.3 ms on the project's VM, before it
/// could stamp and send: every third frame of a 30 fps stream was 1.3 ms late and
/// the frames that were taken in the window came 45–60 µs after their stamp instead
/// of 5–8 (frames-bench, `FRAMES_BENCH_TRACE`). A `sched_yield` lets whatever is
/// runnable on this CPU go first; with nothing runnable it returns at once (one
/// syscall per [`YIELD_EVERY_NS`] of polling).
#[derive(Debug)]
pub(crate) struct PollPause {
    next_yield_ns: u64,
}

impl PollPause {
    pub(crate) fn new(now_ns: u64) -> Self {
        PollPause {
            next_yield_ns: now_ns.saturating_add(YIELD_EVERY_NS),
        }
    }

    /// Pauses between two looks; `now_ns` is the caller's clock reading. True if
    /// it yielded the CPU.
    pub(crate) fn pause(&mut self, now_ns: u64) -> bool {
        if now_ns >= self.next_yield_ns {
            std::thread::yield_now();
            self.next_yield_ns = now_ns.saturating_add(YIELD_EVERY_NS);
            true
        } else {
            std::hint::spin_loop();
            false
        }
    }
}

/// Polls with `take` (pausing with [`PollPause`] between looks) until it finds
/// something, `until_ns` (`CLOCK_MONOTONIC`) passes, or `expired(now_ns)` says the
/// caller's own deadline has; `None` then. The anticipating receives' window and
/// the early frame receive's wait for a send.
pub(crate) fn poll_until<R, E>(
    until_ns: u64,
    expired: impl Fn(u64) -> bool,
    mut take: impl FnMut() -> Result<Option<R>, E>,
) -> Result<Option<R>, E> {
    let mut pause = PollPause::new(crate::clock::monotonic_ns());
    loop {
        if let Some(r) = take()? {
            return Ok(Some(r));
        }
        let now = crate::clock::monotonic_ns();
        if now >= until_ns || expired(now) {
            return Ok(None);
        }
        pause.pause(now);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;
    const US: u64 = 1_000;

    fn learnt(period: u64, n: u64) -> Anticipation {
        let mut a = Anticipation::new(Duration::from_micros(500));
        for i in 0..n {
            a.observe(1_000 * MS + i * period);
        }
        a
    }

    #[test]
    fn blocks_until_a_period_is_known() {
        let mut a = Anticipation::new(Duration::from_micros(500));
        assert_eq!(a.plan(0), Plan::Block);
        a.observe(10 * MS);
        assert_eq!(a.plan(10 * MS + 1), Plan::Block);
        a.observe(43 * MS);
        assert_eq!(a.period(), Some(Duration::from_millis(33)));
    }

    #[test]
    fn sleeps_then_spins_around_the_expected_time_then_blocks() {
        let a = learnt(33 * MS, 10);
        let last = 1_000 * MS + 9 * 33 * MS;
        let expected = last + 33 * MS;
        // No jitter: the window is ±50 µs.
        assert_eq!(a.plan(last + MS), Plan::SleepUntil(expected - 50 * US));
        assert_eq!(
            a.plan(expected - 10 * US),
            Plan::SpinUntil(expected + 50 * US)
        );
        assert_eq!(a.plan(expected + 50 * US), Plan::Block);
    }

    #[test]
    fn jitter_widens_the_window_up_to_the_maximum_spin() {
        let mut a = Anticipation::new(Duration::from_micros(500));
        let mut t = 0;
        for i in 0..40u64 {
            t += 10 * MS + if i % 2 == 0 { 40 * US } else { 0 };
            a.observe(t);
        }
        let Plan::SleepUntil(from) = a.plan(t + MS) else {
            panic!("expected a sleep");
        };
        let Plan::SpinUntil(until) = a.plan(from) else {
            panic!("expected a spin");
        };
        let window = until - from;
        assert!(
            window > 100 * US,
            "jitter must widen the ±50 µs window: {window}"
        );
        assert!(
            window <= 500 * US,
            "never more than the maximum spin: {window}"
        );

        let mut wild = Anticipation::new(Duration::from_micros(200));
        let mut t = 0;
        for i in 0..40u64 {
            t += 10 * MS + if i % 2 == 0 { 3 * MS } else { 0 };
            wild.observe(t);
        }
        let Plan::SleepUntil(from) = wild.plan(t + 100 * US) else {
            panic!("expected a sleep");
        };
        let Plan::SpinUntil(until) = wild.plan(from) else {
            panic!("expected a spin");
        };
        assert!(until - from <= 200 * US);
    }

    #[test]
    fn late_timer_wake_ups_move_the_wake_earlier() {
        let mut a = learnt(10 * MS, 10);
        let last = 1_000 * MS + 9 * 10 * MS;
        let Plan::SleepUntil(before) = a.plan(last + MS) else {
            panic!("expected a sleep");
        };
        for _ in 0..50 {
            a.woke(0, 80 * US);
        }
        let Plan::SleepUntil(after) = a.plan(last + MS) else {
            panic!("expected a sleep");
        };
        assert!(
            before - after > 70 * US && before - after <= 80 * US,
            "{before} → {after}"
        );
    }

    #[test]
    fn lost_samples_do_not_change_the_period_and_a_new_rate_is_followed() {
        let mut a = learnt(10 * MS, 10);
        let mut t = 1_000 * MS + 9 * 10 * MS;
        // One sample lost: a 20 ms interval is ignored.
        t += 20 * MS;
        a.observe(t);
        assert_eq!(a.period(), Some(Duration::from_millis(10)));
        // The stream now runs at 25 Hz: followed after four intervals.
        for _ in 0..4 {
            t += 40 * MS;
            a.observe(t);
        }
        assert_eq!(a.period(), Some(Duration::from_millis(40)));
        // A restarted publisher (stamps go back): no estimate until two new stamps.
        a.observe(5 * MS);
        assert_eq!(a.period(), None);
        assert_eq!(a.plan(6 * MS), Plan::Block);
    }

    #[test]
    fn one_late_send_moves_the_next_prediction_only_partly() {
        let mut a = learnt(10 * MS, 20);
        let grid = |k: u64| 1_000 * MS + k * 10 * MS;
        // Sample 20 was sent 2 ms late; the source stays on its grid.
        a.observe(grid(20) + 2 * MS);
        let Plan::SleepUntil(from) = a.plan(grid(20) + 3 * MS) else {
            panic!("expected a sleep");
        };
        let Plan::SpinUntil(until) = a.plan(from) else {
            panic!("expected a spin");
        };
        let expected = until - a.stats().margin.as_nanos() as u64;
        // Interval by interval it would be grid(21) + 2 ms.
        assert!(
            expected > grid(21) && expected < grid(21) + 700 * US,
            "expected {} µs after the grid",
            expected.saturating_sub(grid(21)) / US
        );
    }

    #[test]
    fn a_poll_yields_the_cpu_every_interval_and_spins_between() {
        let start = 5 * MS;
        let mut pause = PollPause::new(start);
        let yields: Vec<u64> = (0..=100u64)
            .map(|i| start + i * US)
            .filter(|&now| pause.pause(now))
            .collect();
        // 100 µs of polling looked at every microsecond: a yield 25, 50, 75 and
        // 100 µs in, nothing in between.
        let every = YIELD_EVERY_NS;
        assert_eq!(
            yields,
            vec![
                start + every,
                start + 2 * every,
                start + 3 * every,
                start + 4 * every
            ]
        );
        // A look that came late (the thread was preempted) restarts the interval.
        let mut pause = PollPause::new(start);
        assert!(pause.pause(start + 3 * every + 7 * US));
        assert!(!pause.pause(start + 4 * every));
        assert!(pause.pause(start + 4 * every + 7 * US));
    }

    #[test]
    fn zero_spin_always_blocks() {
        let mut a = Anticipation::new(Duration::ZERO);
        a.observe(0);
        a.observe(10 * MS);
        a.observe(20 * MS);
        assert_eq!(a.plan(21 * MS), Plan::Block);
        assert_eq!(a.plan(29_999 * US), Plan::Block);
    }
}
