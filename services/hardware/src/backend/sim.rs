//! The simulated backend: every device is a small text file under the state directory,
//! so a test or an operator reads what the gateways did and writes an input line's
//! file to simulate a button or a sensor.
//!
//! | device | file | content |
//! |---|---|---|
//! | LED | `state_dir/led/<name>` | brightness `0`..`255` |
//! | GPIO line | `state_dir/gpio/<name>` | logical level `0` / `1` |
//! | power channel | `state_dir/power/<name>` | `0` off / `1` on |
//! | LCD | `state_dir/lcd`, `state_dir/lcd_on` | the two lines; `0` / `1` |
//!
//! Writes are atomic; reads accept surrounding whitespace.

use std::path::{Path, PathBuf};

use super::{BackendError, Lcd, Led, Line, LineUse};
use skymesh_runtime::state_file::write_atomic;

/// One number in one file.
#[derive(Debug)]
struct NumberFile {
    path: PathBuf,
}

impl NumberFile {
    /// `dir/kind/name`, its directory created.
    fn at(state_dir: &Path, kind: &str, name: &str) -> Result<NumberFile, BackendError> {
        let dir = state_dir.join(kind);
        std::fs::create_dir_all(&dir).map_err(BackendError::io("creating directory", &dir))?;
        Ok(NumberFile {
            path: dir.join(name),
        })
    }

    fn exists(&self) -> bool {
        self.path.exists()
    }

    fn read(&self, max: u32, expected: &'static str) -> Result<u32, BackendError> {
        let text =
            std::fs::read_to_string(&self.path).map_err(BackendError::io("reading", &self.path))?;
        match text.trim().parse::<u32>() {
            Ok(v) if v <= max => Ok(v),
            _ => Err(BackendError::Parse {
                path: self.path.clone(),
                content: text.trim().chars().take(32).collect(),
                expected,
            }),
        }
    }

    fn write(&self, v: u32) -> Result<(), BackendError> {
        write_atomic(&self.path, format!("{v}\n").as_bytes())
            .map_err(BackendError::io("writing", &self.path))
    }
}

/// A simulated LED.
#[derive(Debug)]
pub struct SimLed {
    file: NumberFile,
}

const LED_EXPECTED: &str = "a brightness 0..=255";
const LINE_EXPECTED: &str = "a level 0 or 1";

impl SimLed {
    /// Opens `state_dir/led/<name>`; a missing file is created at 0, an existing one
    /// keeps its brightness (and must hold a valid one).
    pub fn open(state_dir: &Path, name: &str) -> Result<SimLed, BackendError> {
        let file = NumberFile::at(state_dir, "led", name)?;
        if file.exists() {
            file.read(255, LED_EXPECTED)?;
        } else {
            file.write(0)?;
        }
        Ok(SimLed { file })
    }

    pub fn path(&self) -> &Path {
        &self.file.path
    }
}

impl Led for SimLed {
    fn set(&mut self, value: u8) -> Result<u8, BackendError> {
        self.file.write(value.into())?;
        Ok(value)
    }

    fn get(&mut self) -> Result<u8, BackendError> {
        Ok(self.file.read(255, LED_EXPECTED)? as u8)
    }
}

/// A simulated line: a GPIO line (`gpio/`) or a power channel switch (`power/`).
#[derive(Debug)]
pub struct SimLine {
    file: NumberFile,
}

impl SimLine {
    /// Opens `state_dir/<kind>/<name>`: an output is driven to its initial level; an
    /// input's file is created with its initial level when missing and read as is
    /// otherwise (so a test can prepare it).
    pub fn open(
        state_dir: &Path,
        kind: &str,
        name: &str,
        usage: LineUse,
    ) -> Result<SimLine, BackendError> {
        let file = NumberFile::at(state_dir, kind, name)?;
        match usage {
            LineUse::Output { initial } => file.write(initial.into())?,
            LineUse::Input { initial } => {
                if file.exists() {
                    file.read(1, LINE_EXPECTED)?;
                } else {
                    file.write(initial.into())?;
                }
            }
        }
        Ok(SimLine { file })
    }

    pub fn path(&self) -> &Path {
        &self.file.path
    }
}

impl Line for SimLine {
    fn set(&mut self, active: bool) -> Result<(), BackendError> {
        self.file.write(active.into())
    }

    fn get(&mut self) -> Result<bool, BackendError> {
        Ok(self.file.read(1, LINE_EXPECTED)? == 1)
    }
}

/// A simulated two-line display.
#[derive(Debug)]
pub struct SimLcd {
    text: PathBuf,
    on: PathBuf,
}

impl SimLcd {
    /// Uses `state_dir/lcd` and `state_dir/lcd_on` (written on the first `show`).
    pub fn open(state_dir: &Path) -> Result<SimLcd, BackendError> {
        std::fs::create_dir_all(state_dir)
            .map_err(BackendError::io("creating directory", state_dir))?;
        Ok(SimLcd {
            text: state_dir.join("lcd"),
            on: state_dir.join("lcd_on"),
        })
    }
}

impl Lcd for SimLcd {
    fn show(&mut self, on: bool, lines: &[String; 2]) -> Result<(), BackendError> {
        let text = format!("{}\n{}\n", lines[0], lines[1]);
        write_atomic(&self.text, text.as_bytes())
            .map_err(BackendError::io("writing", &self.text))?;
        write_atomic(&self.on, if on { b"1\n" } else { b"0\n" })
            .map_err(BackendError::io("writing", &self.on))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(p: &Path) -> String {
        std::fs::read_to_string(p).unwrap()
    }

    #[test]
    fn led_file_is_created_kept_and_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut led = SimLed::open(dir.path(), "status").unwrap();
        assert_eq!(led.path(), dir.path().join("led/status"));
        assert_eq!(read(led.path()), "0\n");
        assert_eq!(led.set(200).unwrap(), 200);
        assert_eq!(read(led.path()), "200\n");
        // An operator edits it: the next read sees it; a reopen keeps it.
        std::fs::write(led.path(), " 17 \n").unwrap();
        assert_eq!(led.get().unwrap(), 17);
        let mut again = SimLed::open(dir.path(), "status").unwrap();
        assert_eq!(again.get().unwrap(), 17);
        std::fs::write(led.path(), "256").unwrap();
        let e = led.get().unwrap_err();
        assert!(matches!(e, BackendError::Parse { .. }), "{e}");
        assert!(SimLed::open(dir.path(), "status").is_err());
    }

    #[test]
    fn output_is_driven_at_open_and_input_is_read_each_time() {
        let dir = tempfile::tempdir().unwrap();
        let mut out = SimLine::open(
            dir.path(),
            "gpio",
            "release",
            LineUse::Output { initial: true },
        )
        .unwrap();
        assert_eq!(read(out.path()), "1\n");
        out.set(false).unwrap();
        assert_eq!(read(out.path()), "0\n");
        assert!(!out.get().unwrap());

        let mut input = SimLine::open(
            dir.path(),
            "gpio",
            "button",
            LineUse::Input { initial: false },
        )
        .unwrap();
        assert!(!input.get().unwrap());
        std::fs::write(input.path(), "1\n").unwrap();
        assert!(input.get().unwrap());
        // Reopened: the file is kept, not reset.
        let mut input = SimLine::open(
            dir.path(),
            "gpio",
            "button",
            LineUse::Input { initial: false },
        )
        .unwrap();
        assert!(input.get().unwrap());
        std::fs::write(input.path(), "high").unwrap();
        assert!(matches!(
            input.get().unwrap_err(),
            BackendError::Parse { .. }
        ));
    }

    #[test]
    fn a_write_that_cannot_happen_is_an_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut out = SimLine::open(
            dir.path(),
            "power",
            "cam",
            LineUse::Output { initial: false },
        )
        .unwrap();
        std::fs::remove_file(out.path()).unwrap();
        std::fs::create_dir_all(out.path().join("blocker")).unwrap();
        let e = out.set(true).unwrap_err();
        assert!(matches!(e, BackendError::Io { op: "writing", .. }), "{e}");
    }

    #[test]
    fn lcd_files_hold_the_lines_and_the_power() {
        let dir = tempfile::tempdir().unwrap();
        let mut lcd = SimLcd::open(dir.path()).unwrap();
        lcd.show(true, &["hello".into(), String::new()]).unwrap();
        assert_eq!(read(&dir.path().join("lcd")), "hello\n\n");
        assert_eq!(read(&dir.path().join("lcd_on")), "1\n");
        lcd.show(false, &["a".into(), "b".into()]).unwrap();
        assert_eq!(read(&dir.path().join("lcd")), "a\nb\n");
        assert_eq!(read(&dir.path().join("lcd_on")), "0\n");
    }
}
