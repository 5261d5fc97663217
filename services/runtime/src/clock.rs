//! The one clock samples are stamped with.

/// `CLOCK_MONOTONIC` in nanoseconds: the same clock in every process of a machine,
/// so a consumer can compute the age of a sample stamped by another process.
pub fn monotonic_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000) + ts.tv_nsec() as u64,
        // CLOCK_MONOTONIC cannot fail on Linux; 0 makes any age computation saturate.
        Err(_) => 0,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn monotonic_does_not_go_back() {
        let a = super::monotonic_ns();
        let b = super::monotonic_ns();
        assert!(a > 0 && b >= a);
    }
}
