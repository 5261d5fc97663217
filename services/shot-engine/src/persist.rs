//! What survives a restart: button mappings, the GoPro enable flag and the shot that
//! was active, in a small JSON file.
//!
//! Writes are atomic (a temporary file in the same directory, flushed to disk, then
//! renamed over the old one), so a crash mid-write leaves either the old or the new
//! file, never half of one. A file that cannot be parsed is moved aside to
//! `<file>.corrupt` (kept for a post-mortem) and the engine starts from the defaults;
//! a file that cannot be read at all is left alone and the defaults are used.
//!
//! The active shot is recorded so that a restart can tell the app that its shot
//! ended; a restarted engine never resumes a shot (see `engine`).

use std::path::{Path, PathBuf};

use skymesh_runtime::state_file;

use serde::{Deserialize, Serialize};

/// Format version written to the file.
pub const FORMAT_VERSION: u32 = 1;

/// One button's mapping, as SOLO_SET_BUTTON_SETTING carries it (Press events only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Mapping {
    /// Shot index, −1 for none.
    pub shot: i32,
    /// ArduCopter custom mode number, −1 for none.
    pub mode: i32,
}

impl Mapping {
    pub const NONE: Mapping = Mapping { shot: -1, mode: -1 };

    fn is_sane(&self) -> bool {
        (skymesh_ipc_types::shot_api::shots::MIN..=skymesh_ipc_types::shot_api::shots::MAX)
            .contains(&self.shot)
            && (-1..=255).contains(&self.mode)
    }
}

/// The mappings of the two mappable buttons.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ButtonMap {
    pub a: Mapping,
    pub b: Mapping,
}

impl Default for ButtonMap {
    /// The Solo's factory defaults: A = cable cam, B = orbit.
    fn default() -> Self {
        ButtonMap {
            a: Mapping {
                shot: skymesh_ipc_types::shot_api::shots::CABLECAM,
                mode: -1,
            },
            b: Mapping {
                shot: skymesh_ipc_types::shot_api::shots::ORBIT,
                mode: -1,
            },
        }
    }
}

/// The file's content.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Persisted {
    pub version: u32,
    pub buttons: ButtonMap,
    pub gopro_enabled: bool,
    /// The shot index while a shot is active; `None` when idle.
    pub active_shot: Option<i32>,
}

impl Default for Persisted {
    fn default() -> Self {
        Persisted {
            version: FORMAT_VERSION,
            buttons: ButtonMap::default(),
            gopro_enabled: true,
            active_shot: None,
        }
    }
}

/// Why the state file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PersistError {
    #[error("{op} {path}: {source}")]
    Io {
        op: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("encoding the state: {0}")]
    Encode(#[from] serde_json::Error),
}

/// What [`Store::open`] found (defaults are used unless `Existing`).
pub use skymesh_runtime::state_file::Loaded;

/// The state file and its current content.
#[derive(Debug)]
pub struct Store {
    path: PathBuf,
    state: Persisted,
}

fn parse(text: &str) -> Result<Persisted, String> {
    let p: Persisted = serde_json::from_str(text).map_err(|e| e.to_string())?;
    if p.version != FORMAT_VERSION {
        return Err(format!(
            "format version {} (this build reads {FORMAT_VERSION})",
            p.version
        ));
    }
    if !p.buttons.a.is_sane() || !p.buttons.b.is_sane() {
        return Err(format!("button mapping out of range: {:?}", p.buttons));
    }
    if let Some(s) = p.active_shot {
        if !(skymesh_ipc_types::shot_api::shots::MIN..=skymesh_ipc_types::shot_api::shots::MAX)
            .contains(&s)
        {
            return Err(format!("active shot {s} out of range"));
        }
    }
    Ok(p)
}

impl Store {
    /// Reads `path`; never fails (see [`Loaded`]).
    pub fn open(path: impl Into<PathBuf>) -> (Store, Loaded) {
        let path = path.into();
        let (state, loaded) = state_file::load(&path, parse);
        let state = state.unwrap_or_default();
        (Store { path, state }, loaded)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn state(&self) -> &Persisted {
        &self.state
    }

    /// Applies `change` and writes the file if the content changed. The in-memory
    /// state changes even when writing fails (the engine keeps working; the error is
    /// for the log).
    pub fn update(&mut self, change: impl FnOnce(&mut Persisted)) -> Result<(), PersistError> {
        let before = self.state.clone();
        change(&mut self.state);
        if self.state == before {
            return Ok(());
        }
        self.write()
    }

    /// Writes the current state atomically.
    pub fn write(&self) -> Result<(), PersistError> {
        let io = |op: &'static str, path: &Path| {
            let path = path.to_path_buf();
            move |source| PersistError::Io { op, path, source }
        };
        let mut text = serde_json::to_string_pretty(&self.state)?;
        text.push('\n');
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io("creating directory", dir))?;
        }
        state_file::write_atomic(&self.path, text.as_bytes()).map_err(io("writing", &self.path))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_file_gives_the_solo_defaults() {
        let dir = tempfile::tempdir().unwrap();
        let (store, loaded) = Store::open(dir.path().join("s.json"));
        assert_eq!(loaded, Loaded::Fresh);
        assert_eq!(
            store.state().buttons.a.shot,
            skymesh_ipc_types::shot_api::shots::CABLECAM
        );
        assert_eq!(
            store.state().buttons.b.shot,
            skymesh_ipc_types::shot_api::shots::ORBIT
        );
        assert!(store.state().gopro_enabled);
        assert_eq!(store.state().active_shot, None);
    }

    #[test]
    fn updates_round_trip_and_leave_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nested/s.json");
        let (mut store, _) = Store::open(&path);
        store
            .update(|s| {
                s.gopro_enabled = false;
                s.active_shot = Some(1);
                s.buttons.a = Mapping { shot: -1, mode: 5 };
            })
            .unwrap();
        let (again, loaded) = Store::open(&path);
        assert_eq!(loaded, Loaded::Existing);
        assert_eq!(again.state(), store.state());
        let files: Vec<_> = std::fs::read_dir(dir.path().join("nested"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(files, ["s.json"], "no temporary file left");
    }

    #[test]
    fn a_corrupt_file_is_kept_aside_and_defaults_are_used() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.json");
        for garbage in [
            "{not json",
            r#"{"version":1,"buttons":{"a":{"shot":99,"mode":-1},"b":{"shot":1,"mode":-1}},"gopro_enabled":true,"active_shot":null}"#,
            r#"{"version":7,"buttons":{"a":{"shot":2,"mode":-1},"b":{"shot":1,"mode":-1}},"gopro_enabled":true,"active_shot":null}"#,
        ] {
            std::fs::write(&path, garbage).unwrap();
            let (store, loaded) = Store::open(&path);
            let Loaded::Corrupt {
                kept: Some(kept), ..
            } = loaded
            else {
                panic!("{garbage}: {loaded:?}");
            };
            assert_eq!(std::fs::read_to_string(&kept).unwrap(), garbage);
            assert!(!path.exists());
            assert_eq!(store.state(), &Persisted::default());
        }
    }
}
