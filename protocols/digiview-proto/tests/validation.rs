//! Range validation (what the gateway answers with DATA_ERROR) and the payload
//! decode refusals, each naming its field.

use digiview_proto::*;

fn s(name: &str) -> StreamName {
    StreamName::new(name).unwrap()
}

fn field_of(p: &Param) -> &'static str {
    p.validate().expect_err("should be refused").field
}

fn video() -> VideoOutput {
    VideoOutput {
        stream: s("main"),
        width: 1280,
        height: 720,
        layout_mode: 2,
        overlay_mode: 0,
        views: vec![
            BoundingBox {
                x: 0,
                y: 0,
                w: 640,
                h: 720,
            },
            BoundingBox {
                x: 640,
                y: 0,
                w: 640,
                h: 720,
            },
        ],
        ..VideoOutput::default()
    }
}

fn targeting() -> CamTargeting {
    CamTargeting {
        stream: s("cam0"),
        cam: 0,
        mode: 1,
        yaw: std::f64::consts::PI,
        pitch: -std::f64::consts::FRAC_PI_2,
        latitude: 59.0,
        longitude: 18.0,
        altitude: 100.0,
        ..CamTargeting::default()
    }
}

fn stt() -> SingleTargetTracking {
    SingleTargetTracking {
        command: 1,
        stream: s("cam0"),
        zoom: 10,
        ..SingleTargetTracking::default()
    }
}

#[test]
fn valid_values_pass() {
    Param::VideoOutput(video()).validate().unwrap();
    Param::CamTargeting(targeting()).validate().unwrap();
    Param::SingleTargetTracking(stt()).validate().unwrap();
    // π as it arrives on the wire (3142 mrad) passes.
    let (_, data) = Param::CamTargeting(targeting()).encode();
    let back = Param::decode(ParamType::CamTargeting, &data).unwrap();
    back.validate().unwrap();
}

#[test]
fn video_output_ranges() {
    let cases: Vec<(VideoOutput, &str)> = vec![
        (
            VideoOutput {
                layout_mode: 7,
                ..video()
            },
            "layout_mode",
        ),
        (
            VideoOutput {
                overlay_mode: 6,
                ..video()
            },
            "overlay_mode",
        ),
        (
            VideoOutput {
                width: 639,
                ..video()
            },
            "width",
        ),
        (
            VideoOutput {
                width: 1921,
                ..video()
            },
            "width",
        ),
        (
            VideoOutput {
                height: 479,
                ..video()
            },
            "height",
        ),
        (
            VideoOutput {
                height: 1081,
                ..video()
            },
            "height",
        ),
        (
            VideoOutput {
                layout_views: 5,
                ..video()
            },
            "layout_views",
        ),
        (
            VideoOutput {
                views: vec![BoundingBox::default(); 5],
                ..video()
            },
            "num_views",
        ),
        (
            VideoOutput {
                views: vec![BoundingBox {
                    x: 700,
                    y: 0,
                    w: 640,
                    h: 720,
                }],
                ..video()
            },
            "views",
        ),
        (
            VideoOutput {
                views: vec![BoundingBox {
                    x: 0,
                    y: 65535,
                    w: 0,
                    h: 65535,
                }],
                ..video()
            },
            "views",
        ),
        (
            VideoOutput {
                overlay_box: BoundingBox {
                    x: 1200,
                    y: 0,
                    w: 100,
                    h: 10,
                },
                ..video()
            },
            "overlay_box",
        ),
    ];
    for (v, field) in cases {
        assert_eq!(field_of(&Param::VideoOutput(v.clone())), field, "{v:?}");
    }
}

#[test]
fn targeting_ranges_and_non_finite() {
    let cases: Vec<(CamTargeting, &str)> = vec![
        (
            CamTargeting {
                cam: 4,
                ..targeting()
            },
            "cam",
        ),
        (
            CamTargeting {
                mode: 4,
                ..targeting()
            },
            "mode",
        ),
        (
            CamTargeting {
                yaw: 3.2,
                ..targeting()
            },
            "yaw",
        ),
        (
            CamTargeting {
                yaw: f64::NAN,
                ..targeting()
            },
            "yaw",
        ),
        (
            CamTargeting {
                pitch: 1.6,
                ..targeting()
            },
            "pitch",
        ),
        (
            CamTargeting {
                roll: f64::INFINITY,
                ..targeting()
            },
            "roll",
        ),
        (
            CamTargeting {
                lock_flags: 8,
                ..targeting()
            },
            "lock_flags",
        ),
        (
            CamTargeting {
                x_offset: 1.01,
                ..targeting()
            },
            "x_offset",
        ),
        (
            CamTargeting {
                y_offset: -32768.0 / 32767.0,
                ..targeting()
            },
            "y_offset",
        ),
        (
            CamTargeting {
                latitude: 90.001,
                ..targeting()
            },
            "latitude",
        ),
        (
            CamTargeting {
                longitude: 180.0,
                ..targeting()
            },
            "longitude",
        ),
        (
            CamTargeting {
                altitude: 10000.001,
                ..targeting()
            },
            "altitude",
        ),
    ];
    for (t, field) in cases {
        let err = Param::CamTargeting(t).validate().unwrap_err();
        assert_eq!(err.field, field, "{t:?}");
        assert_eq!(err.param, ParamType::CamTargeting);
    }
    let err = Param::CamTargeting(CamTargeting {
        yaw: f64::NAN,
        ..targeting()
    })
    .validate()
    .unwrap_err();
    assert_eq!(err.problem, Problem::NotFinite);
    assert!(err.to_string().starts_with("CAM_TARGETING.yaw"), "{err}");
}

#[test]
fn detection_ranges() {
    let ok = Detection {
        sorting_mode: 2,
        track_confidence: from_ratio(252),
        ..Detection::default()
    };
    Param::Detection(ok).validate().unwrap();
    let cases = [
        (
            Detection {
                sorting_mode: 3,
                ..ok
            },
            "sorting_mode",
        ),
        (
            Detection {
                track_confidence: from_ratio(253),
                ..ok
            },
            "track_confidence",
        ),
        (
            Detection {
                scan_confidence: 0.99,
                ..ok
            },
            "scan_confidence",
        ),
        (
            Detection {
                track_overlap: -0.1,
                ..ok
            },
            "track_overlap",
        ),
        (
            Detection {
                scan_overlap: f64::NAN,
                ..ok
            },
            "scan_overlap",
        ),
    ];
    for (d, field) in cases {
        assert_eq!(field_of(&Param::Detection(d)), field, "{d:?}");
    }
}

#[test]
fn single_target_tracking_ranges() {
    let cases = [
        (
            SingleTargetTracking {
                command: 5,
                ..stt()
            },
            "command",
        ),
        (SingleTargetTracking { cam: 255, ..stt() }, "cam"),
        (SingleTargetTracking { zoom: 11, ..stt() }, "zoom"),
        (
            SingleTargetTracking {
                rel_frame: 3,
                ..stt()
            },
            "rel_frame",
        ),
        (
            SingleTargetTracking {
                x_offset: -1.5,
                ..stt()
            },
            "x_offset",
        ),
        (
            SingleTargetTracking {
                pitch_global: -2.0,
                ..stt()
            },
            "pitch_global",
        ),
    ];
    for (p, field) in cases {
        assert_eq!(field_of(&Param::SingleTargetTracking(p)), field, "{p:?}");
    }
}

#[test]
fn other_param_ranges() {
    let optics = CamOpticsAndControl {
        stream: s("cam0"),
        cam: 3,
        zoom: -127,
        fov: 1.2,
        crop_mode: 1,
    };
    Param::CamOpticsAndControl(optics).validate().unwrap();
    assert_eq!(
        field_of(&Param::CamOpticsAndControl(CamOpticsAndControl {
            zoom: -128,
            ..optics
        })),
        "zoom"
    );
    assert_eq!(
        field_of(&Param::CamOpticsAndControl(CamOpticsAndControl {
            fov: 3.3,
            ..optics
        })),
        "fov"
    );
    assert_eq!(
        field_of(&Param::CamOpticsAndControl(CamOpticsAndControl {
            crop_mode: 3,
            ..optics
        })),
        "crop_mode"
    );
    assert_eq!(
        field_of(&Param::SystemStatus(SystemStatus {
            status: 4,
            ..SystemStatus::default()
        })),
        "status"
    );
    assert_eq!(
        field_of(&Param::Sensor(Sensor {
            min_exposure: 2,
            max_exposure: 1,
            ..Sensor::default()
        })),
        "min_exposure"
    );
    assert_eq!(
        field_of(&Param::CamDepthEstimation(CamDepthEstimation {
            depth: -1.0,
            ..CamDepthEstimation::default()
        })),
        "depth"
    );
    assert_eq!(
        field_of(&Param::CamOffset(CamOffset {
            x: 2.0,
            ..CamOffset::default()
        })),
        "x"
    );
    assert_eq!(
        field_of(&Param::DetectedRoi(DetectedRoi {
            rel_frame: 3,
            ..DetectedRoi::default()
        })),
        "rel_frame"
    );
}

#[test]
fn payload_decode_refusals_name_the_field() {
    let mut data = [0u8; DATA_LEN];
    data[0] = 2; // ai_enabled neither 0 nor 1
    let err = Param::decode(ParamType::Ai, &data).unwrap_err();
    assert_eq!(
        (err.field, err.problem),
        ("ai_enabled", Problem::NotBool(2))
    );

    let mut data = [0u8; DATA_LEN];
    data[8] = 0b100; // unknown CAPTURE flag bit
    let err = Param::decode(ParamType::Capture, &data).unwrap_err();
    assert_eq!((err.field, err.problem), ("flags", Problem::UnknownBits(4)));

    let mut data = [0u8; DATA_LEN];
    data[15] = 5; // num_views
    assert_eq!(
        Param::decode(ParamType::VideoOutput, &data)
            .unwrap_err()
            .field,
        "num_views"
    );

    let mut data = [0u8; DATA_LEN];
    data[0] = 0xFF; // stream name not UTF-8
    let err = Param::decode(ParamType::CamOffset, &data).unwrap_err();
    assert_eq!(err.field, "stream");
    assert_eq!(err.problem, Problem::Name(NameError::NotUtf8));
    assert_eq!(
        GetRequest::decode(ParamType::CamOffset, &data)
            .unwrap_err()
            .field,
        "stream"
    );
}

#[test]
fn names() {
    assert_eq!(s("abcdefgh").wire(), *b"abcdefgh");
    assert_eq!(
        StreamName::new("abcdefghi"),
        Err(NameError::TooLong { len: 9, max: 8 })
    );
    assert_eq!(StreamName::new("a\0b"), Err(NameError::Nul));
    // On the wire the name ends at the first NUL; what follows is ignored.
    let n = StreamName::from_wire(b"ab\0zzzzz").unwrap();
    assert_eq!(n.as_str(), "ab");
    assert_eq!(n.wire(), *b"ab\0\0\0\0\0\0");
    assert_eq!(
        ModelName::new("yolov8n-person16").unwrap().as_str(),
        "yolov8n-person16"
    );
}

#[test]
fn fixed_point_rounding_and_saturation() {
    assert_eq!(to_milli(1.5714), 1571);
    assert_eq!(to_milli(-0.0005), -1); // rounds half away from zero
    assert_eq!(to_milli(f64::NAN), 0);
    assert_eq!(to_milli(1e12), i32::MAX);
    assert_eq!(to_offset(1.0), 32767);
    assert_eq!(to_offset(-1.0), -32767);
    assert_eq!(to_offset(2.0), i16::MAX);
    assert_eq!(to_ratio(0.5), 128);
    assert_eq!(to_ratio(-1.0), 0);
    assert_eq!(from_ratio(255), 1.0);
}
