//! Random round trips for every parameter type (typed → bytes → typed, values drawn
//! on the wire's fixed-point grid so they survive exactly), whole frames through the
//! codec, and arbitrary bytes that never panic and decode idempotently.

use bytes::BytesMut;
use digiview_proto::*;
use proptest::prelude::*;
use tokio_util::codec::Decoder;

fn stream() -> impl Strategy<Value = StreamName> {
    "[a-zA-Z0-9_]{0,8}".prop_map(|s| StreamName::new(&s).unwrap())
}
fn model() -> impl Strategy<Value = ModelName> {
    "[a-zA-Z0-9_.-]{0,16}".prop_map(|s| ModelName::new(&s).unwrap())
}
fn milli() -> impl Strategy<Value = f64> {
    any::<i32>().prop_map(from_milli)
}
fn offset() -> impl Strategy<Value = f64> {
    any::<i16>().prop_map(from_offset)
}
fn ratio() -> impl Strategy<Value = f64> {
    any::<u8>().prop_map(from_ratio)
}
fn bbox() -> impl Strategy<Value = BoundingBox> {
    (any::<u16>(), any::<u16>(), any::<u16>(), any::<u16>()).prop_map(|(x, y, w, h)| BoundingBox {
        x,
        y,
        w,
        h,
    })
}

fn param() -> impl Strategy<Value = Param> {
    prop_oneof![
        (any::<u8>(), any::<u8>(), milli()).prop_map(|(status, error, temperature)| {
            Param::SystemStatus(SystemStatus {
                status,
                error,
                temperature,
            })
        }),
        (any::<bool>(), model(), model()).prop_map(|(enabled, track_model, scan_model)| {
            Param::Ai(Ai {
                enabled,
                track_model,
                scan_model,
            })
        }),
        model().prop_map(|name| Param::Model(Model { name })),
        (
            (stream(), any::<u16>(), any::<u16>(), any::<u8>()),
            (0u8..16, 0u8..16, any::<u8>()),
            (
                prop::collection::vec(bbox(), 0..=MAX_VIEWS),
                bbox(),
                any::<u16>()
            ),
        )
            .prop_map(
                |(
                    (stream, width, height, fps),
                    (layout_mode, layout_views, overlay_mode),
                    (views, overlay_box, single_detection_size),
                )| {
                    Param::VideoOutput(VideoOutput {
                        stream,
                        width,
                        height,
                        fps,
                        layout_mode,
                        layout_views,
                        overlay_mode,
                        views,
                        overlay_box,
                        single_detection_size,
                    })
                }
            ),
        (
            stream(),
            any::<bool>(),
            any::<bool>(),
            any::<u16>(),
            any::<u16>()
        )
            .prop_map(
                |(stream, single_image, record_video, images_captured, videos_captured)| {
                    Param::Capture(Capture {
                        stream,
                        single_image,
                        record_video,
                        images_captured,
                        videos_captured,
                    })
                }
            ),
        (
            (any::<u8>(), any::<u8>(), ratio(), ratio(), ratio(), ratio()),
            any::<[u8; 5]>()
        )
            .prop_map(|((mode, sorting_mode, tc, sc, to, so), s)| {
                Param::Detection(Detection {
                    mode,
                    sorting_mode,
                    track_confidence: tc,
                    scan_confidence: sc,
                    track_overlap: to,
                    scan_overlap: so,
                    creation_score: s[0],
                    bonus_detection: s[1],
                    bonus_redetection: s[2],
                    missed_detection_penalty: s[3],
                    missed_redetection_penalty: s[4],
                })
            }),
        (
            (
                any::<[u8; 3]>(),
                any::<i16>(),
                milli(),
                milli(),
                any::<u8>()
            ),
            (milli(), milli(), milli(), milli(), milli(), milli()),
        )
            .prop_map(
                |((b, object_type, yg, pg, rel_frame), (yr, pr, la, lo, al, di))| {
                    Param::DetectedRoi(DetectedRoi {
                        index: b[0],
                        score: b[1],
                        total: b[2],
                        object_type,
                        yaw_global: yg,
                        pitch_global: pg,
                        rel_frame,
                        yaw_rel: yr,
                        pitch_rel: pr,
                        latitude: la,
                        longitude: lo,
                        altitude: al,
                        distance: di,
                    })
                }
            ),
        (
            (
                stream(),
                any::<u8>(),
                any::<u8>(),
                any::<bool>(),
                milli(),
                milli()
            ),
            (
                milli(),
                any::<u8>(),
                offset(),
                offset(),
                milli(),
                milli(),
                milli()
            ),
        )
            .prop_map(
                |(
                    (stream, cam, mode, euler_delta, yaw, pitch),
                    (roll, lock_flags, x, y, la, lo, al),
                )| {
                    Param::CamTargeting(CamTargeting {
                        stream,
                        cam,
                        mode,
                        euler_delta,
                        yaw,
                        pitch,
                        roll,
                        lock_flags,
                        x_offset: x,
                        y_offset: y,
                        latitude: la,
                        longitude: lo,
                        altitude: al,
                    })
                }
            ),
        (stream(), any::<u8>(), any::<i8>(), milli(), any::<u8>()).prop_map(
            |(stream, cam, zoom, fov, crop_mode)| {
                Param::CamOpticsAndControl(CamOpticsAndControl {
                    stream,
                    cam,
                    zoom,
                    fov,
                    crop_mode,
                })
            }
        ),
        (
            (stream(), any::<u8>(), offset(), offset()),
            (milli(), milli(), milli(), milli()),
        )
            .prop_map(|((stream, cam, x, y), (yg, pg, yr, pr))| {
                Param::CamOffset(CamOffset {
                    stream,
                    cam,
                    x,
                    y,
                    yaw_global: yg,
                    pitch_global: pg,
                    yaw_rel: yr,
                    pitch_rel: pr,
                })
            }),
        (any::<[u32; 4]>(), any::<i32>()).prop_map(|(v, brightness)| {
            Param::Sensor(Sensor {
                min_exposure: v[0],
                max_exposure: v[1],
                min_gain: v[2],
                max_gain: v[3],
                brightness,
            })
        }),
        (stream(), any::<u8>(), any::<u8>(), milli()).prop_map(|(stream, cam, mode, depth)| {
            Param::CamDepthEstimation(CamDepthEstimation {
                stream,
                cam,
                mode,
                depth,
            })
        }),
        (
            (
                any::<u8>(),
                stream(),
                any::<u8>(),
                offset(),
                offset(),
                any::<u8>(),
                any::<u16>()
            ),
            (milli(), milli(), milli(), any::<u8>(), milli(), milli()),
        )
            .prop_map(
                |(
                    (command, stream, cam, x, y, detection_id, zoom),
                    (conf, yg, pg, rel, yr, pr),
                )| {
                    Param::SingleTargetTracking(SingleTargetTracking {
                        command,
                        stream,
                        cam,
                        x_offset: x,
                        y_offset: y,
                        detection_id,
                        zoom,
                        confidence: conf,
                        yaw_global: yg,
                        pitch_global: pg,
                        rel_frame: rel,
                        yaw_rel: yr,
                        pitch_rel: pr,
                    })
                }
            ),
    ]
}

fn message_type() -> impl Strategy<Value = MessageType> {
    prop::sample::select(MessageType::ALL.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn every_param_round_trips(p in param()) {
        let (pt, data) = p.encode();
        prop_assert_eq!(pt, p.param_type());
        let back = Param::decode(pt, &data).expect("own encoding decodes");
        prop_assert_eq!(&back, &p);
        prop_assert_eq!(back.encode().1, data);
    }

    #[test]
    fn every_param_round_trips_through_the_codec(
        p in param(),
        mt in message_type(),
        timestamp in any::<u64>(),
        interval_ms in any::<u32>(),
        chunk in 1usize..100,
    ) {
        let frame = Frame { timestamp, interval_ms, ..Frame::with_param(mt, &p) };
        let bytes = frame.encode();
        prop_assert_eq!(bytes.len(), FRAME_LEN);
        prop_assert!(bytes[81..].iter().all(|&b| b == 0) && bytes[11] == 0);
        let mut codec = FrameCodec::new();
        let mut buf = BytesMut::new();
        let mut got = Vec::new();
        for piece in bytes.chunks(chunk) {
            buf.extend_from_slice(piece);
            while let Some(item) = codec.decode(&mut buf).unwrap() {
                got.push(item);
            }
        }
        prop_assert!(buf.is_empty(), "every byte consumed");
        prop_assert_eq!(got.len(), 1);
        let f = got.pop().unwrap().unwrap();
        prop_assert_eq!(f, frame);
        prop_assert_eq!(Param::decode(f.param_type, &f.data).unwrap(), p);
    }

    #[test]
    fn arbitrary_frames_never_panic(bytes in any::<[u8; FRAME_LEN]>()) {
        let raw = RawFrame::parse(&bytes);
        match Frame::decode(&bytes) {
            Ok(f) => {
                // Re-encoding reproduces the checksummed bytes (padding zeroed).
                let again = f.encode();
                let mut expect = bytes;
                expect[11] = 0;
                expect[81..].fill(0);
                if bytes[11] == 0 {
                    prop_assert_eq!(again, expect);
                }
            }
            Err(FrameError::BadChecksum { received, computed }) => {
                prop_assert_eq!(received, bytes[80]);
                prop_assert_eq!(computed, crc8_bluetooth(&bytes[..80]));
                prop_assert_eq!(computed, raw.computed_checksum());
            }
            Err(_) => prop_assert_eq!(raw.checksum, raw.computed_checksum()),
        }
    }

    #[test]
    fn arbitrary_payloads_never_panic_and_decode_idempotently(
        data in any::<[u8; DATA_LEN]>(),
        pt in prop::sample::select(ParamType::ALL.to_vec()),
    ) {
        if let Ok(p) = Param::decode(pt, &data) {
            let _ = p.validate();
            let (pt2, once) = p.encode();
            prop_assert_eq!(pt2, pt);
            let again = Param::decode(pt, &once).expect("re-encoded payload decodes");
            prop_assert_eq!(&again, &p);
            prop_assert_eq!(again.encode().1, once);
        }
        let _ = GetRequest::decode(pt, &data);
        let _ = RoiSelector::decode(&data);
    }

    #[test]
    fn arbitrary_streams_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600), chunk in 1usize..200) {
        let mut codec = FrameCodec::new();
        let mut buf = BytesMut::new();
        let mut n = 0;
        for piece in bytes.chunks(chunk) {
            buf.extend_from_slice(piece);
            while codec.decode(&mut buf).unwrap().is_some() {
                n += 1;
            }
        }
        prop_assert_eq!(n, bytes.len() / FRAME_LEN);
        prop_assert_eq!(buf.len(), bytes.len() % FRAME_LEN);
    }
}
