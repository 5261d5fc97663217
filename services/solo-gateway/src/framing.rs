//! Cutting TLV frames from a byte stream with `solo_proto::TlvCodec`, with a
//! deadline per frame.
//!
//! This is what `tokio_util::codec::FramedRead` does (same codec, same buffer
//! handling), plus the one thing it cannot tell its caller: when the first byte of
//! the incomplete frame in its buffer arrived. A client that sends half a frame and
//! stalls is found with that, exactly, without polling. Used by the gateway's
//! sessions and by the app-side [`crate::client`].

use std::time::Duration;

use bytes::BytesMut;
use solo_proto::{FrameError, RawFrame, TlvCodec};
use tokio::io::{AsyncRead, AsyncReadExt};
use tokio::time::Instant;
use tokio_util::codec::Decoder;

/// Why no further frame can be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The declared value length is above the limit (nothing of it was buffered).
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// Part of a frame arrived, and the rest did not within the frame timeout.
    #[error("{buffered} bytes of an incomplete frame, no complete frame within {timeout:?}")]
    Stalled { buffered: usize, timeout: Duration },
    /// The peer closed the connection in the middle of a frame.
    #[error("connection closed inside a frame ({buffered} bytes buffered)")]
    TruncatedFrame { buffered: usize },
}

impl From<std::io::Error> for ReadError {
    fn from(e: std::io::Error) -> Self {
        ReadError::Frame(FrameError::Io(e))
    }
}

const READ_CHUNK: usize = 4096;

/// Reads [`RawFrame`]s from `R`.
#[derive(Debug)]
pub struct FrameReader<R> {
    inner: R,
    codec: TlvCodec,
    buf: BytesMut,
    /// A frame must be complete within this long of its first byte (`None`: no limit).
    frame_timeout: Option<Duration>,
    /// When the first byte still in `buf` arrived (`None` while `buf` is empty).
    /// After a frame is cut, the rest of the buffer counts from the last read: it
    /// arrived then at the latest, and a stream that keeps making progress must
    /// never look stalled.
    partial_since: Option<Instant>,
    last_read: Option<Instant>,
    eof: bool,
}

impl<R: AsyncRead + Unpin> FrameReader<R> {
    pub fn new(inner: R, codec: TlvCodec, frame_timeout: Option<Duration>) -> Self {
        FrameReader {
            inner,
            codec,
            buf: BytesMut::with_capacity(READ_CHUNK),
            frame_timeout,
            partial_since: None,
            last_read: None,
            eof: false,
        }
    }

    /// Bytes received that do not form a complete frame yet.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// The next frame; `Ok(None)` at a clean end of stream.
    ///
    /// Cancel-safe: every byte read is kept in the reader, so dropping the future
    /// (e.g. in `tokio::select!`) loses nothing.
    pub async fn next_frame(&mut self) -> Result<Option<RawFrame>, ReadError> {
        loop {
            if let Some(frame) = self.codec.decode(&mut self.buf)? {
                self.partial_since = if self.buf.is_empty() {
                    None
                } else {
                    self.last_read
                };
                return Ok(Some(frame));
            }
            if self.eof {
                return match self.buf.len() {
                    0 => Ok(None),
                    buffered => Err(ReadError::TruncatedFrame { buffered }),
                };
            }
            if self.buf.is_empty() {
                self.partial_since = None;
            }
            self.buf.reserve(READ_CHUNK);
            let read = self.inner.read_buf(&mut self.buf);
            let n = match (self.partial_since, self.frame_timeout) {
                (Some(since), Some(timeout)) => {
                    match tokio::time::timeout_at(since + timeout, read).await {
                        Ok(r) => r?,
                        Err(_) => {
                            return Err(ReadError::Stalled {
                                buffered: self.buf.len(),
                                timeout,
                            })
                        }
                    }
                }
                _ => read.await?,
            };
            if n == 0 {
                self.eof = true;
            } else {
                let now = Instant::now();
                self.last_read = Some(now);
                self.partial_since.get_or_insert(now);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use solo_proto::{ids, SoloMessage};
    use tokio::io::AsyncWriteExt;

    fn frame(msg: &SoloMessage) -> Vec<u8> {
        msg.to_bytes().to_vec()
    }

    #[tokio::test]
    async fn frames_cut_from_any_chunking() {
        let mut bytes = frame(&SoloMessage::SetCurrentShot(1));
        bytes.extend(frame(&SoloMessage::Pause));
        bytes.extend(frame(&SoloMessage::ShotOptions { cruise_speed: 2.5 }));
        for chunk in 1..=bytes.len() {
            let (mut tx, rx) = tokio::io::duplex(64);
            let mut reader = FrameReader::new(rx, TlvCodec::new(), None);
            let data = bytes.clone();
            let writer = tokio::spawn(async move {
                for c in data.chunks(chunk) {
                    tx.write_all(c).await.unwrap();
                }
            });
            let mut types = Vec::new();
            while let Some(f) = reader.next_frame().await.unwrap() {
                types.push(f.msg_type);
            }
            writer.await.unwrap();
            assert_eq!(
                types,
                [ids::SET_CURRENT_SHOT, ids::PAUSE, ids::SHOT_OPTIONS],
                "chunk {chunk}"
            );
        }
    }

    #[tokio::test(start_paused = true)]
    async fn half_a_frame_then_silence_is_stalled() {
        let (mut tx, rx) = tokio::io::duplex(64);
        let mut reader = FrameReader::new(rx, TlvCodec::new(), Some(Duration::from_secs(10)));
        let bytes = frame(&SoloMessage::SetCurrentShot(1));
        tx.write_all(&bytes).await.unwrap();
        tx.write_all(&bytes[..5]).await.unwrap();
        assert!(reader.next_frame().await.unwrap().is_some());
        let started = Instant::now();
        let e = reader.next_frame().await.unwrap_err();
        assert!(matches!(e, ReadError::Stalled { buffered: 5, .. }), "{e}");
        assert!(started.elapsed() >= Duration::from_secs(10));
        drop(tx);
    }

    #[tokio::test(start_paused = true)]
    async fn a_stream_that_never_empties_the_buffer_is_not_stalled() {
        // Every 2 s: the second half of one frame and the first half of the next,
        // for 40 s; each frame takes 2 s, the limit is 3 s.
        let (mut tx, rx) = tokio::io::duplex(1024);
        let mut reader = FrameReader::new(rx, TlvCodec::new(), Some(Duration::from_secs(3)));
        let frames: Vec<u8> = (0..21)
            .flat_map(|i| frame(&SoloMessage::SetCurrentShot(i % 3)))
            .collect();
        let writer = tokio::spawn(async move {
            tx.write_all(&frames[..6]).await.unwrap();
            for c in frames[6..].chunks(12) {
                tokio::time::sleep(Duration::from_secs(2)).await;
                tx.write_all(c).await.unwrap();
            }
        });
        let mut n = 0;
        while let Some(f) = reader.next_frame().await.unwrap() {
            assert_eq!(f.msg_type, ids::SET_CURRENT_SHOT);
            n += 1;
        }
        writer.await.unwrap();
        assert_eq!(n, 21);
    }

    #[tokio::test(start_paused = true)]
    async fn an_idle_connection_is_not_stalled() {
        let (mut tx, rx) = tokio::io::duplex(64);
        let mut reader = FrameReader::new(rx, TlvCodec::new(), Some(Duration::from_secs(1)));
        let read = tokio::spawn(async move { reader.next_frame().await.map(|f| f.is_some()) });
        tokio::time::sleep(Duration::from_secs(60)).await;
        tx.write_all(&frame(&SoloMessage::Pause)).await.unwrap();
        assert!(read.await.unwrap().unwrap());
    }

    #[tokio::test]
    async fn eof_inside_a_frame_is_reported() {
        let (mut tx, rx) = tokio::io::duplex(64);
        let mut reader = FrameReader::new(rx, TlvCodec::new(), None);
        tx.write_all(&[1, 0, 0]).await.unwrap();
        drop(tx);
        let e = reader.next_frame().await.unwrap_err();
        assert!(
            matches!(e, ReadError::TruncatedFrame { buffered: 3 }),
            "{e}"
        );
    }

    #[tokio::test]
    async fn an_absurd_length_is_refused_at_the_header() {
        let (mut tx, rx) = tokio::io::duplex(64);
        let mut reader = FrameReader::new(rx, TlvCodec::new(), None);
        let mut header = ids::LOCATION.to_le_bytes().to_vec();
        header.extend(u32::MAX.to_le_bytes());
        tx.write_all(&header).await.unwrap();
        let e = reader.next_frame().await.unwrap_err();
        assert!(
            matches!(e, ReadError::Frame(FrameError::TooLong { .. })),
            "{e}"
        );
    }
}
