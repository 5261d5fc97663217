//! The pure core: requests in, replies and state out, time passed in explicitly.
//!
//! [`Hardware`] owns every device (behind the [`crate::backend`] traits) and what is
//! known about it. [`Hardware::handle`] answers one [`HardwareRequest`] with one
//! [`HardwareReply`]; [`Hardware::tick`] runs whatever schedule is due;
//! [`Hardware::poll_inputs`] re-reads the input lines; [`Hardware::state`] is the
//! [`HardwareState`] to publish. Nothing here sleeps or spawns: a power command to run
//! is returned as an [`Effect`], and the next moment something is due is
//! [`Hardware::next_due`], so the service sleeps exactly until then and the tests
//! step time by hand.
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | start, dispatch, ticks, state |
//! | `io.rs` | LEDs and GPIO lines |
//! | `channels.rs` | power channels: on/off/toggle, schedules, save, restart |
//! | `lcd.rs` | the two-line display |
//! | `system_power.rs` | the companion computer's power down / up |

mod channels;
mod io;
mod lcd;
mod system_power;
#[cfg(test)]
mod tests;
mod throttle;

use std::path::PathBuf;
use std::time::Duration;

use skymesh_ipc_types::hardware::{LedEntry, PowerChannelEntry, HW_MAX_ENTRIES};
use skymesh_ipc_types::{
    FixedStr, GpioEntry, HardwareOp, HardwareReply, HardwareRequest, HardwareResult, HardwareState,
    HwName,
};

use crate::backend::{self, BackendError, LineUse};
use crate::config::Settings;
use crate::metrics::{Device, Metrics};
use crate::persist::{Loaded, SavedStates};

pub use system_power::PowerCommand;

/// The two clocks the core needs: schedules in seconds from now run on the
/// monotonic one, schedules at a Unix time are converted with the wall clock once,
/// when they are requested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Now {
    /// Monotonic time since an arbitrary origin (`CLOCK_MONOTONIC`).
    pub mono: Duration,
    /// Seconds since the Unix epoch.
    pub unix_s: f64,
}

impl Now {
    /// The current time on both clocks.
    pub fn current() -> Now {
        Now {
            mono: Duration::from_nanos(skymesh_runtime::clock::monotonic_ns()),
            unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
        }
    }

    /// `self` plus `d` on both clocks (tests step time with it).
    pub fn after(self, d: Duration) -> Now {
        Now {
            mono: self.mono + d,
            unix_s: self.unix_s + d.as_secs_f64(),
        }
    }
}

/// Something the service must do for the core.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Effect {
    /// Run `argv` (no shell) for a companion power operation that is due.
    RunCommand { op: PowerCommand, argv: Vec<String> },
}

/// The answer to one request.
#[derive(Debug, Clone, PartialEq)]
pub struct Answer {
    pub reply: HardwareReply,
    /// The state changed (publish it).
    pub changed: bool,
    pub effects: Vec<Effect>,
}

/// What [`Hardware::tick`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ticked {
    pub changed: bool,
    pub effects: Vec<Effect>,
}

/// Why the service could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("creating the state directory {path}: {source}")]
    StateDir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{device}: {source}")]
    Device {
        device: String,
        source: BackendError,
    },
}

fn device_err(kind: &str, name: &str) -> impl FnOnce(BackendError) -> StartError {
    let device = format!("{kind} `{name}`");
    move |source| StartError::Device { device, source }
}

/// How one request ended, before it becomes a [`HardwareReply`].
#[derive(Debug)]
struct Done {
    result: HardwareResult,
    value: u8,
    /// Replaces the request's sub_op in the reply (power operations).
    sub_op: Option<u8>,
    /// Seconds until the pending operation the reply is about.
    remaining_s: Option<f64>,
    message: String,
    changed: bool,
    effects: Vec<Effect>,
}

impl Done {
    fn ok(value: u8, changed: bool) -> Done {
        Done {
            result: HardwareResult::Ok,
            value,
            sub_op: None,
            remaining_s: None,
            message: String::new(),
            changed,
            effects: Vec::new(),
        }
    }

    fn fail(result: HardwareResult, message: impl Into<String>) -> Done {
        Done {
            message: message.into(),
            ..Done::ok(0, false)
        }
        .with_result(result)
    }

    fn with_result(mut self, result: HardwareResult) -> Done {
        self.result = result;
        self
    }

    fn with_value(mut self, value: u8) -> Done {
        self.value = value;
        self
    }

    fn with_message(mut self, message: impl Into<String>) -> Done {
        self.message = message.into();
        self
    }
}

/// Every device the service owns, and what is known about it.
#[derive(Debug)]
pub struct Hardware {
    leds: Vec<io::LedSlot>,
    gpios: Vec<io::GpioSlot>,
    channels: channels::Channels,
    lcd: lcd::LcdState,
    system: system_power::SystemPower,
    metrics: Metrics,
    throttle: throttle::Throttle,
}

impl Hardware {
    /// Opens every configured device: the state directory is created, outputs are
    /// driven to their initial level, power channels to their saved state (else their
    /// default), the LCD is switched on blank; LEDs and inputs are read.
    pub fn start(settings: &Settings, metrics: Metrics) -> Result<Hardware, StartError> {
        let dir = &settings.state_dir;
        std::fs::create_dir_all(dir).map_err(|source| StartError::StateDir {
            path: dir.clone(),
            source,
        })?;
        let (saved, loaded) = SavedStates::load(dir);
        match &loaded {
            Loaded::Fresh | Loaded::Existing => {}
            Loaded::Corrupt { error, kept } => tracing::warn!(
                file = %saved.path().display(),
                error = %error,
                kept = ?kept,
                "saved power-channel states are unreadable; using the configured defaults"
            ),
            Loaded::Unreadable { error } => tracing::warn!(
                file = %saved.path().display(),
                error = %error,
                "cannot read the saved power-channel states; using the configured defaults"
            ),
        }
        let mut leds = Vec::with_capacity(settings.leds.len());
        for l in &settings.leds {
            let mut dev =
                backend::open_led(&l.backend, dir, &l.name).map_err(device_err("LED", &l.name))?;
            let value = dev.get().map_err(device_err("LED", &l.name))?;
            leds.push(io::LedSlot {
                name: l.name.clone(),
                dev,
                value,
            });
        }
        let mut gpios = Vec::with_capacity(settings.gpios.len());
        for g in &settings.gpios {
            let usage = if g.output {
                LineUse::Output { initial: g.initial }
            } else {
                LineUse::Input { initial: g.initial }
            };
            let mut dev = backend::open_line(&g.backend, dir, "gpio", &g.name, g.active_low, usage)
                .map_err(device_err("GPIO line", &g.name))?;
            let value = if g.output {
                g.initial
            } else {
                dev.get().map_err(device_err("GPIO line", &g.name))?
            };
            gpios.push(io::GpioSlot {
                name: g.name.clone(),
                dev,
                output: g.output,
                value,
            });
        }
        let channels = channels::Channels::start(settings, saved, &metrics)?;
        let lcd = lcd::LcdState::start(settings).map_err(device_err("LCD", "lcd"))?;
        Ok(Hardware {
            leds,
            gpios,
            channels,
            lcd,
            system: system_power::SystemPower::new(&settings.power),
            metrics,
            throttle: throttle::Throttle::default(),
        })
    }

    /// The metrics the core counts into (the service counts power commands there too).
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// Answers one request (running whatever schedule is due first and after).
    pub fn handle(&mut self, req: &HardwareRequest, now: Now) -> Answer {
        let before = self.tick(now);
        let op = req.op();
        let done = match op {
            Err(e) => Done::fail(
                HardwareResult::InvalidValue,
                format!("unknown operation {} ({e})", req.op),
            ),
            Ok(HardwareOp::LedSet) => self.led(req, true),
            Ok(HardwareOp::LedQuery) => self.led(req, false),
            Ok(HardwareOp::GpioSet) => self.gpio(req, true),
            Ok(HardwareOp::GpioGet) => self.gpio(req, false),
            Ok(HardwareOp::PowerChannel) => match request_name(req) {
                Ok(name) => self.channels.request(name, req, now, &self.metrics),
                Err(done) => done,
            },
            Ok(HardwareOp::Lcd) => self.lcd.request(req, &self.metrics),
            Ok(HardwareOp::SystemPower) => self.system.request(req, now),
        };
        let after = self.tick(now);
        self.metrics.request(op.ok(), done.result);
        self.log(req, &done, now);
        let reply = HardwareReply {
            request_id: req.request_id,
            requester_service: req.header.service,
            requester_instance: req.header.instance,
            op: req.op,
            sub_op: done.sub_op.unwrap_or(req.sub_op),
            result: done.result.to_wire(),
            value: done.value,
            time_remaining_s: done.remaining_s.map_or(-1.0, |s| s.max(0.0) as f32),
            name: req.name,
            message: FixedStr::new(&done.message),
            ..HardwareReply::default()
        };
        let mut effects = before.effects;
        effects.extend(done.effects);
        effects.extend(after.effects);
        Answer {
            reply,
            changed: before.changed || done.changed || after.changed,
            effects,
        }
    }

    fn log(&mut self, req: &HardwareRequest, done: &Done, now: Now) {
        let op = req.op().map_or("unknown", HardwareOp::as_str);
        let name = req.name.as_str();
        if done.result == HardwareResult::Ok {
            tracing::debug!(op, sub_op = req.sub_op, name, requester = req.header.service, message = %done.message, "request done");
            return;
        }
        let Some(left_out) = self.throttle.allow(now.mono) else {
            return;
        };
        let result = done.result.as_str();
        let message = done.message.as_str();
        match done.result {
            HardwareResult::BackendError | HardwareResult::Refused => tracing::error!(
                op,
                sub_op = req.sub_op,
                name,
                result,
                requester = req.header.service,
                similar_lines_left_out = left_out,
                "{message}"
            ),
            _ => tracing::warn!(
                op,
                sub_op = req.sub_op,
                name,
                result,
                requester = req.header.service,
                similar_lines_left_out = left_out,
                "request refused: {message}"
            ),
        }
    }

    /// Runs every power-channel schedule and companion power operation that is due.
    pub fn tick(&mut self, now: Now) -> Ticked {
        let changed = self.channels.run_due(now, &self.metrics);
        let effects = self.system.run_due(now);
        Ticked {
            changed: changed || !effects.is_empty(),
            effects,
        }
    }

    /// How long until the next scheduled operation, if any.
    pub fn next_due(&self, now: Now) -> Option<Duration> {
        [self.channels.next_due(), self.system.next_due()]
            .into_iter()
            .flatten()
            .min()
            .map(|at| at.saturating_sub(now.mono))
    }

    /// Re-reads every input line; true if one changed.
    pub fn poll_inputs(&mut self) -> bool {
        let mut changed = false;
        for g in self.gpios.iter_mut().filter(|g| !g.output) {
            match g.dev.get() {
                Ok(v) => {
                    changed |= v != g.value;
                    g.value = v;
                }
                Err(e) => {
                    self.metrics.backend_error(Device::Gpio);
                    tracing::warn!(line = %g.name, error = %e, "reading an input line failed");
                }
            }
        }
        changed
    }

    /// The whole state, with countdowns from `now`.
    pub fn state(&self, now: Now) -> HardwareState {
        let mut s = HardwareState::default();
        let mut leds = [LedEntry::default(); HW_MAX_ENTRIES];
        for (slot, l) in leds.iter_mut().zip(&self.leds) {
            slot.name = HwName::new(&l.name);
            slot.value = l.value;
        }
        let mut gpios = [GpioEntry::default(); HW_MAX_ENTRIES];
        for (slot, g) in gpios.iter_mut().zip(&self.gpios) {
            slot.name = HwName::new(&g.name);
            slot.value = g.value.into();
            slot.output = g.output.into();
        }
        let mut channels = [PowerChannelEntry::default(); HW_MAX_ENTRIES];
        let n_channels = self.channels.fill(&mut channels, now);
        s.leds = leds;
        s.gpios = gpios;
        s.channels = channels;
        s.n_leds = self.leds.len().min(HW_MAX_ENTRIES) as u8;
        s.n_gpios = self.gpios.len().min(HW_MAX_ENTRIES) as u8;
        s.n_channels = n_channels;
        self.lcd.fill(&mut s);
        self.system.fill(&mut s, now);
        s
    }
}

/// The request's name, or the reply for a name that cannot be used.
fn request_name(req: &HardwareRequest) -> Result<&str, Done> {
    match req.name.try_as_str() {
        None => Err(Done::fail(
            HardwareResult::InvalidValue,
            "the name is not valid UTF-8",
        )),
        Some("") => Err(Done::fail(HardwareResult::UnknownName, "no name given")),
        Some(n) => Ok(n),
    }
}

fn unknown(kind: &str, name: &str) -> Done {
    Done::fail(
        HardwareResult::UnknownName,
        format!("no {kind} named `{name}` is configured"),
    )
}

/// Seconds (`sched_s`) of a scheduled operation: finite, 0..=[`crate::config::MAX_SCHEDULE_S`].
fn schedule_seconds(s: f64) -> Result<Duration, Done> {
    if s.is_finite() && (0.0..=crate::config::MAX_SCHEDULE_S).contains(&s) {
        Ok(Duration::from_secs_f64(s))
    } else {
        Err(Done::fail(
            HardwareResult::InvalidValue,
            format!("sched_s {s} is not 0..=604800 seconds"),
        ))
    }
}
