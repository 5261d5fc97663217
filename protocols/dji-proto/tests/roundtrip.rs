//! Random valid requests of every method round-trip (request → `data` JSON → parse,
//! and through bytes: encode_service → parse_envelope → parse_service); arbitrary
//! bytes and arbitrary JSON, as whole payloads or as any method's `data`, never panic,
//! and whatever is accepted re-encodes to the same request.

mod common;

use common::{any_json, drc_down, service_request};
use dji_proto::{
    encode_drc_down, encode_service, parse_drc, parse_envelope, parse_event_reply, parse_service,
    Envelope, TopicKind, SERVICE_METHODS,
};
use proptest::prelude::*;
use serde_json::Value;

const DRC_METHODS: [&str; 3] = ["drone_control", "drone_emergency_stop", "heart_beat"];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn valid_requests_round_trip_through_json(request in service_request()) {
        let env = Envelope::new(request.method(), request.to_data());
        prop_assert_eq!(parse_service(&env), Ok(request.clone()));
        let bytes = encode_service(&request, "tid", "bid", 1_654_070_968_655);
        let env = parse_envelope(TopicKind::Services, &bytes).expect("our bytes are an envelope");
        prop_assert_eq!(env.method.as_str(), request.method());
        prop_assert_eq!(parse_service(&env), Ok(request));
    }

    #[test]
    fn valid_drc_round_trips(message in drc_down()) {
        prop_assert_eq!(parse_drc(&Envelope::new(message.method(), message.to_data())), Ok(message));
        let env = parse_envelope(TopicKind::DrcDown, &encode_drc_down(&message)).expect("envelope");
        prop_assert_eq!(parse_drc(&env), Ok(message));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        feed(&bytes);
    }

    #[test]
    fn arbitrary_data_for_every_method_never_panics(
        data in any_json(),
        which in 0usize..(SERVICE_METHODS.len() + DRC_METHODS.len()),
    ) {
        if let Some(&method) = SERVICE_METHODS.get(which) {
            if let Ok(request) = parse_service(&Envelope::new(method, data)) {
                prop_assert_eq!(request.method(), method);
                prop_assert_eq!(parse_service(&Envelope::new(method, request.to_data())), Ok(request));
            }
        } else {
            let method = DRC_METHODS[which - SERVICE_METHODS.len()];
            if let Ok(message) = parse_drc(&Envelope::new(method, data)) {
                prop_assert_eq!(message.method(), method);
                prop_assert_eq!(parse_drc(&Envelope::new(method, message.to_data())), Ok(message));
            }
        }
    }

    #[test]
    fn arbitrary_json_envelopes_never_panic(value in any_json(), method in 0usize..SERVICE_METHODS.len()) {
        // Whole payloads, and the same JSON as `data` of a well-formed envelope.
        feed(value.to_string().as_bytes());
        let wrapped = serde_json::json!({
            "tid": "t", "bid": "b", "timestamp": 1, "method": SERVICE_METHODS[method], "data": value,
        });
        feed(wrapped.to_string().as_bytes());
    }

    /// One field of a valid request replaced by arbitrary JSON: refused or accepted,
    /// never a panic, and an accepted request re-encodes to itself.
    #[test]
    fn mutated_valid_requests(request in service_request(), pick in any::<prop::sample::Index>(), junk in any_json()) {
        let mut data = request.to_data();
        if let Value::Object(map) = &mut data {
            if !map.is_empty() {
                let key = map.keys().nth(pick.index(map.len())).cloned().expect("in range");
                map.insert(key, junk);
            }
        }
        if let Ok(again) = parse_service(&Envelope::new(request.method(), data)) {
            prop_assert_eq!(parse_service(&Envelope::new(again.method(), again.to_data())), Ok(again));
        }
    }
}

/// What the fuzz target does: every inbound kind, then the matching parser.
fn feed(bytes: &[u8]) {
    for kind in [
        TopicKind::Services,
        TopicKind::EventsReply,
        TopicKind::DrcDown,
    ] {
        let Ok(env) = parse_envelope(kind, bytes) else {
            continue;
        };
        match kind {
            TopicKind::Services => {
                let _ = parse_service(&env);
            }
            TopicKind::EventsReply => {
                let _ = parse_event_reply(&env);
            }
            _ => {
                let _ = parse_drc(&env);
            }
        }
    }
}
