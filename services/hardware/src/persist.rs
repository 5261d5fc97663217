//! Saved power-channel states: what PowerChannel SAVE writes and the service restores
//! at start, in `state_dir/power_channels.json`.
//!
//! `{"version": 1, "channels": {"camera": true, "lights": false}}`. Written atomically.
//! A file that cannot be parsed is moved aside to `power_channels.json.corrupt` and
//! the configured defaults are used; a channel saved but no longer configured stays
//! in the file and is ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use skymesh_runtime::state_file::Loaded;
use skymesh_runtime::state_file::{load, write_atomic};

/// The file's name inside the state directory.
pub const SAVED_FILE_NAME: &str = "power_channels.json";
/// Format version written to the file.
pub const FORMAT_VERSION: u32 = 1;

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SavedFile {
    version: u32,
    /// Channel name → on.
    channels: BTreeMap<String, bool>,
}

/// Why the saved states could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PersistError {
    #[error("writing {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("encoding the saved states: {0}")]
    Encode(#[from] serde_json::Error),
}

/// The saved states and their file.
#[derive(Debug)]
pub struct SavedStates {
    path: PathBuf,
    channels: BTreeMap<String, bool>,
}

impl SavedStates {
    /// Reads `state_dir/power_channels.json`; never fails (see [`Loaded`]).
    pub fn load(state_dir: &Path) -> (SavedStates, Loaded) {
        let path = state_dir.join(SAVED_FILE_NAME);
        let (channels, loaded) = load(&path, |text| {
            let f = serde_json::from_str::<SavedFile>(text).map_err(|e| e.to_string())?;
            if f.version != FORMAT_VERSION {
                return Err(format!(
                    "format version {} (this build reads {FORMAT_VERSION})",
                    f.version
                ));
            }
            Ok(f.channels)
        });
        let channels = channels.unwrap_or_default();
        (SavedStates { path, channels }, loaded)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The saved state of `channel`, if any.
    pub fn get(&self, channel: &str) -> Option<bool> {
        self.channels.get(channel).copied()
    }

    /// Saves `channel` as `on` and writes the file; on failure nothing changes.
    pub fn save(&mut self, channel: &str, on: bool) -> Result<(), PersistError> {
        let previous = self.channels.insert(channel.to_string(), on);
        let result = self.write();
        if result.is_err() {
            match previous {
                Some(p) => self.channels.insert(channel.to_string(), p),
                None => self.channels.remove(channel),
            };
        }
        result
    }

    fn write(&self) -> Result<(), PersistError> {
        let file = SavedFile {
            version: FORMAT_VERSION,
            channels: self.channels.clone(),
        };
        let mut text = serde_json::to_string_pretty(&file)?;
        text.push('\n');
        write_atomic(&self.path, text.as_bytes()).map_err(|source| PersistError::Write {
            path: self.path.clone(),
            source,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saves_survive_a_reload() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, loaded) = SavedStates::load(dir.path());
        assert_eq!(loaded, Loaded::Fresh);
        assert_eq!(s.get("camera"), None);
        s.save("camera", false).unwrap();
        s.save("lights", true).unwrap();
        let (s, loaded) = SavedStates::load(dir.path());
        assert_eq!(loaded, Loaded::Existing);
        assert_eq!(s.get("camera"), Some(false));
        assert_eq!(s.get("lights"), Some(true));
        let text = std::fs::read_to_string(s.path()).unwrap();
        assert!(text.contains("\"version\": 1"), "{text}");
    }

    #[test]
    fn a_corrupt_file_is_kept_aside_and_ignored() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(SAVED_FILE_NAME);
        for bad in ["{not json", "{\"version\": 9, \"channels\": {}}"] {
            std::fs::write(&path, bad).unwrap();
            let (s, loaded) = SavedStates::load(dir.path());
            assert!(
                matches!(loaded, Loaded::Corrupt { kept: Some(_), .. }),
                "{loaded:?}"
            );
            assert_eq!(s.get("camera"), None);
            assert!(!path.exists());
            assert!(dir.path().join("power_channels.json.corrupt").exists());
        }
    }

    #[test]
    fn a_failed_write_changes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let (mut s, _) = SavedStates::load(&dir.path().join("missing-dir"));
        assert!(matches!(
            s.save("camera", true).unwrap_err(),
            PersistError::Write { .. }
        ));
        assert_eq!(s.get("camera"), None);
    }
}
