//! LEDs and GPIO lines: set and query, the device read on every query of an LED or
//! an input line (an output reports the level it is driven to).

use skymesh_ipc_types::{HardwareRequest, HardwareResult};

use super::{request_name, unknown, Done, Hardware};
use crate::backend::{Led, Line};
use crate::metrics::Device;

#[derive(Debug)]
pub(super) struct LedSlot {
    pub(super) name: String,
    pub(super) dev: Box<dyn Led>,
    pub(super) value: u8,
}

#[derive(Debug)]
pub(super) struct GpioSlot {
    pub(super) name: String,
    pub(super) dev: Box<dyn Line>,
    pub(super) output: bool,
    pub(super) value: bool,
}

impl Hardware {
    pub(super) fn led(&mut self, req: &HardwareRequest, set: bool) -> Done {
        let name = match request_name(req) {
            Ok(n) => n,
            Err(done) => return done,
        };
        let Some(led) = self.leds.iter_mut().find(|l| l.name == name) else {
            return unknown("LED", name);
        };
        let result = if set {
            led.dev.set(req.value)
        } else {
            led.dev.get()
        };
        match result {
            Ok(v) => {
                let changed = v != led.value;
                led.value = v;
                let done = Done::ok(v, changed);
                if set && v != req.value {
                    done.with_message(format!("the LED shows {v} (its steps are coarser)"))
                } else {
                    done
                }
            }
            Err(e) => {
                self.metrics.backend_error(Device::Led);
                Done::fail(HardwareResult::BackendError, e.to_string()).with_value(led.value)
            }
        }
    }

    pub(super) fn gpio(&mut self, req: &HardwareRequest, set: bool) -> Done {
        let name = match request_name(req) {
            Ok(n) => n,
            Err(done) => return done,
        };
        let Some(g) = self.gpios.iter_mut().find(|g| g.name == name) else {
            return unknown("GPIO line", name);
        };
        let known = u8::from(g.value);
        if set {
            if !g.output {
                return Done::fail(
                    HardwareResult::NotSupported,
                    format!("`{name}` is an input line: it cannot be set"),
                )
                .with_value(known);
            }
            if req.value > 1 {
                return Done::fail(
                    HardwareResult::InvalidValue,
                    format!("level {} is not 0 or 1", req.value),
                )
                .with_value(known);
            }
            let level = req.value == 1;
            return match g.dev.set(level) {
                Ok(()) => {
                    let changed = level != g.value;
                    g.value = level;
                    Done::ok(level.into(), changed)
                }
                Err(e) => {
                    self.metrics.backend_error(Device::Gpio);
                    Done::fail(HardwareResult::BackendError, e.to_string()).with_value(known)
                }
            };
        }
        if g.output {
            // An output reports the level it is driven to.
            return Done::ok(known, false);
        }
        match g.dev.get() {
            Ok(v) => {
                let changed = v != g.value;
                g.value = v;
                Done::ok(v.into(), changed)
            }
            Err(e) => {
                self.metrics.backend_error(Device::Gpio);
                Done::fail(HardwareResult::BackendError, e.to_string()).with_value(known)
            }
        }
    }
}
