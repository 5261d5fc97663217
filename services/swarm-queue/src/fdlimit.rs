//! File descriptors: a swarm of 250 drones opens over a thousand bus ports (four
//! subscribers and a publisher per drone, each with its event socket), more than the
//! usual soft limit of 1024. The soft limit is raised to the hard limit at start.

use nix::sys::resource::{getrlimit, setrlimit, Resource};

/// Raises the soft `RLIMIT_NOFILE` to the hard limit. Returns (soft before, soft now).
pub fn raise_nofile_limit() -> nix::Result<(u64, u64)> {
    let (soft, hard) = getrlimit(Resource::RLIMIT_NOFILE)?;
    if soft < hard {
        setrlimit(Resource::RLIMIT_NOFILE, hard, hard)?;
    }
    let (now, _) = getrlimit(Resource::RLIMIT_NOFILE)?;
    Ok((soft, now))
}

/// File descriptors this process has open now (`/proc/self/fd`), if readable.
pub fn open_fds() -> Option<usize> {
    std::fs::read_dir("/proc/self/fd").ok().map(|d| d.count())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_soft_limit_reaches_the_hard_limit() {
        let (_, now) = super::raise_nofile_limit().unwrap();
        let (soft, hard) =
            nix::sys::resource::getrlimit(nix::sys::resource::Resource::RLIMIT_NOFILE).unwrap();
        assert_eq!((now, soft), (hard, hard));
        assert!(super::open_fds().unwrap() >= 3);
    }
}
