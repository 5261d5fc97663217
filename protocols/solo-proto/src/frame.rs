//! Framing: the 8-byte header, [`TlvCodec`] for the TCP stream and
//! [`decode_datagram`] for the UDP follow stream.
//!
//! The framer only cuts frames; it never looks inside a value. So a frame whose
//! value is bad (unknown type, wrong length, NaN) is still consumed whole and the
//! next frame starts at the right byte; only a declared length above the limit ends
//! the stream, because nothing after it can be trusted.

use bytes::{Buf, BufMut, Bytes, BytesMut};
use tokio_util::codec::{Decoder, Encoder};

use crate::error::{DatagramError, DecodeError, FrameError};
use crate::message::SoloMessage;
use crate::{HEADER_LEN, MAX_VALUE_LEN};

/// One frame cut from the stream, value not yet decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFrame {
    pub msg_type: u32,
    pub value: Bytes,
}

impl RawFrame {
    /// Decodes the value as the message its type names.
    pub fn decode(&self) -> Result<SoloMessage, DecodeError> {
        SoloMessage::decode(self.msg_type, &self.value)
    }

    /// Writes header and value unchanged (forwarding a frame already checked).
    pub fn encode(&self, dst: &mut BytesMut) -> Result<(), FrameError> {
        let declared = u32::try_from(self.value.len()).map_err(|_| FrameError::TooLong {
            declared: u32::MAX,
            max: MAX_VALUE_LEN,
        })?;
        dst.reserve(HEADER_LEN + self.value.len());
        dst.put_u32_le(self.msg_type);
        dst.put_u32_le(declared);
        dst.put_slice(&self.value);
        Ok(())
    }
}

/// Reads a header from the first [`HEADER_LEN`] bytes.
fn header(bytes: &[u8]) -> Option<(u32, u32)> {
    let (h, _) = bytes.split_first_chunk::<HEADER_LEN>()?;
    let msg_type = u32::from_le_bytes([h[0], h[1], h[2], h[3]]);
    let len = u32::from_le_bytes([h[4], h[5], h[6], h[7]]);
    Some((msg_type, len))
}

/// `tokio_util::codec` adapter: `Decoder<Item = RawFrame, Error = FrameError>`,
/// `Encoder<&SoloMessage>`, `Encoder<SoloMessage>` and `Encoder<&RawFrame>`.
///
/// The header is checked as soon as it has arrived, and a declared length above
/// `max_value_len` is refused before any of the value is buffered; the codec never
/// reserves space for bytes that have not arrived.
#[derive(Debug, Clone)]
pub struct TlvCodec {
    /// The largest value accepted; a larger declared length is [`FrameError::TooLong`].
    max_value_len: usize,
}

impl Default for TlvCodec {
    fn default() -> Self {
        Self::new()
    }
}

impl TlvCodec {
    /// A codec accepting values up to [`MAX_VALUE_LEN`].
    pub fn new() -> Self {
        Self::with_max_value_len(MAX_VALUE_LEN)
    }

    pub fn with_max_value_len(max: usize) -> Self {
        TlvCodec { max_value_len: max }
    }

    pub fn max_value_len(&self) -> usize {
        self.max_value_len
    }
}

impl Decoder for TlvCodec {
    type Item = RawFrame;
    type Error = FrameError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<RawFrame>, FrameError> {
        let Some((msg_type, declared)) = header(src) else {
            return Ok(None);
        };
        let len = match usize::try_from(declared) {
            Ok(len) if len <= self.max_value_len => len,
            _ => {
                return Err(FrameError::TooLong {
                    declared,
                    max: self.max_value_len,
                })
            }
        };
        if src.len() < HEADER_LEN + len {
            return Ok(None);
        }
        src.advance(HEADER_LEN);
        let value = src.split_to(len).freeze();
        Ok(Some(RawFrame { msg_type, value }))
    }
}

impl Encoder<&SoloMessage> for TlvCodec {
    type Error = FrameError;

    fn encode(&mut self, item: &SoloMessage, dst: &mut BytesMut) -> Result<(), FrameError> {
        item.encode(dst);
        Ok(())
    }
}

impl Encoder<SoloMessage> for TlvCodec {
    type Error = FrameError;

    fn encode(&mut self, item: SoloMessage, dst: &mut BytesMut) -> Result<(), FrameError> {
        item.encode(dst);
        Ok(())
    }
}

impl Encoder<&RawFrame> for TlvCodec {
    type Error = FrameError;

    fn encode(&mut self, item: &RawFrame, dst: &mut BytesMut) -> Result<(), FrameError> {
        item.encode(dst)
    }
}

/// Decodes a UDP datagram that must hold exactly one whole frame (the follow stream:
/// one SOLO_MESSAGE_LOCATION per datagram). A short datagram or bytes after the
/// frame are errors. Any known type is decoded; the caller checks it is the one it
/// expects.
pub fn decode_datagram(datagram: &[u8]) -> Result<SoloMessage, DatagramError> {
    let (msg_type, declared) = header(datagram).ok_or(DatagramError::ShortHeader {
        got: datagram.len(),
    })?;
    let body = &datagram[HEADER_LEN..];
    let len = usize::try_from(declared).unwrap_or(usize::MAX);
    if body.len() < len {
        return Err(DatagramError::Truncated {
            declared,
            got: body.len(),
        });
    }
    if body.len() > len {
        return Err(DatagramError::TrailingBytes {
            declared,
            extra: body.len() - len,
        });
    }
    Ok(SoloMessage::decode(msg_type, body)?)
}
