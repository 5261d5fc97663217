//! When the camera makes frames ([`Pace`]): while a reader's [`CameraDemand`] word
//! holds, while the frame topic has a subscriber (for readers that send no word:
//! tools, tests), or always with `always_on`.
//!
//! Idle, no frame clock runs: the camera sleeps until a demand word arrives (the
//! demand topic's event), until its once-a-second look at the frame topic's
//! subscribers (on the machine-wide 1 s grid, where the heartbeats wake it anyway),
//! or until shutdown. A word that says `wanted` starts the frame clock, whose first
//! tick is at once: the frame after the word is made as soon as the word arrives.
//! Active, every frame tick takes the pending words and reads the subscriber count
//! (shared memory, no system call), so the camera idles again within a frame period
//! of the last reader leaving or its word being withdrawn or lapsing.

use std::time::Duration;

use anyhow::Context as _;
use skymesh_ipc_types::{CameraDemand, CAMERA_DEMAND_LEASE_NS};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::timer;
use skymesh_runtime::Context;
use tokio::time::Instant;

use crate::ipc::Ports;
use crate::metrics::{Metrics, Skip};

/// Idle, how often the camera looks whether its frame topic has a subscriber that
/// sends no demand word.
const LOOK_PERIOD: Duration = Duration::from_secs(1);

/// The frame clock: ticks at `fps`, skipping (and counting) missed ticks. On a
/// timerfd ([`skymesh_runtime::timer`]): tokio's wheel would add ~16 wake-ups a
/// second to a 30 fps tick.
#[derive(Debug)]
struct Ticker {
    interval: timer::Ticker,
    period: Duration,
    prev: Option<Instant>,
}

impl Ticker {
    fn new(fps: u32) -> anyhow::Result<Self> {
        let period = Duration::from_secs_f64(1.0 / f64::from(fps));
        let interval = timer::Ticker::new(period).context("creating the frame timer")?;
        Ok(Ticker {
            interval,
            period,
            prev: None,
        })
    }

    /// The next tick, or `None` once `ctx.shutdown` is cancelled.
    async fn tick(&mut self, ctx: &Context, metrics: &Metrics) -> anyhow::Result<Option<Instant>> {
        let tick = tokio::select! {
            _ = ctx.shutdown.cancelled() => return Ok(None),
            t = self.interval.tick() => t.context("the frame timer failed")?,
        };
        if let Some(prev) = self.prev {
            let periods = (tick - prev).as_secs_f64() / self.period.as_secs_f64();
            let missed = periods.round() as u64;
            if missed > 1 {
                metrics.skipped(Skip::Late, missed - 1);
            }
        }
        self.prev = Some(tick);
        Ok(Some(tick))
    }
}

/// What woke the idle camera.
enum Wake {
    Shutdown,
    Word(CameraDemand),
    Look,
}

/// The frame ticks on demand: [`Pace::next`] returns only ticks at which frames are
/// wanted. Changes of demand are logged and exported (`skymesh_camera_active`).
#[derive(Debug)]
pub(crate) struct Pace {
    fps: u32,
    always_on: bool,
    /// Each publisher's (header service, instance) word that it reads the frames,
    /// and when that lapses (monotonic ns).
    words: Vec<((u16, u16), u64)>,
    active: Option<bool>,
    /// The frame clock, only while frames are made (idle, no timer runs).
    clock: Option<Ticker>,
    /// The idle look for subscribers that send no word.
    look: timer::Ticker,
}

impl Pace {
    pub fn new(fps: u32, always_on: bool) -> anyhow::Result<Self> {
        Ok(Pace {
            fps,
            always_on,
            words: Vec::new(),
            active: None,
            clock: None,
            look: timer::Ticker::new(LOOK_PERIOD).context("creating the demand timer")?,
        })
    }

    /// A publisher's newest word, received at `now_ns`.
    fn word(&mut self, w: &CameraDemand, now_ns: u64) {
        let key = (w.header.service, w.header.instance);
        self.words.retain(|(k, _)| *k != key);
        if w.wanted != 0 {
            self.words
                .push((key, now_ns.saturating_add(CAMERA_DEMAND_LEASE_NS)));
        }
    }

    /// Whether frames are wanted now: takes the pending words, forgets lapsed ones,
    /// reads the subscriber count; logs and exports a change.
    fn wanted(&mut self, ports: &Ports, metrics: &Metrics) -> anyhow::Result<bool> {
        while let Some(w) = ports.demand.try_recv()? {
            self.word(&w, monotonic_ns());
        }
        let now_ns = monotonic_ns();
        self.words.retain(|&(_, until)| until > now_ns);
        let readers = ports.readers();
        let words = self.words.len();
        let now = self.always_on || words > 0 || readers > 0;
        if self.active != Some(now) {
            metrics.active.set(if now { 1.0 } else { 0.0 });
            if now {
                tracing::info!(readers, words, always_on = self.always_on, "making frames");
            } else {
                tracing::info!("no reader of the frames: idle until one subscribes");
            }
            self.active = Some(now);
        }
        Ok(now)
    }

    /// The next frame tick, once frames are wanted (idle, sleeps until then); `None`
    /// once `ctx.shutdown` is cancelled.
    pub async fn next(
        &mut self,
        ctx: &Context,
        ports: &mut Ports,
        metrics: &Metrics,
    ) -> anyhow::Result<Option<Instant>> {
        loop {
            if self.wanted(ports, metrics)? {
                let clock = match &mut self.clock {
                    Some(c) => c,
                    // A new clock ticks at once: the frame after the word.
                    None => self.clock.insert(Ticker::new(self.fps)?),
                };
                return clock.tick(ctx, metrics).await;
            }
            // Dropping the clock closes its timer: nothing ticks while idle.
            self.clock = None;
            let wake = tokio::select! {
                _ = ctx.shutdown.cancelled() => Wake::Shutdown,
                w = ports.demand.recv() => Wake::Word(w?),
                t = self.look.tick() => {
                    t.context("the demand timer failed")?;
                    Wake::Look
                }
            };
            match wake {
                Wake::Shutdown => return Ok(None),
                Wake::Word(w) => self.word(&w, monotonic_ns()),
                Wake::Look => {}
            }
        }
    }
}
