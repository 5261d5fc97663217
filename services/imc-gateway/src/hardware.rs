//! IMC hardware messages ↔ the `hardware` service (pure, explicit time).
//!
//! LED, GPIO, power channel, LCD and companion power messages become
//! [`HardwareRequest`]s; each is remembered until its [`HardwareReply`] (matched by
//! request id and our own sample header) or until it times out. The reply becomes
//! the IMC answer the document prescribes: `LedBrightness`, `GpioState`,
//! `PowerChannelState`, `PowerOperation`, or nothing (LCD). A reply with a result
//! other than `ok` gets no IMC answer (the protocol has no error reply) and is
//! counted `hardware_<result>`; the one exception is a refused power down, which is
//! answered `PWR_DOWN_ABORTED` so the requester knows it will not happen.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use imc_proto::{ChannelState, Message, PowerOp};
use skymesh_ipc_types::{
    FixedStr, HardwareOp, HardwareReply, HardwareRequest, HardwareResult, HardwareState, HwName,
    LcdOp, PowerChannelOp, SampleHeader, SystemPowerOp, HW_NAME_CAPACITY,
};

use crate::peers::Destination;

/// Longest LCD text carried in a request.
const LCD_TEXT_CAPACITY: usize = 64;
/// Most requests waiting for their reply; more are dropped (`hardware_busy`).
pub const MAX_PENDING: usize = 1024;

/// Which IMC message answers a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    LedBrightness,
    GpioState,
    PowerChannelState,
    /// `LcdControl` has no reply.
    Nothing,
    PowerOperation {
        power_down: bool,
    },
}

/// Why an IMC hardware message becomes no request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RequestError {
    #[error("name {name:?} is longer than {HW_NAME_CAPACITY} bytes")]
    NameTooLong { name: String },
    #[error("LCD text of {len} bytes is longer than {LCD_TEXT_CAPACITY}")]
    TextTooLong { len: usize },
    #[error("scheduled time {0} is not a finite number")]
    NotFinite(f64),
    #[error("PowerOperation {0:?} is a report, not a request")]
    ReportNotRequest(PowerOp),
}

impl RequestError {
    /// The `skymesh_imc_dropped_total` reason.
    pub fn reason(&self) -> &'static str {
        match self {
            RequestError::ReportNotRequest(_) => "unsupported",
            _ => "invalid_value",
        }
    }
}

fn name(n: &str) -> Result<HwName, RequestError> {
    if n.len() > HW_NAME_CAPACITY {
        return Err(RequestError::NameTooLong {
            name: n.to_string(),
        });
    }
    Ok(HwName::new(n))
}

fn finite(t: f64) -> Result<f64, RequestError> {
    if t.is_finite() {
        Ok(t)
    } else {
        Err(RequestError::NotFinite(t))
    }
}

/// The request for an IMC hardware message (its `request_id` still 0), and how it
/// is answered; `None` for messages that are not hardware requests.
pub fn request_for(message: &Message) -> Option<Result<(HardwareRequest, Answer), RequestError>> {
    let req = |op, n: &str| -> Result<HardwareRequest, RequestError> {
        Ok(HardwareRequest {
            name: name(n)?,
            ..HardwareRequest::new(0, op)
        })
    };
    let built = match message {
        Message::SetLedBrightness { name, value } => req(HardwareOp::LedSet, name).map(|r| {
            (
                HardwareRequest { value: *value, ..r },
                Answer::LedBrightness,
            )
        }),
        Message::QueryLedBrightness { name } => {
            req(HardwareOp::LedQuery, name).map(|r| (r, Answer::LedBrightness))
        }
        Message::GpioStateSet { name, value } => req(HardwareOp::GpioSet, name)
            .map(|r| (HardwareRequest { value: *value, ..r }, Answer::GpioState)),
        Message::GpioStateGet { name } => {
            req(HardwareOp::GpioGet, name).map(|r| (r, Answer::GpioState))
        }
        Message::PowerChannelControl {
            name,
            op,
            sched_time,
        } => finite(*sched_time).and_then(|sched_s| {
            // Both enumerations follow IMC's numbering (PowerChannelControl.op).
            let sub_op = PowerChannelOp::ALL
                .iter()
                .find(|o| o.to_wire() == op.to_u8())
                .copied()
                .unwrap_or(PowerChannelOp::TurnOff);
            req(HardwareOp::PowerChannel, name).map(|r| {
                (
                    HardwareRequest {
                        sub_op: sub_op.to_wire(),
                        sched_s,
                        ..r
                    },
                    Answer::PowerChannelState,
                )
            })
        }),
        Message::LcdControl { op, text } => {
            if text.len() > LCD_TEXT_CAPACITY {
                Err(RequestError::TextTooLong { len: text.len() })
            } else {
                let sub_op = LcdOp::ALL
                    .iter()
                    .find(|o| o.to_wire() == op.to_u8())
                    .copied()
                    .unwrap_or(LcdOp::Clear);
                Ok((
                    HardwareRequest {
                        sub_op: sub_op.to_wire(),
                        text: FixedStr::new(text),
                        ..HardwareRequest::new(0, HardwareOp::Lcd)
                    },
                    Answer::Nothing,
                ))
            }
        }
        Message::PowerOperation { op, sched_time, .. } => match op {
            PowerOp::PowerDownInProgress | PowerOp::PowerUpInProgress => {
                Err(RequestError::ReportNotRequest(*op))
            }
            _ => finite(*sched_time).map(|sched_s| {
                let sub_op = SystemPowerOp::ALL
                    .iter()
                    .find(|o| o.to_wire() == op.to_u8())
                    .copied()
                    .unwrap_or(SystemPowerOp::PowerDownAborted);
                let power_down = matches!(op, PowerOp::PowerDown | PowerOp::SchedulePowerDown);
                (
                    HardwareRequest {
                        sub_op: sub_op.to_wire(),
                        sched_s,
                        ..HardwareRequest::new(0, HardwareOp::SystemPower)
                    },
                    Answer::PowerOperation { power_down },
                )
            }),
        },
        _ => return None,
    };
    Some(built)
}

/// A request waiting for its reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    pub reply_to: Destination,
    pub answer: Answer,
    pub name: String,
    /// The IMC message that asked (for logs).
    pub message: &'static str,
    pub deadline: Instant,
}

/// What a matched reply means for the peer.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Send this answer (and, for `PWR_DOWN_IP`, watch the countdown).
    Reply(Message),
    /// Done, nothing to send (LCD).
    Done,
    /// The hardware service did not do it: count `reason`; send `reply` if any.
    Failed {
        reason: &'static str,
        detail: String,
        reply: Option<Message>,
    },
}

/// The `skymesh_imc_dropped_total` reason of a hardware result.
pub fn result_reason(
    result: Result<HardwareResult, skymesh_ipc_types::UnknownValue>,
) -> &'static str {
    match result {
        Ok(HardwareResult::Ok) => "hardware_ok",
        Ok(HardwareResult::UnknownName) => "hardware_unknown_name",
        Ok(HardwareResult::InvalidValue) => "hardware_invalid_value",
        Ok(HardwareResult::NotSupported) => "hardware_not_supported",
        Ok(HardwareResult::BackendError) => "hardware_backend_error",
        Ok(HardwareResult::Refused) => "hardware_refused",
        Err(_) => "hardware_invalid_reply",
    }
}

fn power_op(wire: u8) -> Option<PowerOp> {
    PowerOp::try_from(wire).ok()
}

fn aborted() -> Message {
    Message::PowerOperation {
        op: PowerOp::PowerDownAborted,
        time_remain: 0.0,
        sched_time: 0.0,
    }
}

/// The IMC answer to `reply` for a request answered as `pending.answer`.
pub fn outcome(pending: &Pending, reply: &HardwareReply) -> Outcome {
    let result = reply.result();
    if result != Ok(HardwareResult::Ok) {
        let refused_power_down =
            matches!(pending.answer, Answer::PowerOperation { power_down: true });
        return Outcome::Failed {
            reason: result_reason(result),
            detail: reply.message.as_str().to_string(),
            reply: refused_power_down.then(aborted),
        };
    }
    let name = pending.name.clone();
    let value = reply.value;
    match pending.answer {
        Answer::LedBrightness => Outcome::Reply(Message::LedBrightness { name, value }),
        Answer::GpioState => Outcome::Reply(Message::GpioState { name, value }),
        Answer::PowerChannelState => Outcome::Reply(Message::PowerChannelState {
            name,
            state: if value != 0 {
                ChannelState::On
            } else {
                ChannelState::Off
            },
        }),
        Answer::Nothing => Outcome::Done,
        Answer::PowerOperation { .. } => match power_op(reply.sub_op) {
            Some(op) => Outcome::Reply(Message::PowerOperation {
                op,
                time_remain: if reply.time_remaining_s.is_finite() {
                    reply.time_remaining_s.max(0.0)
                } else {
                    0.0
                },
                sched_time: 0.0,
            }),
            None => Outcome::Failed {
                reason: "hardware_invalid_reply",
                detail: format!(
                    "power operation {} is not an IMC PowerOperation",
                    reply.sub_op
                ),
                reply: None,
            },
        },
    }
}

/// Requests in flight.
#[derive(Debug)]
pub struct Requests {
    pending: HashMap<u32, Pending>,
    next_id: u32,
    /// Our publisher's header fields: replies for us carry them.
    origin: SampleHeader,
    timeout: Duration,
}

impl Requests {
    pub fn new(origin: SampleHeader, timeout: Duration) -> Self {
        Requests {
            pending: HashMap::new(),
            next_id: 1,
            origin,
            timeout,
        }
    }

    /// Gives `request` an id and remembers it; `None` when too many are in flight.
    pub fn start(
        &mut self,
        mut request: HardwareRequest,
        answer: Answer,
        reply_to: Destination,
        message: &'static str,
        now: Instant,
    ) -> Option<HardwareRequest> {
        if self.pending.len() >= MAX_PENDING {
            return None;
        }
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        request.request_id = id;
        self.pending.insert(
            id,
            Pending {
                reply_to,
                answer,
                name: request.name.as_str().to_string(),
                message,
                deadline: now + self.timeout,
            },
        );
        Some(request)
    }

    /// The pending request `reply` answers, if it is ours.
    pub fn answered(&mut self, reply: &HardwareReply) -> Option<Pending> {
        if !reply.answers(&self.origin, reply.request_id) {
            return None;
        }
        self.pending.remove(&reply.request_id)
    }

    /// Requests whose reply did not come in time.
    /// The earliest reply deadline of the pending requests (what
    /// [`Self::expire`] acts on).
    pub fn next_deadline(&self) -> Option<Instant> {
        self.pending.values().map(|p| p.deadline).min()
    }

    pub fn expire(&mut self, now: Instant) -> Vec<Pending> {
        let late: Vec<u32> = self
            .pending
            .iter()
            .filter(|(_, p)| now >= p.deadline)
            .map(|(id, _)| *id)
            .collect();
        let mut out: Vec<Pending> = late
            .into_iter()
            .filter_map(|id| self.pending.remove(&id))
            .collect();
        out.sort_by_key(|p| p.deadline);
        out
    }

    pub fn len(&self) -> usize {
        self.pending.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }
}

/// One step of watching a pending companion power down for its requester.
#[derive(Debug, Clone, PartialEq)]
pub enum WatchStep {
    /// Still counting down: send `PWR_DOWN_IP` with this many seconds left.
    Progress(f32),
    /// No longer pending: send `PWR_DOWN_ABORTED` and stop watching.
    Aborted,
    /// The state does not show it yet.
    Wait,
}

/// How long after the `PWR_DOWN_IP` reply the state may still not show the power
/// down before the watch concludes it was aborted.
const WATCH_GRACE: Duration = Duration::from_secs(3);

/// The requester of a power down that is in progress, told the time left once a
/// second (from the `HardwareState`).
#[derive(Debug, Clone, PartialEq)]
pub struct PowerWatch {
    pub requester: Destination,
    started: Instant,
    seen_in_progress: bool,
}

impl PowerWatch {
    pub fn new(requester: Destination, now: Instant) -> Self {
        PowerWatch {
            requester,
            started: now,
            seen_in_progress: false,
        }
    }

    pub fn step(&mut self, state: Option<&HardwareState>, now: Instant) -> WatchStep {
        let in_progress =
            state.filter(|s| s.system_power == SystemPowerOp::PowerDownInProgress.to_wire());
        match in_progress {
            Some(s) => {
                self.seen_in_progress = true;
                let left = if s.system_power_in_s.is_finite() {
                    s.system_power_in_s.max(0.0)
                } else {
                    0.0
                };
                WatchStep::Progress(left)
            }
            None if self.seen_in_progress
                || now.saturating_duration_since(self.started) >= WATCH_GRACE =>
            {
                WatchStep::Aborted
            }
            None => WatchStep::Wait,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imc_proto::{ChannelOp, LcdOperation};
    use skymesh_ipc_types::ServiceId;

    fn origin() -> SampleHeader {
        SampleHeader {
            service: ServiceId::ImcGateway.to_wire(),
            instance: 0,
            ..Default::default()
        }
    }

    fn dest() -> Destination {
        Destination {
            addr: ([127, 0, 0, 1], 7000).into(),
            dst: 0x4001,
            dst_ent: 2,
        }
    }

    fn reply_to(req: &HardwareRequest, result: HardwareResult, value: u8) -> HardwareReply {
        HardwareReply {
            request_id: req.request_id,
            requester_service: ServiceId::ImcGateway.to_wire(),
            requester_instance: 0,
            op: req.op,
            sub_op: req.sub_op,
            result: result.to_wire(),
            value,
            time_remaining_s: -1.0,
            name: req.name,
            ..Default::default()
        }
    }

    #[test]
    fn messages_become_requests_numbered_as_imc() {
        let (r, a) = request_for(&Message::SetLedBrightness {
            name: "status".into(),
            value: 200,
        })
        .unwrap()
        .unwrap();
        assert_eq!(
            (r.op(), r.name.as_str(), r.value, a),
            (Ok(HardwareOp::LedSet), "status", 200, Answer::LedBrightness)
        );
        let (r, a) = request_for(&Message::PowerChannelControl {
            name: "payload".into(),
            op: ChannelOp::ScheduleOn,
            sched_time: 5.0,
        })
        .unwrap()
        .unwrap();
        assert_eq!(r.sub_op, PowerChannelOp::ScheduleOn.to_wire());
        assert_eq!((r.sched_s, a), (5.0, Answer::PowerChannelState));
        for op in ChannelOp::ALL {
            let (r, _) = request_for(&Message::PowerChannelControl {
                name: "x".into(),
                op: *op,
                sched_time: 0.0,
            })
            .unwrap()
            .unwrap();
            assert_eq!(r.sub_op, op.to_u8(), "{op:?}");
        }
        let (r, a) = request_for(&Message::LcdControl {
            op: LcdOperation::Write1,
            text: "hello".into(),
        })
        .unwrap()
        .unwrap();
        assert_eq!(
            (r.sub_op, r.text.as_str(), a),
            (LcdOp::WriteLine1.to_wire(), "hello", Answer::Nothing)
        );
        let (r, a) = request_for(&Message::PowerOperation {
            op: PowerOp::SchedulePowerDown,
            time_remain: 0.0,
            sched_time: 1.7e9,
        })
        .unwrap()
        .unwrap();
        assert_eq!(r.sub_op, SystemPowerOp::SchedulePowerDown.to_wire());
        assert_eq!(a, Answer::PowerOperation { power_down: true });
        assert!(request_for(&Message::Heartbeat).is_none());
    }

    #[test]
    fn bad_hardware_messages_are_refused_before_the_bus() {
        let long = "x".repeat(HW_NAME_CAPACITY + 1);
        let cases = [
            Message::QueryLedBrightness { name: long.clone() },
            Message::GpioStateSet {
                name: long,
                value: 1,
            },
            Message::LcdControl {
                op: LcdOperation::Write0,
                text: "y".repeat(65),
            },
            Message::PowerChannelControl {
                name: "a".into(),
                op: ChannelOp::ScheduleOff,
                sched_time: f64::NAN,
            },
        ];
        for m in cases {
            let e = request_for(&m).unwrap().unwrap_err();
            assert_eq!(e.reason(), "invalid_value", "{m:?}");
        }
        let e = request_for(&Message::PowerOperation {
            op: PowerOp::PowerDownInProgress,
            time_remain: 3.0,
            sched_time: 0.0,
        })
        .unwrap()
        .unwrap_err();
        assert_eq!(e.reason(), "unsupported");
    }

    #[test]
    fn replies_are_matched_by_id_and_our_header_and_time_out() {
        let t0 = Instant::now();
        let mut reqs = Requests::new(origin(), Duration::from_secs(2));
        let (r, a) = request_for(&Message::QueryLedBrightness {
            name: "status".into(),
        })
        .unwrap()
        .unwrap();
        let r1 = reqs.start(r, a, dest(), "QueryLedBrightness", t0).unwrap();
        let r2 = reqs.start(r, a, dest(), "QueryLedBrightness", t0).unwrap();
        assert_ne!(r1.request_id, r2.request_id);

        let mut foreign = reply_to(&r1, HardwareResult::Ok, 10);
        foreign.requester_instance = 3;
        assert_eq!(reqs.answered(&foreign), None, "another gateway's reply");
        let p = reqs
            .answered(&reply_to(&r1, HardwareResult::Ok, 10))
            .unwrap();
        assert_eq!(
            outcome(&p, &reply_to(&r1, HardwareResult::Ok, 10)),
            Outcome::Reply(Message::LedBrightness {
                name: "status".into(),
                value: 10
            })
        );
        assert_eq!(
            reqs.answered(&reply_to(&r1, HardwareResult::Ok, 10)),
            None,
            "once"
        );
        assert!(reqs.expire(t0 + Duration::from_millis(1999)).is_empty());
        let late = reqs.expire(t0 + Duration::from_secs(2));
        assert_eq!(late.len(), 1);
        assert!(reqs.is_empty());
    }

    #[test]
    fn failures_get_no_reply_except_a_refused_power_down() {
        let t0 = Instant::now();
        let mut reqs = Requests::new(origin(), Duration::from_secs(2));
        let (r, a) = request_for(&Message::GpioStateGet { name: "x".into() })
            .unwrap()
            .unwrap();
        let r = reqs.start(r, a, dest(), "GpioStateGet", t0).unwrap();
        let reply = reply_to(&r, HardwareResult::UnknownName, 0);
        let p = reqs.answered(&reply).unwrap();
        assert!(matches!(
            outcome(&p, &reply),
            Outcome::Failed {
                reason: "hardware_unknown_name",
                reply: None,
                ..
            }
        ));

        let (r, a) = request_for(&Message::PowerOperation {
            op: PowerOp::PowerDown,
            time_remain: 0.0,
            sched_time: 0.0,
        })
        .unwrap()
        .unwrap();
        let r = reqs.start(r, a, dest(), "PowerOperation", t0).unwrap();
        let mut reply = reply_to(&r, HardwareResult::Refused, 0);
        reply.message = FixedStr::new("no power_down_command configured");
        let p = reqs.answered(&reply).unwrap();
        match outcome(&p, &reply) {
            Outcome::Failed {
                reason,
                detail,
                reply: Some(m),
            } => {
                assert_eq!(reason, "hardware_refused");
                assert!(detail.contains("power_down_command"));
                assert_eq!(m, aborted());
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn power_operation_replies_carry_the_resulting_op_and_time() {
        let p = Pending {
            reply_to: dest(),
            answer: Answer::PowerOperation { power_down: true },
            name: String::new(),
            message: "PowerOperation",
            deadline: Instant::now(),
        };
        let reply = HardwareReply {
            result: HardwareResult::Ok.to_wire(),
            sub_op: SystemPowerOp::PowerDownInProgress.to_wire(),
            time_remaining_s: 30.0,
            ..Default::default()
        };
        assert_eq!(
            outcome(&p, &reply),
            Outcome::Reply(Message::PowerOperation {
                op: PowerOp::PowerDownInProgress,
                time_remain: 30.0,
                sched_time: 0.0
            })
        );
    }

    #[test]
    fn the_power_watch_counts_down_then_reports_the_abort() {
        let t0 = Instant::now();
        let mut w = PowerWatch::new(dest(), t0);
        let mut s = HardwareState::default();
        assert_eq!(
            w.step(Some(&s), t0),
            WatchStep::Wait,
            "state not updated yet"
        );
        s.system_power = SystemPowerOp::PowerDownInProgress.to_wire();
        s.system_power_in_s = 25.0;
        assert_eq!(w.step(Some(&s), t0), WatchStep::Progress(25.0));
        s.system_power = SystemPowerOp::PowerDownAborted.to_wire();
        assert_eq!(w.step(Some(&s), t0), WatchStep::Aborted);
        let mut w = PowerWatch::new(dest(), t0);
        assert_eq!(w.step(None, t0 + WATCH_GRACE), WatchStep::Aborted);
    }
}
