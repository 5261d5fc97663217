//! Arbitrary bytes through digiview-gateway's frame handling (codec + handler, the
//! session without socket and bus), against a populated `VisionState`, with the
//! pipeline down, and from a client that may not SET.
//!
//! Checks, beyond "never panics": one step per whole frame until QUIT; every reply
//! is a valid 88-byte frame (checksum, version 0) echoing the request's timestamp
//! and parameter type byte; a refused frame carries a reason whose reply type is the
//! one sent; a SET is forwarded only if the client may SET and the payload
//! validates.
#![no_main]

use digiview_proto::{Frame, MessageType, Param, RawFrame, FRAME_LEN};
use libfuzzer_sys::fuzz_target;
use skymesh_digiview_gateway::handler::{replies_for_bytes, Rules, Step};
use skymesh_ipc_types::{FixedStr, VisionState};

fn state(seed: u8) -> VisionState {
    let mut s = VisionState {
        status: 1,
        ai_enabled: 1,
        model_count: 2,
        stream_count: 1,
        detection_count: seed % 33,
        temperature_valid: seed & 1,
        temperature_c: 40.0,
        ..VisionState::default()
    };
    s.models[0] = FixedStr::new("blobs");
    s.models[1] = FixedStr::new("people");
    let st = &mut s.streams[0];
    st.name = FixedStr::new("main");
    st.configured = 1;
    st.num_views = 1 + seed % 4;
    for c in st.cams.iter_mut() {
        c.active = 1;
        c.aim_valid = 1;
        c.ned_from_cam_q = [1.0, 0.0, 0.0, 0.0];
        c.effective_hfov_rad = 0.2 + f32::from(seed) / 100.0;
        c.view_rect = [0, 0, 640, 360];
    }
    for (i, d) in s.detections.iter_mut().enumerate() {
        d.overlay_slot = if i % 3 == 0 { 255 } else { i as u8 };
        d.geo_valid = (i % 2) as u8;
        d.lat_deg = 58.0;
        d.lon_deg = 15.0;
    }
    s
}

fuzz_target!(|data: &[u8]| {
    let Some((&seed, stream)) = data.split_first() else {
        return;
    };
    let s = state(seed);
    let rules = Rules {
        may_set: seed & 2 != 0,
        roi_rel_frame: seed % 3,
    };
    for st in [Some(&s), None] {
        let out = replies_for_bytes(stream, &rules, st);
        let frames = stream.len() / FRAME_LEN;
        let quit = out.iter().any(|h| h.step == Step::Quit);
        if quit {
            assert_eq!(out.last().map(|h| &h.step), Some(&Step::Quit));
        } else {
            assert_eq!(out.len(), frames);
        }
        for (i, h) in out.iter().enumerate() {
            let bytes: &[u8; FRAME_LEN] = stream[i * FRAME_LEN..][..FRAME_LEN].try_into().unwrap();
            let raw = RawFrame::parse(bytes);
            let replies = match &h.step {
                Step::Reply(r) | Step::Get { replies: r, .. } => r.clone(),
                Step::Set(f) => {
                    assert!(rules.may_set);
                    let p = Param::decode(f.param_type, &f.data).expect("forwarded SET decodes");
                    assert!(p.validate().is_ok());
                    Vec::new()
                }
                Step::Quit => Vec::new(),
            };
            for r in &replies {
                let wire = r.encode();
                let back = RawFrame::parse(&wire);
                assert_eq!(back.checksum, back.computed_checksum());
                assert_eq!(back.version, 0);
                assert_eq!(back.timestamp, raw.timestamp);
                assert_eq!(back.param_type, raw.param_type);
                if r.message_type == MessageType::Current {
                    let f = Frame::decode(&wire).expect("CURRENT replies are valid frames");
                    assert!(Param::decode(f.param_type, &f.data).is_ok());
                }
            }
            if let Some(no) = &h.refusal {
                assert!(replies
                    .iter()
                    .any(|r| r.message_type == no.reason.reply_type()));
            }
        }
    }
});
