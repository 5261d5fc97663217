//! One inbound MQTT message through every check, in order (pure, explicit time):
//! one of our topics the cloud publishes on (`unexpected_topic`), the per-topic rate,
//! the size (`oversized`), `parse_envelope` (no reply possible: dropped and counted
//! by [`dji_proto::Malformed::kind`]), then `parse_service` / `parse_event_reply`.

use std::time::Instant;

use dji_proto::{
    parse_envelope, parse_event_reply, parse_service, parse_topic, Envelope, EventReply, Reject,
    ServiceRequest, TopicKind,
};

use crate::ratelimit::RateLimiter;

/// What a message is.
#[derive(Debug, Clone, PartialEq)]
pub enum Inbound {
    /// Nothing can be replied: dropped, counted as `kind`.
    Dropped { kind: &'static str, detail: String },
    /// Over the topic's rate: dropped and counted.
    RateLimited(TopicKind),
    /// A services request: checked (`Ok`) or refused with a code (`Err`, replied).
    Request(Box<Envelope>, Result<Box<ServiceRequest>, Reject>),
    /// An events_reply.
    EventReply(Result<EventReply, Reject>),
}

/// Checks one message; also returns its topic kind when it is one of ours.
pub fn classify(
    gateway_sn: &str,
    max_payload_bytes: usize,
    limiter: &mut RateLimiter<TopicKind>,
    topic: &str,
    payload: &[u8],
    now: Instant,
) -> (Option<TopicKind>, Inbound) {
    let Some(kind) = parse_topic(gateway_sn, topic) else {
        let detail = format!("topic `{}`", topic.chars().take(128).collect::<String>());
        return (
            None,
            Inbound::Dropped {
                kind: "unexpected_topic",
                detail,
            },
        );
    };
    if !matches!(kind, TopicKind::Services | TopicKind::EventsReply) {
        return (
            Some(kind),
            Inbound::Dropped {
                kind: "unexpected_topic",
                detail: format!("`{topic}` is a topic the device publishes"),
            },
        );
    }
    if !limiter.admit(kind, now) {
        return (Some(kind), Inbound::RateLimited(kind));
    }
    if payload.len() > max_payload_bytes {
        return (
            Some(kind),
            Inbound::Dropped {
                kind: "oversized",
                detail: format!("{} bytes (max {max_payload_bytes})", payload.len()),
            },
        );
    }
    let env = match parse_envelope(kind, payload) {
        Ok(env) => env,
        Err(e) => {
            return (
                Some(kind),
                Inbound::Dropped {
                    kind: e.kind(),
                    detail: e.to_string(),
                },
            )
        }
    };
    let inbound = match kind {
        TopicKind::Services => {
            let req = parse_service(&env).map(Box::new);
            Inbound::Request(Box::new(env), req)
        }
        _ => Inbound::EventReply(parse_event_reply(&env)),
    };
    (Some(kind), inbound)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dji_proto::codes;
    use std::time::Duration;

    const SN: &str = "SN-1";

    fn run(limiter: &mut RateLimiter<TopicKind>, topic: &str, payload: &[u8]) -> Inbound {
        classify(SN, 1000, limiter, topic, payload, Instant::now()).1
    }

    fn services() -> String {
        dji_proto::topic(SN, TopicKind::Services)
    }

    #[test]
    fn requests_are_parsed_and_refusals_keep_their_envelope() {
        let mut l = RateLimiter::new(100);
        let ok =
            br#"{"tid":"t","bid":"b","timestamp":1,"method":"flight_authority_grab","data":{}}"#;
        match run(&mut l, &services(), ok) {
            Inbound::Request(env, Ok(req)) if *req == ServiceRequest::FlightAuthorityGrab => {
                assert_eq!((env.tid.as_str(), env.bid.as_str()), ("t", "b"))
            }
            other => panic!("{other:?}"),
        }
        let unknown = br#"{"tid":"t","bid":"b","timestamp":1,"method":"self_destruct","data":{}}"#;
        match run(&mut l, &services(), unknown) {
            Inbound::Request(env, Err(r)) => {
                assert_eq!(r.code, codes::UNKNOWN_METHOD);
                assert_eq!(env.method, "self_destruct");
            }
            other => panic!("{other:?}"),
        }
        let reply = br#"{"tid":"t","bid":"b","timestamp":1,"method":"poi_status_notify","data":{"result":0}}"#;
        let topic = dji_proto::topic(SN, TopicKind::EventsReply);
        assert!(matches!(run(&mut l, &topic, reply), Inbound::EventReply(Ok(r)) if r.tid == "t"));
    }

    #[test]
    fn hostile_input_is_dropped_by_kind() {
        let mut l = RateLimiter::new(100);
        let kind = |i: Inbound| match i {
            Inbound::Dropped { kind, .. } => kind,
            other => panic!("{other:?}"),
        };
        assert_eq!(kind(run(&mut l, &services(), b"{not json")), "not_json");
        assert_eq!(kind(run(&mut l, &services(), b"[1,2]")), "not_object");
        assert_eq!(
            kind(run(
                &mut l,
                &services(),
                br#"{"bid":"b","timestamp":1,"method":"x"}"#
            )),
            "missing"
        );
        assert_eq!(
            kind(run(
                &mut l,
                &services(),
                br#"{"tid":7,"bid":"b","timestamp":1,"method":"x"}"#
            )),
            "wrong_type"
        );
        assert_eq!(kind(run(&mut l, &services(), &[b' '; 1001])), "oversized");
        assert_eq!(
            kind(run(&mut l, "thing/product/OTHER/services", b"{}")),
            "unexpected_topic"
        );
        let ours_outbound = dji_proto::topic(SN, TopicKind::ServicesReply);
        assert_eq!(kind(run(&mut l, &ours_outbound, b"{}")), "unexpected_topic");
    }

    #[test]
    fn the_rate_limit_applies_per_topic_before_parsing() {
        let mut l = RateLimiter::new(2);
        let t0 = Instant::now();
        let t = services();
        for _ in 0..2 {
            let (k, i) = classify(SN, 1000, &mut l, &t, b"junk", t0);
            assert_eq!(k, Some(TopicKind::Services));
            assert!(matches!(
                i,
                Inbound::Dropped {
                    kind: "not_json",
                    ..
                }
            ));
        }
        let (_, i) = classify(SN, 1000, &mut l, &t, b"junk", t0);
        assert_eq!(i, Inbound::RateLimited(TopicKind::Services));
        let er = dji_proto::topic(SN, TopicKind::EventsReply);
        let (_, i) = classify(SN, 1000, &mut l, &er, b"junk", t0);
        assert!(matches!(i, Inbound::Dropped { .. }), "its own budget");
        let (_, i) = classify(SN, 1000, &mut l, &t, b"junk", t0 + Duration::from_secs(1));
        assert!(matches!(i, Inbound::Dropped { .. }), "next second");
    }

    /// A services request with `data`.
    fn request(method: &str, data: &str) -> Vec<u8> {
        format!(r#"{{"tid":"t","bid":"b","timestamp":1,"method":"{method}","data":{data}}}"#)
            .into_bytes()
    }

    #[test]
    fn huge_and_out_of_range_numbers_are_refused_with_out_of_range() {
        let mut l = RateLimiter::new(1000);
        let point = |lat: &str, lon: &str, h: &str| {
            format!(r#"{{"latitude":{lat},"longitude":{lon},"height":{h}}}"#)
        };
        let fly = |speed: &str, p: String| {
            request(
                "fly_to_point",
                &format!(r#"{{"fly_to_id":"f","max_speed":{speed},"points":[{p}]}}"#),
            )
        };
        let good = fly("12", point("12.23", "12.23", "100"));
        assert!(matches!(
            run(&mut l, &services(), &good),
            Inbound::Request(_, Ok(_))
        ));
        let zoom = |z: &str| {
            request(
                "camera_focal_length_set",
                &format!(r#"{{"payload_index":"39-0-7","camera_type":"zoom","zoom_factor":{z}}}"#),
            )
        };
        assert!(matches!(
            run(&mut l, &services(), &zoom("5")),
            Inbound::Request(_, Ok(_))
        ));
        let wrong_type = codes::WRONG_TYPE;
        let out_of_range = codes::OUT_OF_RANGE;
        for (bad, code) in [
            // max_speed is an integer field: a huge float (or an integer beyond u64,
            // which JSON parsers read as one) is the wrong type, a huge integer
            // (beyond i64 too) out of range.
            (fly("1e308", point("12.23", "12.23", "100")), wrong_type),
            (
                fly("99999999999999999999", point("12.23", "12.23", "100")),
                wrong_type,
            ),
            (fly("100000", point("12.23", "12.23", "100")), out_of_range),
            (
                fly("18446744073709551615", point("12.23", "12.23", "100")),
                out_of_range,
            ),
            (fly("-5", point("12.23", "12.23", "100")), out_of_range),
            (fly("12", point("1e308", "12.23", "100")), out_of_range),
            (
                fly("12", point("12.23", "-1.7976931348623157e308", "100")),
                out_of_range,
            ),
            (fly("12", point("12.23", "12.23", "1e300")), out_of_range),
            (fly("12", point("12.23", "12.23", "-5")), out_of_range),
            (zoom("1e308"), out_of_range),
            (zoom("-1e-308"), out_of_range),
            (zoom("100000"), out_of_range),
        ] {
            match run(&mut l, &services(), &bad) {
                Inbound::Request(env, Err(r)) => {
                    assert_eq!(r.code, code, "{r}");
                    // The envelope is kept: the refusal is replied with this code.
                    assert_eq!(env.tid, "t");
                }
                other => panic!("{}: {other:?}", String::from_utf8_lossy(&bad)),
            }
        }
        // Beyond f64 (JSON has no NaN/inf; 1e999 is what comes closest): not a
        // parseable document, dropped and counted (no envelope to reply to).
        let beyond = fly("1e999", point("12.23", "12.23", "100"));
        assert!(matches!(
            run(&mut l, &services(), &beyond),
            Inbound::Dropped { .. }
        ));
    }
}
