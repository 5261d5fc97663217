//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! The shipped, commented defaults are `deploy/hardware.toml` (embedded as
//! [`ServiceConfig::DEFAULT_TOML`]): simulated devices only, so the embedded mesh and
//! the tests never touch real hardware.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_ipc_types::hardware::{HW_MAX_ENTRIES, HW_NAME_CAPACITY, LCD_LINE_CAPACITY};
use skymesh_runtime::config::in_range;
use skymesh_runtime::ipc::{DEFAULT_DOMAIN, DOMAIN_ENV};
use skymesh_runtime::{ConfigError, ServiceConfig};

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../../deploy/hardware.toml");

/// Sub-directory of systemd's `STATE_DIRECTORY` (or of `/tmp/skymesh-<domain>`) used
/// when `state_dir` is empty.
pub const STATE_SUBDIR: &str = "hardware";

/// Longest delay of a scheduled operation (power channel or companion power): 7 days.
pub const MAX_SCHEDULE_S: f64 = 7.0 * 24.0 * 3600.0;

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Simulated devices' files and the saved power-channel states.
    pub state_dir: PathBuf,
    pub leds: Vec<LedSettings>,
    pub gpios: Vec<GpioSettings>,
    pub channels: Vec<ChannelSettings>,
    pub lcd: LcdSettings,
    pub power: PowerSettings,
    /// Power channel RESTART: off, then on again this much later.
    pub restart_delay: Duration,
}

/// Where an LED is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LedBackend {
    /// A file `state_dir/led/<name>` holding 0..=255.
    Sim,
    /// A Linux LED class device directory (`brightness`, `max_brightness`).
    Sysfs { dir: PathBuf },
}

impl std::fmt::Display for LedBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LedBackend::Sim => f.write_str("sim"),
            LedBackend::Sysfs { dir } => write!(f, "sysfs {}", dir.display()),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LedSettings {
    pub name: String,
    pub backend: LedBackend,
}

/// Where a GPIO line (or the line switching a power channel) is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LineBackend {
    /// A file `state_dir/gpio/<name>` or `state_dir/power/<name>` holding 0 or 1.
    Sim,
    /// Line `line` of the GPIO character device `chip`.
    Cdev { chip: PathBuf, line: u32 },
}

impl std::fmt::Display for LineBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LineBackend::Sim => f.write_str("sim"),
            LineBackend::Cdev { chip, line } => write!(f, "cdev {} line {line}", chip.display()),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GpioSettings {
    pub name: String,
    /// An output is driven by requests; an input is read from the device.
    pub output: bool,
    pub backend: LineBackend,
    /// The physical level is the inverse of the logical one (cdev only).
    pub active_low: bool,
    /// Output: the level driven at start. Sim input: the level its file is created with.
    pub initial: bool,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSettings {
    pub name: String,
    pub backend: LineBackend,
    pub active_low: bool,
    /// The state at start unless a saved state overrides it.
    pub default_on: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LcdBackend {
    /// No display: LCD requests are answered `not_supported`.
    None,
    /// Files `state_dir/lcd` (the two lines) and `state_dir/lcd_on`.
    Sim,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LcdSettings {
    pub backend: LcdBackend,
    /// Characters per line; longer text is truncated (and the reply says so).
    pub width: usize,
}

#[derive(Debug, Clone, PartialEq)]
pub struct PowerSettings {
    /// Program and arguments run (no shell) to power the companion computer down;
    /// empty → power-down requests are refused.
    pub power_down_command: Vec<String>,
    /// Program and arguments run to power up; empty → power-up requests are refused.
    pub power_up_command: Vec<String>,
    /// PowerDown waits this long (abortable) before running the command.
    pub power_down_delay: Duration,
}

// ---- raw ---------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RawLedBackend {
    Sim,
    Sysfs,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RawLineBackend {
    Sim,
    Cdev,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RawDirection {
    Output,
    Input,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RawOnOff {
    On,
    Off,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RawLcdBackend {
    None,
    Sim,
}

/// One `[[led]]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLed {
    pub name: String,
    #[serde(default = "sim_led")]
    pub backend: RawLedBackend,
    /// sysfs: the LED's directory; default `/sys/class/leds/<name>`.
    pub path: Option<String>,
}

fn sim_led() -> RawLedBackend {
    RawLedBackend::Sim
}

fn sim_line() -> RawLineBackend {
    RawLineBackend::Sim
}

/// One `[[gpio]]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawGpio {
    pub name: String,
    pub direction: RawDirection,
    #[serde(default = "sim_line")]
    pub backend: RawLineBackend,
    pub chip: Option<String>,
    pub line: Option<i64>,
    #[serde(default)]
    pub active_low: bool,
    #[serde(default)]
    pub initial: i64,
}

/// One `[[power_channel]]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawChannel {
    pub name: String,
    #[serde(default = "sim_line")]
    pub backend: RawLineBackend,
    pub chip: Option<String>,
    pub line: Option<i64>,
    #[serde(default)]
    pub active_low: bool,
    pub default: RawOnOff,
}

/// The `[lcd]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawLcd {
    pub backend: RawLcdBackend,
    pub width: i64,
}

impl Default for RawLcd {
    fn default() -> Self {
        RawLcd {
            backend: RawLcdBackend::None,
            width: 16,
        }
    }
}

/// The `[power]` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawPower {
    pub power_down_command: Vec<String>,
    pub power_up_command: Vec<String>,
    pub power_down_delay_s: f64,
}

impl Default for RawPower {
    fn default() -> Self {
        RawPower {
            power_down_command: Vec::new(),
            power_up_command: Vec::new(),
            power_down_delay_s: 10.0,
        }
    }
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub state_dir: String,
    pub restart_delay_s: f64,
    pub led: Vec<RawLed>,
    pub gpio: Vec<RawGpio>,
    pub power_channel: Vec<RawChannel>,
    pub lcd: RawLcd,
    pub power: RawPower,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            state_dir: String::new(),
            restart_delay_s: 1.0,
            led: Vec::new(),
            gpio: Vec::new(),
            power_channel: Vec::new(),
            lcd: RawLcd::default(),
            power: RawPower::default(),
        }
    }
}

/// Where the state lives when `state_dir` is empty: `$STATE_DIRECTORY/hardware`
/// under systemd (the first entry if it lists several), else
/// `/tmp/skymesh-<domain>/hardware`.
pub fn default_state_dir(state_directory: Option<&str>, domain: Option<&str>) -> PathBuf {
    if let Some(dir) = state_directory
        .and_then(|d| d.split(':').next())
        .filter(|d| !d.is_empty())
    {
        return Path::new(dir).join(STATE_SUBDIR);
    }
    let domain = domain.filter(|d| !d.is_empty()).unwrap_or(DEFAULT_DOMAIN);
    PathBuf::from(format!("/tmp/skymesh-{domain}")).join(STATE_SUBDIR)
}

/// A name is 1..=32 bytes of `A-Z a-z 0-9 _ - . +` and space, not starting with `.`
/// or a space: it names a file of the sim backend and a metric label.
pub fn is_valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= HW_NAME_CAPACITY
        && !name.starts_with(['.', ' '])
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.' | b'+' | b' '))
}

fn seconds(field: &str, v: f64, min: f64, max: f64) -> Result<Duration, ConfigError> {
    if !v.is_finite() {
        return Err(ConfigError::invalid(
            field,
            format!("{v} is not a finite number"),
        ));
    }
    Ok(Duration::from_secs_f64(in_range(field, v, min, max)?))
}

fn absolute(field: &str, value: &str) -> Result<PathBuf, ConfigError> {
    let p = PathBuf::from(value);
    if !p.is_absolute() {
        return Err(ConfigError::invalid(
            field,
            format!("`{value}` must be an absolute path (a relative one would depend on the working directory)"),
        ));
    }
    Ok(p)
}

/// Checks the names of one kind: valid, unique, at most [`HW_MAX_ENTRIES`].
fn check_names<'a>(
    kind: &str,
    names: impl ExactSizeIterator<Item = &'a str>,
) -> Result<(), ConfigError> {
    if names.len() > HW_MAX_ENTRIES {
        return Err(ConfigError::invalid(
            kind,
            format!("{} entries; at most {HW_MAX_ENTRIES}", names.len()),
        ));
    }
    let mut seen = HashSet::new();
    for name in names {
        if !is_valid_name(name) {
            return Err(ConfigError::invalid(
                format!("{kind}.name"),
                format!("`{name}` must be 1-{HW_NAME_CAPACITY} bytes of A-Z a-z 0-9 _ - . + and space, not starting with `.` or a space"),
            ));
        }
        if !seen.insert(name) {
            return Err(ConfigError::invalid(
                format!("{kind}.name"),
                format!("`{name}` is configured twice"),
            ));
        }
    }
    Ok(())
}

fn command(field: &str, argv: Vec<String>) -> Result<Vec<String>, ConfigError> {
    if argv.iter().any(|a| a.is_empty() || a.contains('\0')) {
        return Err(ConfigError::invalid(
            field,
            "no argument may be empty or contain NUL",
        ));
    }
    Ok(argv)
}

/// The backend of a line (a GPIO or a power channel): `chip`/`line` only with cdev.
fn line_backend(
    field: &str,
    backend: RawLineBackend,
    chip: Option<String>,
    line: Option<i64>,
    used: &mut HashSet<(PathBuf, u32)>,
) -> Result<LineBackend, ConfigError> {
    match backend {
        RawLineBackend::Sim => {
            if chip.is_some() || line.is_some() {
                return Err(ConfigError::invalid(
                    field,
                    "`chip` and `line` are only for backend = \"cdev\"",
                ));
            }
            Ok(LineBackend::Sim)
        }
        RawLineBackend::Cdev => {
            let chip = absolute(
                &format!("{field}.chip"),
                chip.as_deref().unwrap_or("/dev/gpiochip0"),
            )?;
            let Some(line) = line else {
                return Err(ConfigError::invalid(
                    format!("{field}.line"),
                    "backend = \"cdev\" needs the line offset on the chip",
                ));
            };
            let line = in_range(&format!("{field}.line"), line, 0, 1023)? as u32;
            if !used.insert((chip.clone(), line)) {
                return Err(ConfigError::invalid(
                    format!("{field}.line"),
                    format!("line {line} of {} is configured twice", chip.display()),
                ));
            }
            Ok(LineBackend::Cdev { chip, line })
        }
    }
}

impl RawConfig {
    /// Checks everything and resolves the state directory against the environment.
    pub fn validate_with_env(
        self,
        state_directory: Option<&str>,
        domain: Option<&str>,
    ) -> Result<Settings, ConfigError> {
        check_names("led", self.led.iter().map(|l| l.name.as_str()))?;
        check_names("gpio", self.gpio.iter().map(|g| g.name.as_str()))?;
        check_names(
            "power_channel",
            self.power_channel.iter().map(|c| c.name.as_str()),
        )?;
        let state_dir = if self.state_dir.trim().is_empty() {
            default_state_dir(state_directory, domain)
        } else {
            absolute("state_dir", self.state_dir.trim())?
        };

        let mut led_dirs = HashSet::new();
        let mut leds = Vec::with_capacity(self.led.len());
        for l in self.led {
            let backend = match l.backend {
                RawLedBackend::Sim => {
                    if l.path.is_some() {
                        return Err(ConfigError::invalid(
                            "led.path",
                            format!("LED `{}`: `path` is only for backend = \"sysfs\"", l.name),
                        ));
                    }
                    LedBackend::Sim
                }
                RawLedBackend::Sysfs => {
                    let dir = match &l.path {
                        Some(p) => absolute("led.path", p)?,
                        None => Path::new("/sys/class/leds").join(&l.name),
                    };
                    if !led_dirs.insert(dir.clone()) {
                        return Err(ConfigError::invalid(
                            "led.path",
                            format!("{} is configured twice", dir.display()),
                        ));
                    }
                    LedBackend::Sysfs { dir }
                }
            };
            leds.push(LedSettings {
                name: l.name,
                backend,
            });
        }

        let mut lines = HashSet::new();
        let mut gpios = Vec::with_capacity(self.gpio.len());
        for g in self.gpio {
            let field = format!("gpio `{}`", g.name);
            let initial = in_range(&format!("{field}.initial"), g.initial, 0, 1)? == 1;
            gpios.push(GpioSettings {
                backend: line_backend(&field, g.backend, g.chip, g.line, &mut lines)?,
                name: g.name,
                output: g.direction == RawDirection::Output,
                active_low: g.active_low,
                initial,
            });
        }
        let mut channels = Vec::with_capacity(self.power_channel.len());
        for c in self.power_channel {
            let field = format!("power_channel `{}`", c.name);
            channels.push(ChannelSettings {
                backend: line_backend(&field, c.backend, c.chip, c.line, &mut lines)?,
                name: c.name,
                active_low: c.active_low,
                default_on: c.default == RawOnOff::On,
            });
        }

        let lcd = LcdSettings {
            backend: match self.lcd.backend {
                RawLcdBackend::None => LcdBackend::None,
                RawLcdBackend::Sim => LcdBackend::Sim,
            },
            width: in_range("lcd.width", self.lcd.width, 1, LCD_LINE_CAPACITY as i64)? as usize,
        };
        let power = PowerSettings {
            power_down_command: command("power.power_down_command", self.power.power_down_command)?,
            power_up_command: command("power.power_up_command", self.power.power_up_command)?,
            power_down_delay: seconds(
                "power.power_down_delay_s",
                self.power.power_down_delay_s,
                0.0,
                3600.0,
            )?,
        };
        Ok(Settings {
            state_dir,
            leds,
            gpios,
            channels,
            lcd,
            power,
            restart_delay: seconds("restart_delay_s", self.restart_delay_s, 0.05, 60.0)?,
        })
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = DEFAULT_CONFIG_TOML;

    fn validate(self) -> Result<Settings, ConfigError> {
        let state_directory = std::env::var("STATE_DIRECTORY").ok();
        let domain = std::env::var(DOMAIN_ENV).ok();
        self.validate_with_env(state_directory.as_deref(), domain.as_deref())
    }
}

#[cfg(test)]
mod tests;
