//! Real-time scheduling for the control path (`SKYMESH_REALTIME_PRIORITY`).
//!
//! A service asked for a priority runs every one of its threads under `SCHED_FIFO`
//! at that priority: the runtime sets it on the main thread before the tokio runtime
//! (or anything else) starts a thread, and Linux threads inherit their creator's
//! policy. A woken `SCHED_FIFO` thread preempts every normal thread at once, so a
//! command's hops through the broker, a gateway, the bus and the autopilot link are
//! not queued behind the camera and the vision pipeline. Measured with the vision
//! load running (docs/benchmarks.md, "Real-time priority for the control path"):
//! DRC `drone_control` → MAVLink setpoint p99 6.7–7.1 ms without, 0.83–0.92 ms
//! with (on one CPU, below).
//!
//! The supervisor passes the variable from a service's `realtime_priority` key;
//! systemd units set the policy themselves (`CPUSchedulingPolicy=fifo`), and the
//! supervisor's `skymesh_service_realtime_priority` gauge reads back what each
//! process really runs with, whoever set it. A priority the kernel refuses (no
//! `CAP_SYS_NICE`, `RLIMIT_RTPRIO` too low, or a unit's `RestrictRealtime=`) is a
//! warning, not a failure: the service runs with normal scheduling rather than not
//! at all.
//!
//! **One CPU for the control path** (`SKYMESH_CPU_AFFINITY`). Real-time threads
//! are not pulled to their waker's CPU the way normal ones often are: a wake-up goes
//! to the CPU the thread last ran on, and on an idle machine that CPU is asleep (in
//! a VM, a halted vCPU the host must schedule again). Measured on the project's VM
//! with nothing else running, real-time priority alone took the DRC path's p99 from
//! 1.1–1.2 ms to 3.0–4.0 ms; with the control path's processes on one CPU, each
//! hop's wake-up is on the CPU that is already awake, and the p99 was 0.94–1.02 ms.
//! The affinity is applied the same way as the priority (the main thread, before any
//! other starts; threads inherit it); a CPU the machine does not have is a warning.
//!
//! Keep the priorities below the kernel's interrupt threads (50): 1..=49 is the
//! range for services. The kernel's real-time throttling (`sched_rt_runtime_us`,
//! 95 % by default) and its fair-server reservation keep a runaway real-time thread
//! from starving the rest of the machine, and the heartbeat watchdog still sees it.

use thread_priority::{
    set_thread_priority_and_policy, thread_native_id, thread_schedule_policy_param,
    RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
};

use rustix::thread::{sched_getaffinity, sched_setaffinity, CpuSet};

use crate::config::ConfigError;

/// The real-time priority (`SCHED_FIFO`, 1..=99) a service runs its threads at;
/// unset, empty or `0`: normal scheduling.
pub const REALTIME_ENV: &str = "SKYMESH_REALTIME_PRIORITY";

/// The CPUs every thread of a service may run on, e.g. `1` or `2,3`; unset or
/// empty: wherever the scheduler puts them.
pub const AFFINITY_ENV: &str = "SKYMESH_CPU_AFFINITY";

/// The highest priority [`REALTIME_ENV`] takes (`SCHED_FIFO`'s range is 1..=99).
pub const MAX_PRIORITY: u8 = 99;

/// A `SCHED_FIFO` priority, 1..=99.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RealtimePriority(u8);

impl RealtimePriority {
    /// `Some` for 1..=99; `None` for 0 (normal scheduling); an error above 99.
    pub fn new(value: u8) -> Result<Option<RealtimePriority>, String> {
        match value {
            0 => Ok(None),
            1..=MAX_PRIORITY => Ok(Some(RealtimePriority(value))),
            _ => Err(format!(
                "{value} is not a SCHED_FIFO priority (1..={MAX_PRIORITY}; 0 = normal scheduling)"
            )),
        }
    }

    pub fn get(self) -> u8 {
        self.0
    }
}

/// Parses [`REALTIME_ENV`]'s value: empty or `0` is normal scheduling.
pub fn parse(value: &str) -> Result<Option<RealtimePriority>, String> {
    let v = value.trim();
    if v.is_empty() {
        return Ok(None);
    }
    let n: u8 = v.parse().map_err(|_| {
        format!(
            "`{value}` is not a SCHED_FIFO priority (1..={MAX_PRIORITY}; 0 = normal scheduling)"
        )
    })?;
    RealtimePriority::new(n)
}

/// The priority asked for in the environment (a bad value is a configuration error).
pub fn from_env() -> Result<Option<RealtimePriority>, ConfigError> {
    match std::env::var(REALTIME_ENV) {
        Ok(v) => parse(&v).map_err(|message| ConfigError::Env {
            name: REALTIME_ENV,
            message,
        }),
        Err(_) => Ok(None),
    }
}

/// Parses a CPU list (`1`, `2,3`): every entry a CPU number below
/// [`CpuSet::MAX_CPU`]; empty: no affinity.
pub fn parse_cpus(value: &str) -> Result<Vec<usize>, String> {
    let mut cpus = Vec::new();
    for part in value.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let cpu: usize = part
            .parse()
            .ok()
            .filter(|c| *c < CpuSet::MAX_CPU)
            .ok_or_else(|| {
                format!(
                    "`{part}` is not a CPU number (0..{}; a list is `2,3`)",
                    CpuSet::MAX_CPU
                )
            })?;
        if !cpus.contains(&cpu) {
            cpus.push(cpu);
        }
    }
    Ok(cpus)
}

/// [`AFFINITY_ENV`]'s value for `cpus` (what the supervisor passes), checked as
/// [`parse_cpus`] checks it.
pub fn cpu_list(cpus: &[usize]) -> Result<String, String> {
    let list = cpus
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(",");
    parse_cpus(&list)?;
    Ok(list)
}

/// The CPUs asked for in the environment (a bad list is a configuration error).
pub fn cpus_from_env() -> Result<Vec<usize>, ConfigError> {
    match std::env::var(AFFINITY_ENV) {
        Ok(v) => parse_cpus(&v).map_err(|message| ConfigError::Env {
            name: AFFINITY_ENV,
            message,
        }),
        Err(_) => Ok(Vec::new()),
    }
}

/// Lets the calling thread run only on `cpus`; threads it creates afterwards
/// inherit it. Call before any other thread is started.
pub fn pin(cpus: &[usize]) -> rustix::io::Result<()> {
    let mut set = CpuSet::new();
    for &cpu in cpus {
        set.set(cpu);
    }
    sched_setaffinity(None, &set)
}

/// The CPUs the calling thread may run on.
pub fn current_cpus() -> Vec<usize> {
    match sched_getaffinity(None) {
        Ok(set) => (0..CpuSet::MAX_CPU).filter(|c| set.is_set(*c)).collect(),
        Err(_) => Vec::new(),
    }
}

/// Puts the calling thread under `SCHED_FIFO` at `priority`; threads it creates
/// afterwards inherit it. Call before any other thread is started.
pub fn apply(priority: RealtimePriority) -> Result<(), thread_priority::Error> {
    let value = ThreadPriorityValue::try_from(priority.get())
        .map_err(|_| thread_priority::Error::Priority("priority out of range"))?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
}

/// The calling thread's real-time priority: `Some(p)` under `SCHED_FIFO` or
/// `SCHED_RR`, `None` under a normal policy (or if the kernel does not say).
pub fn current() -> Option<u8> {
    let (policy, params) = thread_schedule_policy_param(thread_native_id()).ok()?;
    match policy {
        ThreadSchedulePolicy::Realtime(
            RealtimeThreadSchedulePolicy::Fifo | RealtimeThreadSchedulePolicy::RoundRobin,
        ) => u8::try_from(params.sched_priority).ok(),
        _ => None,
    }
}

/// What the runtime does with [`AFFINITY_ENV`] and [`REALTIME_ENV`] at start:
/// applies them, and logs the outcome (a refusal is a warning; the service runs
/// unpinned, with normal scheduling).
pub(crate) fn apply_at_start(cpus: &[usize], priority: Option<RealtimePriority>) {
    if !cpus.is_empty() {
        match pin(cpus) {
            Ok(()) => tracing::info!(cpus = ?cpus, "scheduling: pinned (every thread)"),
            Err(e) => tracing::warn!(
                cpus = ?cpus,
                error = %e,
                "CPU affinity refused, running unpinned: the machine has no such CPU or \
                 it is not in this process's allowed set"
            ),
        }
    }
    let Some(p) = priority else {
        return;
    };
    match apply(p) {
        Ok(()) => tracing::info!(priority = p.get(), "scheduling: SCHED_FIFO (every thread)"),
        Err(e) => tracing::warn!(
            priority = p.get(),
            error = %e,
            "real-time priority refused, running with normal scheduling: the process needs \
             CAP_SYS_NICE or an RLIMIT_RTPRIO of at least the priority (systemd: \
             CPUSchedulingPolicy=fifo in the unit instead)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_priorities_and_refuses_the_rest() {
        assert_eq!(parse(""), Ok(None));
        assert_eq!(parse(" 0 "), Ok(None));
        assert_eq!(parse("1").unwrap().map(RealtimePriority::get), Some(1));
        assert_eq!(parse("30").unwrap().map(RealtimePriority::get), Some(30));
        assert_eq!(parse("99").unwrap().map(RealtimePriority::get), Some(99));
        for bad in ["100", "255", "256", "-1", "fifo", "20.5"] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains("SCHED_FIFO priority"), "{bad}: {e}");
        }
    }

    #[test]
    fn parses_cpu_lists_and_refuses_the_rest() {
        assert_eq!(parse_cpus(""), Ok(vec![]));
        assert_eq!(parse_cpus("1"), Ok(vec![1]));
        assert_eq!(parse_cpus(" 2, 3 ,2"), Ok(vec![2, 3]));
        for bad in ["-1", "one", "1-3", "1024", "99999999999999999999"] {
            let e = parse_cpus(bad).unwrap_err();
            assert!(e.contains("not a CPU number"), "{bad}: {e}");
        }
    }

    /// Pinning a thread of its own to the first CPU it may use: it reads back that
    /// one CPU, and a thread it starts inherits it; a CPU nobody has is refused.
    #[test]
    fn pins_a_thread_and_its_children() {
        std::thread::spawn(|| {
            let first = current_cpus()[0];
            pin(&[first]).unwrap();
            assert_eq!(current_cpus(), vec![first]);
            assert_eq!(
                std::thread::spawn(current_cpus).join().unwrap(),
                vec![first]
            );
            assert!(
                pin(&[CpuSet::MAX_CPU - 1]).is_err(),
                "a CPU this machine lacks"
            );
            assert_eq!(current_cpus(), vec![first], "a refused pin changed nothing");
        })
        .join()
        .unwrap();
    }

    /// On a thread of its own (the test harness's threads stay as they are):
    /// applied, the thread reads back the priority; refused (an unprivileged
    /// user), it stays at normal scheduling and says why.
    #[test]
    fn applies_or_refuses_cleanly_and_reads_back() {
        std::thread::spawn(|| {
            assert_eq!(
                current(),
                None,
                "a new thread starts with normal scheduling"
            );
            let p = RealtimePriority::new(7).unwrap().unwrap();
            match apply(p) {
                Ok(()) => {
                    assert_eq!(current(), Some(7));
                    // A thread started now inherits it.
                    let child = std::thread::spawn(current).join().unwrap();
                    assert_eq!(child, Some(7), "threads inherit the policy");
                }
                Err(e) => {
                    assert_eq!(current(), None, "refused ({e}) but changed anyway");
                }
            }
        })
        .join()
        .unwrap();
    }
}
