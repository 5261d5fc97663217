//! The emergency stop, driven until the autopilot confirms it. Pure: every instant
//! and every observation is passed in, so it is tested without sleeping.
//!
//! An `EmergencyStop` the arbiter let through starts (or joins) a *drive*:
//!
//! - In RTL, LAND or SmartRTL (the autopilot's own failsafe descents) nothing is
//!   sent: the descent goes on, and the stop is answered `accepted` "failsafe
//!   descent held" at once (the arbiter's emergency latch still keeps every other
//!   source out). A drive that sees one of these modes reported mid-way stops
//!   sending for the same reason: the autopilot has taken over.
//! - Otherwise DO_SET_MODE BRAKE goes out at once and again every `mode_retry`
//!   (with COMMAND_LONG `confirmation` counting the repeats) until a HEARTBEAT
//!   reports BRAKE; a COMMAND_ACK accepting it postpones the next repeat by one
//!   more `mode_retry` (the HEARTBEAT that shows it is on its way), one refusing it
//!   is kept for the failure's detail. A zero-velocity setpoint goes out at once
//!   and every `setpoint_period` until the measured speed has stayed below
//!   `stopped_mps` for `settle` (GUIDED flies them; any other mode ignores them).
//!
//! Each stop command is answered once: `accepted` when a HEARTBEAT reports BRAKE
//! or the measured speed confirms the vehicle stopped (whichever comes first; a
//! stop that joins a confirmed drive is answered at once), else refused `failed`
//! `confirm_timeout` after it arrived, with what was seen. Nothing is sent after
//! the last stop's deadline: a drive ends once BRAKE is reported and the vehicle
//! stopped, or at that deadline. The emergency latch itself is the arbiter's; a
//! failed stop leaves it in force (a source may send the stop again).
//!
//! A latch with nobody left braking for it gets an *unowned* drive
//! ([`StopTracker::rebrake`]): when autopilot-link starts with an emergency latch
//! restored from its state file, or the link comes back up while a latch is in
//! force, the vehicle may be moving (the drive that braked it ended with the link
//! or the process). The drive is the same as for a fresh stop (BRAKE and
//! zero-velocity setpoints until confirmed, at most `confirm_timeout`; nothing in
//! a failsafe descent) with no stop command to answer; a disarmed vehicle gets
//! nothing.
//!
//! Speed is the norm of the measured NED velocity (horizontal and vertical): a
//! vehicle still sinking or climbing has not stopped. Only measurements taken
//! after the stop arrived count (the service feeds each new one), and a mode is
//! the one the latest HEARTBEAT reported.

use std::time::{Duration, Instant};

use skymesh_ipc_types::{AckResult, FlightMode, RefusalReason};

use crate::acks::{classify, Answer, Origin};

/// How a stop is driven and when it is given up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopPolicy {
    /// A stop not confirmed this long after it arrived is answered `failed`.
    pub confirm_timeout: Duration,
    /// DO_SET_MODE BRAKE is repeated this often until BRAKE is reported.
    pub mode_retry: Duration,
    /// Zero-velocity setpoints are repeated this often until stopped.
    pub setpoint_period: Duration,
    /// Below this speed (m/s) the vehicle counts as stopped...
    pub stopped_mps: f32,
    /// ... once every measurement for this long said so.
    pub settle: Duration,
}

impl StopPolicy {
    /// 5 s to confirm, BRAKE every second, setpoints at 10 Hz, < 0.3 m/s for 0.2 s.
    pub const DEFAULT: StopPolicy = StopPolicy {
        confirm_timeout: Duration::from_secs(5),
        mode_retry: Duration::from_secs(1),
        setpoint_period: Duration::from_millis(100),
        stopped_mps: 0.3,
        settle: Duration::from_millis(200),
    };
}

/// Something the service must do for the stop.
#[derive(Debug, Clone, PartialEq)]
pub enum StopAction {
    /// Write COMMAND_LONG DO_SET_MODE BRAKE with this `confirmation` (0 first).
    BrakeMode { confirmation: u8 },
    /// Write a zero-velocity SET_POSITION_TARGET_LOCAL_NED.
    ZeroSetpoint,
    /// Publish this answer to a stop command.
    Answer(Answer),
}

/// The autopilot's failsafe descents, which an emergency stop holds, not brakes.
pub fn is_failsafe(mode: FlightMode) -> bool {
    matches!(
        mode,
        FlightMode::Rtl | FlightMode::Land | FlightMode::SmartRtl
    )
}

fn held(origin: Origin, mode: FlightMode) -> Answer {
    Answer {
        detail: format!("failsafe descent held ({mode})"),
        ..Answer::accepted(origin)
    }
}

#[derive(Debug)]
struct Waiter {
    origin: Origin,
    deadline: Instant,
}

#[derive(Debug)]
struct Drive {
    waiters: Vec<Waiter>,
    /// Nothing is sent from here on (the last waiter's deadline).
    until: Instant,
    started: Instant,
    /// Sticky: once BRAKE was reported, it is not commanded again by this drive.
    mode_confirmed: bool,
    next_mode: Instant,
    mode_sends: u8,
    /// The autopilot's last refusal of BRAKE.
    refusal: Option<String>,
    stopped: bool,
    next_setpoint: Instant,
    slow_since: Option<Instant>,
    speed: Option<f32>,
    mode: FlightMode,
}

impl Drive {
    /// A drive starting at `now` in `mode`, sending until `until`, nobody waiting.
    fn new(now: Instant, until: Instant, mode: FlightMode) -> Drive {
        Drive {
            waiters: Vec::new(),
            until,
            started: now,
            mode_confirmed: mode == FlightMode::Brake,
            next_mode: now,
            mode_sends: 0,
            refusal: None,
            stopped: false,
            next_setpoint: now,
            slow_since: None,
            speed: None,
            mode,
        }
    }

    fn confirmation(&self) -> Option<String> {
        if self.mode_confirmed {
            Some("BRAKE confirmed by the autopilot".to_string())
        } else if self.stopped {
            Some(format!(
                "stopped: {:.2} m/s measured",
                self.speed.unwrap_or(0.0)
            ))
        } else {
            None
        }
    }

    fn failure(&self, now: Instant) -> String {
        let waited = now.saturating_duration_since(self.started).as_secs_f32();
        let speed = self
            .speed
            .map_or_else(|| "no speed".to_string(), |s| format!("{s:.1} m/s"));
        // The ack's detail holds 48 bytes: what was measured first.
        match &self.refusal {
            Some(r) => format!("{speed} after {waited:.1} s; BRAKE: {r}"),
            None => format!("{speed} after {waited:.1} s; mode {}", self.mode),
        }
    }
}

/// The emergency stop of one vehicle.
#[derive(Debug)]
pub struct StopTracker {
    policy: StopPolicy,
    drive: Option<Drive>,
}

impl StopTracker {
    pub fn new(policy: StopPolicy) -> Self {
        StopTracker {
            policy,
            drive: None,
        }
    }

    /// Whether a stop is being driven (frames still go out or answers are due).
    pub fn is_active(&self) -> bool {
        self.drive.is_some()
    }

    /// The arbiter let the stop `origin` through at `now`; `mode` is the mode the
    /// latest HEARTBEAT reported.
    pub fn engage(&mut self, origin: Origin, now: Instant, mode: FlightMode) -> Vec<StopAction> {
        if is_failsafe(mode) {
            // A drive still running would brake the descent: it ends, its stops held too.
            let mut out = self.end_held(mode);
            out.push(StopAction::Answer(held(origin, mode)));
            return out;
        }
        let deadline = now + self.policy.confirm_timeout;
        let drive = self
            .drive
            .get_or_insert_with(|| Drive::new(now, deadline, mode));
        drive.until = drive.until.max(deadline);
        drive.waiters.push(Waiter { origin, deadline });
        self.step(now)
    }

    /// An emergency latch is in force with no drive behind it (restored at start,
    /// or the link came back up): brake as for a fresh stop, with no stop command to
    /// answer. Nothing is sent to a disarmed vehicle (it is not moving; BRAKE would
    /// only be a mode it cannot arm in) or in a failsafe descent (`mode` RTL, LAND,
    /// SmartRTL). A drive already running just goes on.
    pub fn rebrake(&mut self, now: Instant, mode: FlightMode, armed: bool) -> Vec<StopAction> {
        if self.drive.is_none() {
            if !armed || is_failsafe(mode) {
                return Vec::new();
            }
            self.drive = Some(Drive::new(now, now + self.policy.confirm_timeout, mode));
        }
        self.step(now)
    }

    /// A HEARTBEAT reported `mode`.
    pub fn on_heartbeat(&mut self, now: Instant, mode: FlightMode) -> Vec<StopAction> {
        let Some(drive) = self.drive.as_mut() else {
            return Vec::new();
        };
        drive.mode = mode;
        if is_failsafe(mode) {
            return self.end_held(mode);
        }
        if mode == FlightMode::Brake {
            drive.mode_confirmed = true;
        }
        self.step(now)
    }

    /// A new velocity measurement (NED, m/s) arrived at `now`.
    pub fn on_velocity(&mut self, now: Instant, vel_ned_mps: [f32; 3]) -> Vec<StopAction> {
        let Some(drive) = self.drive.as_mut() else {
            return Vec::new();
        };
        let [n, e, d] = vel_ned_mps;
        let speed = (n * n + e * e + d * d).sqrt();
        drive.speed = Some(speed);
        if !drive.stopped {
            if speed < self.policy.stopped_mps {
                let since = *drive.slow_since.get_or_insert(now);
                drive.stopped = now.saturating_duration_since(since) >= self.policy.settle;
            } else {
                drive.slow_since = None;
            }
        }
        self.step(now)
    }

    /// A COMMAND_ACK for DO_SET_MODE that no tracked command claimed. `true` if it
    /// was taken as the answer to the drive's BRAKE.
    pub fn on_mode_ack(&mut self, now: Instant, mav_result: u8, detail: Option<&str>) -> bool {
        let Some(drive) = self
            .drive
            .as_mut()
            .filter(|d| d.mode_sends > 0 && !d.mode_confirmed)
        else {
            return false;
        };
        match classify(mav_result) {
            (AckResult::Accepted, _) => {
                drive.refusal = None;
                drive.next_mode = drive.next_mode.max(now + self.policy.mode_retry);
            }
            (AckResult::Refused, reason) => {
                drive.refusal = Some(match detail {
                    Some(text) if !text.is_empty() => text.to_string(),
                    _ => reason.as_str().to_string(),
                });
            }
            _ => {}
        }
        true
    }

    /// Repeats and deadlines due at `now`.
    pub fn poll(&mut self, now: Instant) -> Vec<StopAction> {
        if self.drive.is_none() {
            return Vec::new();
        }
        self.step(now)
    }

    /// When [`StopTracker::poll`] next has something to do.
    pub fn next_deadline(&self) -> Option<Instant> {
        let d = self.drive.as_ref()?;
        let mode = (!d.mode_confirmed).then_some(d.next_mode);
        let setpoint = (!d.stopped).then_some(d.next_setpoint);
        let answer = d.waiters.iter().map(|w| w.deadline).min();
        [mode, setpoint, answer, Some(d.until)]
            .into_iter()
            .flatten()
            .min()
    }

    /// Ends the drive (emergency cleared, link lost, shutting down): nothing more
    /// is sent; stops still waiting are refused with `reason`.
    pub fn end(&mut self, reason: RefusalReason, detail: &str) -> Vec<Answer> {
        self.drive
            .take()
            .map(|d| d.waiters)
            .unwrap_or_default()
            .into_iter()
            .map(|w| Answer::refused(w.origin, reason, detail))
            .collect()
    }

    fn end_held(&mut self, mode: FlightMode) -> Vec<StopAction> {
        self.drive
            .take()
            .map(|d| d.waiters)
            .unwrap_or_default()
            .into_iter()
            .map(|w| StopAction::Answer(held(w.origin, mode)))
            .collect()
    }

    fn step(&mut self, now: Instant) -> Vec<StopAction> {
        let policy = self.policy;
        let Some(d) = self.drive.as_mut() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        if let Some(detail) = d.confirmation() {
            out.extend(d.waiters.drain(..).map(|w| {
                StopAction::Answer(Answer {
                    detail: detail.clone(),
                    ..Answer::accepted(w.origin)
                })
            }));
        } else if d.waiters.iter().any(|w| w.deadline <= now) {
            let failure = d.failure(now);
            d.waiters.retain(|w| {
                if w.deadline > now {
                    return true;
                }
                out.push(StopAction::Answer(Answer::refused(
                    w.origin,
                    RefusalReason::Failed,
                    failure.clone(),
                )));
                false
            });
        }
        let done = d.mode_confirmed && d.stopped;
        if done || now >= d.until {
            if d.waiters.is_empty() {
                self.drive = None;
            }
            return out;
        }
        if !d.mode_confirmed && now >= d.next_mode {
            out.push(StopAction::BrakeMode {
                confirmation: d.mode_sends,
            });
            d.mode_sends = d.mode_sends.saturating_add(1);
            d.next_mode = now + policy.mode_retry;
        }
        if !d.stopped && now >= d.next_setpoint {
            out.push(StopAction::ZeroSetpoint);
            d.next_setpoint = now + policy.setpoint_period;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{Command, CommandSource, VehicleCommand};

    fn origin(source: CommandSource, id: u32) -> Origin {
        Origin::of(&VehicleCommand::new(1, source, id, &Command::EmergencyStop).unwrap())
    }

    fn tracker() -> StopTracker {
        StopTracker::new(StopPolicy::DEFAULT)
    }

    fn answers(actions: &[StopAction]) -> Vec<&Answer> {
        actions
            .iter()
            .filter_map(|a| match a {
                StopAction::Answer(a) => Some(a),
                _ => None,
            })
            .collect()
    }

    fn brakes(actions: &[StopAction]) -> Vec<u8> {
        actions
            .iter()
            .filter_map(|a| match a {
                StopAction::BrakeMode { confirmation } => Some(*confirmation),
                _ => None,
            })
            .collect()
    }

    fn setpoints(actions: &[StopAction]) -> usize {
        actions
            .iter()
            .filter(|a| **a == StopAction::ZeroSetpoint)
            .count()
    }

    const MOVING: [f32; 3] = [4.0, 3.0, 0.0];
    const STILL: [f32; 3] = [0.1, 0.05, -0.05];

    #[test]
    fn guided_stop_sends_brake_and_a_setpoint_and_waits_for_confirmation() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        let a = t.engage(origin(CommandSource::DjiDrc, 7), t0, FlightMode::Guided);
        assert_eq!(brakes(&a), vec![0]);
        assert_eq!(setpoints(&a), 1);
        assert!(answers(&a).is_empty(), "not accepted when sent: {a:?}");
        // The autopilot accepting the command is not a confirmation either.
        assert!(t.on_mode_ack(ms(30), 0, None));
        assert!(answers(&t.poll(ms(40))).is_empty());
        // Moving: no answer from the speed.
        assert!(answers(&t.on_velocity(ms(50), MOVING)).is_empty());
        // The HEARTBEAT reporting BRAKE is.
        let a = t.on_heartbeat(ms(400), FlightMode::Brake);
        let [ans] = answers(&a)[..] else {
            panic!("{a:?}")
        };
        assert_eq!(ans.origin, origin(CommandSource::DjiDrc, 7));
        assert_eq!(
            (ans.result, ans.reason),
            (AckResult::Accepted, RefusalReason::None)
        );
        assert_eq!(ans.detail, "BRAKE confirmed by the autopilot");
        // BRAKE is not sent again once reported; setpoints go on until stopped.
        let a = t.poll(ms(2000));
        assert!(brakes(&a).is_empty(), "{a:?}");
        assert_eq!(setpoints(&a), 1);
        assert!(t.is_active());
        t.on_velocity(ms(2100), STILL);
        t.on_velocity(ms(2300), STILL);
        assert!(!t.is_active(), "BRAKE reported and stopped: the drive ends");
        assert_eq!(t.next_deadline(), None);
        assert!(t.poll(ms(2400)).is_empty());
    }

    #[test]
    fn setpoints_repeat_at_the_period_and_speed_alone_confirms() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.engage(origin(CommandSource::Operator, 1), t0, FlightMode::Guided);
        assert_eq!(t.next_deadline(), Some(ms(100)));
        assert!(t.poll(ms(99)).is_empty());
        let mut sent = 1;
        for k in 1..=9 {
            let a = t.poll(ms(100 * k));
            assert_eq!(setpoints(&a), 1, "at {k}00 ms: {a:?}");
            sent += 1;
        }
        assert_eq!(sent, 10, "10 Hz");
        // Slowing below 0.3 m/s once is not enough: it must stay there for 0.2 s.
        assert!(answers(&t.on_velocity(ms(950), STILL)).is_empty());
        assert!(answers(&t.on_velocity(ms(1000), [0.5, 0.0, 0.0])).is_empty());
        assert!(answers(&t.on_velocity(ms(1050), STILL)).is_empty());
        assert!(answers(&t.on_velocity(ms(1200), STILL)).is_empty());
        let a = t.on_velocity(ms(1250), STILL);
        let [ans] = answers(&a)[..] else {
            panic!("{a:?}")
        };
        assert_eq!(ans.result, AckResult::Accepted);
        assert!(
            ans.detail.starts_with("stopped: 0.12 m/s"),
            "{}",
            ans.detail
        );
        // Stopped: no more setpoints, BRAKE still retried until reported.
        let a = t.poll(ms(1300));
        assert_eq!(setpoints(&a), 0);
        assert!(t.is_active());
        let a = t.poll(ms(2000));
        assert_eq!(brakes(&a), vec![2], "0 ms, 1000 ms, then 2000 ms: {a:?}");
        t.on_heartbeat(ms(2100), FlightMode::Brake);
        assert!(!t.is_active());
    }

    #[test]
    fn a_lost_brake_is_repeated_with_confirmation_counting() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        assert_eq!(
            brakes(&t.engage(origin(CommandSource::Operator, 1), t0, FlightMode::Loiter)),
            vec![0]
        );
        assert!(brakes(&t.poll(ms(999))).is_empty());
        assert_eq!(brakes(&t.poll(ms(1000))), vec![1]);
        // An accepting COMMAND_ACK gives the HEARTBEAT another period to show it.
        assert!(t.on_mode_ack(ms(1050), 0, None));
        assert!(brakes(&t.poll(ms(2000))).is_empty());
        assert_eq!(brakes(&t.poll(ms(2050))), vec![2]);
        let a = t.on_heartbeat(ms(2200), FlightMode::Brake);
        assert_eq!(answers(&a).len(), 1);
        assert!(!t.on_mode_ack(ms(2300), 0, None), "nothing outstanding");
    }

    #[test]
    fn unconfirmed_after_the_deadline_fails_with_the_reason_and_stops_sending() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.engage(origin(CommandSource::SwarmQueue, 3), t0, FlightMode::Guided);
        assert!(t.on_mode_ack(ms(20), 2, Some("Flight mode change failed")));
        t.on_velocity(ms(4000), [2.0, 0.0, 0.0]);
        let a = t.poll(ms(4999));
        assert!(answers(&a).is_empty());
        let a = t.poll(ms(5000));
        let [ans] = answers(&a)[..] else {
            panic!("{a:?}")
        };
        assert_eq!(
            (ans.result, ans.reason),
            (AckResult::Refused, RefusalReason::Failed)
        );
        assert_eq!(
            ans.detail,
            "2.0 m/s after 5.0 s; BRAKE: Flight mode change failed"
        );
        assert!(brakes(&a).is_empty() && setpoints(&a) == 0, "{a:?}");
        assert!(!t.is_active());
        assert!(t.poll(ms(6000)).is_empty(), "nothing after giving up");
        // Without a refusal or any measurement, the detail says what was seen.
        let mut t = tracker();
        t.engage(origin(CommandSource::SwarmQueue, 4), t0, FlightMode::Guided);
        let a = t.poll(ms(5000));
        assert_eq!(answers(&a)[0].detail, "no speed after 5.0 s; mode guided");
    }

    #[test]
    fn in_a_failsafe_descent_nothing_is_sent_and_the_stop_is_held() {
        let t0 = Instant::now();
        for mode in [FlightMode::Rtl, FlightMode::Land, FlightMode::SmartRtl] {
            let mut t = tracker();
            let a = t.engage(origin(CommandSource::SwarmQueue, 9), t0, mode);
            assert!(brakes(&a).is_empty() && setpoints(&a) == 0, "{a:?}");
            let [ans] = answers(&a)[..] else {
                panic!("{a:?}")
            };
            assert_eq!(ans.result, AckResult::Accepted);
            assert_eq!(ans.detail, format!("failsafe descent held ({mode})"));
            assert!(!t.is_active());
            assert!(t.poll(t0 + Duration::from_secs(1)).is_empty());
        }
    }

    #[test]
    fn a_failsafe_that_starts_mid_drive_ends_it() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.engage(origin(CommandSource::Operator, 1), t0, FlightMode::Guided);
        let a = t.on_heartbeat(ms(500), FlightMode::Land);
        let [ans] = answers(&a)[..] else {
            panic!("{a:?}")
        };
        assert_eq!(ans.detail, "failsafe descent held (land)");
        assert!(!t.is_active());
        assert!(t.poll(ms(1000)).is_empty(), "no BRAKE over the landing");
    }

    #[test]
    fn a_second_stop_joins_the_drive_and_is_answered_at_once_when_confirmed() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.engage(origin(CommandSource::DjiDrc, 1), t0, FlightMode::Guided);
        let a = t.engage(
            origin(CommandSource::SwarmQueue, 2),
            ms(300),
            FlightMode::Guided,
        );
        assert!(brakes(&a).is_empty(), "no extra BRAKE: {a:?}");
        let a = t.on_heartbeat(ms(600), FlightMode::Brake);
        assert_eq!(answers(&a).len(), 2, "both answered: {a:?}");
        let a = t.engage(
            origin(CommandSource::Operator, 3),
            ms(700),
            FlightMode::Brake,
        );
        assert_eq!(answers(&a).len(), 1, "already confirmed: {a:?}");
        // The later stop has its own deadline.
        let mut t = tracker();
        t.engage(origin(CommandSource::DjiDrc, 1), t0, FlightMode::Guided);
        t.engage(
            origin(CommandSource::SwarmQueue, 2),
            ms(2000),
            FlightMode::Guided,
        );
        let a = t.poll(ms(5000));
        assert_eq!(answers(&a).len(), 1);
        assert_eq!(answers(&a)[0].origin.command_id, 1);
        assert!(t.is_active());
        assert_eq!(t.next_deadline(), Some(ms(5100)), "setpoints go on");
        let a = t.poll(ms(7000));
        assert_eq!(answers(&a)[0].origin.command_id, 2);
        assert!(!t.is_active());
    }

    #[test]
    fn a_latch_without_a_drive_is_braked_until_confirmed_answering_nobody() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        // Restored latch, link up, the vehicle flying GUIDED: BRAKE and a setpoint
        // at once, repeated like a fresh stop's.
        let a = t.rebrake(t0, FlightMode::Guided, true);
        assert_eq!(brakes(&a), vec![0]);
        assert_eq!(setpoints(&a), 1);
        assert!(answers(&a).is_empty());
        assert!(t.is_active());
        assert_eq!(setpoints(&t.poll(ms(100))), 1);
        t.on_velocity(ms(150), MOVING);
        assert_eq!(brakes(&t.poll(ms(1000))), vec![1], "BRAKE retried");
        // Confirmed by the mode and the speed: the drive ends, nothing answered.
        let a = t.on_heartbeat(ms(1100), FlightMode::Brake);
        assert!(answers(&a).is_empty(), "{a:?}");
        t.on_velocity(ms(1200), STILL);
        let a = t.on_velocity(ms(1400), STILL);
        assert!(answers(&a).is_empty(), "{a:?}");
        assert!(!t.is_active());
        assert!(t.poll(ms(1500)).is_empty());

        // Never confirmed: nothing is sent after `confirm_timeout`.
        let mut t = tracker();
        t.rebrake(t0, FlightMode::Loiter, true);
        assert_eq!(setpoints(&t.poll(ms(4900))), 1);
        let a = t.poll(ms(5000));
        assert!(a.is_empty(), "{a:?}");
        assert!(!t.is_active());

        // Already in BRAKE: only the setpoints, until stopped.
        let mut t = tracker();
        let a = t.rebrake(t0, FlightMode::Brake, true);
        assert!(brakes(&a).is_empty());
        assert_eq!(setpoints(&a), 1);

        // A failsafe descent is held: nothing at all.
        for mode in [FlightMode::Rtl, FlightMode::Land, FlightMode::SmartRtl] {
            let mut t = tracker();
            assert!(t.rebrake(t0, mode, true).is_empty(), "{mode}");
            assert!(!t.is_active());
        }
        // A disarmed vehicle (a restart on the ground) is left alone.
        let mut t = tracker();
        assert!(t.rebrake(t0, FlightMode::Loiter, false).is_empty());
        assert!(!t.is_active());

        // A drive already running goes on; its stop is still answered by it.
        let mut t = tracker();
        t.engage(origin(CommandSource::DjiDrc, 1), t0, FlightMode::Guided);
        let a = t.rebrake(ms(10), FlightMode::Guided, true);
        assert!(brakes(&a).is_empty() && setpoints(&a) == 0, "{a:?}");
        let a = t.on_heartbeat(ms(300), FlightMode::Brake);
        assert_eq!(answers(&a).len(), 1);
    }

    #[test]
    fn ending_the_drive_answers_who_waits() {
        let t0 = Instant::now();
        let mut t = tracker();
        t.engage(origin(CommandSource::DjiDrc, 1), t0, FlightMode::Guided);
        let rest = t.end(RefusalReason::LinkDown, "link lost");
        assert_eq!(rest.len(), 1);
        assert_eq!(rest[0].reason, RefusalReason::LinkDown);
        assert!(!t.is_active());
        assert!(t.poll(t0 + Duration::from_secs(1)).is_empty());
    }
}
