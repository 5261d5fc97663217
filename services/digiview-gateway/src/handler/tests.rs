//! The handler without socket or bus.

use digiview_proto::{Frame, MessageType, Param, ParamType, SystemStatus, DATA_LEN};
use skymesh_ipc_types::{FixedStr, VisionState};

use super::*;

const RULES: Rules = Rules {
    may_set: true,
    roi_rel_frame: 2,
};

fn state() -> VisionState {
    let mut s = VisionState {
        status: 1,
        ..VisionState::default()
    };
    s.stream_count = 1;
    s.streams[0].name = FixedStr::new("main");
    s.streams[0].configured = 1;
    s
}

fn first_reply(h: &Handled) -> Reply {
    match &h.step {
        Step::Reply(r) | Step::Get { replies: r, .. } => r[0],
        other => panic!("no reply: {other:?}"),
    }
}

#[test]
fn garbage_shifts_alignment_into_checksum_errors() {
    let get = Frame::new(MessageType::Get, ParamType::SystemStatus).encode();
    let mut bytes = vec![1, 2, 3];
    bytes.extend_from_slice(&get);
    bytes.extend_from_slice(&get);
    let out = replies_for_bytes(&bytes, &RULES, Some(&state()));
    assert_eq!(out.len(), 2);
    for h in &out {
        assert_eq!(first_reply(h).message_type, MessageType::ChecksumError);
        assert_eq!(h.refusal.as_ref().unwrap().reason, Refusal::BadChecksum);
    }
}

#[test]
fn quit_stops_the_stream_whatever_its_parameter() {
    let mut quit = Frame::new(MessageType::Quit, ParamType::Ai).encode();
    quit[10] = 99;
    quit[80] = digiview_proto::crc8_bluetooth(&quit[..80]);
    let get = Frame::new(MessageType::Get, ParamType::Ai).encode();
    let bytes: Vec<u8> = quit.iter().chain(get.iter()).copied().collect();
    let out = replies_for_bytes(&bytes, &RULES, Some(&state()));
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].step, Step::Quit);
}

#[test]
fn get_intervals() {
    let s = state();
    let mut f = Frame::new(MessageType::Get, ParamType::SystemStatus);
    let h = handle(Ok(f), &RULES, Some(&s));
    assert!(matches!(
        h.step,
        Step::Get {
            periodic: Periodic::Cancel(ParamType::SystemStatus),
            ..
        }
    ));
    f.interval_ms = 99;
    let h = handle(Ok(f), &RULES, Some(&s));
    assert_eq!(first_reply(&h).message_type, MessageType::DataError);
    f.interval_ms = 100;
    let h = handle(Ok(f), &RULES, Some(&s));
    assert!(matches!(
        h.step,
        Step::Get {
            periodic: Periodic::Start(_),
            ..
        }
    ));
    // A request error does not start a periodic GET; the pipeline being down does.
    let mut v = Frame::new(MessageType::Get, ParamType::VideoOutput);
    v.interval_ms = 100;
    let h = handle(Ok(v), &RULES, Some(&s));
    assert!(matches!(
        h.step,
        Step::Get {
            periodic: Periodic::Unchanged,
            ..
        }
    ));
    let h = handle(Ok(f), &RULES, None);
    assert_eq!(first_reply(&h).message_type, MessageType::Unknown);
    assert!(matches!(
        h.step,
        Step::Get {
            periodic: Periodic::Start(_),
            ..
        }
    ));
}

#[test]
fn sets_are_checked_before_they_are_forwarded() {
    let ai = Param::Ai(digiview_proto::Ai::default());
    let f = Frame::with_param(MessageType::Set, &ai);
    assert_eq!(handle(Ok(f), &RULES, None).step, Step::Set(f));
    let no = Rules {
        may_set: false,
        ..RULES
    };
    assert_eq!(
        first_reply(&handle(Ok(f), &no, None)).message_type,
        MessageType::Forbidden
    );
    let status = Frame::with_param(
        MessageType::Set,
        &Param::SystemStatus(SystemStatus::default()),
    );
    assert_eq!(
        first_reply(&handle(Ok(status), &RULES, None)).message_type,
        MessageType::DataError
    );
    let sensor = Frame::new(MessageType::Set, ParamType::Sensor);
    assert_eq!(
        first_reply(&handle(Ok(sensor), &RULES, None)).message_type,
        MessageType::Unknown
    );
    let mut bad_bool = Frame::new(MessageType::Set, ParamType::Ai);
    bad_bool.data = [0; DATA_LEN];
    bad_bool.data[0] = 2;
    assert_eq!(
        first_reply(&handle(Ok(bad_bool), &RULES, None)).message_type,
        MessageType::DataError
    );
}
