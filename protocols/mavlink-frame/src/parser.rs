//! Splitting a byte stream into MAVLink frames.
//!
//! The `mavlink` crate's reader only returns frames whose message id its dialect
//! knows (it needs the id's CRC_EXTRA to check the checksum), so it would silently
//! drop newer or vendor messages. [`FrameParser`] frames by itself, as
//! mavlink-router does: a frame whose id the ardupilotmega dialect knows must
//! carry a valid checksum; a frame with an unknown id cannot be checked and is
//! either passed on as it is ([`UnknownIds::Forward`]: the receiver checks it
//! against its own dialect) or refused as soon as its header is in
//! ([`UnknownIds::Reject`]: a stray marker in garbage then rarely holds back the
//! frames behind it). Anything else (junk, a bad checksum, unknown
//! incompatibility flags) is skipped from the next byte on, so a real frame
//! hidden inside a failed candidate is still found, and is counted.
//!
//! Nothing is allocated from a declared length: a frame is at most
//! [`MAX_FRAME`] bytes.

use mavlink::calculate_crc;

use crate::raw::{
    message_info, RawFrame, CHECKSUM_LEN, IFLAG_SIGNED, MAX_FRAME, SIGNATURE_LEN, STX_V1, STX_V2,
    V1_HEADER, V2_HEADER,
};

/// Once this much undecoded input is buffered the caller is not draining the
/// parser; [`FrameParser::push`] discards the oldest bytes.
pub const MAX_BUFFERED: usize = 64 * 1024;

/// What to do with a frame whose message id the dialect does not know.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UnknownIds {
    /// Pass it on unchecked (a router).
    #[default]
    Forward,
    /// Refuse it once its header is in, and resync from the next byte.
    Reject,
}

/// Input that was thrown away, or a frame that does not decode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadFrame {
    /// Bytes before the next frame marker (or cut off at a datagram's end, or
    /// dropped because the buffer was not drained).
    #[error("{len} bytes of garbage before a frame marker")]
    Garbage {
        /// Discarded bytes.
        len: usize,
    },
    /// A MAVLink 2 header with incompatibility flags we cannot handle.
    #[error("unsupported MAVLink 2 incompatibility flags {flags:#04x}")]
    IncompatFlags {
        /// The flags byte.
        flags: u8,
    },
    /// A message id outside the ardupilotmega dialect ([`UnknownIds::Reject`]).
    #[error("unknown message id {id}")]
    UnknownMessage {
        /// Message id.
        id: u32,
    },
    /// The checksum did not match.
    #[error("checksum mismatch on message id {id}")]
    Checksum {
        /// Message id.
        id: u32,
    },
    /// A well-framed message whose payload does not decode (e.g. a bad enum
    /// value); only [`crate::FrameDecoder`] reports it.
    #[error("message id {id} does not decode: {reason}")]
    Payload {
        /// Message id.
        id: u32,
        /// Parser message.
        reason: String,
    },
}

/// Splits a byte stream into [`RawFrame`]s; see the module documentation.
///
/// Feed it with [`push`](Self::push) and drain it with
/// [`next_frame`](Self::next_frame) (or [`next_checked`](Self::next_checked))
/// until `None` before pushing again: at most one partial frame (< [`MAX_FRAME`]
/// bytes) stays buffered between reads. For datagram transports call
/// [`end_datagram`](Self::end_datagram) after draining: a frame never spans
/// datagrams.
#[derive(Debug, Default)]
pub struct FrameParser {
    buf: Vec<u8>,
    /// Bytes before `start` are consumed; compacted on the next `push`.
    start: usize,
    unknown_ids: UnknownIds,
    /// Bytes `push` dropped from an undrained buffer, not reported yet.
    dropped: usize,
    /// Bytes were skipped since the last good frame (one resync counts once).
    skipping: bool,
    malformed: u64,
}

impl FrameParser {
    /// A parser that forwards frames with unknown message ids.
    pub fn new() -> Self {
        Self::with_unknown_ids(UnknownIds::Forward)
    }

    /// A parser that rejects frames with unknown message ids.
    pub fn dialect_only() -> Self {
        Self::with_unknown_ids(UnknownIds::Reject)
    }

    /// A parser with the given policy for unknown message ids.
    pub fn with_unknown_ids(unknown_ids: UnknownIds) -> Self {
        FrameParser {
            buf: Vec::with_capacity(4 * MAX_FRAME),
            unknown_ids,
            ..FrameParser::default()
        }
    }

    /// Appends received bytes. Beyond [`MAX_BUFFERED`] undecoded bytes the oldest
    /// are dropped (reported as [`BadFrame::Garbage`]).
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
        if self.buf.len() > MAX_BUFFERED {
            let excess = self.buf.len() - MAX_BUFFERED;
            self.buf.drain(..excess);
            self.dropped += excess;
            self.note_skip();
        }
    }

    /// Bytes buffered that do not form a whole frame yet.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Skipped input since the last call: runs of junk and rejected candidates, each
    /// resynchronisation counted once.
    pub fn take_malformed(&mut self) -> u64 {
        std::mem::take(&mut self.malformed)
    }

    fn note_skip(&mut self) {
        if !self.skipping {
            self.skipping = true;
            self.malformed += 1;
        }
    }

    fn skip(&mut self, n: usize) {
        self.start += n;
        self.note_skip();
    }

    /// Drops a trailing partial frame (counted as malformed) and returns how many
    /// bytes it had.
    pub fn end_datagram(&mut self) -> usize {
        let n = self.pending();
        if n > 0 {
            self.skip(n);
        }
        self.buf.clear();
        self.start = 0;
        self.skipping = false;
        n
    }

    /// The next whole frame, or `None` when more bytes are needed; skipped input
    /// is only counted ([`take_malformed`](Self::take_malformed)).
    pub fn next_frame(&mut self) -> Option<RawFrame> {
        loop {
            match self.next_checked()? {
                Ok(frame) => return Some(frame),
                Err(_) => continue,
            }
        }
    }

    /// The next whole frame, what had to be skipped to find it (one error per
    /// garbage run or rejected candidate), or `None` when more bytes are needed.
    pub fn next_checked(&mut self) -> Option<Result<RawFrame, BadFrame>> {
        if self.dropped > 0 {
            let len = std::mem::take(&mut self.dropped);
            return Some(Err(BadFrame::Garbage { len }));
        }
        let avail = &self.buf[self.start..];
        let Some(at) = avail.iter().position(|b| *b == STX_V2 || *b == STX_V1) else {
            let len = avail.len();
            if len == 0 {
                return None;
            }
            self.skip(len);
            return Some(Err(BadFrame::Garbage { len }));
        };
        if at > 0 {
            self.skip(at);
            return Some(Err(BadFrame::Garbage { len: at }));
        }
        let v2 = avail[0] == STX_V2;
        if avail.len() < 3 {
            return None;
        }
        let (header, signature) = if v2 {
            let flags = avail[2];
            if flags & !IFLAG_SIGNED != 0 {
                // Unknown incompatibility flags: not a frame we may handle.
                self.skip(1);
                return Some(Err(BadFrame::IncompatFlags { flags }));
            }
            let signed = flags & IFLAG_SIGNED != 0;
            (V2_HEADER, if signed { SIGNATURE_LEN } else { 0 })
        } else {
            (V1_HEADER, 0)
        };
        if avail.len() < header {
            return None;
        }
        let id = if v2 {
            u32::from_le_bytes([avail[7], avail[8], avail[9], 0])
        } else {
            u32::from(avail[5])
        };
        let info = message_info(id);
        if info.is_none() && self.unknown_ids == UnknownIds::Reject {
            self.skip(1);
            return Some(Err(BadFrame::UnknownMessage { id }));
        }
        let crc_at = header + usize::from(avail[1]);
        let total = crc_at + CHECKSUM_LEN + signature;
        if avail.len() < total {
            return None;
        }
        if let Some(info) = info {
            let sent = u16::from_le_bytes([avail[crc_at], avail[crc_at + 1]]);
            if calculate_crc(&avail[1..crc_at], info.extra_crc) != sent {
                self.skip(1);
                return Some(Err(BadFrame::Checksum { id }));
            }
        }
        let frame = RawFrame::copy_from(&avail[..total]);
        self.start += total;
        self.skipping = false;
        if self.start == self.buf.len() {
            self.buf.clear();
            self.start = 0;
        }
        Some(Ok(frame))
    }
}

#[cfg(test)]
mod tests;
