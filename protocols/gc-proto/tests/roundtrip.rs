//! Properties: every record round-trips bytes → record → bytes exactly (NaN payloads
//! included) at any chunking; records built with the member their type names
//! round-trip as values; random bytes never panic; text and pose records round-trip.

use bytes::BytesMut;
use gc_proto::{
    decode_pose_datagram, encode_pose_datagram, pack_text, pose_records, unpack_text, NetCmdType,
    ParamKind, Params, PoseRecord, Record, RecordCodec, POSE_RECORD_LEN, RECORD_LEN,
};
use proptest::prelude::*;
use tokio_util::codec::Decoder;

fn any_kind() -> impl Strategy<Value = i32> {
    prop_oneof![
        3 => proptest::sample::select(NetCmdType::ALL.to_vec()).prop_map(NetCmdType::id),
        1 => any::<i32>(),
    ]
}

prop_compose! {
    fn typed_record()(kind in any_kind(), context in any::<i32>(), int1 in any::<i32>(),
                      int2 in any::<i32>(), f in any::<[f32; 4]>(), d in any::<[f64; 2]>(),
                      l in any::<[i64; 2]>()) -> Record {
        let params = match NetCmdType::param_kind_of(kind) {
            ParamKind::Floats => Params::Floats(f),
            ParamKind::Doubles => Params::Doubles(d),
            ParamKind::Longs => Params::Longs(l),
        };
        Record { kind, context, int1, int2, params }
    }
}

prop_compose! {
    fn pose()(id in any::<u16>(), object_type in any::<u8>(), liveness in any::<u8>(),
              v in proptest::collection::vec(-1e6f32..1e6, 16), frame_count in any::<u32>(),
              drone_state in any::<i32>(), flags in any::<u32>(), rot in -360f32..360.0) -> PoseRecord {
        PoseRecord {
            id, object_type, liveness,
            tracking: [v[0], v[1], v[2]], tracking_yaw_deg: v[3],
            target: [v[4], v[5], v[6]], target_yaw_deg: v[7],
            color: [v[8], v[9], v[10]], timestamp: v[11],
            quaternion: [v[12], v[13], v[14], v[15]],
            frame_count, drone_state, flags, relative_rotation_deg: rot,
        }
    }
}

proptest! {
    #[test]
    fn random_streams_round_trip_at_any_chunking(
        bytes in proptest::collection::vec(any::<u8>(), 0..400),
        chunk in 1usize..64,
    ) {
        let mut codec = RecordCodec::new();
        let mut buf = BytesMut::new();
        let mut out = Vec::new();
        for c in bytes.chunks(chunk) {
            buf.extend_from_slice(c);
            while let Some(r) = codec.decode(&mut buf).unwrap() {
                out.extend_from_slice(&r.encode());
            }
        }
        let whole = bytes.len() / RECORD_LEN * RECORD_LEN;
        prop_assert_eq!(&out[..], &bytes[..whole]);
        prop_assert_eq!(buf.len(), bytes.len() - whole);
        if buf.is_empty() {
            prop_assert!(codec.decode_eof(&mut buf).unwrap().is_none());
        } else {
            prop_assert!(codec.decode_eof(&mut buf).is_err());
        }
    }

    #[test]
    fn typed_records_round_trip_as_values(r in typed_record()) {
        let bytes = r.encode();
        let back = Record::decode(&bytes);
        // Compared as bytes (NaN != NaN), and the member is the type's.
        prop_assert_eq!(back.encode(), bytes);
        prop_assert_eq!(back.params.kind(), NetCmdType::param_kind_of(r.kind));
        prop_assert_eq!((back.kind, back.context, back.int1, back.int2), (r.kind, r.context, r.int1, r.int2));
    }

    #[test]
    fn texts_round_trip(s in "[ -~]{0,20}") {
        let (i, l) = pack_text(&s).unwrap();
        prop_assert_eq!(unpack_text(i, l).unwrap(), s);
    }

    #[test]
    fn random_text_bytes_never_panic(int2 in any::<i32>(), l in any::<[i64; 2]>()) {
        if let Ok(s) = unpack_text(int2, l) {
            prop_assert!(s.len() <= 20);
            let (i2, l2) = pack_text(&s).unwrap();
            prop_assert_eq!(unpack_text(i2, l2).unwrap(), s);
        }
    }

    #[test]
    fn pose_datagrams_round_trip(poses in proptest::collection::vec(pose(), 0..40)) {
        let mut buf = Vec::new();
        encode_pose_datagram(&poses, &mut buf);
        prop_assert_eq!(buf.len(), poses.len() * POSE_RECORD_LEN);
        prop_assert_eq!(decode_pose_datagram(&buf).unwrap(), poses.clone());
        prop_assert_eq!(pose_records(&buf).unwrap().len(), poses.len());
    }

    #[test]
    fn random_datagrams_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        match decode_pose_datagram(&bytes) {
            Ok(poses) => {
                prop_assert_eq!(bytes.len() % POSE_RECORD_LEN, 0);
                let mut again = Vec::new();
                encode_pose_datagram(&poses, &mut again);
                prop_assert_eq!(again, bytes);
            }
            Err(e) => {
                prop_assert_ne!(bytes.len() % POSE_RECORD_LEN, 0);
                prop_assert_eq!(e.len, bytes.len());
            }
        }
    }
}

#[test]
fn a_reused_buffer_is_not_reallocated() {
    let poses = vec![PoseRecord::default(); 250];
    let mut buf = Vec::with_capacity(250 * POSE_RECORD_LEN);
    let ptr = buf.as_ptr();
    for _ in 0..3 {
        encode_pose_datagram(&poses, &mut buf);
    }
    assert_eq!(buf.as_ptr(), ptr);
    assert_eq!(buf.len(), 21_000);
    assert!(decode_pose_datagram(&buf[..83]).is_err());
    assert_eq!(decode_pose_datagram(&[]).unwrap(), vec![]);
}
