//! Which of our finished logs to delete, oldest first: [`plan`] decides (pure),
//! [`enforce`] lists the directory, asks the file system for its free space and
//! deletes. Only files whose names are ours ([`super::format::parse_name`]) and
//! that are regular files are ever listed; the file being written is never one of
//! them (it still ends in `.part`).

use std::io;
use std::path::{Path, PathBuf};

use super::format::parse_name;

/// The limits of `[tlog]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Logs kept, the one being written included.
    pub max_files: u32,
    /// Bytes of all logs together, the one being written included.
    pub max_total: u64,
    /// Free bytes left on the file system (for unprivileged users).
    pub min_free: u64,
}

/// What [`plan`] decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Plan {
    /// Delete this many of the oldest finished logs.
    pub delete: usize,
    /// The limits hold once they are gone; `false`: they cannot hold even with
    /// every finished log deleted (the file being written alone is too big, or the
    /// disk is full of other things): stop recording.
    pub fits: bool,
}

/// `finished`: the sizes of our finished logs, oldest first; `current`: bytes of
/// the file being written (or about to be opened: 0), which counts as one file;
/// `free`: free bytes on the file system now.
pub fn plan(finished: &[u64], current: u64, free: u64, limits: Limits) -> Plan {
    let mut count = finished.len() as u64 + 1;
    let mut total = finished.iter().sum::<u64>() + current;
    let mut free = free;
    let over = |count: u64, total: u64, free: u64| {
        count > u64::from(limits.max_files) || total > limits.max_total || free < limits.min_free
    };
    let mut delete = 0;
    while over(count, total, free) && delete < finished.len() {
        count -= 1;
        total -= finished[delete];
        free = free.saturating_add(finished[delete]);
        delete += 1;
    }
    Plan {
        delete,
        fits: !over(count, total, free),
    }
}

/// Our finished logs of `vehicle` in `dir`, oldest first, with their sizes.
pub fn finished_logs(dir: &Path, vehicle: u8) -> io::Result<Vec<(PathBuf, u64)>> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some(ours) = name.to_str().and_then(|n| parse_name(vehicle, n)) else {
            continue;
        };
        // Not through symlinks: a link is not a log we wrote.
        let meta = entry.metadata()?;
        if ours.part || !meta.file_type().is_file() {
            continue;
        }
        found.push((ours, entry.path(), meta.len()));
    }
    found.sort();
    Ok(found.into_iter().map(|(_, p, len)| (p, len)).collect())
}

/// Free bytes for unprivileged users on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> io::Result<u64> {
    let s = nix::sys::statvfs::statvfs(dir).map_err(io::Error::from)?;
    Ok(s.blocks_available().saturating_mul(s.fragment_size()))
}

/// What [`enforce`] did.
#[derive(Debug, Default)]
pub struct Enforced {
    pub deleted: Vec<PathBuf>,
    /// See [`Plan::fits`].
    pub fits: bool,
}

/// Deletes the oldest of our finished logs until the limits hold with a file of
/// `current` bytes being written.
pub fn enforce(dir: &Path, vehicle: u8, current: u64, limits: Limits) -> io::Result<Enforced> {
    let logs = finished_logs(dir, vehicle)?;
    let sizes: Vec<u64> = logs.iter().map(|(_, len)| *len).collect();
    let p = plan(&sizes, current, free_bytes(dir)?, limits);
    let mut done = Enforced {
        deleted: Vec::new(),
        fits: p.fits,
    };
    for (path, _) in logs.into_iter().take(p.delete) {
        match std::fs::remove_file(&path) {
            Ok(()) => done.deleted.push(path),
            // Deleted by someone else meanwhile: what we wanted.
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ROOMY: Limits = Limits {
        max_files: 100,
        max_total: 1 << 40,
        min_free: 0,
    };

    #[test]
    fn the_oldest_go_first_until_every_limit_holds() {
        let sizes = [10, 20, 30, 40];
        assert_eq!(
            plan(&sizes, 0, 1000, ROOMY),
            Plan {
                delete: 0,
                fits: true
            }
        );
        // 4 kept + 1 new > 3 files: the two oldest go.
        let files = Limits {
            max_files: 3,
            ..ROOMY
        };
        assert_eq!(plan(&sizes, 0, 1000, files).delete, 2);
        // 100 + 25 being written > 100 bytes: 10, 20 go (95 left).
        let total = Limits {
            max_total: 100,
            ..ROOMY
        };
        assert_eq!(
            plan(&sizes, 25, 1000, total),
            Plan {
                delete: 2,
                fits: true
            }
        );
        // 5 bytes free, 50 wanted: 10 + 20 + 30 freed make 65.
        let free = Limits {
            min_free: 50,
            ..ROOMY
        };
        assert_eq!(plan(&sizes, 0, 5, free).delete, 3);
    }

    #[test]
    fn limits_that_cannot_hold_say_so() {
        let total = Limits {
            max_total: 100,
            ..ROOMY
        };
        assert_eq!(
            plan(&[10, 20], 150, 1000, total),
            Plan {
                delete: 2,
                fits: false
            }
        );
        let free = Limits {
            min_free: 1000,
            ..ROOMY
        };
        assert!(!plan(&[], 0, 999, free).fits);
        assert!(plan(&[], 0, 1000, free).fits);
        let one = Limits {
            max_files: 1,
            ..ROOMY
        };
        assert_eq!(
            plan(&[1, 2, 3], 0, 0, one),
            Plan {
                delete: 3,
                fits: true
            }
        );
    }

    fn write(dir: &Path, name: &str, len: usize) {
        std::fs::write(dir.join(name), vec![0u8; len]).unwrap();
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn enforce_deletes_only_our_oldest_finished_logs() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // Ours, out of creation order on purpose: the name's time decides.
        write(d, "skymesh-v1-20260102T000000.000Z.tlog", 100);
        write(d, "skymesh-v1-20260101T000000.000Z.tlog", 100);
        write(d, "skymesh-v1-20260101T000000.000Z-1.tlog", 100);
        write(d, "skymesh-v1-20260103T000000.000Z.tlog", 100);
        // Being written: never listed.
        write(d, "skymesh-v1-20250101T000000.000Z.tlog.part", 100);
        // Not ours: another vehicle's, a user's, look-alikes, a directory.
        write(d, "skymesh-v2-20240101T000000.000Z.tlog", 100);
        write(d, "flight-2024.tlog", 100);
        write(d, "skymesh-v1-2024.tlog", 100);
        std::fs::create_dir(d.join("skymesh-v1-20240101T000000.000Z.tlog")).unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(
            d.join("flight-2024.tlog"),
            d.join("skymesh-v1-20240102T000000.000Z.tlog"),
        )
        .unwrap();

        let listed = finished_logs(d, 1).unwrap();
        let listed: Vec<_> = listed
            .iter()
            .map(|(p, len)| (p.file_name().unwrap().to_str().unwrap().to_string(), *len))
            .collect();
        assert_eq!(
            listed,
            vec![
                ("skymesh-v1-20260101T000000.000Z.tlog".to_string(), 100),
                ("skymesh-v1-20260101T000000.000Z-1.tlog".to_string(), 100),
                ("skymesh-v1-20260102T000000.000Z.tlog".to_string(), 100),
                ("skymesh-v1-20260103T000000.000Z.tlog".to_string(), 100),
            ]
        );

        // Two files kept besides the one about to open.
        let limits = Limits {
            max_files: 3,
            ..ROOMY
        };
        let done = enforce(d, 1, 0, limits).unwrap();
        assert!(done.fits);
        assert_eq!(done.deleted.len(), 2);
        let left = names(d);
        assert!(!left.contains(&"skymesh-v1-20260101T000000.000Z.tlog".to_string()));
        assert!(!left.contains(&"skymesh-v1-20260101T000000.000Z-1.tlog".to_string()));
        for kept in [
            "skymesh-v1-20260102T000000.000Z.tlog",
            "skymesh-v1-20260103T000000.000Z.tlog",
            "skymesh-v1-20250101T000000.000Z.tlog.part",
            "skymesh-v2-20240101T000000.000Z.tlog",
            "flight-2024.tlog",
            "skymesh-v1-2024.tlog",
            "skymesh-v1-20240101T000000.000Z.tlog",
            "skymesh-v1-20240102T000000.000Z.tlog",
        ] {
            assert!(left.contains(&kept.to_string()), "{kept} deleted: {left:?}");
        }

        // By total size: 200 kept + 150 being written > 300 → the older goes.
        let bytes = Limits {
            max_total: 300,
            ..ROOMY
        };
        let done = enforce(d, 1, 150, bytes).unwrap();
        assert!(done.fits);
        assert_eq!(
            done.deleted,
            vec![d.join("skymesh-v1-20260102T000000.000Z.tlog")]
        );
        // Nothing of ours can make 1000 bytes being written fit in 300.
        let done = enforce(d, 1, 1000, bytes).unwrap();
        assert!(!done.fits);
        assert_eq!(finished_logs(d, 1).unwrap().len(), 0);
        assert_eq!(names(d).len(), 6, "{:?}", names(d));
    }

    #[test]
    fn the_disk_must_keep_its_free_space() {
        let dir = tempfile::tempdir().unwrap();
        let free = free_bytes(dir.path()).unwrap();
        assert!(free > 0);
        write(dir.path(), "skymesh-v1-20260101T000000.000Z.tlog", 10);
        // More free space than the disk has: even without our log it cannot hold.
        let limits = Limits {
            min_free: u64::MAX,
            ..ROOMY
        };
        let done = enforce(dir.path(), 1, 0, limits).unwrap();
        assert!(!done.fits);
        assert_eq!(done.deleted.len(), 1);
        let limits = Limits {
            min_free: 0,
            ..ROOMY
        };
        assert!(enforce(dir.path(), 1, 0, limits).unwrap().fits);
    }
}
