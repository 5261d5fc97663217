//! One 88-byte frame: header fields, the 64 data bytes, the CRC-8/BLUETOOTH checksum.
//!
//! Layout (FACTS.md, the C struct of `msg_defs.hpp` with its padding, little-endian):
//!
//! | offset | field |
//! |---|---|
//! | 0 | `u64 timestamp` |
//! | 8 | `u8 version` (0) |
//! | 9 | `u8 message_type` |
//! | 10 | `u8 param_type` |
//! | 11 | pad (1 byte) |
//! | 12 | `u32 interval_ms` |
//! | 16 | `u8 data[64]` |
//! | 80 | `u8 checksum` over bytes 0..80 |
//! | 81 | pad (7 bytes) |
//!
//! Padding: written as zeros, **tolerated** when non-zero on reading. Real clients
//! fill the C struct field by field and send it whole, so padding may hold whatever
//! was on their stack; byte 11 is inside the checksummed range and is checked as
//! received, bytes 81..88 are outside it and ignored. Refusing them would turn
//! harmless client garbage into CHECKSUM_ERROR/DATA_ERROR storms.
//!
//! Checks on reading, in this order (the first failure wins): checksum, version,
//! message type, parameter type. Every 88-byte input is a [`RawFrame`], so a
//! refused frame still tells the gateway what to echo in its error reply.

use crc::{Crc, CRC_8_BLUETOOTH};

use crate::{CHECKSUM_OFFSET, DATA_LEN, FRAME_LEN, VERSION};

const BLUETOOTH: Crc<u8> = Crc::<u8>::new(&CRC_8_BLUETOOTH);

/// CRC-8/BLUETOOTH (poly 0xA7, init 0, reflected in and out, no final xor).
pub fn crc8_bluetooth(bytes: &[u8]) -> u8 {
    BLUETOOTH.checksum(bytes)
}

/// `message_type` as sent on the wire (FACTS.md; the document's own table is stale).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MessageType {
    Empty = 0,
    Get = 1,
    Set = 2,
    Current = 3,
    Acknowledgement = 4,
    ChecksumError = 5,
    DataError = 6,
    Forbidden = 7,
    Unknown = 8,
    Quit = 255,
}

impl MessageType {
    pub const ALL: [MessageType; 10] = [
        MessageType::Empty,
        MessageType::Get,
        MessageType::Set,
        MessageType::Current,
        MessageType::Acknowledgement,
        MessageType::ChecksumError,
        MessageType::DataError,
        MessageType::Forbidden,
        MessageType::Unknown,
        MessageType::Quit,
    ];

    pub fn from_u8(v: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|m| *m as u8 == v)
    }

    /// Stable lower-case name for logs and metric labels.
    pub fn name(self) -> &'static str {
        match self {
            MessageType::Empty => "empty",
            MessageType::Get => "get",
            MessageType::Set => "set",
            MessageType::Current => "current",
            MessageType::Acknowledgement => "acknowledgement",
            MessageType::ChecksumError => "checksum_error",
            MessageType::DataError => "data_error",
            MessageType::Forbidden => "forbidden",
            MessageType::Unknown => "unknown",
            MessageType::Quit => "quit",
        }
    }
}

/// `param_type`: which payload layout `data` holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum ParamType {
    SystemStatus = 0,
    Ai = 1,
    Model = 2,
    VideoOutput = 3,
    Capture = 4,
    Detection = 5,
    DetectedRoi = 6,
    CamTargeting = 7,
    CamOpticsAndControl = 8,
    CamOffset = 9,
    Sensor = 10,
    CamDepthEstimation = 11,
    SingleTargetTracking = 12,
}

impl ParamType {
    pub const ALL: [ParamType; 13] = [
        ParamType::SystemStatus,
        ParamType::Ai,
        ParamType::Model,
        ParamType::VideoOutput,
        ParamType::Capture,
        ParamType::Detection,
        ParamType::DetectedRoi,
        ParamType::CamTargeting,
        ParamType::CamOpticsAndControl,
        ParamType::CamOffset,
        ParamType::Sensor,
        ParamType::CamDepthEstimation,
        ParamType::SingleTargetTracking,
    ];

    pub fn from_u8(v: u8) -> Option<Self> {
        Self::ALL.get(usize::from(v)).copied()
    }

    /// The document's upper-case name (`CAM_TARGETING`), for logs and metric labels.
    pub fn name(self) -> &'static str {
        match self {
            ParamType::SystemStatus => "SYSTEM_STATUS",
            ParamType::Ai => "AI",
            ParamType::Model => "MODEL",
            ParamType::VideoOutput => "VIDEO_OUTPUT",
            ParamType::Capture => "CAPTURE",
            ParamType::Detection => "DETECTION",
            ParamType::DetectedRoi => "DETECTED_ROI",
            ParamType::CamTargeting => "CAM_TARGETING",
            ParamType::CamOpticsAndControl => "CAM_OPTICS_AND_CONTROL",
            ParamType::CamOffset => "CAM_OFFSET",
            ParamType::Sensor => "SENSOR",
            ParamType::CamDepthEstimation => "CAM_DEPTH_ESTIMATION",
            ParamType::SingleTargetTracking => "SINGLE_TARGET_TRACKING",
        }
    }
}

/// Why an 88-byte frame was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The gateway answers CHECKSUM_ERROR.
    #[error("checksum {received:#04x} does not match computed {computed:#04x}")]
    BadChecksum { received: u8, computed: u8 },
    #[error("version {0} is not {VERSION}")]
    BadVersion(u8),
    /// The gateway answers UNKNOWN.
    #[error("message type {0} is unknown")]
    UnknownMessageType(u8),
    /// The gateway answers UNKNOWN.
    #[error("parameter type {0} is unknown")]
    UnknownParamType(u8),
}

impl FrameError {
    /// Stable metric label: `bad_checksum`, `bad_version`, `unknown_message_type`,
    /// `unknown_param_type`.
    pub fn kind(&self) -> &'static str {
        match self {
            FrameError::BadChecksum { .. } => "bad_checksum",
            FrameError::BadVersion(_) => "bad_version",
            FrameError::UnknownMessageType(_) => "unknown_message_type",
            FrameError::UnknownParamType(_) => "unknown_param_type",
        }
    }
}

/// Every field of an 88-byte frame as received, nothing checked (padding dropped).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame {
    pub timestamp: u64,
    pub version: u8,
    pub message_type: u8,
    pub param_type: u8,
    /// Byte 11, inside the checksum.
    pub pad11: u8,
    pub interval_ms: u32,
    pub data: [u8; DATA_LEN],
    pub checksum: u8,
}

impl RawFrame {
    pub fn parse(bytes: &[u8; FRAME_LEN]) -> Self {
        let mut data = [0u8; DATA_LEN];
        data.copy_from_slice(&bytes[16..16 + DATA_LEN]);
        RawFrame {
            timestamp: u64::from_le_bytes(le(bytes, 0)),
            version: bytes[8],
            message_type: bytes[9],
            param_type: bytes[10],
            pad11: bytes[11],
            interval_ms: u32::from_le_bytes(le(bytes, 12)),
            data,
            checksum: bytes[CHECKSUM_OFFSET],
        }
    }

    /// The checksum this frame's bytes 0..80 should carry.
    pub fn computed_checksum(&self) -> u8 {
        crc8_bluetooth(&self.header_and_data())
    }

    fn header_and_data(&self) -> [u8; CHECKSUM_OFFSET] {
        let mut out = [0u8; CHECKSUM_OFFSET];
        out[0..8].copy_from_slice(&self.timestamp.to_le_bytes());
        out[8] = self.version;
        out[9] = self.message_type;
        out[10] = self.param_type;
        out[11] = self.pad11;
        out[12..16].copy_from_slice(&self.interval_ms.to_le_bytes());
        out[16..].copy_from_slice(&self.data);
        out
    }

    /// Checksum, version, message type, parameter type — in that order.
    pub fn validate(&self) -> Result<Frame, FrameError> {
        let computed = self.computed_checksum();
        if computed != self.checksum {
            return Err(FrameError::BadChecksum {
                received: self.checksum,
                computed,
            });
        }
        if self.version != VERSION {
            return Err(FrameError::BadVersion(self.version));
        }
        let message_type = MessageType::from_u8(self.message_type)
            .ok_or(FrameError::UnknownMessageType(self.message_type))?;
        let param_type = ParamType::from_u8(self.param_type)
            .ok_or(FrameError::UnknownParamType(self.param_type))?;
        Ok(Frame {
            timestamp: self.timestamp,
            version: self.version,
            message_type,
            param_type,
            interval_ms: self.interval_ms,
            data: self.data,
        })
    }
}

fn le<const N: usize>(bytes: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&bytes[at..at + N]);
    out
}

/// One checked frame. `data` is the parameter payload as bytes; [`crate::Param`]
/// and [`crate::GetRequest`] give it meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// Set by the sender ("must be set manually"); echoed in replies.
    pub timestamp: u64,
    pub version: u8,
    pub message_type: MessageType,
    pub param_type: ParamType,
    /// GET: 0 = once / cancel periodic replies, else the period (minimum
    /// [`crate::MIN_INTERVAL_MS`]).
    pub interval_ms: u32,
    pub data: [u8; DATA_LEN],
}

impl Frame {
    /// A version-0 frame with zero timestamp, interval and data.
    pub fn new(message_type: MessageType, param_type: ParamType) -> Self {
        Frame {
            timestamp: 0,
            version: VERSION,
            message_type,
            param_type,
            interval_ms: 0,
            data: [0; DATA_LEN],
        }
    }

    /// A version-0 frame carrying `param`'s payload.
    pub fn with_param(message_type: MessageType, param: &crate::Param) -> Self {
        let (param_type, data) = param.encode();
        Frame {
            data,
            ..Frame::new(message_type, param_type)
        }
    }

    /// Exactly [`FRAME_LEN`] bytes: padding zero, checksum at [`CHECKSUM_OFFSET`].
    pub fn encode(&self) -> [u8; FRAME_LEN] {
        let raw = RawFrame {
            timestamp: self.timestamp,
            version: self.version,
            message_type: self.message_type as u8,
            param_type: self.param_type as u8,
            pad11: 0,
            interval_ms: self.interval_ms,
            data: self.data,
            checksum: 0,
        };
        let mut out = [0u8; FRAME_LEN];
        out[..CHECKSUM_OFFSET].copy_from_slice(&raw.header_and_data());
        out[CHECKSUM_OFFSET] = raw.computed_checksum();
        out
    }

    /// Parse and check one frame ([`RawFrame::validate`]).
    pub fn decode(bytes: &[u8; FRAME_LEN]) -> Result<Frame, FrameError> {
        RawFrame::parse(bytes).validate()
    }
}
