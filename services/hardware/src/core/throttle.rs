//! Keeps a flood of bad requests from flooding the log: at most [`LINES`] warning
//! lines per [`WINDOW`], then silence, and the next line says how many were left out.
//! Every request is counted in the metrics regardless.

use std::time::Duration;

/// Length of one window.
pub const WINDOW: Duration = Duration::from_secs(10);
/// Lines let through per window.
pub const LINES: u32 = 20;

#[derive(Debug, Default)]
pub struct Throttle {
    window_start: Option<Duration>,
    lines: u32,
    suppressed: u64,
}

impl Throttle {
    /// `Some(n)` if a line may be logged now (`n` lines were left out before it),
    /// `None` to stay silent.
    pub fn allow(&mut self, now: Duration) -> Option<u64> {
        let new_window = self
            .window_start
            .is_none_or(|s| now.saturating_sub(s) >= WINDOW);
        if new_window {
            self.window_start = Some(now);
            self.lines = 0;
        }
        if self.lines >= LINES {
            self.suppressed += 1;
            return None;
        }
        self.lines += 1;
        Some(std::mem::take(&mut self.suppressed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lets_a_burst_through_then_reports_what_it_left_out() {
        let mut t = Throttle::default();
        let t0 = Duration::from_secs(100);
        for _ in 0..LINES {
            assert_eq!(t.allow(t0), Some(0));
        }
        assert_eq!(t.allow(t0), None);
        assert_eq!(t.allow(t0 + Duration::from_secs(9)), None);
        assert_eq!(t.allow(t0 + WINDOW), Some(2));
        assert_eq!(t.allow(t0 + WINDOW), Some(0));
    }
}
