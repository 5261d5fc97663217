//! Answer bookkeeping: which command sample each COMMAND_ACK or GOPRO_SET_RESPONSE
//! belongs to, retransmission and timeouts. Pure: no I/O, every instant is passed in.
//!
//! One outstanding command per MAV_CMD id (a newer one supersedes the older, which
//! is answered `Cancelled`). `ACCEPTED` → accepted;
//! `IN_PROGRESS` → in progress, then wait up to the in-progress timeout for the final
//! answer; `DENIED`/`FAILED`/`UNSUPPORTED`/`TEMPORARILY_REJECTED`/`CANCELLED` →
//! refused with that reason. No answer within the timeout → retransmitted with
//! `confirmation` + 1, up to the configured retries, then refused `Timeout`.
//!
//! A retransmission is not written blindly: [`AckTracker::poll`] hands it back with
//! the command sample it serves, the service has the arbiter decide that sample
//! again, and a refusal cancels it ([`AckTracker::cancel`], answered with the
//! arbiter's reason). An emergency stop or a pre-emption cancels the affected
//! commands at once ([`AckTracker::cancel_where`]): nothing the stop or the
//! higher-priority source overrides goes out again.
//!
//! GoPro requests ride the same tracker, keyed by GOPRO_COMMAND instead of MAV_CMD
//! ([`AnswerKey`]): one outstanding per `cmd_id` (a newer one supersedes the older,
//! `Cancelled`), GOPRO_SET_RESPONSE `SUCCESS` → accepted, `FAILED` → refused
//! `Failed`, nothing within the timeout → refused `Timeout` without retransmitting.
//! As with COMMAND_ACK, an answer carries no request id: a late answer to a
//! superseded request is taken as the answer to its successor.

use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavResult;
use skymesh_ipc_types::{AckResult, RefusalReason, VehicleCommand};

use crate::commands::{AnswerKey, MavCommand};

/// Identifies the command sample an answer belongs to (everything a `CommandAck` echoes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Origin {
    pub vehicle_id: u8,
    pub source: u8,
    pub kind: u8,
    pub command_id: u32,
    pub command_seq: u32,
}

impl Origin {
    pub fn of(sample: &VehicleCommand) -> Self {
        Origin {
            vehicle_id: sample.vehicle_id,
            source: sample.source,
            kind: sample.kind,
            command_id: sample.command_id,
            // CommandAck carries 32 bits of the sample sequence.
            command_seq: sample.header.seq as u32,
        }
    }
}

/// The outcome to publish for one command.
#[derive(Debug, Clone, PartialEq)]
pub struct Answer {
    pub origin: Origin,
    pub result: AckResult,
    pub reason: RefusalReason,
    /// `MAV_RESULT`, or 255 when the autopilot did not answer.
    pub mav_result: u8,
    pub detail: String,
    /// Command sample → COMMAND_ACK, when the autopilot answered.
    pub latency: Option<Duration>,
}

impl Answer {
    pub fn refused(origin: Origin, reason: RefusalReason, detail: impl Into<String>) -> Self {
        Answer {
            origin,
            result: AckResult::Refused,
            reason,
            mav_result: skymesh_ipc_types::CommandAck::NO_MAV_RESULT,
            detail: detail.into(),
            latency: None,
        }
    }

    pub fn accepted(origin: Origin) -> Self {
        Answer {
            origin,
            result: AckResult::Accepted,
            reason: RefusalReason::None,
            mav_result: skymesh_ipc_types::CommandAck::NO_MAV_RESULT,
            detail: String::new(),
            latency: None,
        }
    }
}

/// Maps a `MAV_RESULT` to the answer's result and reason.
pub fn classify(mav_result: u8) -> (AckResult, RefusalReason) {
    const ACCEPTED: u8 = MavResult::MAV_RESULT_ACCEPTED as u8;
    const IN_PROGRESS: u8 = MavResult::MAV_RESULT_IN_PROGRESS as u8;
    const TEMPORARILY_REJECTED: u8 = MavResult::MAV_RESULT_TEMPORARILY_REJECTED as u8;
    const DENIED: u8 = MavResult::MAV_RESULT_DENIED as u8;
    const FAILED: u8 = MavResult::MAV_RESULT_FAILED as u8;
    const CANCELLED: u8 = MavResult::MAV_RESULT_CANCELLED as u8;
    const NOT_IN_CONTROL: u8 = MavResult::MAV_RESULT_NOT_IN_CONTROL as u8;
    let refused = |r| (AckResult::Refused, r);
    match mav_result {
        ACCEPTED => (AckResult::Accepted, RefusalReason::None),
        IN_PROGRESS => (AckResult::InProgress, RefusalReason::None),
        TEMPORARILY_REJECTED => refused(RefusalReason::TemporarilyRejected),
        DENIED | NOT_IN_CONTROL => refused(RefusalReason::Denied),
        FAILED => refused(RefusalReason::Failed),
        CANCELLED => refused(RefusalReason::Cancelled),
        // UNSUPPORTED, COMMAND_LONG_ONLY, COMMAND_INT_ONLY, UNSUPPORTED_MAV_FRAME.
        _ => refused(RefusalReason::Unsupported),
    }
}

fn mav_result_name(mav_result: u8) -> &'static str {
    match mav_result {
        0 => "accepted",
        1 => "temporarily rejected",
        2 => "denied",
        3 => "unsupported",
        4 => "failed",
        5 => "in progress",
        6 => "cancelled",
        7 => "COMMAND_LONG only",
        8 => "COMMAND_INT only",
        9 => "unsupported frame",
        10 => "not in control",
        _ => "unknown result",
    }
}

/// Timeouts of the command protocol.
#[derive(Debug, Clone, Copy)]
pub struct AckPolicy {
    pub timeout: Duration,
    pub retries: u8,
    pub in_progress_timeout: Duration,
}

#[derive(Debug)]
struct Pending {
    origin: Origin,
    /// The command sample, for the arbiter to decide a retransmission again.
    sample: Option<VehicleCommand>,
    command: MavCommand,
    /// When the command sample was taken in (latency is measured from here).
    received: Instant,
    deadline: Instant,
    retries_left: u8,
    in_progress: bool,
}

/// Something the caller must do after [`AckTracker::poll`].
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Write `command` (with `confirmation` already incremented) again, unless the
    /// arbiter now refuses `sample` (then [`AckTracker::cancel`] it).
    Retransmit {
        origin: Origin,
        sample: Option<VehicleCommand>,
        command: MavCommand,
    },
    /// Publish this answer.
    Answer(Answer),
}

/// Outstanding answered requests, at most one per [`AnswerKey`] (MAV_CMD or GOPRO_COMMAND).
#[derive(Debug)]
pub struct AckTracker {
    policy: AckPolicy,
    pending: Vec<Pending>,
}

impl AckTracker {
    pub fn new(policy: AckPolicy) -> Self {
        AckTracker {
            policy,
            pending: Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        self.pending.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }

    /// Tracks `command`, which was written to the link at `now` for the sample taken
    /// in at `received`. Returns the answer for the command it supersedes, if any.
    pub fn submit(
        &mut self,
        origin: Origin,
        command: MavCommand,
        received: Instant,
        now: Instant,
    ) -> Option<Answer> {
        self.track(origin, None, command, received, now)
    }

    /// [`AckTracker::submit`] for `sample`, kept so that a retransmission can be
    /// decided again.
    pub fn submit_sample(
        &mut self,
        sample: &VehicleCommand,
        command: MavCommand,
        received: Instant,
        now: Instant,
    ) -> Option<Answer> {
        self.track(Origin::of(sample), Some(*sample), command, received, now)
    }

    fn track(
        &mut self,
        origin: Origin,
        sample: Option<VehicleCommand>,
        command: MavCommand,
        received: Instant,
        now: Instant,
    ) -> Option<Answer> {
        let key = command.key();
        let superseded = self
            .pending
            .iter()
            .position(|p| p.command.key() == key)
            .map(|i| self.pending.swap_remove(i))
            .map(|old| {
                Answer::refused(
                    old.origin,
                    RefusalReason::Cancelled,
                    format!(
                        "superseded by command {} before the autopilot answered",
                        origin.command_id
                    ),
                )
            });
        let retries_left = if command.retransmits() {
            self.policy.retries
        } else {
            0
        };
        self.pending.push(Pending {
            origin,
            sample,
            command,
            received,
            deadline: now + self.policy.timeout,
            retries_left,
            in_progress: false,
        });
        superseded
    }

    /// A COMMAND_ACK arrived. Returns the answer for the matching command, if one is
    /// outstanding (acks of commands others sent, or already answered, are `None`).
    /// `refusal_detail` is used as detail for refusals (e.g. a recent STATUSTEXT).
    pub fn on_ack(
        &mut self,
        mav_cmd: u32,
        mav_result: u8,
        refusal_detail: Option<&str>,
        now: Instant,
    ) -> Option<Answer> {
        let i = self
            .pending
            .iter()
            .position(|p| p.command.key() == AnswerKey::CommandAck(mav_cmd))?;
        let (result, reason) = classify(mav_result);
        let p = &mut self.pending[i];
        // Latency is to the first COMMAND_ACK (a final one after IN_PROGRESS is not a round trip).
        let latency = (!p.in_progress).then(|| now.saturating_duration_since(p.received));
        if result == AckResult::InProgress {
            p.in_progress = true;
            p.deadline = now + self.policy.in_progress_timeout;
            return Some(Answer {
                origin: p.origin,
                result,
                reason,
                mav_result,
                detail: "in progress".to_string(),
                latency,
            });
        }
        let p = self.pending.swap_remove(i);
        let detail = match result {
            AckResult::Refused => match refusal_detail {
                Some(text) if !text.is_empty() => text.to_string(),
                _ => format!("autopilot: {}", mav_result_name(mav_result)),
            },
            _ => String::new(),
        };
        Some(Answer {
            origin: p.origin,
            result,
            reason,
            mav_result,
            detail,
            latency,
        })
    }

    /// A GOPRO_SET_RESPONSE arrived from the vehicle's system. Returns the answer for
    /// the outstanding GoPro request with that `cmd_id`, if there is one.
    pub fn on_gopro_response(&mut self, cmd_id: u8, success: bool, now: Instant) -> Option<Answer> {
        let i = self
            .pending
            .iter()
            .position(|p| p.command.key() == AnswerKey::GoPro(cmd_id))?;
        let p = self.pending.swap_remove(i);
        let latency = Some(now.saturating_duration_since(p.received));
        Some(if success {
            Answer {
                latency,
                ..Answer::accepted(p.origin)
            }
        } else {
            Answer {
                latency,
                ..Answer::refused(p.origin, RefusalReason::Failed, "GoPro: request failed")
            }
        })
    }

    /// Retransmissions and timeouts due at `now`.
    pub fn poll(&mut self, now: Instant) -> Vec<Action> {
        let mut actions = Vec::new();
        let timeout = self.policy.timeout;
        self.pending.retain_mut(|p| {
            if now < p.deadline {
                return true;
            }
            if !p.in_progress && p.retries_left > 0 {
                p.retries_left -= 1;
                p.command.bump_confirmation();
                p.deadline = now + timeout;
                actions.push(Action::Retransmit {
                    origin: p.origin,
                    sample: p.sample,
                    command: p.command.clone(),
                });
                return true;
            }
            let detail = match p.command.key() {
                AnswerKey::GoPro(_) => "no GOPRO_SET_RESPONSE from the gimbal",
                AnswerKey::CommandAck(_) if p.in_progress => "no final answer after in progress",
                AnswerKey::CommandAck(_) => "no COMMAND_ACK from the autopilot",
            };
            actions.push(Action::Answer(Answer::refused(
                p.origin,
                RefusalReason::Timeout,
                detail,
            )));
            false
        });
        actions
    }

    /// The earliest instant at which [`AckTracker::poll`] has something to do.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.pending.iter().map(|p| p.deadline).min()
    }

    /// Stops tracking the command of `origin` (its retransmission is not written),
    /// answering it refused with `reason`. `None` if it is not outstanding.
    pub fn cancel(
        &mut self,
        origin: &Origin,
        reason: RefusalReason,
        detail: &str,
    ) -> Option<Answer> {
        let i = self.pending.iter().position(|p| p.origin == *origin)?;
        let p = self.pending.swap_remove(i);
        Some(Answer::refused(p.origin, reason, detail))
    }

    /// Cancels every outstanding command whose origin `matches` (an emergency stop:
    /// every flight command; a pre-emption: the pre-empted source's), answering
    /// each refused with `reason`; they are not retransmitted.
    pub fn cancel_where(
        &mut self,
        matches: impl Fn(&Origin) -> bool,
        reason: RefusalReason,
        detail: &str,
    ) -> Vec<Answer> {
        let mut answers = Vec::new();
        self.pending.retain(|p| {
            if !matches(&p.origin) {
                return true;
            }
            answers.push(Answer::refused(p.origin, reason, detail));
            false
        });
        answers
    }

    /// Answers every outstanding command (link lost, shutting down).
    pub fn fail_all(&mut self, reason: RefusalReason, detail: &str) -> Vec<Answer> {
        self.pending
            .drain(..)
            .map(|p| Answer::refused(p.origin, reason, detail))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::{plan, PlanContext, Target};
    use mavlink::dialects::ardupilotmega::MavCmd;
    use skymesh_ipc_types::{Command, CommandSource, FlightMode};

    fn plan_of(c: Command) -> crate::commands::Plan {
        let ctx = PlanContext {
            target: Target {
                system: 1,
                component: 1,
            },
            mode: FlightMode::Loiter,
            capture_seq: 1,
        };
        plan(&c, &ctx).unwrap()
    }

    fn sample(cmd: &Command, id: u32) -> VehicleCommand {
        let mut s = VehicleCommand::new(1, CommandSource::Operator, id, cmd).unwrap();
        s.header.seq = u64::from(id) + 100;
        s
    }

    fn origin(id: u32) -> Origin {
        Origin::of(&sample(&Command::Arm { force: false }, id))
    }

    fn arm() -> MavCommand {
        plan_of(Command::Arm { force: false }).command.unwrap()
    }

    fn tracker() -> AckTracker {
        AckTracker::new(AckPolicy {
            timeout: Duration::from_millis(1500),
            retries: 1,
            in_progress_timeout: Duration::from_secs(30),
        })
    }

    const ARM: u32 = MavCmd::MAV_CMD_COMPONENT_ARM_DISARM as u32;

    #[test]
    fn an_accepted_ack_answers_with_latency() {
        let t0 = Instant::now();
        let mut t = tracker();
        assert_eq!(t.submit(origin(1), arm(), t0, t0), None);
        assert_eq!(t.next_deadline(), Some(t0 + Duration::from_millis(1500)));
        // An ack for a command nobody is waiting for is ignored.
        assert_eq!(t.on_ack(176, 0, None, t0), None);
        let a = t
            .on_ack(ARM, 0, None, t0 + Duration::from_millis(40))
            .unwrap();
        assert_eq!(a.origin, origin(1));
        assert_eq!(
            (a.result, a.reason, a.mav_result),
            (AckResult::Accepted, RefusalReason::None, 0)
        );
        assert_eq!(a.latency, Some(Duration::from_millis(40)));
        assert!(t.is_empty());
        assert_eq!(t.on_ack(ARM, 0, None, t0), None, "answered only once");
    }

    #[test]
    fn refusals_carry_the_reason_and_a_detail() {
        let t0 = Instant::now();
        for (result, reason) in [
            (2, RefusalReason::Denied),
            (4, RefusalReason::Failed),
            (3, RefusalReason::Unsupported),
            (1, RefusalReason::TemporarilyRejected),
            (6, RefusalReason::Cancelled),
        ] {
            let mut t = tracker();
            t.submit(origin(1), arm(), t0, t0);
            let a = t.on_ack(ARM, result, None, t0).unwrap();
            assert_eq!(
                (a.result, a.reason, a.mav_result),
                (AckResult::Refused, reason, result)
            );
            assert!(a.detail.starts_with("autopilot: "), "{}", a.detail);
        }
        let mut t = tracker();
        t.submit(origin(1), arm(), t0, t0);
        let a = t
            .on_ack(ARM, 2, Some("PreArm: Need Position Estimate"), t0)
            .unwrap();
        assert_eq!(a.detail, "PreArm: Need Position Estimate");
    }

    #[test]
    fn no_answer_retransmits_once_with_confirmation_then_times_out() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.submit(origin(1), arm(), t0, t0);
        assert!(t.poll(ms(1499)).is_empty());
        let actions = t.poll(ms(1500));
        let [Action::Retransmit {
            origin: o,
            sample: None,
            command: MavCommand::Long(c),
        }] = actions.as_slice()
        else {
            panic!("{actions:?}")
        };
        assert_eq!(*o, origin(1));
        assert_eq!(c.confirmation, 1);
        assert_eq!(t.next_deadline(), Some(ms(3000)));
        assert!(t.poll(ms(2999)).is_empty());
        let actions = t.poll(ms(3000));
        let [Action::Answer(a)] = actions.as_slice() else {
            panic!("{actions:?}")
        };
        assert_eq!(
            (a.result, a.reason),
            (AckResult::Refused, RefusalReason::Timeout)
        );
        assert_eq!(a.mav_result, 255);
        assert!(t.is_empty());
        assert_eq!(t.next_deadline(), None);
    }

    #[test]
    fn an_answer_to_the_retransmission_still_counts() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.submit(origin(1), arm(), t0, t0);
        assert_eq!(t.poll(ms(1500)).len(), 1);
        let a = t.on_ack(ARM, 0, None, ms(1600)).unwrap();
        assert_eq!(a.result, AckResult::Accepted);
        assert_eq!(a.latency, Some(Duration::from_millis(1600)));
    }

    #[test]
    fn in_progress_waits_for_the_final_answer_without_retransmitting() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.submit(origin(1), arm(), t0, t0);
        let a = t.on_ack(ARM, 5, None, ms(100)).unwrap();
        assert_eq!(a.result, AckResult::InProgress);
        assert_eq!(a.latency, Some(Duration::from_millis(100)));
        assert_eq!(t.len(), 1);
        assert!(
            t.poll(ms(20_000)).is_empty(),
            "no retransmit while in progress"
        );
        let a = t.on_ack(ARM, 0, None, ms(25_000)).unwrap();
        assert_eq!(a.result, AckResult::Accepted);
        assert_eq!(a.latency, None, "latency was taken at the in-progress ack");
        // And an in-progress command that never finishes times out.
        t.submit(origin(2), arm(), t0, t0);
        t.on_ack(ARM, 5, None, ms(100));
        let actions = t.poll(ms(30_100));
        let [Action::Answer(a)] = actions.as_slice() else {
            panic!("{actions:?}")
        };
        assert_eq!(a.reason, RefusalReason::Timeout);
    }

    fn gopro(command: u8, value: u8) -> MavCommand {
        plan_of(Command::GoProSet {
            command,
            value: [value, 0, 0, 0],
        })
        .command
        .unwrap()
    }

    #[test]
    fn a_gopro_response_answers_the_request_with_its_cmd_id() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        // Capture mode (1) and shutter (2) outstanding, and an arm waiting for its
        // COMMAND_ACK: a MAV_CMD number never answers a GOPRO_COMMAND of that number.
        assert_eq!(t.submit(origin(1), gopro(1, 1), t0, t0), None);
        assert_eq!(t.submit(origin(2), gopro(2, 1), t0, t0), None);
        assert_eq!(t.submit(origin(3), arm(), t0, t0), None);
        // Nobody waits for cmd_id 5; a COMMAND_ACK never answers a GoPro request.
        assert_eq!(t.on_gopro_response(5, true, ms(10)), None);
        assert_eq!(t.on_ack(1, 0, None, ms(10)), None);
        let a = t.on_gopro_response(2, true, ms(80)).unwrap();
        assert_eq!(a.origin, origin(2));
        assert_eq!(
            (a.result, a.reason, a.mav_result),
            (AckResult::Accepted, RefusalReason::None, 255)
        );
        assert_eq!(a.latency, Some(Duration::from_millis(80)));
        assert_eq!(t.on_gopro_response(2, true, ms(90)), None, "answered once");
        let a = t.on_gopro_response(1, false, ms(100)).unwrap();
        assert_eq!(a.origin, origin(1));
        assert_eq!(
            (a.result, a.reason),
            (AckResult::Refused, RefusalReason::Failed)
        );
        assert_eq!(a.detail, "GoPro: request failed");
        assert_eq!(t.len(), 1, "the arm command is still waiting");
        assert_eq!(t.on_ack(ARM, 0, None, ms(100)).unwrap().origin, origin(3));
    }

    #[test]
    fn an_unanswered_gopro_request_times_out_without_retransmission() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        t.submit(origin(1), gopro(2, 1), t0, t0);
        assert!(t.poll(ms(1499)).is_empty());
        let actions = t.poll(ms(1500));
        let [Action::Answer(a)] = actions.as_slice() else {
            panic!("no retransmission, only the timeout: {actions:?}")
        };
        assert_eq!(
            (a.result, a.reason, a.mav_result),
            (AckResult::Refused, RefusalReason::Timeout, 255)
        );
        assert_eq!(a.detail, "no GOPRO_SET_RESPONSE from the gimbal");
        assert!(t.is_empty());
    }

    #[test]
    fn a_second_gopro_request_with_the_same_cmd_id_cancels_the_first() {
        let t0 = Instant::now();
        let mut t = tracker();
        t.submit(origin(1), gopro(1, 0), t0, t0);
        let old = t.submit(origin(2), gopro(1, 1), t0, t0).unwrap();
        assert_eq!(old.origin, origin(1));
        assert_eq!(
            (old.result, old.reason),
            (AckResult::Refused, RefusalReason::Cancelled)
        );
        assert_eq!(
            t.submit(origin(3), gopro(2, 1), t0, t0),
            None,
            "other cmd_id"
        );
        assert_eq!(t.len(), 2);
        assert_eq!(t.on_gopro_response(1, true, t0).unwrap().origin, origin(2));
        let rest = t.fail_all(RefusalReason::LinkDown, "link lost");
        assert_eq!(rest.len(), 1);
        assert_eq!(rest[0].origin, origin(3));
    }

    #[test]
    fn a_newer_command_with_the_same_id_supersedes_the_older() {
        let t0 = Instant::now();
        let mut t = tracker();
        t.submit(origin(1), arm(), t0, t0);
        let takeoff = plan_of(Command::Takeoff { alt_rel_m: 5.0 })
            .command
            .unwrap();
        assert_eq!(
            t.submit(origin(2), takeoff, t0, t0),
            None,
            "different MAV_CMD"
        );
        let disarm = plan_of(Command::Disarm { force: false }).command.unwrap();
        let old = t.submit(origin(3), disarm, t0, t0).unwrap();
        assert_eq!(old.origin, origin(1));
        assert_eq!(
            (old.result, old.reason),
            (AckResult::Refused, RefusalReason::Cancelled)
        );
        assert_eq!(t.len(), 2);
        let a = t.on_ack(ARM, 0, None, t0).unwrap();
        assert_eq!(a.origin, origin(3));
        let rest = t.fail_all(RefusalReason::LinkDown, "link lost");
        assert_eq!(rest.len(), 1);
        assert_eq!(rest[0].origin, origin(2));
        assert_eq!(rest[0].reason, RefusalReason::LinkDown);
        assert!(t.is_empty());
    }

    #[test]
    fn a_retransmission_carries_its_sample_and_a_cancelled_one_never_goes_out() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        let arm_sample = sample(&Command::Arm { force: false }, 1);
        t.submit_sample(&arm_sample, arm(), t0, t0);
        let actions = t.poll(ms(1500));
        let [Action::Retransmit {
            origin: o,
            sample: Some(s),
            ..
        }] = actions.as_slice()
        else {
            panic!("{actions:?}")
        };
        assert_eq!((*o, *s), (origin(1), arm_sample));
        // The service's arbiter refuses it now: cancelled with that reason.
        let a = t
            .cancel(&origin(1), RefusalReason::Emergency, "emergency stop")
            .unwrap();
        assert_eq!(
            (a.origin, a.result, a.reason),
            (origin(1), AckResult::Refused, RefusalReason::Emergency)
        );
        assert!(t.is_empty());
        assert!(
            t.poll(ms(3000)).is_empty(),
            "no timeout answer, no second retransmission"
        );
        assert_eq!(t.cancel(&origin(1), RefusalReason::Emergency, ""), None);
        assert_eq!(
            t.on_ack(ARM, 0, None, ms(3100)),
            None,
            "a late ack answers nothing"
        );
    }

    #[test]
    fn cancel_where_answers_the_matching_commands_and_keeps_the_others() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut t = tracker();
        let takeoff = sample(&Command::Takeoff { alt_rel_m: 5.0 }, 2);
        let servo = sample(
            &Command::Servo {
                channel: 9,
                pwm_us: 1500,
            },
            3,
        );
        t.submit_sample(&sample(&Command::Arm { force: false }, 1), arm(), t0, t0);
        t.submit_sample(
            &takeoff,
            plan_of(Command::Takeoff { alt_rel_m: 5.0 })
                .command
                .unwrap(),
            t0,
            t0,
        );
        t.submit_sample(
            &servo,
            plan_of(Command::Servo {
                channel: 9,
                pwm_us: 1500,
            })
            .command
            .unwrap(),
            t0,
            t0,
        );
        let flight = |o: &Origin| {
            skymesh_ipc_types::CommandKind::try_from(o.kind)
                .ok()
                .and_then(|k| k.authority())
                == Some(skymesh_ipc_types::AuthorityDomain::Flight)
        };
        let mut cancelled = t.cancel_where(flight, RefusalReason::Cancelled, "emergency stop");
        cancelled.sort_by_key(|a| a.origin.command_id);
        assert_eq!(
            cancelled
                .iter()
                .map(|a| a.origin.command_id)
                .collect::<Vec<_>>(),
            vec![1, 2]
        );
        assert!(cancelled
            .iter()
            .all(|a| a.reason == RefusalReason::Cancelled && a.detail == "emergency stop"));
        // Only the servo (payload) is retransmitted.
        let actions = t.poll(ms(1500));
        let [Action::Retransmit { origin: o, .. }] = actions.as_slice() else {
            panic!("{actions:?}")
        };
        assert_eq!(o.command_id, 3);
    }
}
