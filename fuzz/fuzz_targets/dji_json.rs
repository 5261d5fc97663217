//! Arbitrary bytes as an MQTT payload on each topic the DJI gateway subscribes to
//! (`services`, `events_reply`, `drc/down`): parse_envelope, then the topic's parser.
//!
//! Checks, beyond "never panics": an accepted request names the envelope's method,
//! and re-encodes (to_data / encode_service / encode_drc_down) to bytes that parse
//! back to the same request; an accepted events_reply copies tid, bid and method.
#![no_main]

use dji_proto::{
    encode_drc_down, encode_service, parse_drc, parse_envelope, parse_event_reply, parse_service,
    Envelope, TopicKind,
};
use libfuzzer_sys::fuzz_target;

fn check_service(env: &Envelope) {
    let Ok(request) = parse_service(env) else {
        return;
    };
    assert_eq!(request.method(), env.method, "method changed");
    let again = Envelope::new(request.method(), request.to_data());
    assert_eq!(parse_service(&again).as_ref(), Ok(&request), "to_data round trip");
    let bytes = encode_service(&request, &env.tid, &env.bid, env.timestamp);
    let reparsed = match parse_envelope(TopicKind::Services, &bytes) {
        Ok(reparsed) => reparsed,
        Err(e) => panic!("{} re-encoded is not an envelope: {e}", request.method()),
    };
    assert_eq!(parse_service(&reparsed), Ok(request), "bytes round trip");
}

fn check_drc(env: &Envelope) {
    let Ok(message) = parse_drc(env) else {
        return;
    };
    assert_eq!(message.method(), env.method, "method changed");
    let reparsed = match parse_envelope(TopicKind::DrcDown, &encode_drc_down(&message)) {
        Ok(reparsed) => reparsed,
        Err(e) => panic!("{} re-encoded is not an envelope: {e}", message.method()),
    };
    assert_eq!(parse_drc(&reparsed), Ok(message), "bytes round trip");
}

fn check_event_reply(env: &Envelope) {
    if let Ok(reply) = parse_event_reply(env) {
        assert_eq!(
            (&reply.tid, &reply.bid, &reply.method),
            (&env.tid, &env.bid, &env.method)
        );
    }
}

fuzz_target!(|data: &[u8]| {
    for kind in [TopicKind::Services, TopicKind::EventsReply, TopicKind::DrcDown] {
        let Ok(env) = parse_envelope(kind, data) else {
            continue;
        };
        match kind {
            TopicKind::Services => check_service(&env),
            TopicKind::EventsReply => check_event_reply(&env),
            _ => check_drc(&env),
        }
    }
});
