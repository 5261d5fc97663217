//! Restart policy: what to do when a child ends. Pure logic with explicit instants
//! and an explicit random number, so it is tested without sleeping.
//!
//! - exit code 64 (bad configuration) is never restarted;
//! - a clean exit (0) is restarted only in `always` mode;
//! - everything else is restarted after a jittered exponential backoff, unless the
//!   restart budget (`max_restarts` within `window`) is spent, which fails the service;
//! - a run that lasted `stable_after` resets the backoff to its initial value.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use skymesh_runtime::{exit, Backoff};

/// When a service that exited is started again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestartMode {
    /// After a failure (non-zero exit, signal, hang); a clean exit stays stopped.
    OnFailure,
    /// After any exit except a configuration error.
    Always,
}

/// A service's restart settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestartPolicy {
    pub mode: RestartMode,
    /// Delay before the first restart of a streak.
    pub backoff_initial: Duration,
    /// The delay doubles per consecutive failure up to this.
    pub backoff_max: Duration,
    /// Relative jitter (0.2 = ±20 %), so services that failed together restart apart
    /// (the runtime's [`Backoff`] rule: never above `backoff_max`).
    pub jitter: f64,
    /// A run at least this long resets the backoff.
    pub stable_after: Duration,
    /// Restarts allowed within `window`; one more failure and the service is `failed`.
    pub max_restarts: u32,
    pub window: Duration,
}

impl RestartPolicy {
    /// The restart delays: `backoff_initial` doubling to `backoff_max`, `jitter`.
    pub fn backoff(&self) -> Backoff {
        Backoff::new(self.backoff_initial, self.backoff_max).with_jitter(self.jitter)
    }
}

impl Default for RestartPolicy {
    fn default() -> Self {
        RestartPolicy {
            mode: RestartMode::OnFailure,
            backoff_initial: Duration::from_millis(100),
            backoff_max: Duration::from_secs(30),
            jitter: 0.2,
            stable_after: Duration::from_secs(10),
            max_restarts: 5,
            window: Duration::from_secs(60),
        }
    }
}

/// How a run of a child ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// The process exited with this code.
    Code(i32),
    /// The process was killed by this signal (not by the supervisor's hang detection).
    Signal(i32),
    /// The supervisor killed it: heartbeats stopped, or never started.
    Hung,
    /// The process could not be started at all.
    SpawnFailed,
    /// An adopted process (started by an earlier supervisor) ended. It is not our
    /// child, so its exit status went to its new parent: counted as a failure.
    Lost,
}

impl Ending {
    /// The value exported as `last_exit_code`: the code, or 128 + signal as a shell reports it.
    pub fn exit_code(self) -> Option<i32> {
        match self {
            Ending::Code(c) => Some(c),
            Ending::Signal(s) => Some(128 + s),
            Ending::Hung => Some(128 + nix::sys::signal::Signal::SIGKILL as i32),
            Ending::SpawnFailed | Ending::Lost => None,
        }
    }
}

/// What the supervisor does next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// Start it again after this delay.
    Restart { after: Duration },
    /// Exit code 64: never restarted, state `config-error`.
    ConfigError,
    /// The restart budget is spent: state `failed`.
    Failed { restarts_in_window: usize },
    /// Clean exit under `on-failure`: state `stopped`.
    Stopped,
}

/// One service's restart history.
#[derive(Debug, Clone)]
pub struct RestartTracker {
    policy: RestartPolicy,
    /// Failures since the last stable run.
    streak: u32,
    /// When each restart inside the current window was decided.
    recent: VecDeque<Instant>,
}

impl RestartTracker {
    pub fn new(policy: RestartPolicy) -> Self {
        RestartTracker {
            policy,
            streak: 0,
            recent: VecDeque::new(),
        }
    }

    /// Decides what follows a run that lasted `ran_for` and ended at `now` with `ending`.
    pub fn on_exit(
        &mut self,
        now: Instant,
        ran_for: Duration,
        ending: Ending,
        rand01: f64,
    ) -> Decision {
        match ending {
            Ending::Code(c) if c == i32::from(exit::CONFIG) => return Decision::ConfigError,
            Ending::Code(0) if self.policy.mode == RestartMode::OnFailure => {
                return Decision::Stopped
            }
            _ => {}
        }
        if ran_for >= self.policy.stable_after {
            self.streak = 0;
        }
        while let Some(&t) = self.recent.front() {
            if now.saturating_duration_since(t) >= self.policy.window {
                self.recent.pop_front();
            } else {
                break;
            }
        }
        if self.recent.len() >= self.policy.max_restarts as usize {
            return Decision::Failed {
                restarts_in_window: self.recent.len(),
            };
        }
        self.streak = self.streak.saturating_add(1);
        self.recent.push_back(now);
        Decision::Restart {
            after: self.policy.backoff().delay(self.streak, rand01),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn no_jitter() -> RestartPolicy {
        RestartPolicy {
            jitter: 0.0,
            max_restarts: 100,
            ..RestartPolicy::default()
        }
    }

    #[test]
    fn the_policy_paces_restarts_with_its_settings() {
        // The rule itself is tested in skymesh_runtime::backoff.
        let p = RestartPolicy::default();
        assert_eq!(p.backoff().delay(1, 0.0), ms(80));
        assert_eq!(p.backoff().delay(1, 1.0), ms(120));
        assert_eq!(
            no_jitter().backoff().delay(11, 0.5),
            Duration::from_secs(30)
        );
        for r in [0.0, 0.5, 1.0] {
            assert!(p.backoff().delay(30, r) <= Duration::from_secs(30));
        }
    }

    #[test]
    fn crash_loop_backs_off_and_stable_run_resets() {
        let mut t = RestartTracker::new(no_jitter());
        let t0 = Instant::now();
        let mut delays = Vec::new();
        for i in 0..4 {
            match t.on_exit(t0 + ms(i * 100), ms(50), Ending::Code(1), 0.5) {
                Decision::Restart { after } => delays.push(after),
                d => panic!("{d:?}"),
            }
        }
        assert_eq!(delays, [ms(100), ms(200), ms(400), ms(800)]);
        // Up for 10 s, then a crash: back to the initial delay.
        let d = t.on_exit(
            t0 + Duration::from_secs(20),
            Duration::from_secs(10),
            Ending::Signal(9),
            0.5,
        );
        assert_eq!(d, Decision::Restart { after: ms(100) });
        let d = t.on_exit(t0 + Duration::from_secs(21), ms(10), Ending::Hung, 0.5);
        assert_eq!(d, Decision::Restart { after: ms(200) });
    }

    #[test]
    fn exit_64_is_never_restarted_and_clean_exit_depends_on_mode() {
        let mut t = RestartTracker::new(RestartPolicy::default());
        let now = Instant::now();
        assert_eq!(
            t.on_exit(now, ms(5), Ending::Code(64), 0.5),
            Decision::ConfigError
        );
        assert_eq!(
            t.on_exit(now, ms(5), Ending::Code(0), 0.5),
            Decision::Stopped
        );
        // The end of an adopted process (exit status unknown) is a failure.
        assert!(matches!(
            t.on_exit(now, ms(5), Ending::Lost, 0.5),
            Decision::Restart { .. }
        ));
        let mut always = RestartTracker::new(RestartPolicy {
            mode: RestartMode::Always,
            ..no_jitter()
        });
        assert_eq!(
            always.on_exit(now, ms(5), Ending::Code(0), 0.5),
            Decision::Restart { after: ms(100) }
        );
        assert_eq!(
            always.on_exit(now, ms(5), Ending::Code(64), 0.5),
            Decision::ConfigError
        );
    }

    #[test]
    fn budget_spent_within_the_window_fails_and_old_restarts_expire() {
        let policy = RestartPolicy {
            max_restarts: 3,
            window: Duration::from_secs(60),
            ..no_jitter()
        };
        let mut t = RestartTracker::new(policy);
        let t0 = Instant::now();
        for i in 0..3 {
            assert!(matches!(
                t.on_exit(t0 + Duration::from_secs(i), ms(1), Ending::Code(1), 0.5),
                Decision::Restart { .. }
            ));
        }
        assert_eq!(
            t.on_exit(t0 + Duration::from_secs(10), ms(1), Ending::Code(1), 0.5),
            Decision::Failed {
                restarts_in_window: 3
            }
        );
        // The same failures spread over more than the window are allowed.
        let mut t = RestartTracker::new(policy);
        for i in 0..10 {
            assert!(matches!(
                t.on_exit(
                    t0 + Duration::from_secs(i * 30),
                    ms(1),
                    Ending::Code(1),
                    0.5
                ),
                Decision::Restart { .. }
            ));
        }
        let mut none = RestartTracker::new(RestartPolicy {
            max_restarts: 0,
            ..policy
        });
        assert!(matches!(
            none.on_exit(t0, ms(1), Ending::SpawnFailed, 0.5),
            Decision::Failed { .. }
        ));
    }

    #[test]
    fn exit_codes_follow_the_shell_convention() {
        assert_eq!(Ending::Code(3).exit_code(), Some(3));
        assert_eq!(Ending::Signal(15).exit_code(), Some(143));
        assert_eq!(Ending::Hung.exit_code(), Some(137));
        assert_eq!(Ending::SpawnFailed.exit_code(), None);
        assert_eq!(Ending::Lost.exit_code(), None);
    }
}
