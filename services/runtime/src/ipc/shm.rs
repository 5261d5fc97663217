//! The room left in the shared-memory file system, checked before a bus opens.

use std::path::{Path, PathBuf};

use crate::config::ConfigError;

/// Where POSIX shared memory (every iceoryx2 segment) lives on Linux.
pub const SHM_DIR: &str = "/dev/shm";
/// Environment variable overriding [`SHM_MIN_FREE_BYTES`] (bytes; 0 turns the check off).
pub const SHM_MIN_FREE_ENV: &str = "SKYMESH_SHM_MIN_FREE_BYTES";
/// A service refuses to start (exit [`crate::exit::SHM_FULL`]) with less room than
/// this in [`SHM_DIR`]: iceoryx2 maps its segments sparsely and touches the pages
/// later, and a page that cannot be backed then kills the process with SIGBUS. One
/// service's segments take a few hundred KiB up to tens of MiB (camera frames).
pub const SHM_MIN_FREE_BYTES: u64 = 4 << 20;
/// Below this much room a starting service warns: size `/dev/shm` up.
pub const SHM_LOW_FREE_BYTES: u64 = 64 << 20;

/// Room in a shared-memory file system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShmSpace {
    /// Bytes an unprivileged process can still allocate.
    pub free: u64,
    /// Size of the file system.
    pub size: u64,
}

/// The room in `dir` (normally [`SHM_DIR`]), by `statvfs`.
// The statvfs field types are u64 here but u32 on 32-bit targets.
#[allow(clippy::useless_conversion)]
pub fn shm_space(dir: &Path) -> std::io::Result<ShmSpace> {
    let st = nix::sys::statvfs::statvfs(dir).map_err(std::io::Error::from)?;
    let frag = u64::from(st.fragment_size());
    Ok(ShmSpace {
        free: u64::from(st.blocks_available()).saturating_mul(frag),
        size: u64::from(st.blocks()).saturating_mul(frag),
    })
}

/// `dir` has less room than a service needs to open its bus.
#[derive(Debug, thiserror::Error)]
#[error(
    "shared memory {dir} is full: {free} bytes free of {size}, need at least {need} \
     (make room or size it up, e.g. `mount -o remount,size=256m {dir}`; \
     ${SHM_MIN_FREE_ENV} sets the minimum)",
    dir = dir.display()
)]
pub struct ShmFull {
    pub dir: PathBuf,
    pub free: u64,
    pub size: u64,
    pub need: u64,
}

/// Checked before the bus is opened: `Err` if `dir` has less than `need` bytes free
/// (creating segments there could end in SIGBUS instead of an error), else its room.
/// A `dir` that cannot be examined is not an error (`Ok(None)`): iceoryx2 reports it.
pub fn check_shm_room(dir: &Path, need: u64) -> Result<Option<ShmSpace>, ShmFull> {
    let Ok(space) = shm_space(dir) else {
        return Ok(None);
    };
    if space.free < need {
        return Err(ShmFull {
            dir: dir.to_path_buf(),
            free: space.free,
            size: space.size,
            need,
        });
    }
    Ok(Some(space))
}

/// The minimum room from `$SKYMESH_SHM_MIN_FREE_BYTES` (bytes), else [`SHM_MIN_FREE_BYTES`].
pub fn shm_min_free_from_env() -> Result<u64, ConfigError> {
    match std::env::var(SHM_MIN_FREE_ENV) {
        Ok(v) if !v.trim().is_empty() => v.trim().parse().map_err(|_| ConfigError::Env {
            name: SHM_MIN_FREE_ENV,
            message: format!("`{v}` is not a number of bytes"),
        }),
        _ => Ok(SHM_MIN_FREE_BYTES),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shm_room_check_names_the_dir_and_the_numbers() {
        let dir = Path::new(SHM_DIR);
        let space = check_shm_room(dir, 0)
            .unwrap()
            .expect("/dev/shm is examinable");
        assert!(space.size >= space.free, "{space:?}");
        let e = check_shm_room(dir, u64::MAX).unwrap_err();
        assert_eq!(e.need, u64::MAX);
        let text = e.to_string();
        assert!(
            text.starts_with("shared memory /dev/shm is full: ")
                && text.contains(&format!("need at least {}", u64::MAX))
                && text.contains(SHM_MIN_FREE_ENV),
            "{text}"
        );
        // A directory that cannot be examined is left to iceoryx2.
        assert!(check_shm_room(Path::new("/nonexistent/skymesh"), u64::MAX)
            .unwrap()
            .is_none());
    }
}
