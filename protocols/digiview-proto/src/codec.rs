//! [`FrameCodec`]: frames from a byte stream, whatever its chunking.
//!
//! Frames are a fixed [`FRAME_LEN`] bytes with no sync word or length, so the stream
//! is cut every 88 bytes. A frame that fails its checks is still consumed whole and
//! surfaces as an `Err(BadFrame)` *item* (`Item = Result<Frame, BadFrame>`): the
//! stream goes on with the next frame and the gateway answers CHECKSUM_ERROR or
//! UNKNOWN for the bad one. The decoder's own `Error` is reserved for what ends a
//! stream: I/O, or the peer closing inside a frame. It never buffers more than one
//! partial frame of its own accord.

use bytes::{Buf, BytesMut};
use tokio_util::codec::{Decoder, Encoder};

use crate::frame::{Frame, FrameError, RawFrame};
use crate::FRAME_LEN;

/// A frame consumed from the stream but refused: what was received and why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{error}")]
pub struct BadFrame {
    pub error: FrameError,
    /// The fields as received, for the error reply (timestamp, param type).
    pub raw: RawFrame,
}

/// Why no further frame can be read.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// The peer closed the stream with part of a frame buffered.
    #[error("stream ended inside a frame ({buffered} of {FRAME_LEN} bytes)")]
    Truncated { buffered: usize },
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

impl CodecError {
    /// Bounded metric label: `truncated` or `io`.
    pub fn kind(&self) -> &'static str {
        match self {
            CodecError::Truncated { .. } => "truncated",
            CodecError::Io(_) => "io",
        }
    }
}

/// `tokio_util::codec` adapter: `Decoder<Item = Result<Frame, BadFrame>>`,
/// `Encoder<Frame>` and `Encoder<&Frame>`.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameCodec;

impl FrameCodec {
    pub fn new() -> Self {
        FrameCodec
    }
}

impl Decoder for FrameCodec {
    type Item = Result<Frame, BadFrame>;
    type Error = CodecError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, CodecError> {
        let Some(bytes) = src.first_chunk::<FRAME_LEN>() else {
            src.reserve(FRAME_LEN - src.len());
            return Ok(None);
        };
        let raw = RawFrame::parse(bytes);
        src.advance(FRAME_LEN);
        Ok(Some(
            raw.validate().map_err(|error| BadFrame { error, raw }),
        ))
    }

    fn decode_eof(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, CodecError> {
        match self.decode(src)? {
            Some(item) => Ok(Some(item)),
            None if src.is_empty() => Ok(None),
            None => Err(CodecError::Truncated {
                buffered: src.len(),
            }),
        }
    }
}

impl Encoder<&Frame> for FrameCodec {
    type Error = CodecError;

    fn encode(&mut self, item: &Frame, dst: &mut BytesMut) -> Result<(), CodecError> {
        dst.extend_from_slice(&item.encode());
        Ok(())
    }
}

impl Encoder<Frame> for FrameCodec {
    type Error = CodecError;

    fn encode(&mut self, item: Frame, dst: &mut BytesMut) -> Result<(), CodecError> {
        self.encode(&item, dst)
    }
}
