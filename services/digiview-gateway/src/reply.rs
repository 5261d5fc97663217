//! The frames the gateway sends, and how the pipeline's answer to a SET becomes one.
//!
//! Reply conventions (documented in `deploy/digiview-gateway.toml` too):
//! - every reply echoes the request's `timestamp` (periodic replies echo the GET that
//!   started them), so a client matches replies to requests by it;
//! - every reply echoes the request's `param_type` byte, even one the gateway does not
//!   know (UNKNOWN);
//! - CURRENT replies echo the GET's `interval_ms`; error and ACKNOWLEDGEMENT replies
//!   carry 0 and an all-zero payload.

use digiview_proto::{
    crc8_bluetooth, Frame, MessageType, Param, CHECKSUM_OFFSET, DATA_LEN, FRAME_LEN, VERSION,
};
use skymesh_ipc_types::VisionResult;

/// One frame to send to a client.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reply {
    pub timestamp: u64,
    pub message_type: MessageType,
    /// As received: may be a parameter type the gateway does not know.
    pub param_type: u8,
    pub interval_ms: u32,
    pub data: [u8; DATA_LEN],
}

impl Reply {
    /// A payload-less reply (`ACKNOWLEDGEMENT` or an error) to a request.
    pub fn bare(message_type: MessageType, timestamp: u64, param_type: u8) -> Reply {
        Reply {
            timestamp,
            message_type,
            param_type,
            interval_ms: 0,
            data: [0; DATA_LEN],
        }
    }

    /// A CURRENT_PARAMETERS reply to `request` carrying `param`.
    pub fn current(request: &Frame, param: &Param) -> Reply {
        let (param_type, data) = param.encode();
        Reply {
            timestamp: request.timestamp,
            message_type: MessageType::Current,
            param_type: param_type as u8,
            interval_ms: request.interval_ms,
            data,
        }
    }

    /// The 88 wire bytes: version 0, padding zero, CRC-8/BLUETOOTH over 0..80.
    pub fn encode(&self) -> [u8; FRAME_LEN] {
        let mut out = [0u8; FRAME_LEN];
        out[0..8].copy_from_slice(&self.timestamp.to_le_bytes());
        out[8] = VERSION;
        out[9] = self.message_type as u8;
        out[10] = self.param_type;
        out[12..16].copy_from_slice(&self.interval_ms.to_le_bytes());
        out[16..16 + DATA_LEN].copy_from_slice(&self.data);
        out[CHECKSUM_OFFSET] = crc8_bluetooth(&out[..CHECKSUM_OFFSET]);
        out
    }
}

/// What the pipeline's answer to a forwarded SET becomes (`None`: no answer within
/// `set_timeout`): Applied → ACKNOWLEDGEMENT; Ignored, Invalid, Failed → DATA_ERROR
/// (DigiView has no finer code); Unsupported or no answer → UNKNOWN.
pub fn set_reply_type(result: Option<VisionResult>) -> MessageType {
    match result {
        Some(VisionResult::Applied) => MessageType::Acknowledgement,
        Some(VisionResult::Ignored | VisionResult::Invalid | VisionResult::Failed) => {
            MessageType::DataError
        }
        Some(VisionResult::Unsupported) | None => MessageType::Unknown,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use digiview_proto::{ParamType, SystemStatus};

    #[test]
    fn replies_are_valid_frames_echoing_the_request() {
        let mut req = Frame::new(MessageType::Get, ParamType::SystemStatus);
        req.timestamp = 0x0102_0304_0506_0708;
        req.interval_ms = 250;
        let p = Param::SystemStatus(SystemStatus {
            status: 1,
            error: 0,
            temperature: 41.5,
        });
        let bytes = Reply::current(&req, &p).encode();
        let f = Frame::decode(&bytes).expect("a valid frame");
        assert_eq!(f.message_type, MessageType::Current);
        assert_eq!(f.timestamp, req.timestamp);
        assert_eq!(f.interval_ms, 250);
        assert_eq!(Param::decode(f.param_type, &f.data).unwrap(), p);
        // An unknown parameter type is echoed as received.
        let e = Reply::bare(MessageType::Unknown, 9, 200).encode();
        assert_eq!((e[9], e[10]), (MessageType::Unknown as u8, 200));
        assert_eq!(e[80], crc8_bluetooth(&e[..80]));
    }

    #[test]
    fn pipeline_results_map_to_digiview_codes() {
        use VisionResult::*;
        assert_eq!(set_reply_type(Some(Applied)), MessageType::Acknowledgement);
        for r in [Ignored, Invalid, Failed] {
            assert_eq!(set_reply_type(Some(r)), MessageType::DataError);
        }
        assert_eq!(set_reply_type(Some(Unsupported)), MessageType::Unknown);
        assert_eq!(set_reply_type(None), MessageType::Unknown);
    }
}
