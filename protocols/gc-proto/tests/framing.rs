//! The record stream under hostile chunking: every chunk size, one byte at a time,
//! adjacent records, trailing partial records, end of stream inside a record, and
//! bytes after garbage records (fixed size: nothing can desynchronise the stream).

use bytes::BytesMut;
use gc_proto::{NetCmdType, Record, RecordCodec, RecordError, RECORD_LEN};
use tokio_util::codec::{Decoder, Encoder};

fn sample_stream() -> (Vec<Record>, Vec<u8>) {
    let records = vec![
        Record::ping_request(1, 0.0, 0.0),
        Record::floats(NetCmdType::ExtParam1, 2, 0, 0, [1.0, 0.0, 0.5, 0.0]),
        Record::floats(NetCmdType::CmdExtColor, 2, 0, 0, [3.0, 0.0, 0.0, 0.0]),
        Record {
            kind: -77,
            context: i32::MAX,
            int1: i32::MIN,
            int2: -1,
            ..Record::default()
        },
        Record::floats(
            NetCmdType::CmdExtWaypoint,
            9,
            -4500,
            0,
            [1.0, 2.0, 3.0, 4.0],
        ),
    ];
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::new();
    for r in &records {
        codec.encode(r, &mut buf).unwrap();
    }
    (records, buf.to_vec())
}

fn decode_chunked(bytes: &[u8], chunk: usize) -> (Vec<Record>, usize) {
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::new();
    let mut out = Vec::new();
    for c in bytes.chunks(chunk) {
        buf.extend_from_slice(c);
        while let Some(r) = codec.decode(&mut buf).unwrap() {
            out.push(r);
        }
    }
    (out, buf.len())
}

#[test]
fn every_chunk_size_gives_the_same_records() {
    let (records, bytes) = sample_stream();
    assert_eq!(bytes.len(), records.len() * RECORD_LEN);
    for chunk in 1..=bytes.len() {
        let (got, left) = decode_chunked(&bytes, chunk);
        assert_eq!(got, records, "chunk {chunk}");
        assert_eq!(left, 0, "chunk {chunk}");
    }
}

#[test]
fn one_byte_at_a_time_waits_for_the_32nd() {
    let (records, bytes) = sample_stream();
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::new();
    for (i, b) in bytes.iter().enumerate() {
        buf.extend_from_slice(&[*b]);
        let got = codec.decode(&mut buf).unwrap();
        if (i + 1) % RECORD_LEN == 0 {
            assert_eq!(got, Some(records[i / RECORD_LEN]), "byte {i}");
        } else {
            assert_eq!(got, None, "byte {i}");
        }
    }
}

#[test]
fn trailing_bytes_stay_buffered_and_eof_inside_a_record_is_reported() {
    let (records, mut bytes) = sample_stream();
    bytes.extend_from_slice(&[0xA6, 0, 0, 0, 1]);
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::from(&bytes[..]);
    let mut got = Vec::new();
    while let Some(r) = codec.decode(&mut buf).unwrap() {
        got.push(r);
    }
    assert_eq!(got, records);
    assert_eq!(buf.len(), 5);
    match codec.decode_eof(&mut buf) {
        Err(RecordError::Truncated { buffered: 5 }) => {}
        other => panic!("expected Truncated, got {other:?}"),
    }
    // A clean end is not an error.
    let mut empty = BytesMut::new();
    assert!(codec.decode_eof(&mut empty).unwrap().is_none());
}

#[test]
fn the_decoder_reserves_only_what_the_record_needs() {
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::new();
    buf.extend_from_slice(&[0xFF; 7]);
    assert!(codec.decode(&mut buf).unwrap().is_none());
    assert!(buf.capacity() >= RECORD_LEN);
    assert!(buf.capacity() < 4 * RECORD_LEN, "{}", buf.capacity());
}

#[test]
fn garbage_records_do_not_desynchronise() {
    // 64 bytes of 0xFF (two records of type -1) then a valid waypoint.
    let mut bytes = vec![0xFF; 2 * RECORD_LEN];
    let wp = Record::floats(NetCmdType::CmdExtWaypoint, 1, 0, 0, [1.0; 4]);
    bytes.extend_from_slice(&wp.encode());
    let (got, left) = decode_chunked(&bytes, 5);
    assert_eq!(got.len(), 3);
    assert_eq!(got[0].kind, -1);
    assert_eq!(got[0].net_type(), None);
    assert_eq!(got[2], wp);
    assert_eq!(left, 0);
}
