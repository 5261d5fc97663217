//! Topics and the envelope: what is not an envelope at all (size, JSON, object,
//! envelope field presence and types) per topic kind, hostile JSON (deep nesting,
//! trailing bytes, bad UTF-8), and the size limit checked before parsing.

use dji_proto::{parse_envelope, parse_topic, topic, Malformed, TopicKind, MAX_PAYLOAD_BYTES};

const SN: &str = "4BRSN1234";

#[test]
fn topics_and_back() {
    let expected = [
        (TopicKind::Services, "thing/product/4BRSN1234/services"),
        (
            TopicKind::ServicesReply,
            "thing/product/4BRSN1234/services_reply",
        ),
        (TopicKind::Events, "thing/product/4BRSN1234/events"),
        (
            TopicKind::EventsReply,
            "thing/product/4BRSN1234/events_reply",
        ),
        (TopicKind::DrcDown, "thing/product/4BRSN1234/drc/down"),
        (TopicKind::DrcUp, "thing/product/4BRSN1234/drc/up"),
    ];
    assert_eq!(TopicKind::ALL.len(), expected.len());
    for (kind, text) in expected {
        assert_eq!(topic(SN, kind), text);
        assert_eq!(parse_topic(SN, text), Some(kind));
    }
    let inbound: Vec<TopicKind> = TopicKind::ALL
        .into_iter()
        .filter(|k| k.is_inbound())
        .collect();
    assert_eq!(
        inbound,
        [
            TopicKind::Services,
            TopicKind::EventsReply,
            TopicKind::DrcDown
        ]
    );
}

#[test]
fn foreign_topics() {
    for text in [
        "thing/product/OTHER/services",
        "thing/product/4BRSN12345/services",
        "thing/product/4BRSN123/services",
        "thing/product/4BRSN1234/services/",
        "thing/product/4BRSN1234/drc",
        "thing/product/4BRSN1234/drc/down/x",
        "thing/product/4BRSN1234/osd",
        "thing/product/4BRSN1234",
        "sys/product/4BRSN1234/status",
        "/thing/product/4BRSN1234/services",
        "thing/product//services",
        "",
    ] {
        assert_eq!(parse_topic(SN, text), None, "{text}");
    }
}

fn services(text: &str) -> Result<dji_proto::Envelope, Malformed> {
    parse_envelope(TopicKind::Services, text.as_bytes())
}

#[test]
fn oversized_is_refused_before_parsing() {
    // Not JSON at all, but too large: the size check comes first.
    let big = vec![b'{'; MAX_PAYLOAD_BYTES + 1];
    assert_eq!(
        parse_envelope(TopicKind::Services, &big),
        Err(Malformed::Oversized(MAX_PAYLOAD_BYTES + 1))
    );
    // Exactly the limit (valid JSON padded with spaces) is parsed.
    let mut ok = br#"{"method":"m","data":{}}"#.to_vec();
    ok.resize(MAX_PAYLOAD_BYTES, b' ');
    assert!(parse_envelope(TopicKind::DrcDown, &ok).is_ok());
    ok.push(b' ');
    assert_eq!(
        parse_envelope(TopicKind::DrcDown, &ok).map_err(|e| e.kind()),
        Err("oversized")
    );
}

#[test]
fn not_json() {
    for text in [
        "",
        "{",
        "{\"method\": \"x\"} trailing",
        "{\"method\": \"x\"}{}",
        "{'method': 'x'}",
        "{\"method\": \"x\",}",
        "{\"method\": NaN}",
        "\u{feff}{\"method\": \"x\"}",
    ] {
        let err = parse_envelope(TopicKind::DrcDown, text.as_bytes()).expect_err(text);
        assert_eq!(err.kind(), "not_json", "{text:?}: {err}");
    }
    // Invalid UTF-8 inside a string.
    let bytes = b"{\"method\": \"\xff\"}";
    assert_eq!(
        parse_envelope(TopicKind::DrcDown, bytes).map_err(|e| e.kind()),
        Err("not_json")
    );
}

#[test]
fn deep_nesting_is_refused_without_overflowing_the_stack() {
    // Tens of thousands of levels fit in the size limit; serde_json's recursion limit
    // (128) stops them.
    for (open, close) in [("[", "]"), ("{\"a\":", "}")] {
        let depth = 60_000 / (open.len() + close.len());
        let text = format!(
            "{{\"method\":\"drone_control\",\"data\":{}1{}}}",
            open.repeat(depth),
            close.repeat(depth)
        );
        assert!(text.len() <= MAX_PAYLOAD_BYTES);
        let err = parse_envelope(TopicKind::DrcDown, text.as_bytes()).expect_err("refused");
        assert_eq!(err.kind(), "not_json");
    }
    // Moderate nesting inside data is fine (it is the data checks' business).
    let text = format!(
        "{{\"method\":\"x\",\"data\":{}1{}}}",
        "[".repeat(100),
        "]".repeat(100)
    );
    assert!(parse_envelope(TopicKind::DrcDown, text.as_bytes()).is_ok());
}

#[test]
fn not_an_object() {
    for text in [
        "[]",
        "null",
        "1",
        "\"services\"",
        "true",
        "[{\"method\":\"x\"}]",
    ] {
        assert_eq!(services(text), Err(Malformed::NotObject), "{text}");
    }
}

#[test]
fn required_envelope_fields_per_kind() {
    let full = r#"{"tid":"t","bid":"b","method":"m","timestamp":1}"#;
    for kind in [
        TopicKind::Services,
        TopicKind::EventsReply,
        TopicKind::ServicesReply,
        TopicKind::Events,
    ] {
        assert!(parse_envelope(kind, full.as_bytes()).is_ok(), "{kind:?}");
        for (field, without) in [
            ("tid", r#"{"bid":"b","method":"m","timestamp":1}"#),
            ("bid", r#"{"tid":"t","method":"m","timestamp":1}"#),
            ("method", r#"{"tid":"t","bid":"b","timestamp":1}"#),
            ("timestamp", r#"{"tid":"t","bid":"b","method":"m"}"#),
            (
                "tid",
                r#"{"tid":null,"bid":"b","method":"m","timestamp":1}"#,
            ),
        ] {
            assert_eq!(
                parse_envelope(kind, without.as_bytes()),
                Err(Malformed::Missing(field)),
                "{kind:?} {without}"
            );
        }
    }
    for kind in [TopicKind::DrcDown, TopicKind::DrcUp] {
        let env = parse_envelope(kind, br#"{"method":"heart_beat"}"#).expect("method only");
        assert_eq!(
            (env.tid.as_str(), env.bid.as_str(), env.timestamp),
            ("", "", 0)
        );
        assert_eq!(env.data, serde_json::Value::Null);
        assert_eq!(
            parse_envelope(kind, br#"{"data":{}}"#),
            Err(Malformed::Missing("method"))
        );
    }
}

#[test]
fn envelope_field_types() {
    let cases = [
        (r#"{"tid":1,"bid":"b","method":"m","timestamp":1}"#, "tid"),
        (
            r#"{"tid":"t","bid":["b"],"method":"m","timestamp":1}"#,
            "bid",
        ),
        (
            r#"{"tid":"t","bid":"b","method":{},"timestamp":1}"#,
            "method",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":-1}"#,
            "timestamp",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1.5}"#,
            "timestamp",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1e3}"#,
            "timestamp",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":"1654070968655"}"#,
            "timestamp",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":18446744073709551616}"#,
            "timestamp",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1,"gateway":5}"#,
            "gateway",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1,"need_reply":2}"#,
            "need_reply",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1,"need_reply":true}"#,
            "need_reply",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1,"need_reply":1.0}"#,
            "need_reply",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1,"seq":"1"}"#,
            "seq",
        ),
        (
            r#"{"tid":"t","bid":"b","method":"m","timestamp":1,"seq":1.5}"#,
            "seq",
        ),
    ];
    for (text, field) in cases {
        assert_eq!(services(text), Err(Malformed::WrongType(field)), "{text}");
    }
    // Optional fields are type-checked on drc/down too.
    assert_eq!(
        parse_envelope(TopicKind::DrcDown, br#"{"method":"m","tid":7}"#),
        Err(Malformed::WrongType("tid"))
    );
    assert_eq!(
        parse_envelope(TopicKind::DrcDown, br#"{"method":"m","timestamp":-5}"#),
        Err(Malformed::WrongType("timestamp"))
    );
}

#[test]
fn every_field_read() {
    let text = br#"{"tid":"t1","bid":"b1","method":"poi_status_notify","timestamp":18446744073709551615,
        "gateway":"4BRSN1234","need_reply":1,"seq":-9,"data":{"result":0},"extra":{"ignored":true}}"#;
    let env = parse_envelope(TopicKind::EventsReply, text).expect("parses");
    assert_eq!(env.tid, "t1");
    assert_eq!(env.bid, "b1");
    assert_eq!(env.method, "poi_status_notify");
    assert_eq!(env.timestamp, u64::MAX);
    assert_eq!(env.gateway.as_deref(), Some(SN));
    assert_eq!(env.need_reply, Some(1));
    assert_eq!(env.seq, Some(-9));
    assert_eq!(env.data, serde_json::json!({"result": 0}));
    let env = services(
        r#"{"tid":"t","bid":"b","method":"m","timestamp":0,"need_reply":0,"gateway":null}"#,
    )
    .expect("parses");
    assert_eq!((env.need_reply, env.gateway), (Some(0), None));
}

#[test]
fn malformed_kinds_are_metric_labels() {
    let labels: Vec<&str> = [
        Malformed::Oversized(1),
        Malformed::NotJson(String::new()),
        Malformed::NotObject,
        Malformed::Missing("tid"),
        Malformed::WrongType("tid"),
    ]
    .iter()
    .map(Malformed::kind)
    .collect();
    assert_eq!(
        labels,
        [
            "oversized",
            "not_json",
            "not_object",
            "missing",
            "wrong_type"
        ]
    );
}
