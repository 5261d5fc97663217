//! Synclair Vision DigiView's TCP protocol (`../shared/specs/digiview-vision.md`,
//! corrected by `../shared/specs/FACTS.md`): a pure codec, no I/O. The
//! digiview-gateway owns the socket (TCP [`PORT`]).
//!
//! Every message is one fixed [`FRAME_LEN`]-byte frame, little-endian, the C struct
//! of the vendor's `msg_defs.hpp` including its padding: header, [`DATA_LEN`] payload
//! bytes, a CRC-8/BLUETOOTH over bytes 0..80 at [`CHECKSUM_OFFSET`]. There is no
//! length field or sync word; frames arrive back to back.
//!
//! | step | here | refuses (gateway reply) |
//! |---|---|---|
//! | stream | [`FrameCodec`] cuts every 88 bytes; a bad frame is an `Err(BadFrame)` item, the stream goes on | peer closing inside a frame ([`CodecError::Truncated`]) |
//! | frame | [`Frame::decode`] / [`RawFrame::validate`] | [`FrameError`]: checksum (CHECKSUM_ERROR), version, unknown message or parameter type (UNKNOWN) |
//! | payload | [`Param::decode`] (SET, CURRENT), [`GetRequest`] / [`RoiSelector`] (GET) | [`PayloadError`]: bool byte not 0/1, unknown CAPTURE bits, name not UTF-8, more than 4 views (DATA_ERROR) |
//! | values | [`Param::validate`] | [`PayloadError`]: out of the document's ranges, NaN/∞ (DATA_ERROR) |
//!
//! | file | content |
//! |---|---|
//! | `frame.rs` | [`Frame`], [`RawFrame`], [`MessageType`], [`ParamType`], [`FrameError`], [`crc8_bluetooth`]; padding policy |
//! | `codec.rs` | [`FrameCodec`] (`tokio_util` `Decoder`/`Encoder`) |
//! | `params.rs` | [`Param`] and one struct per parameter type, offsets as FACTS.md |
//! | `validate.rs` | [`Param::validate`], [`PayloadError`], [`Problem`] |
//! | `get.rs` | [`GetRequest`], [`RoiSelector`] |
//! | `fixed.rs` | fixed-point conversions, [`FixedName`] (zero-padded `char[N]`) |
#![forbid(unsafe_code)]

mod codec;
mod fixed;
mod frame;
mod get;
mod params;
mod validate;

pub use codec::{BadFrame, CodecError, FrameCodec};
pub use fixed::{
    from_milli, from_offset, from_ratio, to_milli, to_offset, to_ratio, FixedName, ModelName,
    NameError, StreamName,
};
pub use frame::{crc8_bluetooth, Frame, FrameError, MessageType, ParamType, RawFrame};
pub use get::{GetRequest, RoiSelector, CAM_NONE, ROI_ALL_KNOWN, ROI_ALL_VISIBLE};
pub use params::{
    Ai, BoundingBox, CamDepthEstimation, CamOffset, CamOpticsAndControl, CamTargeting, Capture,
    DetectedRoi, Detection, Model, Param, Sensor, SingleTargetTracking, SystemStatus, VideoOutput,
    CAPTURE_RECORD_VIDEO, CAPTURE_SINGLE_IMAGE, MAX_VIEWS, SCORE_KEEP,
};
pub use validate::{PayloadError, Problem};

/// Bytes of one frame.
pub const FRAME_LEN: usize = 88;
/// Bytes of the parameter payload (`data`, at offset 16).
pub const DATA_LEN: usize = 64;
/// Offset of the checksum byte; the checksum covers bytes `0..CHECKSUM_OFFSET`.
pub const CHECKSUM_OFFSET: usize = 80;
/// The only `version` (of `msg_defs.hpp`) spoken.
pub const VERSION: u8 = 0;
/// Shortest period of a periodic GET; 0 means once / cancel.
pub const MIN_INTERVAL_MS: u32 = 100;
/// The gateway's TCP port (issue 8).
pub const PORT: u16 = 8555;
