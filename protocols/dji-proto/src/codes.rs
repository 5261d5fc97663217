//! Result codes (`data.result`). 0 is success. The DRC codes are the document's
//! (FACTS.md); the rest are skymesh's, documented in docs/protocols.md (the DJI code table):
//!
//! | code | name | when |
//! |---|---|---|
//! | 0 | `OK` | success |
//! | 319030 | `NO_FLIGHT_AUTHORITY` (= `FLIGHT_AUTHORITY_REQUIRED`) | no flight control authority (DJI's code; grab it first) |
//! | 319033 | `SEQ_OUT_OF_ORDER` | `drone_control` seq lower than the last accepted one (seq 0 restarts the count) |
//! | 319034 | `STICK_STALE` | the previous stick command went stale: the vehicle braked to hover; reported on the next one |
//! | 319035 | `EMERGENCY_STOP_FAILED` | `drone_emergency_stop` failed |
//! | 314000 | `UNKNOWN_METHOD` | unknown method on this topic |
//! | 314001 | `MISSING_FIELD` | a required field is absent or null |
//! | 314002 | `WRONG_TYPE` | wrong JSON type (an `int` field given 1.5 or 1.0, a string for a number, ...) |
//! | 314003 | `OUT_OF_RANGE` | a number outside the document's min/max (or skymesh's where the document has none), or not finite |
//! | 314004 | `NOT_IN_ENUM` | not one of the documented enum values (or of this method's `camera_type`s) |
//! | 314005 | `BAD_ARRAY_SIZE` | wrong number of items (`points`: exactly 1; storage settings: 1..=4) or a repeated item |
//! | 314006 | `BAD_TEXT` | text empty, longer than 256 bytes, or not of its form (`payload_index` `{int}-{int}-{int}`, broker `host:port`) |
//! | 314010 | `PAYLOAD_AUTHORITY_REQUIRED` | the command needs payload authority the gateway does not hold |
//! | 314011 | `REFUSED_BY_ARBITER` | the arbiter refused the command (higher-priority source, geofence, in-air rule, ...) |
//! | 314012 | `VEHICLE_UNAVAILABLE` | no acknowledgement in time / autopilot link down |
//! | 314013 | `WRONG_STATE` | the vehicle state does not allow it (not flying for POI, no position fix, ...) |
//! | 314014 | `PAYLOAD_UNSUPPORTED` | the aircraft's payload cannot do this |
//! | 314015 | `UNKNOWN_PAYLOAD` | `payload_index` names no payload of this aircraft |
//! | 314016 | `DRC_STATE` | DRC mode required (`drc_mode_enter` first) or already in the requested state |
//! | 314017 | `DRC_BROKER_UNREACHABLE` | the broker named in `drc_mode_enter` cannot be reached |
//! | 314018 | `NO_TASK` | no flyto / takeoff task to stop or update |
//! | 314030 | `DRC_HEARTBEAT_TIMEOUT` | DRC mode left: no `heart_beat` for `heartbeat_timeout_s` (in `drc_status_notify`) |
//! | 314099 | `INTERNAL` | internal error (bus unavailable); logged |
//!
//! Payloads that are not an envelope at all (not JSON, over 64 KiB, missing or
//! mistyped `tid`/`bid`/`method`/`timestamp`) get no reply: nothing to address it to.
//! They are dropped and counted by reason ([`crate::Malformed::kind`]).

/// Success.
pub const OK: u32 = 0;

// --- DRC (FACTS.md) ---
/// No flight control authority.
pub const NO_FLIGHT_AUTHORITY: u32 = 319030;
/// `seq` lower than the last accepted one (seq 0 restarts the count).
pub const SEQ_OUT_OF_ORDER: u32 = 319033;
/// The previous stick command went stale (longer than the freshness limit): the
/// vehicle braked to hover; this command is reported with this code.
pub const STICK_STALE: u32 = 319034;
/// Emergency stop failed.
pub const EMERGENCY_STOP_FAILED: u32 = 319035;

// --- request validation (skymesh) ---
/// Unknown method on this topic.
pub const UNKNOWN_METHOD: u32 = 314000;
/// A required field is missing.
pub const MISSING_FIELD: u32 = 314001;
/// A field has the wrong JSON type.
pub const WRONG_TYPE: u32 = 314002;
/// A number is outside the documented range, or not finite.
pub const OUT_OF_RANGE: u32 = 314003;
/// A value is not one of the documented enum values.
pub const NOT_IN_ENUM: u32 = 314004;
/// An array has the wrong number of items (e.g. `points` must hold exactly one), or
/// repeats an item that must be unique (storage settings).
pub const BAD_ARRAY_SIZE: u32 = 314005;
/// A text field is empty, longer than [`MAX_TEXT_LEN`], or not of its documented form
/// (`payload_index` `{type}-{subtype}-{gimbalindex}`, broker address `host:port`).
pub const BAD_TEXT: u32 = 314006;

/// Longest accepted text field (ids, payload_index, broker address...), bytes.
pub const MAX_TEXT_LEN: usize = 256;

/// Longest accepted `mqtt_broker.password`, bytes: the document's example is a JWT,
/// which routinely exceeds [`MAX_TEXT_LEN`].
pub const MAX_SECRET_LEN: usize = 4096;

// --- execution (skymesh) ---
/// The command needs flight authority the gateway does not hold (grab it first).
pub const FLIGHT_AUTHORITY_REQUIRED: u32 = NO_FLIGHT_AUTHORITY;
/// The command needs payload authority the gateway does not hold.
pub const PAYLOAD_AUTHORITY_REQUIRED: u32 = 314010;
/// The arbiter refused the command (higher-priority source, geofence, in-air rule...).
pub const REFUSED_BY_ARBITER: u32 = 314011;
/// The vehicle did not acknowledge in time / the autopilot link is down.
pub const VEHICLE_UNAVAILABLE: u32 = 314012;
/// The vehicle state does not allow it (not flying for POI, no position fix, ...).
pub const WRONG_STATE: u32 = 314013;
/// The aircraft's payload cannot do this (no such camera/lens, no MAVLink equivalent).
pub const PAYLOAD_UNSUPPORTED: u32 = 314014;
/// `payload_index` names no payload of this aircraft.
pub const UNKNOWN_PAYLOAD: u32 = 314015;
/// DRC mode is required (drc_mode_enter first) or already in the requested state.
pub const DRC_STATE: u32 = 314016;
/// Could not reach the DRC broker named in `drc_mode_enter`.
pub const DRC_BROKER_UNREACHABLE: u32 = 314017;
/// No flyto / takeoff task to stop or update.
pub const NO_TASK: u32 = 314018;
/// DRC mode was left because no `heart_beat` arrived within the configured timeout
/// (the `result` of that `drc_status_notify` with `drc_state` 0).
pub const DRC_HEARTBEAT_TIMEOUT: u32 = 314030;
/// Internal error (bus unavailable); logged.
pub const INTERNAL: u32 = 314099;
