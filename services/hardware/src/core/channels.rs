//! Power channels: switched outputs with schedules and a saved state.
//!
//! Each channel has at most one pending turn-on and one pending turn-off (monotonic
//! deadlines); a new schedule of the same kind replaces the old; on, off and toggle
//! leave schedules alone; RESTART is off now plus a pending turn-on after the
//! restart delay (it takes the pending-on slot). Due operations run oldest first; one
//! whose device fails is logged and counted, and not retried. Schedules are volatile;
//! SAVE persists the current state (see [`crate::persist`]).

use std::time::Duration;

use skymesh_ipc_types::hardware::{PowerChannelEntry, PowerChannelOp};
use skymesh_ipc_types::{HardwareRequest, HardwareResult, HwName};
use skymesh_runtime::Gauge;

use super::{device_err, schedule_seconds, unknown, Done, Now, StartError};
use crate::backend::{self, Line, LineUse};
use crate::config::Settings;
use crate::metrics::{Device, Metrics};
use crate::persist::SavedStates;

#[derive(Debug)]
struct Channel {
    name: String,
    dev: Box<dyn Line>,
    on: bool,
    sched_on: Option<Duration>,
    sched_off: Option<Duration>,
    gauge: Gauge,
}

impl Channel {
    /// Drives the channel; the known state changes only if the device did.
    fn switch(&mut self, on: bool, metrics: &Metrics) -> Result<bool, String> {
        match self.dev.set(on) {
            Ok(()) => {
                let changed = on != self.on;
                self.on = on;
                self.gauge.set(if on { 1.0 } else { 0.0 });
                Ok(changed)
            }
            Err(e) => {
                metrics.backend_error(Device::PowerChannel);
                Err(e.to_string())
            }
        }
    }

    fn soonest(&self) -> Option<Duration> {
        self.sched_on.into_iter().chain(self.sched_off).min()
    }
}

/// Every power channel and the saved states.
#[derive(Debug)]
pub(super) struct Channels {
    list: Vec<Channel>,
    saved: SavedStates,
    restart_delay: Duration,
}

fn remaining(at: Option<Duration>, now: Now) -> f32 {
    at.map_or(-1.0, |at| at.saturating_sub(now.mono).as_secs_f32())
}

impl Channels {
    pub(super) fn start(
        settings: &Settings,
        saved: SavedStates,
        metrics: &Metrics,
    ) -> Result<Channels, StartError> {
        let mut list = Vec::with_capacity(settings.channels.len());
        for c in &settings.channels {
            let restored = saved.get(&c.name);
            let on = restored.unwrap_or(c.default_on);
            let dev = backend::open_line(
                &c.backend,
                &settings.state_dir,
                "power",
                &c.name,
                c.active_low,
                LineUse::Output { initial: on },
            )
            .map_err(device_err("power channel", &c.name))?;
            tracing::info!(
                channel = %c.name,
                on,
                from = if restored.is_some() { "saved state" } else { "configured default" },
                backend = %c.backend,
                "power channel"
            );
            let gauge = metrics.channel_gauge(&c.name);
            gauge.set(if on { 1.0 } else { 0.0 });
            list.push(Channel {
                name: c.name.clone(),
                dev,
                on,
                sched_on: None,
                sched_off: None,
                gauge,
            });
        }
        Ok(Channels {
            list,
            saved,
            restart_delay: settings.restart_delay,
        })
    }

    /// One PowerChannel request on channel `name`.
    pub(super) fn request(
        &mut self,
        name: &str,
        req: &HardwareRequest,
        now: Now,
        metrics: &Metrics,
    ) -> Done {
        let op = match PowerChannelOp::try_from(req.sub_op) {
            Ok(op) => op,
            Err(e) => {
                return Done::fail(
                    HardwareResult::InvalidValue,
                    format!("unknown power channel operation {} ({e})", req.sub_op),
                )
            }
        };
        let restart_delay = self.restart_delay;
        let Some(ch) = self.list.iter_mut().find(|c| c.name == name) else {
            return unknown("power channel", name);
        };
        let switched = |ch: &mut Channel, on: bool| match ch.switch(on, metrics) {
            Ok(changed) => Done::ok(ch.on.into(), changed),
            Err(e) => Done::fail(HardwareResult::BackendError, e).with_value(ch.on.into()),
        };
        let mut done = match op {
            PowerChannelOp::TurnOn => switched(ch, true),
            PowerChannelOp::TurnOff => switched(ch, false),
            PowerChannelOp::Toggle => {
                let target = !ch.on;
                switched(ch, target)
            }
            PowerChannelOp::ScheduleOn | PowerChannelOp::ScheduleOff => {
                let delay = match schedule_seconds(req.sched_s) {
                    Ok(d) => d,
                    Err(done) => return done.with_value(ch.on.into()),
                };
                let on = op == PowerChannelOp::ScheduleOn;
                if delay.is_zero() {
                    // Due now: done before the reply, which then shows the result;
                    // it replaces a pending schedule of the same kind like any other.
                    if on {
                        ch.sched_on = None;
                    } else {
                        ch.sched_off = None;
                    }
                    let mut done = switched(ch, on);
                    done.remaining_s = Some(0.0);
                    return done;
                }
                let slot = if on {
                    &mut ch.sched_on
                } else {
                    &mut ch.sched_off
                };
                *slot = Some(now.mono + delay);
                let mut done = Done::ok(ch.on.into(), true);
                done.remaining_s = Some(delay.as_secs_f64());
                return done;
            }
            PowerChannelOp::ScheduleReset => {
                let had = ch.sched_on.is_some() || ch.sched_off.is_some();
                ch.sched_on = None;
                ch.sched_off = None;
                let done = Done::ok(ch.on.into(), had);
                if had {
                    done
                } else {
                    done.with_message("nothing was scheduled")
                }
            }
            PowerChannelOp::Save => match self.saved.save(name, ch.on) {
                Ok(()) => Done::ok(ch.on.into(), true).with_message(format!(
                    "saved: `{name}` starts {} from now on",
                    if ch.on { "on" } else { "off" }
                )),
                Err(e) => {
                    metrics.backend_error(Device::SavedState);
                    Done::fail(HardwareResult::BackendError, e.to_string()).with_value(ch.on.into())
                }
            },
            PowerChannelOp::Restart => {
                let mut done = switched(ch, false);
                if done.result == HardwareResult::Ok {
                    ch.sched_on = Some(now.mono + restart_delay);
                    done.changed = true;
                    done.remaining_s = Some(restart_delay.as_secs_f64());
                    return done;
                }
                done
            }
        };
        if done.remaining_s.is_none() {
            done.remaining_s = ch
                .soonest()
                .map(|at| at.saturating_sub(now.mono).as_secs_f64());
        }
        done
    }

    /// Runs the due schedules, oldest first; true if anything changed.
    pub(super) fn run_due(&mut self, now: Now, metrics: &Metrics) -> bool {
        let mut changed = false;
        for ch in &mut self.list {
            let mut due: Vec<(Duration, bool)> = Vec::new();
            if let Some(at) = ch.sched_on.filter(|at| *at <= now.mono) {
                due.push((at, true));
                ch.sched_on = None;
            }
            if let Some(at) = ch.sched_off.filter(|at| *at <= now.mono) {
                due.push((at, false));
                ch.sched_off = None;
            }
            due.sort_by_key(|(at, _)| *at);
            for (_, on) in due {
                changed = true;
                match ch.switch(on, metrics) {
                    Ok(_) => {
                        tracing::info!(channel = %ch.name, on, "scheduled power channel operation done")
                    }
                    Err(e) => {
                        tracing::error!(channel = %ch.name, on, error = %e, "scheduled power channel operation failed")
                    }
                }
            }
        }
        changed
    }

    pub(super) fn next_due(&self) -> Option<Duration> {
        self.list.iter().filter_map(Channel::soonest).min()
    }

    /// Fills the state entries; returns how many.
    pub(super) fn fill(&self, out: &mut [PowerChannelEntry], now: Now) -> u8 {
        for (slot, ch) in out.iter_mut().zip(&self.list) {
            *slot = PowerChannelEntry {
                name: HwName::new(&ch.name),
                on: ch.on.into(),
                saved: u8::from(self.saved.get(&ch.name) == Some(ch.on)),
                sched_on_in_s: remaining(ch.sched_on, now),
                sched_off_in_s: remaining(ch.sched_off, now),
                ..PowerChannelEntry::default()
            };
        }
        self.list.len().min(out.len()) as u8
    }
}
