//! Small files written atomically: a temporary sibling, flushed, then renamed over the
//! target, so a reader (or a crash) sees the old content or the new, never half.

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// `.<file name>.tmp` next to `path`: configured names never start with `.`, so this
/// cannot be another device's file.
fn temp_sibling(path: &Path) -> PathBuf {
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(".tmp");
    path.with_file_name(name)
}

/// Writes `bytes` to `path` atomically (the directory must exist).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = temp_sibling(path);
    let mut file = std::fs::File::create(&tmp)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    drop(file);
    std::fs::rename(&tmp, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_content_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x");
        write_atomic(&p, b"1\n").unwrap();
        write_atomic(&p, b"22\n").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "22\n");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("x")]);
    }
}
