//! Topics and the JSON envelope: inbound envelope parsing (size first, then JSON, then
//! the envelope fields' types) and the device's outbound messages. Output is compact
//! JSON.

use serde_json::{json, Map, Value};

/// Largest accepted MQTT payload, bytes; larger payloads are [`Malformed::Oversized`].
pub const MAX_PAYLOAD_BYTES: usize = 64 * 1024;

/// The six topics of this document under `thing/product/{gateway_sn}/`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TopicKind {
    /// cloud → device
    Services,
    /// device → cloud
    ServicesReply,
    /// device → cloud
    Events,
    /// cloud → device
    EventsReply,
    /// cloud → device
    DrcDown,
    /// device → cloud
    DrcUp,
}

impl TopicKind {
    /// All six, in the document's order of use.
    pub const ALL: [TopicKind; 6] = [
        TopicKind::Services,
        TopicKind::ServicesReply,
        TopicKind::Events,
        TopicKind::EventsReply,
        TopicKind::DrcDown,
        TopicKind::DrcUp,
    ];

    /// The last topic level(s): `services`, ..., `drc/down`, `drc/up`.
    pub fn suffix(self) -> &'static str {
        match self {
            TopicKind::Services => "services",
            TopicKind::ServicesReply => "services_reply",
            TopicKind::Events => "events",
            TopicKind::EventsReply => "events_reply",
            TopicKind::DrcDown => "drc/down",
            TopicKind::DrcUp => "drc/up",
        }
    }

    /// Published by the cloud, subscribed by the device.
    pub fn is_inbound(self) -> bool {
        matches!(
            self,
            TopicKind::Services | TopicKind::EventsReply | TopicKind::DrcDown
        )
    }

    /// `drc/down` and `drc/up` (no tid/bid; method and data only).
    pub fn is_drc(self) -> bool {
        matches!(self, TopicKind::DrcDown | TopicKind::DrcUp)
    }
}

/// `thing/product/{gateway_sn}/{services|services_reply|events|events_reply|drc/down|drc/up}`.
pub fn topic(gateway_sn: &str, kind: TopicKind) -> String {
    format!("thing/product/{gateway_sn}/{}", kind.suffix())
}

/// The kind of `topic` if it is one of `gateway_sn`'s six topics (exact match).
pub fn parse_topic(gateway_sn: &str, topic: &str) -> Option<TopicKind> {
    let rest = topic
        .strip_prefix("thing/product/")?
        .strip_prefix(gateway_sn)?
        .strip_prefix('/')?;
    TopicKind::ALL.into_iter().find(|k| k.suffix() == rest)
}

/// A parsed inbound message. `services`/`events_reply` carry tid, bid, timestamp and
/// method; `drc/down` messages carry only `method` and `data` (tid/bid empty then).
/// Top-level fields the document does not define are ignored.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope {
    pub tid: String,
    pub bid: String,
    /// Milliseconds since the epoch (0 when absent, as on `drc/down`).
    pub timestamp: u64,
    /// `gateway`, when present.
    pub gateway: Option<String>,
    pub method: String,
    /// `data` (`Value::Null` when absent; `{}` for methods without data).
    pub data: Value,
    /// `need_reply` (events only).
    pub need_reply: Option<u8>,
    /// Top-level `seq`, when present (some DRC senders put it there).
    pub seq: Option<i64>,
}

impl Envelope {
    /// An envelope of `method` with `data` and everything else empty (tests, fake clouds).
    pub fn new(method: &str, data: Value) -> Self {
        Envelope {
            tid: String::new(),
            bid: String::new(),
            timestamp: 0,
            gateway: None,
            method: method.to_owned(),
            data,
            need_reply: None,
            seq: None,
        }
    }
}

/// Why an inbound payload is not an envelope at all (no reply can be addressed:
/// logged and counted by the gateway).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Malformed {
    #[error("payload of {0} bytes exceeds {MAX_PAYLOAD_BYTES}")]
    Oversized(usize),
    #[error("not JSON: {0}")]
    NotJson(String),
    #[error("not a JSON object")]
    NotObject,
    #[error("envelope field `{0}` missing")]
    Missing(&'static str),
    #[error("envelope field `{0}` has the wrong type")]
    WrongType(&'static str),
}

impl Malformed {
    /// A short label for metrics: oversized, not_json, not_object, missing, wrong_type.
    pub fn kind(&self) -> &'static str {
        match self {
            Malformed::Oversized(_) => "oversized",
            Malformed::NotJson(_) => "not_json",
            Malformed::NotObject => "not_object",
            Malformed::Missing(_) => "missing",
            Malformed::WrongType(_) => "wrong_type",
        }
    }
}

/// Parse an inbound payload of topic `kind`. `services` and `events_reply` need `tid`,
/// `bid`, `method` (strings) and `timestamp` (integer); `drc/down` needs `method`.
///
/// The size is checked before any parsing; JSON nesting is bounded by serde_json's
/// recursion limit (128), so hostile nesting is `NotJson`, never a stack overflow.
/// Present fields are type-checked even where optional: `tid`/`bid`/`method`/`gateway`
/// strings, `timestamp` a non-negative integer, `need_reply` 0 or 1, `seq` an integer.
/// The device-bound kinds work too (a fake cloud reading the device's messages):
/// `services_reply`/`events` like `services`, `drc/up` like `drc/down`.
pub fn parse_envelope(kind: TopicKind, payload: &[u8]) -> Result<Envelope, Malformed> {
    if payload.len() > MAX_PAYLOAD_BYTES {
        return Err(Malformed::Oversized(payload.len()));
    }
    let value: Value =
        serde_json::from_slice(payload).map_err(|e| Malformed::NotJson(e.to_string()))?;
    let Value::Object(mut map) = value else {
        return Err(Malformed::NotObject);
    };
    let full = !kind.is_drc();
    let tid = string_field(&map, "tid", full)?;
    let bid = string_field(&map, "bid", full)?;
    let method = string_field(&map, "method", true)?;
    let timestamp = match present(&map, "timestamp") {
        None if full => return Err(Malformed::Missing("timestamp")),
        None => 0,
        Some(v) => v.as_u64().ok_or(Malformed::WrongType("timestamp"))?,
    };
    let gateway = match present(&map, "gateway") {
        None => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(_) => return Err(Malformed::WrongType("gateway")),
    };
    let need_reply = match present(&map, "need_reply").map(Value::as_u64) {
        None => None,
        Some(Some(0)) => Some(0),
        Some(Some(1)) => Some(1),
        Some(_) => return Err(Malformed::WrongType("need_reply")),
    };
    let seq = match present(&map, "seq") {
        None => None,
        Some(v) => Some(v.as_i64().ok_or(Malformed::WrongType("seq"))?),
    };
    let data = map.remove("data").unwrap_or(Value::Null);
    Ok(Envelope {
        tid: tid.unwrap_or_default(),
        bid: bid.unwrap_or_default(),
        timestamp,
        gateway,
        method: method.unwrap_or_default(),
        data,
        need_reply,
        seq,
    })
}

/// The value of `key` unless absent or JSON null.
fn present<'a>(map: &'a Map<String, Value>, key: &str) -> Option<&'a Value> {
    map.get(key).filter(|v| !v.is_null())
}

fn string_field(
    map: &Map<String, Value>,
    key: &'static str,
    required: bool,
) -> Result<Option<String>, Malformed> {
    match present(map, key) {
        None if required => Err(Malformed::Missing(key)),
        None => Ok(None),
        Some(Value::String(s)) => Ok(Some(s.clone())),
        Some(_) => Err(Malformed::WrongType(key)),
    }
}

fn to_bytes(value: &Value) -> Vec<u8> {
    // `Value`'s Display is compact JSON and cannot fail (keys are strings).
    value.to_string().into_bytes()
}

/// `services_reply` for `request`: same tid, bid and method, `gateway`, `timestamp`,
/// `data.result` and, when given, `data.output`.
pub fn encode_services_reply(
    request: &Envelope,
    gateway_sn: &str,
    result: u32,
    output: Option<Value>,
    now_ms: u64,
) -> Vec<u8> {
    let mut data = Map::new();
    data.insert("result".into(), result.into());
    if let Some(output) = output {
        data.insert("output".into(), output);
    }
    to_bytes(&json!({
        "tid": request.tid,
        "bid": request.bid,
        "method": request.method,
        "gateway": gateway_sn,
        "timestamp": now_ms,
        "data": Value::Object(data),
    }))
}

/// An `events` message: fresh `tid`/`bid` given by the caller (UUID text), `gateway`,
/// `timestamp`, `method`, `data`, `need_reply` (0/1).
pub fn encode_event(
    gateway_sn: &str,
    method: &str,
    data: Value,
    need_reply: bool,
    tid: &str,
    bid: &str,
    now_ms: u64,
) -> Vec<u8> {
    to_bytes(&json!({
        "tid": tid,
        "bid": bid,
        "gateway": gateway_sn,
        "timestamp": now_ms,
        "method": method,
        "data": data,
        "need_reply": u8::from(need_reply),
    }))
}

/// A `drc/up` message: `{"method": .., "data": .., "timestamp": now_ms}` (plus top-level
/// `seq` when given).
pub fn encode_drc_up(method: &str, data: Value, seq: Option<i64>, now_ms: u64) -> Vec<u8> {
    let mut m = Map::new();
    m.insert("method".into(), method.into());
    m.insert("data".into(), data);
    m.insert("timestamp".into(), now_ms.into());
    if let Some(seq) = seq {
        m.insert("seq".into(), seq.into());
    }
    to_bytes(&Value::Object(m))
}

// --- the cloud's side (fake clouds in tests; the fuzz target's round trips) ---

/// A `services` message as the cloud sends it: tid, bid, timestamp, method, data.
pub fn encode_service(
    request: &crate::ServiceRequest,
    tid: &str,
    bid: &str,
    now_ms: u64,
) -> Vec<u8> {
    to_bytes(&json!({
        "tid": tid,
        "bid": bid,
        "timestamp": now_ms,
        "method": request.method(),
        "data": request.to_data(),
    }))
}

/// A `drc/down` message as the cloud sends it: `{"method": .., "data": ..}` (seq in data).
pub fn encode_drc_down(message: &crate::DrcDown) -> Vec<u8> {
    to_bytes(&json!({ "method": message.method(), "data": message.to_data() }))
}

/// An `events_reply` as the cloud sends it for an event with `need_reply: 1`.
pub fn encode_event_reply(
    tid: &str,
    bid: &str,
    method: &str,
    result: i64,
    gateway_sn: &str,
    now_ms: u64,
) -> Vec<u8> {
    to_bytes(&json!({
        "tid": tid,
        "bid": bid,
        "method": method,
        "gateway": gateway_sn,
        "timestamp": now_ms,
        "data": { "result": result },
    }))
}
