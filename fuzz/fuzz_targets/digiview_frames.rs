//! Arbitrary bytes through DigiView's frame decoder in arbitrary chunkings, and as
//! a payload of every parameter type.
//!
//! Checks, beyond "never panics": frames do not depend on how the bytes arrive
//! (chunked and whole-buffer decoding give the same items and remainder), every
//! 88-byte frame is consumed whole whether good or bad, a good frame re-encodes to
//! its checksummed bytes (padding zeroed), `decode_eof` reports a remainder as
//! truncated, and a payload that decodes re-encodes to bytes that decode to the
//! same value.
#![no_main]

use bytes::BytesMut;
use digiview_proto::{
    BadFrame, Frame, FrameCodec, GetRequest, Param, ParamType, RoiSelector, DATA_LEN, FRAME_LEN,
};
use libfuzzer_sys::fuzz_target;
use tokio_util::codec::Decoder;

type Item = Result<Frame, BadFrame>;

fn decode_chunked(stream: &[u8], mut seed: u8) -> (Vec<Item>, usize) {
    let mut codec = FrameCodec::new();
    let mut buf = BytesMut::new();
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < stream.len() {
        // A small LCG on the seed byte picks chunk sizes 1..=120.
        seed = seed.wrapping_mul(37).wrapping_add(11);
        let n = (usize::from(seed % 120) + 1).min(stream.len() - pos);
        buf.extend_from_slice(&stream[pos..pos + n]);
        pos += n;
        while let Some(item) = codec.decode(&mut buf).expect("decode never fails") {
            out.push(item);
        }
        assert!(buf.len() < FRAME_LEN);
    }
    let left = buf.len();
    match codec.decode_eof(&mut buf) {
        Ok(None) => assert_eq!(left, 0),
        Err(_) => assert!(left > 0 && left < FRAME_LEN),
        Ok(Some(_)) => panic!("decode_eof found a frame decode missed"),
    }
    (out, left)
}

fn check_payload(pt: ParamType, data: &[u8; DATA_LEN]) {
    if let Ok(p) = Param::decode(pt, data) {
        let _ = p.validate();
        let (pt2, once) = p.encode();
        assert_eq!(pt2, pt);
        let again = Param::decode(pt, &once).expect("re-encoded payload decodes");
        assert_eq!(again, p);
        assert_eq!(again.encode().1, once);
    }
    if let Ok(g) = GetRequest::decode(pt, data) {
        assert_eq!(GetRequest::decode(pt, &g.encode()), Ok(g));
    }
    let sel = RoiSelector::decode(data);
    assert_eq!(RoiSelector::decode(&sel.encode()), sel);
}

fuzz_target!(|data: &[u8]| {
    let Some((&seed, stream)) = data.split_first() else {
        return;
    };
    let (chunked, left) = decode_chunked(stream, seed);
    assert_eq!(chunked.len(), stream.len() / FRAME_LEN);
    assert_eq!(left, stream.len() % FRAME_LEN);
    for (i, item) in chunked.iter().enumerate() {
        let bytes: &[u8; FRAME_LEN] = stream[i * FRAME_LEN..][..FRAME_LEN].try_into().unwrap();
        assert_eq!(item.as_ref().ok(), Frame::decode(bytes).ok().as_ref());
        match item {
            Ok(f) => {
                let again = f.encode();
                assert_eq!(again[..11], bytes[..11]);
                assert_eq!(again[12..80], bytes[12..80]);
                // Padding byte 11 is checksummed as received but re-encoded as zero.
                if bytes[11] == 0 {
                    assert_eq!(again[80], bytes[80]);
                }
                assert!(again[11] == 0 && again[81..].iter().all(|&b| b == 0));
                check_payload(f.param_type, &f.data);
            }
            Err(bad) => assert_eq!(Some(bad.error), Frame::decode(bytes).err()),
        }
    }

    // The first 64 bytes as a payload of every parameter type, checksum or not.
    let mut payload = [0u8; DATA_LEN];
    let n = stream.len().min(DATA_LEN);
    payload[..n].copy_from_slice(&stream[..n]);
    for pt in ParamType::ALL {
        check_payload(pt, &payload);
    }
});
