//! Why a frame got no CURRENT reply or ACKNOWLEDGEMENT: the bounded label of
//! `skymesh_digiview_refused_total{reason}` and the DigiView reply it gets.

use digiview_proto::{FrameError, MessageType};

/// Every reason the gateway refuses, drops or closes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Refusal {
    /// CRC-8 mismatch (CHECKSUM_ERROR).
    BadChecksum,
    /// `version` is not 0 (UNKNOWN).
    BadVersion,
    /// A `message_type` value DigiView does not define (UNKNOWN).
    UnknownMessageType,
    /// A `param_type` value DigiView does not define (UNKNOWN).
    UnknownParamType,
    /// A message type only DigiView sends (CURRENT, ACKNOWLEDGEMENT, errors) (UNKNOWN).
    UnexpectedMessageType,
    /// A SET from an address not in `write_allowed` (FORBIDDEN).
    Forbidden,
    /// SENSOR, CAM_DEPTH_ESTIMATION: disabled as in DigiView (UNKNOWN).
    Disabled,
    /// A SET of a GET-only type (DATA_ERROR).
    GetOnly,
    /// The payload does not decode or is out of range (DATA_ERROR).
    BadPayload,
    /// A GET interval of 1–99 ms (DATA_ERROR; DigiView ignores it).
    BadInterval,
    /// The stream named is not configured (DATA_ERROR; DigiView ignores it).
    NoSuchStream,
    /// The camera named is not shown by the stream's layout (DATA_ERROR).
    NoSuchCam,
    /// Nothing to answer with: no model, no such detection, no view direction yet
    /// (DATA_ERROR).
    NotFound,
    /// No `VisionState` within `state_timeout` (UNKNOWN: no better DigiView code).
    PipelineDown,
    /// The pipeline answered a SET Ignored, Invalid or Failed (DATA_ERROR).
    PipelineRefused,
    /// The pipeline answered a SET Unsupported (UNKNOWN).
    PipelineUnsupported,
    /// The pipeline did not answer a SET within `set_timeout` (UNKNOWN).
    PipelineTimeout,
    /// More than `max_frames_per_s` from one client: dropped, no reply.
    RateLimited,
    /// A frame begun and not completed within `partial_frame_timeout_s`: closed.
    PartialFrameTimeout,
}

impl Refusal {
    pub const ALL: [Refusal; 19] = [
        Refusal::BadChecksum,
        Refusal::BadVersion,
        Refusal::UnknownMessageType,
        Refusal::UnknownParamType,
        Refusal::UnexpectedMessageType,
        Refusal::Forbidden,
        Refusal::Disabled,
        Refusal::GetOnly,
        Refusal::BadPayload,
        Refusal::BadInterval,
        Refusal::NoSuchStream,
        Refusal::NoSuchCam,
        Refusal::NotFound,
        Refusal::PipelineDown,
        Refusal::PipelineRefused,
        Refusal::PipelineUnsupported,
        Refusal::PipelineTimeout,
        Refusal::RateLimited,
        Refusal::PartialFrameTimeout,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Refusal::BadChecksum => "bad_checksum",
            Refusal::BadVersion => "bad_version",
            Refusal::UnknownMessageType => "unknown_message_type",
            Refusal::UnknownParamType => "unknown_param_type",
            Refusal::UnexpectedMessageType => "unexpected_message_type",
            Refusal::Forbidden => "forbidden",
            Refusal::Disabled => "disabled",
            Refusal::GetOnly => "get_only",
            Refusal::BadPayload => "bad_payload",
            Refusal::BadInterval => "bad_interval",
            Refusal::NoSuchStream => "no_such_stream",
            Refusal::NoSuchCam => "no_such_cam",
            Refusal::NotFound => "not_found",
            Refusal::PipelineDown => "pipeline_down",
            Refusal::PipelineRefused => "pipeline_refused",
            Refusal::PipelineUnsupported => "pipeline_unsupported",
            Refusal::PipelineTimeout => "pipeline_timeout",
            Refusal::RateLimited => "rate_limited",
            Refusal::PartialFrameTimeout => "partial_frame_timeout",
        }
    }

    /// The reply a refused frame gets (`RateLimited` and `PartialFrameTimeout` get
    /// none; they map to UNKNOWN only for completeness).
    pub fn reply_type(self) -> MessageType {
        match self {
            Refusal::BadChecksum => MessageType::ChecksumError,
            Refusal::Forbidden => MessageType::Forbidden,
            Refusal::GetOnly
            | Refusal::BadPayload
            | Refusal::BadInterval
            | Refusal::NoSuchStream
            | Refusal::NoSuchCam
            | Refusal::NotFound
            | Refusal::PipelineRefused => MessageType::DataError,
            Refusal::BadVersion
            | Refusal::UnknownMessageType
            | Refusal::UnknownParamType
            | Refusal::UnexpectedMessageType
            | Refusal::Disabled
            | Refusal::PipelineDown
            | Refusal::PipelineUnsupported
            | Refusal::PipelineTimeout
            | Refusal::RateLimited
            | Refusal::PartialFrameTimeout => MessageType::Unknown,
        }
    }

    /// True if asking again cannot succeed (a periodic GET is then not started).
    pub fn is_request_error(self) -> bool {
        matches!(
            self,
            Refusal::BadPayload | Refusal::NoSuchStream | Refusal::NoSuchCam | Refusal::Disabled
        )
    }

    pub fn of_frame_error(e: &FrameError) -> Refusal {
        match e {
            FrameError::BadChecksum { .. } => Refusal::BadChecksum,
            FrameError::BadVersion(_) => Refusal::BadVersion,
            FrameError::UnknownMessageType(_) => Refusal::UnknownMessageType,
            FrameError::UnknownParamType(_) => Refusal::UnknownParamType,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_distinct() {
        let mut names: Vec<_> = Refusal::ALL.iter().map(|r| r.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Refusal::ALL.len());
    }
}
