//! Arbitrary bytes through GroundControl's record decoder in arbitrary chunkings,
//! and as one pose-broadcast datagram.
//!
//! Checks, beyond "never panics": records do not depend on how the bytes arrive
//! (chunked and whole-buffer decoding cut the same records and leave the same
//! remainder), every record re-encodes to exactly its 32 input bytes, `decode_eof`
//! reports a remainder as truncated, text unpacking is total, and a datagram either
//! decodes into records that re-encode to its bytes or is refused for its length.
#![no_main]

use bytes::BytesMut;
use gc_proto::{
    decode_pose_datagram, encode_pose_datagram, unpack_text, Record, RecordCodec, POSE_RECORD_LEN,
    RECORD_LEN,
};
use libfuzzer_sys::fuzz_target;
use tokio_util::codec::Decoder;

/// The records' bytes and what stayed buffered.
fn decode_chunked(stream: &[u8], mut seed: u8) -> (Vec<u8>, usize) {
    let mut codec = RecordCodec::new();
    let mut buf = BytesMut::new();
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < stream.len() {
        // A small LCG on the seed byte picks chunk sizes 1..=48.
        seed = seed.wrapping_mul(37).wrapping_add(11);
        let n = (usize::from(seed % 48) + 1).min(stream.len() - pos);
        buf.extend_from_slice(&stream[pos..pos + n]);
        pos += n;
        while let Some(r) = codec.decode(&mut buf).expect("decode never fails") {
            if let Ok(text) = unpack_text(r.int2, r.params.as_longs()) {
                assert!(text.len() <= 20);
            }
            out.extend_from_slice(&r.encode());
        }
    }
    let left = buf.len();
    match codec.decode_eof(&mut buf) {
        Ok(None) => assert_eq!(left, 0),
        Err(_) => assert!(left > 0 && left < RECORD_LEN),
        Ok(Some(_)) => panic!("decode_eof found a record decode missed"),
    }
    (out, left)
}

fuzz_target!(|data: &[u8]| {
    let Some((&seed, stream)) = data.split_first() else {
        return;
    };
    let (chunked, left) = decode_chunked(stream, seed);
    let whole = stream.len() / RECORD_LEN * RECORD_LEN;
    assert_eq!(
        &chunked[..],
        &stream[..whole],
        "records changed on re-encoding"
    );
    assert_eq!(left, stream.len() - whole);
    if let Some(r) = Record::from_prefix(stream) {
        assert_eq!(r.encode()[..], stream[..RECORD_LEN]);
    }

    match decode_pose_datagram(stream) {
        Ok(poses) => {
            let mut again = Vec::new();
            encode_pose_datagram(&poses, &mut again);
            assert_eq!(again, stream, "pose records changed on re-encoding");
        }
        Err(e) => {
            assert_ne!(stream.len() % POSE_RECORD_LEN, 0);
            assert_eq!(e.len, stream.len());
        }
    }
});
