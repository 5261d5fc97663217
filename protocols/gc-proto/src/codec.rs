//! [`RecordCodec`]: state-server records from a byte stream, whatever its chunking.
//!
//! Every record is [`RECORD_LEN`] bytes and every bit pattern is a record, so the
//! decoder has nothing to reject: it waits for 32 bytes, cuts them, and never
//! buffers more than one partial record of its own accord (it reserves only what
//! the record in progress still needs). The one failure is the stream ending inside
//! a record ([`RecordError::Truncated`]), reported by `decode_eof`.

use bytes::{Buf, BytesMut};
use tokio_util::codec::{Decoder, Encoder};

use crate::record::Record;
use crate::RECORD_LEN;

/// Why no further record can be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The peer closed the stream with part of a record buffered.
    #[error("stream ended inside a record ({buffered} of {RECORD_LEN} bytes)")]
    Truncated { buffered: usize },
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

impl RecordError {
    /// Bounded metric label: `truncated` or `io`.
    pub fn kind(&self) -> &'static str {
        match self {
            RecordError::Truncated { .. } => "truncated",
            RecordError::Io(_) => "io",
        }
    }
}

/// `tokio_util::codec` adapter: `Decoder<Item = Record>`, `Encoder<Record>` and
/// `Encoder<&Record>`.
#[derive(Debug, Clone, Copy, Default)]
pub struct RecordCodec;

impl RecordCodec {
    pub fn new() -> Self {
        RecordCodec
    }
}

impl Decoder for RecordCodec {
    type Item = Record;
    type Error = RecordError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Record>, RecordError> {
        let Some(bytes) = src.first_chunk::<RECORD_LEN>() else {
            src.reserve(RECORD_LEN - src.len());
            return Ok(None);
        };
        let record = Record::decode(bytes);
        src.advance(RECORD_LEN);
        Ok(Some(record))
    }

    fn decode_eof(&mut self, src: &mut BytesMut) -> Result<Option<Record>, RecordError> {
        match self.decode(src)? {
            Some(r) => Ok(Some(r)),
            None if src.is_empty() => Ok(None),
            None => Err(RecordError::Truncated {
                buffered: src.len(),
            }),
        }
    }
}

impl Encoder<&Record> for RecordCodec {
    type Error = RecordError;

    fn encode(&mut self, item: &Record, dst: &mut BytesMut) -> Result<(), RecordError> {
        dst.extend_from_slice(&item.encode());
        Ok(())
    }
}

impl Encoder<Record> for RecordCodec {
    type Error = RecordError;

    fn encode(&mut self, item: Record, dst: &mut BytesMut) -> Result<(), RecordError> {
        self.encode(&item, dst)
    }
}
