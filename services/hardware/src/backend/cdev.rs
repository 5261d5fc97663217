//! Lines of the Linux GPIO character device (`/dev/gpiochipN`), through `gpiocdev`
//! (pure Rust; uAPI v2, falling back to v1 on kernels before 5.10).
//!
//! Each configured line is its own line request, held for as long as the service
//! runs (the kernel shows the consumer `skymesh-hardware` in `gpioinfo`). Outputs are
//! requested with their start level, so there is no glitch at start; `active_low` is
//! handed to the kernel, so every level here is logical.

use std::path::{Path, PathBuf};

use gpiocdev::line::Value;
use gpiocdev::Request;

use super::{BackendError, Line, LineUse};

/// The consumer label the kernel shows for our lines.
pub const CONSUMER: &str = "skymesh-hardware";

/// One requested line.
#[derive(Debug)]
pub struct CdevLine {
    chip: PathBuf,
    line: u32,
    request: Request,
}

fn value(active: bool) -> Value {
    if active {
        Value::Active
    } else {
        Value::Inactive
    }
}

impl CdevLine {
    /// Requests `line` of `chip` as an output (driven to its initial level) or input.
    pub fn open(
        chip: &Path,
        line: u32,
        active_low: bool,
        usage: LineUse,
    ) -> Result<CdevLine, BackendError> {
        // Checked first for a clear message: the crate reports a missing chip as a bare errno.
        if let Err(e) = std::fs::metadata(chip) {
            return Err(BackendError::GpioChip {
                chip: chip.to_path_buf(),
                line,
                message: format!(
                    "cannot open the GPIO chip: {e} (is the GPIO driver loaded, and may the service user open it, e.g. group gpio?)"
                ),
            });
        }
        let mut builder = Request::builder();
        builder
            .on_chip(chip)
            .with_consumer(CONSUMER)
            .with_line(line);
        match usage {
            LineUse::Output { initial } => builder.as_output(value(initial)),
            LineUse::Input { .. } => builder.as_input(),
        };
        if active_low {
            builder.as_active_low();
        }
        let request = builder.request().map_err(|source| BackendError::Gpio {
            chip: chip.to_path_buf(),
            line,
            source,
        })?;
        Ok(CdevLine {
            chip: chip.to_path_buf(),
            line,
            request,
        })
    }

    fn err(&self) -> impl FnOnce(gpiocdev::Error) -> BackendError {
        let (chip, line) = (self.chip.clone(), self.line);
        move |source| BackendError::Gpio { chip, line, source }
    }
}

impl Line for CdevLine {
    fn set(&mut self, active: bool) -> Result<(), BackendError> {
        let err = self.err();
        self.request
            .set_value(self.line, value(active))
            .map_err(err)
    }

    fn get(&mut self) -> Result<bool, BackendError> {
        let err = self.err();
        self.request
            .value(self.line)
            .map(|v| v == Value::Active)
            .map_err(err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_chip_is_a_clear_error() {
        let e = CdevLine::open(
            Path::new("/dev/gpiochip-does-not-exist"),
            17,
            false,
            LineUse::Output { initial: false },
        )
        .unwrap_err();
        assert!(matches!(e, BackendError::GpioChip { line: 17, .. }), "{e}");
        let text = e.to_string();
        assert!(text.contains("/dev/gpiochip-does-not-exist"), "{text}");
        assert!(text.contains("cannot open the GPIO chip"), "{text}");
    }

    #[test]
    fn a_file_that_is_not_a_gpio_chip_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let fake = dir.path().join("gpiochip0");
        std::fs::write(&fake, "").unwrap();
        let e = CdevLine::open(&fake, 0, false, LineUse::Input { initial: false }).unwrap_err();
        assert!(matches!(e, BackendError::Gpio { line: 0, .. }), "{e}");
        assert!(e.to_string().contains("gpiochip0"), "{e}");
    }
}
