//! What one frame from a client becomes (pure: no socket, no bus, no clock).
//!
//! | frame | step |
//! |---|---|
//! | bad checksum | CHECKSUM_ERROR |
//! | bad version, unknown message or parameter type | UNKNOWN |
//! | EMPTY | nothing (counted) |
//! | CURRENT, ACKNOWLEDGEMENT, an error type (DigiView's own replies) | UNKNOWN |
//! | QUIT (whatever its parameter type) | close the connection |
//! | GET, interval 0 | the answer once; cancels a periodic GET of that type |
//! | GET CAM_OFFSET (checked) | the pipeline's `DirectionAt` answer ([`Ask`]), once or periodically |
//! | GET, interval 1–99 ms | DATA_ERROR (DigiView ignores it; skymesh says so) |
//! | GET, interval ≥ 100 ms | the answer now, then every interval (replaces an earlier periodic GET of that type) |
//! | SET | FORBIDDEN (address not allowed), UNKNOWN (SENSOR, CAM_DEPTH_ESTIMATION), DATA_ERROR (GET-only type, payload refused), else translated ([`crate::translate`]) and sent to the pipeline |
//!
//! The session (`session.rs`) carries the steps out; [`replies_for_bytes`] runs a
//! whole byte stream through the codec and this handler (the fuzz target).

use bytes::BytesMut;
use digiview_proto::{
    BadFrame, CamOffset, Frame, FrameCodec, FrameError, MessageType, Param, ParamType,
    MIN_INTERVAL_MS,
};
use skymesh_ipc_types::{ViewControl, ViewReply, VisionResult, VisionState};
use tokio_util::codec::Decoder;

use crate::answer::{answer_get, Answer, NoAnswer};
use crate::ipc::CallError;
use crate::refusal::Refusal;
use crate::reply::Reply;
use crate::translate;

/// What the handler needs to know about the client and the gateway.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rules {
    /// The client's address is in `write_allowed`.
    pub may_set: bool,
    /// `roi_rel_frame` of the configuration.
    pub roi_rel_frame: u8,
}

/// What happens to periodic replies of a GET's parameter type.
#[derive(Debug, Clone, PartialEq)]
pub enum Periodic {
    Unchanged,
    /// Answer `frame` every `frame.interval_ms` from now on.
    Start(Frame),
    Cancel(ParamType),
}

/// What one frame becomes.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Send these now (may be none).
    Reply(Vec<Reply>),
    /// A GET's replies and its effect on periodic replies; `ask`: its answer is the
    /// pipeline's (then `replies` is empty).
    Get {
        replies: Vec<Reply>,
        periodic: Periodic,
        ask: Option<Box<Ask>>,
    },
    /// A checked SET: forward to the pipeline, reply with its answer.
    Set(Frame),
    /// Close the connection.
    Quit,
}

/// A GET whose answer is the pipeline's: send [`Ask::control`], then
/// [`Ask::answer`] its reply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ask {
    /// The GET (its timestamp and interval are echoed).
    pub frame: Frame,
    /// The payload to complete with the pipeline's answer.
    pub request: CamOffset,
}

impl Ask {
    /// The question for the pipeline.
    pub fn control(&self) -> ViewControl {
        translate::direction_at(&self.request)
    }

    /// The replies to the GET once the pipeline answered (or did not).
    pub fn answer(&self, result: Result<ViewReply, CallError>) -> (Vec<Reply>, Option<NoAnswer>) {
        let pt = self.frame.param_type;
        let refused = |reason: Refusal, detail: String| {
            (
                vec![Reply::bare(
                    reason.reply_type(),
                    self.frame.timestamp,
                    pt as u8,
                )],
                Some(NoAnswer { reason, detail }),
            )
        };
        match result {
            Ok(reply) => {
                let message = reply.message.as_str();
                match reply.result() {
                    VisionResult::Applied => (
                        vec![Reply::current(
                            &self.frame,
                            &Param::CamOffset(translate::cam_offset(&self.request, &reply)),
                        )],
                        None,
                    ),
                    VisionResult::Ignored => {
                        refused(Refusal::NotFound, format!("{}: {message}", pt.name()))
                    }
                    VisionResult::Unsupported => refused(
                        Refusal::PipelineUnsupported,
                        format!("{}: {message}", pt.name()),
                    ),
                    r @ (VisionResult::Invalid | VisionResult::Failed) => refused(
                        Refusal::PipelineRefused,
                        format!("{} {}: {message}", pt.name(), r.as_str()),
                    ),
                }
            }
            Err(e) => refused(Refusal::PipelineTimeout, format!("{}: {e}", pt.name())),
        }
    }
}

/// A GET's answer now: replies (and why some were refused), or a question.
#[derive(Debug, Clone, PartialEq)]
pub struct Answered {
    pub replies: Vec<Reply>,
    pub refusal: Option<NoAnswer>,
    pub ask: Option<Box<Ask>>,
}

/// A step and, if the frame was refused (entirely or in part), why.
#[derive(Debug, Clone, PartialEq)]
pub struct Handled {
    pub step: Step,
    pub refusal: Option<NoAnswer>,
}

impl Handled {
    fn refused(timestamp: u64, param_type: u8, reason: Refusal, detail: String) -> Handled {
        Handled {
            step: Step::Reply(vec![Reply::bare(
                reason.reply_type(),
                timestamp,
                param_type,
            )]),
            refusal: Some(NoAnswer { reason, detail }),
        }
    }
}

/// Parameter types DigiView only answers: a SET of one is DATA_ERROR.
pub fn is_get_only(pt: ParamType) -> bool {
    matches!(
        pt,
        ParamType::SystemStatus | ParamType::Model | ParamType::DetectedRoi | ParamType::CamOffset
    )
}

/// Parameter types DigiView has disabled: UNKNOWN both ways.
pub fn is_disabled(pt: ParamType) -> bool {
    matches!(pt, ParamType::Sensor | ParamType::CamDepthEstimation)
}

/// One frame from the stream. `state`: the newest `VisionState`, `None` while the
/// pipeline is down (no state within `state_timeout`).
pub fn handle(
    item: Result<Frame, BadFrame>,
    rules: &Rules,
    state: Option<&VisionState>,
) -> Handled {
    let frame = match item {
        Ok(f) => f,
        Err(BadFrame { error, raw }) => {
            // QUIT is honoured whatever parameter type it carries.
            if matches!(error, FrameError::UnknownParamType(_))
                && raw.message_type == MessageType::Quit as u8
            {
                return Handled {
                    step: Step::Quit,
                    refusal: None,
                };
            }
            return Handled::refused(
                raw.timestamp,
                raw.param_type,
                Refusal::of_frame_error(&error),
                error.to_string(),
            );
        }
    };
    let pt = frame.param_type;
    match frame.message_type {
        MessageType::Quit => Handled {
            step: Step::Quit,
            refusal: None,
        },
        MessageType::Empty => Handled {
            step: Step::Reply(Vec::new()),
            refusal: None,
        },
        MessageType::Get => get(&frame, rules, state),
        MessageType::Set => set(&frame, rules),
        other => Handled::refused(
            frame.timestamp,
            pt as u8,
            Refusal::UnexpectedMessageType,
            format!(
                "{} is a reply type DigiView sends, not receives",
                other.name()
            ),
        ),
    }
}

fn get(frame: &Frame, rules: &Rules, state: Option<&VisionState>) -> Handled {
    let interval = frame.interval_ms;
    if interval != 0 && interval < MIN_INTERVAL_MS {
        return Handled::refused(
            frame.timestamp,
            frame.param_type as u8,
            Refusal::BadInterval,
            format!("GET interval {interval} ms is below the minimum {MIN_INTERVAL_MS} ms"),
        );
    }
    let Answered {
        replies,
        refusal,
        ask,
    } = answer(frame, state, rules.roi_rel_frame);
    let periodic = if interval == 0 {
        Periodic::Cancel(frame.param_type)
    } else if refusal
        .as_ref()
        .is_some_and(|r| r.reason.is_request_error())
    {
        Periodic::Unchanged
    } else {
        Periodic::Start(*frame)
    };
    Handled {
        step: Step::Get {
            replies,
            periodic,
            ask,
        },
        refusal,
    }
}

/// The answer to a GET now (also each tick of a periodic GET).
pub fn answer(frame: &Frame, state: Option<&VisionState>, roi_rel_frame: u8) -> Answered {
    let result = match state {
        // Disabled types say so even while the pipeline is down.
        _ if is_disabled(frame.param_type) => Err(NoAnswer {
            reason: Refusal::Disabled,
            detail: format!("{} is disabled as in DigiView", frame.param_type.name()),
        }),
        None => Err(NoAnswer {
            reason: Refusal::PipelineDown,
            detail: "no VisionState from the vision pipeline: is it running?".to_string(),
        }),
        Some(s) => answer_get(s, frame, roi_rel_frame),
    };
    match result {
        Ok(Answer::Now(params)) => Answered {
            replies: params.iter().map(|p| Reply::current(frame, p)).collect(),
            refusal: None,
            ask: None,
        },
        Ok(Answer::Ask(request)) => Answered {
            replies: Vec::new(),
            refusal: None,
            ask: Some(Box::new(Ask {
                frame: *frame,
                request,
            })),
        },
        Err(no) => Answered {
            replies: vec![Reply::bare(
                no.reason.reply_type(),
                frame.timestamp,
                frame.param_type as u8,
            )],
            refusal: Some(no),
            ask: None,
        },
    }
}

fn set(frame: &Frame, rules: &Rules) -> Handled {
    let pt = frame.param_type;
    let refuse = |reason, detail| Handled::refused(frame.timestamp, pt as u8, reason, detail);
    if !rules.may_set {
        return refuse(
            Refusal::Forbidden,
            format!("SET {} from an address not in write_allowed", pt.name()),
        );
    }
    if is_disabled(pt) {
        return refuse(
            Refusal::Disabled,
            format!("{} is disabled as in DigiView", pt.name()),
        );
    }
    if is_get_only(pt) {
        return refuse(
            Refusal::GetOnly,
            format!("{} can only be read (GET)", pt.name()),
        );
    }
    match Param::decode(pt, &frame.data).and_then(|p| p.validate()) {
        Ok(()) => Handled {
            step: Step::Set(*frame),
            refusal: None,
        },
        Err(e) => refuse(Refusal::BadPayload, e.to_string()),
    }
}

/// Every step a byte stream produces, as a session would see it (SETs are not sent
/// anywhere). The bytes after the last whole frame stay unread, as in a session.
pub fn replies_for_bytes(bytes: &[u8], rules: &Rules, state: Option<&VisionState>) -> Vec<Handled> {
    let mut codec = FrameCodec::new();
    let mut buf = BytesMut::from(bytes);
    let mut out = Vec::new();
    // The codec's only errors are I/O and end of stream; neither happens here.
    while let Ok(Some(item)) = codec.decode(&mut buf) {
        let h = handle(item, rules, state);
        let quit = h.step == Step::Quit;
        out.push(h);
        if quit {
            break;
        }
    }
    out
}

#[cfg(test)]
mod tests;
