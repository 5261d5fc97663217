//! The parameter model without bus or frames: every view control's checks and
//! effects, and the other controls.

use super::*;
use skymesh_ipc_types::VisionOrigin;

fn params() -> Params {
    Params {
        ai_enabled: true,
        scan_model: MODELS[0].into(),
        track_model: MODELS[0].into(),
        detection_mode: 0,
        tracker: TrackerParams::default(),
        streams: vec![
            StreamParams {
                name: "main".into(),
                out_width: 1280,
                out_height: 720,
                layout_mode: 0,
                overlay_mode: 2,
            },
            StreamParams {
                name: "aux".into(),
                out_width: 640,
                out_height: 480,
                layout_mode: 4,
                overlay_mode: 0,
            },
        ],
    }
}

/// A control of `kind` for stream `stream`.
fn ctl(kind: ViewControlKind, stream: &str) -> ViewControl {
    ViewControl {
        request_id: 7,
        kind: kind.to_wire(),
        origin: VisionOrigin::DigiView.to_wire(),
        stream: FixedStr::new(stream),
        ..ViewControl::default()
    }
}

fn video(name: &str, w: u16, h: u16, layout: u8, overlay: u8) -> ViewControl {
    ViewControl {
        width: w,
        height: h,
        layout_mode: layout,
        overlay_mode: overlay,
        ..ctl(ViewControlKind::Output, name)
    }
}

#[test]
fn video_output_clamps_ignores_and_keeps_per_the_document() {
    let mut p = params();
    assert_eq!(
        p.apply_view(&video("main", 1920, 1080, 4, 3)),
        Ok(Effect::Changed)
    );
    let s = &p.streams[0];
    assert_eq!(
        (s.out_width, s.out_height, s.layout_mode, s.overlay_mode),
        (1920, 1080, 4, 3)
    );
    // Above the maximum: clamped; out-of-range modes leave the setting unchanged.
    assert_eq!(
        p.apply_view(&video("main", 4000, 2000, 9, 9)),
        Ok(Effect::Changed)
    );
    let s = &p.streams[0];
    assert_eq!(
        (s.out_width, s.out_height, s.layout_mode, s.overlay_mode),
        (1920, 1080, 4, 3)
    );
    // Below the minimum: the whole operation is ignored.
    let before = p.clone();
    let e = p.apply_view(&video("main", 320, 720, 1, 1)).unwrap_err();
    assert_eq!(e.result, VisionResult::Ignored);
    assert_eq!(p, before);
    // Unknown stream: ignored; the other stream is addressed by name.
    let e = p.apply_view(&video("nope", 800, 600, 1, 1)).unwrap_err();
    assert_eq!(e.result, VisionResult::Ignored);
    assert!(e.message.contains("nope"), "{}", e.message);
    p.apply_view(&video("aux", 800, 600, 6, 5)).unwrap();
    assert_eq!((p.streams[1].out_width, p.streams[1].layout_mode), (800, 6));
    assert_eq!(p.streams[0].out_width, 1920);
}

#[test]
fn ai_models_must_exist_and_empty_names_keep() {
    let mut p = params();
    let ai = |enabled: bool, scan: &str, track: &str| ViewControl {
        ai_enabled: u8::from(enabled),
        scan_model: FixedStr::new(scan),
        track_model: FixedStr::new(track),
        ..ctl(ViewControlKind::Ai, "")
    };
    assert_eq!(
        p.apply_view(&ai(false, "motion-bg", "")),
        Ok(Effect::AiChanged)
    );
    assert!(!p.ai_enabled);
    assert_eq!(
        (p.scan_model.as_str(), p.track_model.as_str()),
        ("motion-bg", MODELS[0])
    );
    let before = p.clone();
    let e = p.apply_view(&ai(true, "yolo-v9", "motion-bg")).unwrap_err();
    assert_eq!(e.result, VisionResult::Ignored);
    assert!(e.message.contains("yolo-v9"));
    assert_eq!(p, before, "nothing changes on an unknown model");
}

#[test]
fn detection_keeps_out_of_range_values_and_score_255() {
    let mut p = params();
    let d = ViewControl {
        detection_mode: 3,
        sorting_mode: 2,
        track_confidence: 0.6,
        scan_confidence: 0.995,
        track_overlap: 0.2,
        scan_overlap: 0.4,
        creation_score: 100,
        bonus_detection: SCORE_KEEP,
        bonus_redetection: 5,
        missed_detection_penalty: SCORE_KEEP,
        missed_redetection_penalty: 0,
        ..ctl(ViewControlKind::Detection, "")
    };
    assert_eq!(p.apply_view(&d), Ok(Effect::Changed));
    let t = p.tracker;
    let def = TrackerParams::default();
    assert_eq!(p.detection_mode, 3);
    assert_eq!(t.sorting_mode, 2);
    assert!((t.track_confidence - 0.6).abs() < 0.005);
    assert_eq!(
        t.scan_confidence, def.scan_confidence,
        "0.995 is out of range"
    );
    assert!((t.track_overlap - 0.2).abs() < 0.005);
    assert_eq!(t.creation_score, 100);
    assert_eq!(t.bonus_detection, def.bonus_detection);
    assert_eq!(t.bonus_redetection, 5);
    assert_eq!(t.missed_detection_penalty, def.missed_detection_penalty);
    assert_eq!(t.missed_redetection_penalty, 0);
    p.apply_view(&ViewControl {
        sorting_mode: 3,
        ..d
    })
    .unwrap();
    assert_eq!(
        p.tracker.sorting_mode, 2,
        "sorting mode 3 leaves it unchanged"
    );
}

#[test]
fn capture_names_the_stream() {
    let mut p = params();
    let c = |name: &str, image: bool, record: bool| ViewControl {
        capture_image: u8::from(image),
        record: u8::from(record),
        ..ctl(ViewControlKind::Capture, name)
    };
    assert_eq!(
        p.apply_view(&c("aux", true, false)),
        Ok(Effect::Capture {
            stream: 1,
            single_image: true,
            record: Some(false)
        })
    );
    assert_eq!(
        p.apply_view(&c("main", false, true)),
        Ok(Effect::Capture {
            stream: 0,
            single_image: false,
            record: Some(true)
        })
    );
    assert_eq!(
        p.apply_view(&c("x", true, true)).unwrap_err().result,
        VisionResult::Ignored
    );
}

#[test]
fn cameras_are_checked_and_ranges_validated() {
    let mut p = params();
    let t = ViewControl {
        cam: 2,
        targeting_mode: 1,
        lat_deg: 47.0,
        lon_deg: 8.0,
        alt_rel_m: -50.0,
        ..ctl(ViewControlKind::Targeting, "main")
    };
    match p.apply_view(&t) {
        Ok(Effect::Targeting {
            stream: 0,
            cam: 2,
            targeting,
        }) => assert_eq!(
            (targeting.mode, targeting.latitude, targeting.altitude),
            (1, 47.0, -50.0)
        ),
        other => panic!("{other:?}"),
    }
    let e = p.apply_view(&ViewControl { cam: 4, ..t }).unwrap_err();
    assert_eq!(e.result, VisionResult::Ignored);
    let e = p
        .apply_view(&ViewControl {
            stream: FixedStr::new("zz"),
            ..t
        })
        .unwrap_err();
    assert_eq!(e.result, VisionResult::Ignored);
    for bad in [
        ViewControl {
            pitch_rad: 2.0,
            ..t
        },
        ViewControl {
            yaw_rad: f64::NAN,
            ..t
        },
        ViewControl { x_offset: 1.5, ..t },
        ViewControl {
            lon_deg: 180.0,
            ..t
        },
        ViewControl { lock_flags: 8, ..t },
        ViewControl {
            targeting_mode: 4,
            ..t
        },
    ] {
        let e = p.apply_view(&bad).unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid, "{bad:?}");
    }
    let e = p
        .apply_view(&ViewControl {
            pitch_rad: 2.0,
            ..t
        })
        .unwrap_err();
    assert!(e.message.contains("pitch"), "{}", e.message);
    let o = ViewControl {
        cam: 1,
        zoom: 20,
        fov_rad: 1.0,
        crop_mode: 2,
        ..ctl(ViewControlKind::Optics, "aux")
    };
    assert_eq!(
        p.apply_view(&o),
        Ok(Effect::Optics {
            stream: 1,
            cam: 1,
            optics: Optics {
                zoom: 20,
                fov: 1.0,
                crop_mode: 2
            }
        })
    );
    for bad in [
        ViewControl { fov_rad: 4.0, ..o },
        ViewControl { zoom: -128, ..o },
        ViewControl { crop_mode: 3, ..o },
    ] {
        let e = p.apply_view(&bad).unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid, "{bad:?}");
    }
}

#[test]
fn single_target_commands_resolve() {
    let mut p = params();
    let s = ViewControl {
        track_command: TrackCommand::Direction.to_wire(),
        cam: 0,
        x_offset: 1.0,
        y_offset: -1.0,
        detection_id: 9,
        track_zoom: 3,
        yaw_rad: 1.0,
        pitch_rad: -0.5,
        reference: ReferenceFrame::Camera.to_wire(),
        ..ctl(ViewControlKind::SingleTarget, "main")
    };
    let req = |p: &mut Params, s: ViewControl| match p.apply_view(&s) {
        Ok(Effect::Stt {
            request,
            zoom_level,
            rel_frame,
            ..
        }) => {
            assert_eq!((zoom_level, rel_frame), (s.track_zoom, s.reference));
            request
        }
        other => panic!("{other:?}"),
    };
    let cmd = |c: TrackCommand| ViewControl {
        track_command: c.to_wire(),
        ..s
    };
    assert_eq!(req(&mut p, s), SttRequest::ViewOffset { x: 1.0, y: -1.0 });
    assert_eq!(
        req(
            &mut p,
            ViewControl {
                reference: ReferenceFrame::Global.to_wire(),
                ..s
            }
        ),
        SttRequest::Global {
            yaw: 1.0,
            pitch: -0.5
        }
    );
    assert_eq!(
        req(&mut p, cmd(TrackCommand::Detection)),
        SttRequest::Detection(9)
    );
    assert_eq!(
        req(&mut p, cmd(TrackCommand::Nudge)),
        SttRequest::Nudge { x: 1.0, y: -1.0 }
    );
    assert_eq!(req(&mut p, cmd(TrackCommand::Disable)), SttRequest::Disable);
    assert_eq!(req(&mut p, cmd(TrackCommand::NoOp)), SttRequest::NoOp);
    for bad in [
        ViewControl {
            track_zoom: 11,
            ..s
        },
        ViewControl {
            track_command: 5,
            ..s
        },
        ViewControl { reference: 3, ..s },
        ViewControl {
            pitch_rad: 1.6,
            ..s
        },
    ] {
        let e = p.apply_view(&bad).unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid, "{bad:?}");
    }
}

#[test]
fn direction_at_checks_the_view_and_the_offsets() {
    let mut p = params();
    let d = ViewControl {
        cam: 3,
        x_offset: 0.5,
        y_offset: -0.25,
        ..ctl(ViewControlKind::DirectionAt, "aux")
    };
    assert_eq!(
        p.apply_view(&d),
        Ok(Effect::DirectionAt {
            stream: 1,
            cam: 3,
            x: 0.5,
            y: -0.25
        })
    );
    let e = p
        .apply_view(&ViewControl {
            y_offset: -1.5,
            ..d
        })
        .unwrap_err();
    assert_eq!(e.result, VisionResult::Invalid);
    let e = p.apply_view(&ViewControl { cam: 4, ..d }).unwrap_err();
    assert_eq!(e.result, VisionResult::Ignored);
}

#[test]
fn unknown_kinds_and_protocol_payloads_are_invalid() {
    let mut p = params();
    for k in [0u8, 9, 200] {
        let e = p
            .apply_view(&ViewControl {
                kind: k,
                ..ViewControl::default()
            })
            .unwrap_err();
        assert_eq!(e.result, VisionResult::Invalid);
    }
    let e = p
        .apply(&VisionControl {
            // Once protocol payloads; settings come as a ViewControl.
            kind: 1,
            ..VisionControl::default()
        })
        .unwrap_err();
    assert_eq!(e.result, VisionResult::Invalid);
    let e = p
        .apply(&VisionControl {
            kind: 200,
            ..VisionControl::default()
        })
        .unwrap_err();
    assert_eq!(e.result, VisionResult::Invalid);
    // Garbage everywhere: never a panic, always an answer.
    for k in 0..=255u8 {
        let mut c = ViewControl {
            kind: k,
            ..ctl(ViewControlKind::Ai, "main")
        };
        c.yaw_rad = f64::INFINITY;
        c.targeting_mode = 0xff;
        let _ = p.apply_view(&c);
    }
}

#[test]
fn gimbal_roi_zoom_and_capture_controls() {
    let mut p = params();
    let c = |kind: VisionControlKind| VisionControl {
        kind: kind.to_wire(),
        origin: VisionOrigin::GimbalV2.to_wire(),
        stream: 0,
        cam: 1,
        ..VisionControl::default()
    };
    let g = VisionControl {
        yaw_rad: 0.5,
        gimbal_flags: GIMBAL_YAW_IN_EARTH_FRAME,
        ..c(VisionControlKind::GimbalAttitude)
    };
    assert_eq!(
        p.apply(&g),
        Ok(Effect::Gimbal {
            stream: 0,
            cam: 1,
            yaw: Some(0.5),
            pitch: None,
            yaw_rate: None,
            pitch_rate: None,
            yaw_global: true
        })
    );
    // Nothing given, an infinite angle, a camera out of range, an unknown stream.
    assert_eq!(
        p.apply(&c(VisionControlKind::GimbalAttitude))
            .unwrap_err()
            .result,
        VisionResult::Invalid
    );
    let inf = VisionControl {
        pitch_rad: f32::INFINITY,
        ..g
    };
    assert_eq!(p.apply(&inf).unwrap_err().result, VisionResult::Invalid);
    assert_eq!(
        p.apply(&VisionControl { cam: 255, ..g })
            .unwrap_err()
            .result,
        VisionResult::Ignored
    );
    assert_eq!(
        p.apply(&VisionControl { stream: 2, ..g })
            .unwrap_err()
            .result,
        VisionResult::Ignored
    );

    let roi = VisionControl {
        cam: ALL_CAMS,
        lat_deg: 47.0,
        lon_deg: 8.0,
        alt_msl_m: 500.0,
        ..c(VisionControlKind::RoiLocation)
    };
    assert!(matches!(
        p.apply(&roi),
        Ok(Effect::Roi {
            cams: Cams::All,
            ..
        })
    ));
    let nan = VisionControl {
        lat_deg: f64::NAN,
        ..roi
    };
    assert_eq!(p.apply(&nan).unwrap_err().result, VisionResult::Invalid);
    assert_eq!(
        p.apply(&c(VisionControlKind::RoiNone)),
        Ok(Effect::RoiNone {
            stream: 0,
            cams: Cams::One(1)
        })
    );
    let z = VisionControl {
        zoom_mode: 2,
        value: 50.0,
        ..c(VisionControlKind::Zoom)
    };
    assert!(matches!(p.apply(&z), Ok(Effect::Zoom { mode: 2, .. })));
    let znan = VisionControl {
        value: f32::NAN,
        ..z
    };
    assert_eq!(p.apply(&znan).unwrap_err().result, VisionResult::Invalid);
    assert_eq!(
        p.apply(&c(VisionControlKind::RecordStop)),
        Ok(Effect::Capture {
            stream: 0,
            single_image: false,
            record: Some(false)
        })
    );
    assert_eq!(
        p.apply(&c(VisionControlKind::ImageCapture)),
        Ok(Effect::Capture {
            stream: 0,
            single_image: true,
            record: None
        })
    );
    assert_eq!(Cams::All.indices(), 0..4);
    assert_eq!(Cams::One(2).indices(), 2..3);
}
