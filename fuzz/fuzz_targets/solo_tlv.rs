//! Arbitrary bytes through the Solo TLV framer in arbitrary chunkings, every frame
//! decoded, and the same bytes as one UDP datagram.
//!
//! Checks, beyond "never panics": framing does not depend on how the bytes arrive
//! (chunked and whole-buffer decoding cut the same frames and stop at the same
//! error), and every accepted message re-encodes to bytes that decode to the same
//! bytes again.
#![no_main]

use bytes::BytesMut;
use libfuzzer_sys::fuzz_target;
use solo_proto::{decode_datagram, RawFrame, SoloMessage, TlvCodec};
use tokio_util::codec::Decoder;

/// What framing produced: the frames, and the error kind that ended the stream.
type Framed = (Vec<RawFrame>, Option<&'static str>);

fn frame_chunked(stream: &[u8], mut seed: u8, max: usize) -> Framed {
    let mut codec = TlvCodec::with_max_value_len(max);
    let mut buf = BytesMut::new();
    let mut frames = Vec::new();
    let mut pos = 0;
    while pos < stream.len() {
        // A small LCG on the seed byte picks chunk sizes 1..=32.
        seed = seed.wrapping_mul(37).wrapping_add(11);
        let n = (usize::from(seed % 32) + 1).min(stream.len() - pos);
        buf.extend_from_slice(&stream[pos..pos + n]);
        pos += n;
        loop {
            match codec.decode(&mut buf) {
                Ok(Some(frame)) => frames.push(frame),
                Ok(None) => break,
                Err(e) => return (frames, Some(e.kind())),
            }
        }
    }
    (frames, None)
}

fn frame_whole(stream: &[u8], max: usize) -> Framed {
    let mut codec = TlvCodec::with_max_value_len(max);
    let mut buf = BytesMut::from(stream);
    let mut frames = Vec::new();
    loop {
        match codec.decode(&mut buf) {
            Ok(Some(frame)) => frames.push(frame),
            Ok(None) => return (frames, None),
            Err(e) => return (frames, Some(e.kind())),
        }
    }
}

/// An accepted message must survive its own encoding (compared as bytes: NaN
/// coordinates of an ignored geofence removal are not equal to themselves).
fn check_reencodes(msg: &SoloMessage) {
    let bytes = msg.to_bytes();
    let again = match decode_datagram(&bytes) {
        Ok(again) => again,
        Err(e) => panic!("{} re-encoded does not decode: {e}", msg.name()),
    };
    assert_eq!(
        again.to_bytes(),
        bytes,
        "{} changed on re-encoding",
        msg.name()
    );
}

fuzz_target!(|data: &[u8]| {
    let Some((&seed, stream)) = data.split_first() else {
        return;
    };
    // Half the runs use a small limit so TooLong is reached often.
    let max = if seed & 1 == 0 {
        solo_proto::MAX_VALUE_LEN
    } else {
        64
    };

    let chunked = frame_chunked(stream, seed, max);
    let whole = frame_whole(stream, max);
    assert_eq!(chunked, whole, "framing depends on chunking");

    for frame in &chunked.0 {
        if let Ok(msg) = frame.decode() {
            assert_eq!(msg.msg_type(), frame.msg_type);
            check_reencodes(&msg);
        }
    }

    if let Ok(msg) = decode_datagram(stream) {
        check_reencodes(&msg);
    }
});
