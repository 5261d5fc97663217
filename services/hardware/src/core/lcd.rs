//! The two-line character display (IMC `LcdControl`).
//!
//! The text memory is kept while the display is off (a write while off shows when it
//! is turned on). Text longer than the configured width is cut to it and the reply
//! says so; text with control characters (a newline would break the display's lines)
//! or that is not UTF-8 is refused. The device is written first: if that fails,
//! nothing changes.

use skymesh_ipc_types::hardware::LcdOp;
use skymesh_ipc_types::{FixedStr, HardwareRequest, HardwareResult, HardwareState};

use super::Done;
use crate::backend::{sim::SimLcd, BackendError, Lcd};
use crate::config::{LcdBackend, Settings};
use crate::metrics::{Device, Metrics};

#[derive(Debug)]
pub(super) struct LcdState {
    dev: Option<Box<dyn Lcd>>,
    width: usize,
    on: bool,
    lines: [String; 2],
}

impl LcdState {
    /// Opens the display and shows it on and blank.
    pub(super) fn start(settings: &Settings) -> Result<LcdState, BackendError> {
        let mut dev: Option<Box<dyn Lcd>> = match settings.lcd.backend {
            LcdBackend::None => None,
            LcdBackend::Sim => Some(Box::new(SimLcd::open(&settings.state_dir)?)),
        };
        let lines = [String::new(), String::new()];
        if let Some(d) = &mut dev {
            d.show(true, &lines)?;
        }
        Ok(LcdState {
            on: dev.is_some(),
            dev,
            width: settings.lcd.width,
            lines,
        })
    }

    pub(super) fn request(&mut self, req: &HardwareRequest, metrics: &Metrics) -> Done {
        let Some(dev) = &mut self.dev else {
            return Done::fail(
                HardwareResult::NotSupported,
                "no LCD is configured (lcd.backend = \"none\")",
            );
        };
        let op = match LcdOp::try_from(req.sub_op) {
            Ok(op) => op,
            Err(e) => {
                return Done::fail(
                    HardwareResult::InvalidValue,
                    format!("unknown LCD operation {} ({e})", req.sub_op),
                )
                .with_value(self.on.into())
            }
        };
        let (mut on, mut lines) = (self.on, self.lines.clone());
        let mut message = String::new();
        match op {
            LcdOp::TurnOff => on = false,
            LcdOp::TurnOn => on = true,
            LcdOp::Clear => lines = [String::new(), String::new()],
            LcdOp::WriteLine0 | LcdOp::WriteLine1 => {
                let Some(text) = req.text.try_as_str() else {
                    return Done::fail(HardwareResult::InvalidValue, "text is not valid UTF-8")
                        .with_value(self.on.into());
                };
                if text.chars().any(char::is_control) {
                    return Done::fail(
                        HardwareResult::InvalidValue,
                        "text contains control characters",
                    )
                    .with_value(self.on.into());
                }
                let cut: String = text.chars().take(self.width).collect();
                if cut.len() < text.len() {
                    message = format!(
                        "text cut to the display's {} characters: `{cut}`",
                        self.width
                    );
                }
                lines[usize::from(op == LcdOp::WriteLine1)] = cut;
            }
        }
        if let Err(e) = dev.show(on, &lines) {
            metrics.backend_error(Device::Lcd);
            return Done::fail(HardwareResult::BackendError, e.to_string())
                .with_value(self.on.into());
        }
        let changed = on != self.on || lines != self.lines;
        self.on = on;
        self.lines = lines;
        Done::ok(on.into(), changed).with_message(message)
    }

    pub(super) fn fill(&self, s: &mut HardwareState) {
        s.lcd_on = self.on.into();
        s.lcd_lines = [FixedStr::new(&self.lines[0]), FixedStr::new(&self.lines[1])];
    }
}
