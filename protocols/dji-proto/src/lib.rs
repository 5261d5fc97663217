//! DJI Cloud API live flight controls, device side (`../shared/specs/dji-cloud-live-flight-controls.md`
//! with `specs/FACTS.md`): a pure codec, no I/O.
//!
//! skymesh plays the dock/gateway with serial number `gateway_sn`. The cloud
//! publishes on `services`, `events_reply` and `drc/down`; the device publishes on
//! `services_reply`, `events` and `drc/up` ([`topic`]).
//!
//! Inbound: [`parse_envelope`] (bytes → [`Envelope`], or [`Malformed`]: not JSON,
//! oversized, missing/mistyped envelope fields), then [`parse_service`] /
//! [`parse_drc`] / [`parse_event_reply`] (envelope → typed, checked request, or a
//! [`Reject`] carrying the documented non-zero result code of [`codes`]).
//! Every field is checked against the document's constraint column: JSON type,
//! range, enum membership, required fields, array sizes, finite numbers.
//!
//! Outbound: [`encode_services_reply`], [`encode_event`], [`encode_drc_up`] build the
//! exact JSON the document shows (compact). The events' and pushes' `data` are the
//! serde structs of this crate (`serde_json::to_value`).
//!
//! The cloud's side, for fake clouds in tests and the fuzz target's round trips:
//! [`ServiceRequest::to_data`], [`DrcDown::to_data`], [`encode_service`],
//! [`encode_drc_down`], [`encode_event_reply`]; `parse_service(to_data(r)) == r`.
//!
//! Check conventions: fields in the document's table order (the first violation is
//! the one reported); a JSON `null` counts as absent; fields the document does not
//! define are ignored (forward compatibility: a newer cloud may send more); `int`
//! fields take integer JSON numbers only, `double`/`float` fields any finite number.
#![forbid(unsafe_code)]

mod check;
pub mod codes;
mod drc;
mod envelope;
mod events;
mod request_json;
mod requests;
mod services;

pub use envelope::{
    encode_drc_down, encode_drc_up, encode_event, encode_event_reply, encode_service,
    encode_services_reply, parse_envelope, parse_topic, topic, Envelope, Malformed, TopicKind,
    MAX_PAYLOAD_BYTES,
};
pub use events::*;
pub use requests::*;

/// A request the device refuses: the non-zero `result` of the reply, and why (for logs
/// and `output.reason`-free replies; the code alone goes on the wire).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("result {code}: {field}: {reason}")]
pub struct Reject {
    /// One of [`codes`]; never 0.
    pub code: u32,
    /// The offending field path (`data.points[0].latitude`), or the method name.
    pub field: String,
    /// Human-readable reason: "required", "expected number", "above max 17", ...
    pub reason: String,
}

impl Reject {
    /// A refusal with `code` (one of [`codes`]) for `field`.
    pub fn new(code: u32, field: impl Into<String>, reason: impl Into<String>) -> Self {
        check::reject(code, field, reason)
    }
}
