//! Real-time scheduling for the control path (`SKYMESH_REALTIME_PRIORITY`).
//!
//! A service asked for a priority runs every one of its threads under `SCHED_FIFO`
//! at that priority: the runtime sets it on the main thread before the tokio runtime
//! (or anything else) starts a thread, and Linux threads inherit their creator's
//! policy. A woken `SCHED_FIFO` thread preempts every normal thread at once, so a
//! command's hops through the broker, a gateway, the bus and the autopilot link are
//! not queued behind the camera and the vision pipeline. Measured with the vision
//! load running (docs/benchmarks.md, "Real-time priority for the control path"):
//! DRC `drone_control` → MAVLink setpoint p99 6.5–6.7 ms without, 1.2 ms with.
//!
//! The supervisor passes the variable from a service's `realtime_priority` key;
//! systemd units set the policy themselves (`CPUSchedulingPolicy=fifo`), and the
//! supervisor's `skymesh_service_realtime_priority` gauge reads back what each
//! process really runs with, whoever set it. A priority the kernel refuses (no
//! `CAP_SYS_NICE`, `RLIMIT_RTPRIO` too low, or a unit's `RestrictRealtime=`) is a
//! warning, not a failure: the service runs with normal scheduling rather than not
//! at all.
//!
//! Keep the priorities below the kernel's interrupt threads (50): 1..=49 is the
//! range for services. The kernel's real-time throttling (`sched_rt_runtime_us`,
//! 95 % by default) and its fair-server reservation keep a runaway real-time thread
//! from starving the rest of the machine, and the heartbeat watchdog still sees it.

use thread_priority::{
    set_thread_priority_and_policy, thread_native_id, thread_schedule_policy_param,
    RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
};

use crate::config::ConfigError;

/// The real-time priority (`SCHED_FIFO`, 1..=99) a service runs its threads at;
/// unset, empty or `0`: normal scheduling.
pub const REALTIME_ENV: &str = "SKYMESH_REALTIME_PRIORITY";

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

/// What the runtime does with [`REALTIME_ENV`] at start: applies it, and logs the
/// outcome (a refusal is a warning; the service runs with normal scheduling).
pub(crate) fn apply_at_start(priority: Option<RealtimePriority>) {
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
