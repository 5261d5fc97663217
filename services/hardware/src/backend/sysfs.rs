//! Linux LED class devices (`/sys/class/leds/<name>`), with `std::fs` only.
//!
//! The bus carries 0..=255; the device takes 0..=`max_brightness` (often 1 for a
//! GPIO LED, 255 for a PWM one), so values are scaled both ways, rounding to the
//! nearest step. At open the LED's `trigger` is set to `none`: while a kernel trigger
//! (heartbeat, mmc0, ...) drives the LED, brightness writes would not stick.

use std::path::{Path, PathBuf};

use super::{BackendError, Led};

/// An LED under `/sys/class/leds`.
#[derive(Debug)]
pub struct SysfsLed {
    brightness: PathBuf,
    max: u32,
}

fn read_u32(path: &Path) -> Result<u32, BackendError> {
    let text = std::fs::read_to_string(path).map_err(BackendError::io("reading", path))?;
    text.trim().parse().map_err(|_| BackendError::Parse {
        path: path.to_path_buf(),
        content: text.trim().chars().take(32).collect(),
        expected: "an unsigned integer",
    })
}

/// 0..=255 → 0..=max, to the nearest step.
pub fn to_device(value: u8, max: u32) -> u32 {
    ((u64::from(value) * u64::from(max) + 127) / 255) as u32
}

/// 0..=max → 0..=255, to the nearest step (values above `max` count as `max`).
pub fn from_device(raw: u32, max: u32) -> u8 {
    if max == 0 {
        return 0;
    }
    let raw = u64::from(raw.min(max));
    ((raw * 255 + u64::from(max) / 2) / u64::from(max)) as u8
}

impl SysfsLed {
    /// Opens the LED directory `dir`: reads `max_brightness` (must be > 0), checks
    /// `brightness` is readable, and sets `trigger` to `none` when the LED has one.
    pub fn open(dir: &Path) -> Result<SysfsLed, BackendError> {
        let max_path = dir.join("max_brightness");
        let max = read_u32(&max_path)?;
        if max == 0 {
            return Err(BackendError::Parse {
                path: max_path,
                content: "0".into(),
                expected: "a max_brightness above 0",
            });
        }
        let brightness = dir.join("brightness");
        read_u32(&brightness)?;
        let trigger = dir.join("trigger");
        if trigger.exists() {
            std::fs::write(&trigger, "none").map_err(BackendError::io("writing", &trigger))?;
        }
        Ok(SysfsLed { brightness, max })
    }

    pub fn max_brightness(&self) -> u32 {
        self.max
    }
}

impl Led for SysfsLed {
    fn set(&mut self, value: u8) -> Result<u8, BackendError> {
        let raw = to_device(value, self.max);
        // A sysfs attribute takes the whole value in one write(2); no temp file.
        std::fs::write(&self.brightness, format!("{raw}\n"))
            .map_err(BackendError::io("writing", &self.brightness))?;
        Ok(from_device(raw, self.max))
    }

    fn get(&mut self) -> Result<u8, BackendError> {
        Ok(from_device(read_u32(&self.brightness)?, self.max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A directory shaped like `/sys/class/leds/<name>`.
    fn fake_led(root: &Path, max: u32, with_trigger: bool) -> PathBuf {
        let dir = root.join("sys/class/leds/led0");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("max_brightness"), format!("{max}\n")).unwrap();
        std::fs::write(dir.join("brightness"), "0\n").unwrap();
        if with_trigger {
            std::fs::write(dir.join("trigger"), "none [mmc0] heartbeat\n").unwrap();
        }
        dir
    }

    #[test]
    fn scaling_rounds_to_the_nearest_step() {
        assert_eq!(to_device(0, 1), 0);
        assert_eq!(to_device(127, 1), 0);
        assert_eq!(to_device(128, 1), 1);
        assert_eq!(to_device(255, 1), 1);
        assert_eq!(to_device(255, 4095), 4095);
        assert_eq!(to_device(200, 255), 200);
        assert_eq!(from_device(1, 1), 255);
        assert_eq!(from_device(2048, 4095), 128);
        assert_eq!(from_device(9999, 100), 255);
        for v in 0..=255u8 {
            assert_eq!(from_device(to_device(v, 255), 255), v);
            assert_eq!(from_device(to_device(v, 4095), 4095), v);
        }
    }

    #[test]
    fn writes_brightness_scaled_and_takes_over_the_trigger() {
        let root = tempfile::tempdir().unwrap();
        let dir = fake_led(root.path(), 100, true);
        let mut led = SysfsLed::open(&dir).unwrap();
        assert_eq!(led.max_brightness(), 100);
        assert_eq!(
            std::fs::read_to_string(dir.join("trigger")).unwrap(),
            "none"
        );
        assert_eq!(led.set(255).unwrap(), 255);
        assert_eq!(
            std::fs::read_to_string(dir.join("brightness")).unwrap(),
            "100\n"
        );
        assert_eq!(led.set(128).unwrap(), 128, "50 of 100, read back as 0..255");
        assert_eq!(
            std::fs::read_to_string(dir.join("brightness")).unwrap(),
            "50\n"
        );
        std::fs::write(dir.join("brightness"), "25\n").unwrap();
        assert_eq!(led.get().unwrap(), 64);
    }

    #[test]
    fn a_binary_led_is_on_or_off() {
        let root = tempfile::tempdir().unwrap();
        let dir = fake_led(root.path(), 1, false);
        let mut led = SysfsLed::open(&dir).unwrap();
        assert!(!dir.join("trigger").exists(), "no trigger file is created");
        assert_eq!(led.set(10).unwrap(), 0);
        assert_eq!(led.set(200).unwrap(), 255);
        assert_eq!(
            std::fs::read_to_string(dir.join("brightness")).unwrap(),
            "1\n"
        );
    }

    #[test]
    fn a_missing_or_broken_led_is_refused_at_open() {
        let root = tempfile::tempdir().unwrap();
        let e = SysfsLed::open(&root.path().join("nope")).unwrap_err();
        assert!(matches!(e, BackendError::Io { op: "reading", .. }), "{e}");
        assert!(e.to_string().contains("max_brightness"), "{e}");
        let dir = fake_led(root.path(), 0, false);
        assert!(matches!(
            SysfsLed::open(&dir).unwrap_err(),
            BackendError::Parse { .. }
        ));
        std::fs::write(dir.join("max_brightness"), "x").unwrap();
        assert!(SysfsLed::open(&dir).is_err());
    }
}
