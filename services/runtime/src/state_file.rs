//! A service's small state files (the arbiter's stops and fences, the shot engine's
//! buttons and shot, the hardware's power channels), in one way for every service:
//!
//! - [`write_atomic`]: a temporary sibling (`.<name>.tmp`: configured names never
//!   start with `.`, so it is never another file of the service) written and flushed
//!   to disk, renamed over the file, and the directory synced so that the rename is
//!   durable too. A crash mid-write leaves the old file or the new one, never half.
//! - [`load`]: read once at start. A missing file is a first start; a file that does
//!   not parse is moved aside to `<file>.corrupt` (kept for a post-mortem); a file
//!   that cannot be read is left alone. What to do in each case is the service's.

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// `.<file name>.tmp` next to `path`.
fn temp_sibling(path: &Path) -> PathBuf {
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(".tmp");
    path.with_file_name(name)
}

/// `<file name>.<suffix>` next to `path`.
pub fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".");
    name.push(suffix);
    path.with_file_name(name)
}

/// Writes `bytes` to `path` atomically (see the module doc). The directory must
/// exist.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = temp_sibling(path);
    let mut file = std::fs::File::create(&tmp)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    drop(file);
    std::fs::rename(&tmp, path)?;
    // The rename itself is durable once the directory is synced (best effort: not
    // every file system lets a directory be opened for it).
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

/// What [`load`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Loaded {
    /// No file yet.
    Fresh,
    /// Read and parsed.
    Existing,
    /// Could not be parsed (or checked); moved to `kept` when the move worked.
    Corrupt {
        error: String,
        kept: Option<PathBuf>,
    },
    /// Could not be read (permissions, I/O); left alone.
    Unreadable { error: String },
}

/// Reads `path` and parses it with `parse`; never fails (see [`Loaded`]): the
/// value is there only for [`Loaded::Existing`].
pub fn load<T>(path: &Path, parse: impl FnOnce(&str) -> Result<T, String>) -> (Option<T>, Loaded) {
    match std::fs::read_to_string(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => (None, Loaded::Fresh),
        Err(e) => (
            None,
            Loaded::Unreadable {
                error: e.to_string(),
            },
        ),
        Ok(text) => match parse(&text) {
            Ok(value) => (Some(value), Loaded::Existing),
            Err(error) => {
                let target = sibling(path, "corrupt");
                let kept = std::fs::rename(path, &target).ok().map(|()| target);
                (None, Loaded::Corrupt { error, kept })
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut n: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        n.sort();
        n
    }

    #[test]
    fn replaces_content_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x");
        write_atomic(&p, b"1\n").unwrap();
        write_atomic(&p, b"22\n").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "22\n");
        assert_eq!(names(dir.path()), ["x"]);
    }

    #[test]
    fn load_tells_fresh_existing_corrupt_and_unreadable_apart() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("state.json");
        let parse = |t: &str| t.trim().parse::<u32>().map_err(|e| e.to_string());
        assert_eq!(load(&p, parse), (None, Loaded::Fresh));
        write_atomic(&p, b"7\n").unwrap();
        assert_eq!(load(&p, parse), (Some(7), Loaded::Existing));
        write_atomic(&p, b"seven\n").unwrap();
        let (v, loaded) = load(&p, parse);
        assert_eq!(v, None);
        let kept = dir.path().join("state.json.corrupt");
        assert!(
            matches!(&loaded, Loaded::Corrupt { kept: Some(k), .. } if *k == kept),
            "{loaded:?}"
        );
        assert_eq!(names(dir.path()), ["state.json.corrupt"], "moved aside");
        // A directory where the file should be cannot be read as one.
        std::fs::create_dir(&p).unwrap();
        let (v, loaded) = load(&p, parse);
        assert_eq!(v, None);
        assert!(matches!(loaded, Loaded::Unreadable { .. }), "{loaded:?}");
        assert!(p.is_dir(), "left alone");
    }
}
