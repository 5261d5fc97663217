//! The stream adapter under hostile chunking: every chunk size, one byte at a time,
//! adjacent frames, a corrupted frame between good ones, trailing bytes, and a
//! stream that ends inside a frame.

use bytes::BytesMut;
use digiview_proto::{
    BadFrame, CamOffset, CodecError, Frame, FrameCodec, FrameError, MessageType, Param, ParamType,
    StreamName, SystemStatus, FRAME_LEN,
};
use tokio_util::codec::{Decoder, Encoder};

fn frames() -> Vec<Frame> {
    let mut a = Frame::with_param(
        MessageType::Current,
        &Param::SystemStatus(SystemStatus {
            status: 1,
            error: 0,
            temperature: 47.5,
        }),
    );
    a.timestamp = 1;
    let mut b = Frame::with_param(
        MessageType::Get,
        &Param::CamOffset(CamOffset {
            stream: StreamName::new("cam0").unwrap(),
            cam: 2,
            x: 0.5,
            ..CamOffset::default()
        }),
    );
    b.timestamp = 2;
    b.interval_ms = 100;
    let mut c = Frame::new(MessageType::Quit, ParamType::SystemStatus);
    c.timestamp = u64::MAX;
    vec![a, b, c]
}

fn stream_of(frames: &[Frame]) -> Vec<u8> {
    let mut buf = BytesMut::new();
    let mut codec = FrameCodec::new();
    for f in frames {
        codec.encode(f, &mut buf).unwrap();
    }
    buf.to_vec()
}

/// Feed `bytes` in chunks of `chunk`, collecting every item, then end the stream.
fn decode_chunked(
    bytes: &[u8],
    chunk: usize,
) -> (Vec<Result<Frame, BadFrame>>, Result<(), CodecError>) {
    let mut codec = FrameCodec::new();
    let mut buf = BytesMut::new();
    let mut out = Vec::new();
    for piece in bytes.chunks(chunk) {
        buf.extend_from_slice(piece);
        while let Some(item) = codec.decode(&mut buf).unwrap() {
            out.push(item);
        }
        assert!(buf.len() < FRAME_LEN, "a whole frame stayed buffered");
    }
    let end = loop {
        match codec.decode_eof(&mut buf) {
            Ok(Some(item)) => out.push(item),
            Ok(None) => break Ok(()),
            Err(e) => break Err(e),
        }
    };
    (out, end)
}

#[test]
fn encoder_writes_88_bytes_per_frame() {
    let fs = frames();
    let bytes = stream_of(&fs);
    assert_eq!(bytes.len(), 3 * FRAME_LEN);
    for (i, f) in fs.iter().enumerate() {
        assert_eq!(bytes[i * FRAME_LEN..(i + 1) * FRAME_LEN], f.encode());
    }
}

#[test]
fn adjacent_frames_at_every_chunk_size() {
    let fs = frames();
    let bytes = stream_of(&fs);
    for chunk in 1..=bytes.len() {
        let (items, end) = decode_chunked(&bytes, chunk);
        let got: Vec<Frame> = items.into_iter().map(|r| r.unwrap()).collect();
        assert_eq!(got, fs, "chunk size {chunk}");
        assert!(end.is_ok(), "chunk size {chunk}");
    }
}

#[test]
fn corrupted_checksum_between_good_frames_keeps_sync() {
    let fs = frames();
    let mut bytes = stream_of(&fs);
    bytes[FRAME_LEN + 80] ^= 0xFF; // the second frame's checksum
    for chunk in [1, 7, 87, 88, 89, 176, bytes.len()] {
        let (items, end) = decode_chunked(&bytes, chunk);
        assert!(end.is_ok());
        assert_eq!(items.len(), 3, "chunk size {chunk}");
        assert_eq!(items[0].as_ref().unwrap(), &fs[0]);
        let bad = items[1].as_ref().unwrap_err();
        assert!(matches!(bad.error, FrameError::BadChecksum { .. }));
        assert_eq!(bad.raw.timestamp, 2, "the refused frame's fields survive");
        assert_eq!(bad.raw.param_type, ParamType::CamOffset as u8);
        assert_eq!(items[2].as_ref().unwrap(), &fs[2]);
    }
}

#[test]
fn unknown_types_are_consumed_whole() {
    let fs = frames();
    let mut bytes = stream_of(&fs);
    // Second frame: param type 200, resealed so only the type is wrong.
    let at = FRAME_LEN;
    bytes[at + 10] = 200;
    bytes[at + 80] = digiview_proto::crc8_bluetooth(&bytes[at..at + 80]);
    let (items, end) = decode_chunked(&bytes, 5);
    assert!(end.is_ok());
    assert_eq!(
        items[1].as_ref().unwrap_err().error,
        FrameError::UnknownParamType(200)
    );
    assert_eq!(items[2].as_ref().unwrap(), &fs[2]);
}

#[test]
fn trailing_bytes_are_truncation_at_eof() {
    let fs = frames();
    let mut bytes = stream_of(&fs[..1]);
    bytes.extend_from_slice(&[0xAB; 10]);
    for chunk in [1, 3, 88, 98] {
        let (items, end) = decode_chunked(&bytes, chunk);
        assert_eq!(items.len(), 1);
        assert_eq!(items[0].as_ref().unwrap(), &fs[0]);
        match end {
            Err(CodecError::Truncated { buffered }) => assert_eq!(buffered, 10),
            other => panic!("expected truncation, got {other:?}"),
        }
    }
}

#[test]
fn empty_stream_ends_cleanly() {
    let (items, end) = decode_chunked(&[], 1);
    assert!(items.is_empty());
    assert!(end.is_ok());
}

#[test]
fn garbage_is_cut_every_88_bytes_without_panicking() {
    let bytes: Vec<u8> = (0..10 * FRAME_LEN as u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let (items, end) = decode_chunked(&bytes, 13);
    assert_eq!(items.len(), 10);
    assert!(end.is_ok());
}
