//! The companion computer's own power (IMC `PowerOperation`).
//!
//! One pending operation at a time; the latest request replaces it:
//!
//! | request | with its command configured | without |
//! |---|---|---|
//! | PowerDown | pending down in `power_down_delay_s` → `power_down_in_progress` | `refused` |
//! | SchedulePowerDown (Unix time) | pending down then → `power_down_in_progress` | `refused` |
//! | PowerDownAborted | cancels whatever is pending → `power_down_aborted` | same |
//! | PowerUp | cancels anything pending, runs the command now → `power_up_in_progress` | `refused` |
//! | SchedulePowerUp (Unix time) | pending up then → `power_up_in_progress` | `refused` |
//!
//! A refusal's reply carries `power_down_aborted` (nothing will happen). Scheduled
//! times must be in the next 7 days; the wall clock is read once, at the request, and
//! the wait runs on the monotonic clock. A due operation becomes an
//! [`Effect::RunCommand`] for the service to run.

use std::time::Duration;

use skymesh_ipc_types::hardware::SystemPowerOp;
use skymesh_ipc_types::{HardwareRequest, HardwareResult, HardwareState};

use super::{Done, Effect, Now};
use crate::config::{PowerSettings, MAX_SCHEDULE_S};

/// Which command runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PowerCommand {
    PowerDown,
    PowerUp,
}

impl PowerCommand {
    pub fn as_str(self) -> &'static str {
        match self {
            PowerCommand::PowerDown => "power_down",
            PowerCommand::PowerUp => "power_up",
        }
    }

    fn in_progress(self) -> SystemPowerOp {
        match self {
            PowerCommand::PowerDown => SystemPowerOp::PowerDownInProgress,
            PowerCommand::PowerUp => SystemPowerOp::PowerUpInProgress,
        }
    }

    fn config_key(self) -> &'static str {
        match self {
            PowerCommand::PowerDown => "power_down_command",
            PowerCommand::PowerUp => "power_up_command",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Pending {
    what: PowerCommand,
    at: Duration,
}

#[derive(Debug)]
pub(super) struct SystemPower {
    down: Vec<String>,
    up: Vec<String>,
    delay: Duration,
    pending: Option<Pending>,
}

fn aborted() -> Option<u8> {
    Some(SystemPowerOp::PowerDownAborted.to_wire())
}

impl SystemPower {
    pub(super) fn new(settings: &PowerSettings) -> SystemPower {
        SystemPower {
            down: settings.power_down_command.clone(),
            up: settings.power_up_command.clone(),
            delay: settings.power_down_delay,
            pending: None,
        }
    }

    fn command(&self, what: PowerCommand) -> &[String] {
        match what {
            PowerCommand::PowerDown => &self.down,
            PowerCommand::PowerUp => &self.up,
        }
    }

    pub(super) fn request(&mut self, req: &HardwareRequest, now: Now) -> Done {
        let op = match SystemPowerOp::try_from(req.sub_op) {
            Ok(op) => op,
            Err(e) => {
                return Done::fail(
                    HardwareResult::InvalidValue,
                    format!("unknown power operation {} ({e})", req.sub_op),
                )
            }
        };
        let (what, at) = match op {
            SystemPowerOp::PowerDownInProgress | SystemPowerOp::PowerUpInProgress => {
                return Done::fail(
                    HardwareResult::InvalidValue,
                    format!("{op} only appears in replies and state"),
                )
            }
            SystemPowerOp::PowerDownAborted => {
                let done = match self.pending.take() {
                    Some(p) => {
                        tracing::warn!(
                            operation = p.what.as_str(),
                            "pending companion power operation aborted"
                        );
                        Done::ok(0, true)
                            .with_message(format!("pending {} aborted", p.what.as_str()))
                    }
                    None => Done::ok(0, false).with_message("nothing was pending"),
                };
                return Done {
                    sub_op: aborted(),
                    ..done
                };
            }
            SystemPowerOp::PowerDown => (PowerCommand::PowerDown, None),
            SystemPowerOp::SchedulePowerDown => (PowerCommand::PowerDown, Some(req.sched_s)),
            SystemPowerOp::PowerUp => (PowerCommand::PowerUp, None),
            SystemPowerOp::SchedulePowerUp => (PowerCommand::PowerUp, Some(req.sched_s)),
        };
        let argv = self.command(what);
        if argv.is_empty() {
            let message = match what {
                PowerCommand::PowerDown => {
                    "power down requested but no power_down_command is configured; refusing"
                        .to_string()
                }
                PowerCommand::PowerUp => {
                    "power up requested but no power_up_command is configured; refusing".to_string()
                }
            };
            return Done {
                sub_op: aborted(),
                ..Done::fail(HardwareResult::Refused, message)
            };
        }
        let delay = match (what, at) {
            (_, Some(unix)) => {
                let from_now = unix - now.unix_s;
                if !from_now.is_finite() || from_now <= 0.0 || from_now > MAX_SCHEDULE_S {
                    return Done {
                        sub_op: aborted(),
                        ..Done::fail(
                            HardwareResult::InvalidValue,
                            format!("sched_s {unix} is not a Unix time within the next 7 days"),
                        )
                    };
                }
                Duration::from_secs_f64(from_now)
            }
            (PowerCommand::PowerDown, None) => self.delay,
            (PowerCommand::PowerUp, None) => Duration::ZERO,
        };
        if let Some(old) = self.pending {
            tracing::warn!(
                replaced = old.what.as_str(),
                by = what.as_str(),
                "a pending companion power operation was replaced by a newer request"
            );
        }
        tracing::warn!(
            operation = what.as_str(),
            in_s = delay.as_secs_f64(),
            command = ?self.command(what),
            "companion power operation pending (`{}` runs when it is due)",
            what.config_key()
        );
        self.pending = Some(Pending {
            what,
            at: now.mono + delay,
        });
        let mut done = Done::ok(0, true);
        done.sub_op = Some(what.in_progress().to_wire());
        done.remaining_s = Some(delay.as_secs_f64());
        done
    }

    /// The command of the pending operation when it is due.
    pub(super) fn run_due(&mut self, now: Now) -> Vec<Effect> {
        match self.pending {
            Some(p) if p.at <= now.mono => {
                self.pending = None;
                vec![Effect::RunCommand {
                    op: p.what,
                    argv: self.command(p.what).to_vec(),
                }]
            }
            _ => Vec::new(),
        }
    }

    pub(super) fn next_due(&self) -> Option<Duration> {
        self.pending.map(|p| p.at)
    }

    pub(super) fn fill(&self, s: &mut HardwareState, now: Now) {
        match self.pending {
            Some(p) => {
                s.system_power = p.what.in_progress().to_wire();
                s.system_power_in_s = p.at.saturating_sub(now.mono).as_secs_f32();
            }
            None => {
                s.system_power = SystemPowerOp::PowerDownAborted.to_wire();
                s.system_power_in_s = -1.0;
            }
        }
    }
}
