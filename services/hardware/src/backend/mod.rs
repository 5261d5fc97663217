//! The devices behind the names: one small trait per kind, one file per backend.
//!
//! | backend | LEDs | lines (GPIO, power channels) | LCD |
//! |---|---|---|---|
//! | [`sim`] | file `state_dir/led/<name>` | file `state_dir/{gpio,power}/<name>` | files `state_dir/lcd`, `lcd_on` |
//! | [`sysfs`] | `/sys/class/leds/<name>` | — | — |
//! | [`cdev`] | — | Linux GPIO character device (`gpiocdev`) | — |
//!
//! Levels are logical (`true` = active); a backend applies `active_low`. Every call is
//! a short blocking system call (a sysfs attribute, a small file, an ioctl), made on
//! the service's one task.

pub mod cdev;
pub mod sim;
pub mod sysfs;

use std::path::{Path, PathBuf};

use crate::config::{LedBackend, LineBackend};

/// A device operation failed.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    #[error("{op} {path}: {source}")]
    Io {
        op: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} holds `{content}`, expected {expected}")]
    Parse {
        path: PathBuf,
        content: String,
        expected: &'static str,
    },
    #[error("GPIO line {line} of {chip}: {source}")]
    Gpio {
        chip: PathBuf,
        line: u32,
        source: gpiocdev::Error,
    },
    #[error("GPIO line {line} of {chip}: {message}")]
    GpioChip {
        chip: PathBuf,
        line: u32,
        message: String,
    },
}

impl BackendError {
    pub(crate) fn io(op: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.to_path_buf();
        move |source| BackendError::Io { op, path, source }
    }
}

/// An LED, brightness 0..=255 on the bus.
pub trait Led: Send + std::fmt::Debug {
    /// Sets the brightness; returns what the device now shows (scaled back to 0..=255).
    fn set(&mut self, value: u8) -> Result<u8, BackendError>;
    /// Reads the brightness from the device.
    fn get(&mut self) -> Result<u8, BackendError>;
}

/// A digital line: a GPIO line or the switch of a power channel.
pub trait Line: Send + std::fmt::Debug {
    /// Drives the line (outputs only).
    fn set(&mut self, active: bool) -> Result<(), BackendError>;
    /// Reads the line from the device.
    fn get(&mut self) -> Result<bool, BackendError>;
}

/// A two-line character display.
pub trait Lcd: Send + std::fmt::Debug {
    /// Shows `lines` (already cut to the display's width) with the display on or off.
    fn show(&mut self, on: bool, lines: &[String; 2]) -> Result<(), BackendError>;
}

/// Opens an LED.
pub fn open_led(
    backend: &LedBackend,
    state_dir: &Path,
    name: &str,
) -> Result<Box<dyn Led>, BackendError> {
    Ok(match backend {
        LedBackend::Sim => Box::new(sim::SimLed::open(state_dir, name)?),
        LedBackend::Sysfs { dir } => Box::new(sysfs::SysfsLed::open(dir)?),
    })
}

/// What a line is for, and its level at start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineUse {
    /// A GPIO output (or power channel switch) driven to `initial` at start.
    Output { initial: bool },
    /// A GPIO input; `initial` is the level a new sim file is created with.
    Input { initial: bool },
}

/// Opens a line; `kind` is the sim sub-directory (`gpio` or `power`).
pub fn open_line(
    backend: &LineBackend,
    state_dir: &Path,
    kind: &str,
    name: &str,
    active_low: bool,
    usage: LineUse,
) -> Result<Box<dyn Line>, BackendError> {
    Ok(match backend {
        LineBackend::Sim => Box::new(sim::SimLine::open(state_dir, kind, name, usage)?),
        LineBackend::Cdev { chip, line } => {
            Box::new(cdev::CdevLine::open(chip, *line, active_low, usage)?)
        }
    })
}
