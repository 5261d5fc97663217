//! CPU time, resident memory and scheduling of a process, from `/proc/<pid>/stat`
//! and `statm`.

use std::sync::OnceLock;

use nix::unistd::{sysconf, SysconfVar};

/// Resource usage of one process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcUsage {
    /// User + system CPU time.
    pub cpu_seconds: f64,
    pub resident_bytes: u64,
    /// The main thread's `SCHED_FIFO`/`SCHED_RR` priority; 0 under a normal policy.
    pub realtime_priority: u32,
}

/// Clock ticks per second and page size, asked of the kernel once.
fn units() -> (f64, u64) {
    static UNITS: OnceLock<(f64, u64)> = OnceLock::new();
    *UNITS.get_or_init(|| {
        // Linux always answers both; the fallbacks are its universal values.
        let ticks = sysconf(SysconfVar::CLK_TCK)
            .ok()
            .flatten()
            .filter(|t| *t > 0)
            .unwrap_or(100);
        let page = sysconf(SysconfVar::PAGE_SIZE)
            .ok()
            .flatten()
            .filter(|p| *p > 0)
            .unwrap_or(4096);
        (ticks as f64, page as u64)
    })
}

/// Clock ticks per second (`CLK_TCK`), the unit of times in `/proc/<pid>/stat`.
pub fn ticks_per_second() -> f64 {
    units().0
}

/// Usage of `pid`, or `None` if it is gone or its files cannot be read.
pub fn usage(pid: u32) -> Option<ProcUsage> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let statm = std::fs::read_to_string(format!("/proc/{pid}/statm")).ok()?;
    let (ticks_per_s, page) = units();
    let stat = StatLine::parse(&stat)?;
    let ticks = cpu_ticks(&stat)?;
    let pages = parse_statm_resident_pages(&statm)?;
    Some(ProcUsage {
        cpu_seconds: ticks as f64 / ticks_per_s,
        resident_bytes: pages.saturating_mul(page),
        realtime_priority: realtime_priority(&stat).unwrap_or(0),
    })
}

/// The fields of a `/proc/<pid>/stat` line, addressed by their numbers in proc(5).
/// The command name (field 2) is in parentheses and may contain spaces and `)`, so
/// fields are counted from the last `)`; fields 1 and 2 are not kept.
#[derive(Debug)]
pub struct StatLine<'a>(Vec<&'a str>);

impl<'a> StatLine<'a> {
    pub fn parse(stat: &'a str) -> Option<Self> {
        let (_, rest) = stat.rsplit_once(')')?;
        Some(Self(rest.split_ascii_whitespace().collect()))
    }

    /// Field `n` (3 = state, 5 = pgrp, 14 = utime, …), if the line has it.
    pub fn field(&self, n: usize) -> Option<&'a str> {
        self.0.get(n.checked_sub(3)?).copied()
    }

    /// Field `n` parsed as a number.
    pub fn number<T: std::str::FromStr>(&self, n: usize) -> Option<T> {
        self.field(n)?.parse().ok()
    }
}

/// utime + stime (fields 14 and 15).
fn cpu_ticks(stat: &StatLine<'_>) -> Option<u64> {
    let utime: u64 = stat.number(14)?;
    let stime: u64 = stat.number(15)?;
    Some(utime.saturating_add(stime))
}

/// `rt_priority` (field 40) under `SCHED_FIFO` or `SCHED_RR` (`policy`, field 41:
/// 1 or 2), else 0.
fn realtime_priority(stat: &StatLine<'_>) -> Option<u32> {
    let rt_priority: u32 = stat.number(40)?;
    let policy: u32 = stat.number(41)?;
    Some(if matches!(policy, 1 | 2) {
        rt_priority
    } else {
        0
    })
}

/// utime + stime of a `/proc/<pid>/stat` line.
pub fn parse_stat_cpu_ticks(stat: &str) -> Option<u64> {
    cpu_ticks(&StatLine::parse(stat)?)
}

/// The real-time priority of a `/proc/<pid>/stat` line; 0 under a normal policy.
pub fn parse_stat_realtime_priority(stat: &str) -> Option<u32> {
    realtime_priority(&StatLine::parse(stat)?)
}

/// The resident set size in pages (second field of `/proc/<pid>/statm`).
pub fn parse_statm_resident_pages(statm: &str) -> Option<u64> {
    statm.split_ascii_whitespace().nth(1)?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_stat_even_with_parentheses_in_the_name() {
        let line = "1234 (we ird) name) S 1 1234 1234 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 1 0 12345 1000000 200 18446744073709551615";
        assert_eq!(parse_stat_cpu_ticks(line), Some(300));
        assert_eq!(parse_stat_cpu_ticks("garbage"), None);
        assert_eq!(
            parse_statm_resident_pages("1000 250 100 1 0 300 0\n"),
            Some(250)
        );
        assert_eq!(parse_statm_resident_pages(""), None);
    }

    #[test]
    fn parses_the_realtime_priority_only_under_a_realtime_policy() {
        // `chrt -f 20 cat /proc/self/stat` on kernel 6.18: rt_priority 20, policy 1.
        let fifo = "14251 (cat) R 14249 14249 16858 0 -1 4194560 174 0 0 0 0 0 0 0 -21 0 1 0 \
                    5633607 3133440 379 18446744073709551615 93844405014528 93844405034409 \
                    140721775032320 0 0 0 0 0 0 0 0 0 17 1 20 1 0 0 0 93844405050416 \
                    93844405052032 93844871458816 140721775033056 140721775033076 \
                    140721775033076 140721775034347 0";
        assert_eq!(parse_stat_realtime_priority(fifo), Some(20));
        let rr = fifo.replace(" 17 1 20 1 ", " 17 1 20 2 ");
        assert_eq!(parse_stat_realtime_priority(&rr), Some(20));
        // SCHED_OTHER (0) and SCHED_BATCH (3) have no real-time priority.
        let other = fifo.replace(" 17 1 20 1 ", " 17 1 0 0 ");
        assert_eq!(parse_stat_realtime_priority(&other), Some(0));
        let batch = fifo.replace(" 17 1 20 1 ", " 17 1 0 3 ");
        assert_eq!(parse_stat_realtime_priority(&batch), Some(0));
        assert_eq!(parse_stat_realtime_priority("1 (x) S 1 2 3"), None);
    }

    #[test]
    fn reads_this_process() {
        let u = usage(std::process::id()).expect("own /proc entry");
        assert!(u.resident_bytes > 0);
        assert!(u.cpu_seconds >= 0.0);
        // The test harness runs with normal scheduling.
        assert_eq!(u.realtime_priority, 0);
        assert!(usage(u32::MAX).is_none());
    }
}
