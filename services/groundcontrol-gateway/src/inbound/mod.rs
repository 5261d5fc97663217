//! What to do with one record from a client (pure: no I/O, no clock).
//!
//! [`Inbound`] is one connection's state: who it is, whether it is privileged, and
//! the `EXT_PARAM_1`/`EXT_PARAM_2` records waiting for their command. Each record
//! gets a [`Verdict`]:
//!
//! | record | verdict |
//! |---|---|
//! | `PING_REQUEST` | [`Verdict::Reply`] `PING_RESPONSE` echoing context, intParam1/2 and the doubles |
//! | `EXT_PARAM_1`, `EXT_PARAM_2` | [`Verdict::Stored`] for the next command of the same context |
//! | `EXT_PARAM_ACK` | [`Verdict::Ignored`] (see below) |
//! | a command (`CMD_*`, `CMD_EXT_*`) | [`Verdict::Publish`] one `SwarmCommand`, or [`Verdict::Refused`] |
//! | a server-to-client type, `DATA_BLOB`, `CLIENT_INFO`, an unknown id | [`Verdict::Refused`] |
//!
//! Decisions taken from the reference client (the public Unity project), where the
//! spec is silent:
//!
//! - **Parameter records** apply to the next command *for the same context* and are
//!   then cleared, needed or not. The reference client's `CmdExtColor` sends its
//!   `EXT_PARAM_1` with a drone *bitmask* as context and the command with the drone
//!   id, so when a command finds no parameters of its own and the records right
//!   before it were parameters of one other context, those are used (and cleared).
//!   Any client (privileged or not) may send parameter records: the command that
//!   uses them is what privilege is checked on.
//! - **`EXT_PARAM_ACK`** (intParam1 bit 0 "ack wanted", bit 1 "override", i64
//!   retries and retry period in ms) asks GroundControl to retransmit a command to
//!   the drone over its radio until acknowledged. skymesh's bus does not lose
//!   commands and the swarm queue reports every command that finishes
//!   (`ACK_CMD_SUCCESS`/`ACK_CMD_TIMEOUT`) whether asked or not, so the record is
//!   accepted, counted and has no further effect; no record answers it.
//! - **Global commands**: `CMD_EXT_CHECK_ALL_IDLE` (the client sends context 0 and
//!   expects one answer per drone), `CMD_EXT_SET_BOUNDING_BOX`, `CMD_EXT_TIMECODE`
//!   and `CMD_EXT_TIMECODE_ACTIVE` (sent without a context) go to
//!   [`ALL_DRONES`]. Every other command names one drone: contexts outside
//!   `0..65535` are refused (`bad_context`); the client never uses −1 or a bitmask
//!   for "all", it loops over the ids. Ids that are no drone are refused by the
//!   queue.
//! - **No record answers a refusal**: the protocol has none. Refusals are logged
//!   and counted by [`RefuseReason`]. Except the geofence commands: a refused one
//!   is answered `ACK_CMD_TIMEOUT` ([`refusal_reply`]), as the hub answers the
//!   queue's refusal of one, so a client never believes a fence is in force that
//!   is not.

use std::collections::HashMap;

use gc_proto::{unpack_text, NetCmdType, ParamKind, Record};
use skymesh_ipc_types::{
    swarm_flags, FixedStr, SwarmCommand, SwarmCommandError, SwarmCommandKind, ALL_DRONES,
};

/// Most contexts with parameter records waiting in one connection; a parameter
/// record for yet another context is refused (`too_many_pending`).
pub const MAX_PENDING_CONTEXTS: usize = 512;

/// Why a record was refused (label `reason` of `skymesh_gc_refused_total`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RefuseReason {
    /// A command other than `CMD_EXT_*` (or `DATA_BLOB`, `CLIENT_INFO`) from a
    /// client not on the privileged list.
    NotPrivileged,
    /// A type id the protocol does not have.
    UnknownType,
    /// NaN, ∞, out of range, text that is not UTF-8.
    InvalidValue,
    /// A command that needs `EXT_PARAM_1`/`_2` came without them.
    MissingExtParam,
    /// A context that is no drone id (negative, or 65535 and above).
    BadContext,
    /// A type only the server sends (`PING_RESPONSE`, `ACK_*`, `SERVER_INFO`).
    WrongDirection,
    /// A privileged client's `DATA_BLOB` or `CLIENT_INFO`: the spec defines no content.
    Unsupported,
    /// Parameter records for more than [`MAX_PENDING_CONTEXTS`] contexts.
    TooManyPending,
    /// Beyond the client's `max_records_per_s`/`record_burst` (decided by the
    /// session, before this module sees the record).
    RateLimited,
    /// A command while no swarm queue read the bus for `backend_wait_ms`
    /// (decided by the session, which answers ACK_CMD_TIMEOUT).
    BackendMissing,
}

impl RefuseReason {
    pub const ALL: [RefuseReason; 10] = [
        RefuseReason::NotPrivileged,
        RefuseReason::UnknownType,
        RefuseReason::InvalidValue,
        RefuseReason::MissingExtParam,
        RefuseReason::BadContext,
        RefuseReason::WrongDirection,
        RefuseReason::Unsupported,
        RefuseReason::TooManyPending,
        RefuseReason::RateLimited,
        RefuseReason::BackendMissing,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            RefuseReason::NotPrivileged => "not_privileged",
            RefuseReason::UnknownType => "unknown_type",
            RefuseReason::InvalidValue => "invalid_value",
            RefuseReason::MissingExtParam => "missing_ext_param",
            RefuseReason::BadContext => "bad_context",
            RefuseReason::WrongDirection => "wrong_direction",
            RefuseReason::Unsupported => "unsupported",
            RefuseReason::TooManyPending => "too_many_pending",
            RefuseReason::RateLimited => "rate_limited",
            RefuseReason::BackendMissing => "backend_missing",
        }
    }
}

/// A refused record: the counted reason, a line for the log, and the record that
/// answers it, if the protocol has one ([`refusal_reply`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub reason: RefuseReason,
    pub detail: String,
    pub reply: Option<Record>,
}

/// The answer to a refused record: `ACK_CMD_TIMEOUT` (the protocol's one failure
/// record) for a geofence command, echoing its context and type; nothing for any
/// other record.
pub fn refusal_reply(r: &Record) -> Option<Record> {
    matches!(
        r.net_type(),
        Some(
            NetCmdType::CmdSetGeofence
                | NetCmdType::CmdSetGeofencePosition
                | NetCmdType::CmdReconfigureGeofence
        )
    )
    .then(|| Record::ack(false, r.context, r.kind))
}

/// What to do with one record.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Write this record back to the client.
    Reply(Record),
    /// Publish this command (`request_id` still 0: the session numbers it).
    Publish(Box<SwarmCommand>),
    /// A parameter record, kept for the next command.
    Stored,
    /// Accepted without effect (`EXT_PARAM_ACK`).
    Ignored,
    Refused(Refusal),
}

fn refused(reason: RefuseReason, detail: impl Into<String>) -> Verdict {
    Verdict::Refused(Refusal {
        reason,
        detail: detail.into(),
        reply: None,
    })
}

/// Parameter records waiting for one context's next command.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Pending {
    ext1: Option<[f32; 4]>,
    ext2: Option<[f32; 4]>,
}

/// Commands that concern the whole swarm, whatever their context.
pub fn is_global(kind: SwarmCommandKind) -> bool {
    matches!(
        kind,
        SwarmCommandKind::ExtCheckAllIdle
            | SwarmCommandKind::ExtSetBoundingBox
            | SwarmCommandKind::ExtTimecode
            | SwarmCommandKind::ExtTimecodeActive
    )
}

/// One connection's view of its input.
#[derive(Debug)]
pub struct Inbound {
    client: u16,
    privileged: bool,
    pending: HashMap<i32, Pending>,
    /// The context of the parameter records immediately before the current record
    /// (`None` once anything else came).
    last_param_context: Option<i32>,
}

impl Inbound {
    pub fn new(client: u16, privileged: bool) -> Inbound {
        Inbound {
            client,
            privileged,
            pending: HashMap::new(),
            last_param_context: None,
        }
    }

    pub fn privileged(&self) -> bool {
        self.privileged
    }

    /// Contexts with parameter records waiting.
    pub fn pending_contexts(&self) -> usize {
        self.pending.len()
    }

    /// Decides about one record.
    pub fn on_record(&mut self, r: &Record) -> Verdict {
        let Some(t) = r.net_type() else {
            self.last_param_context = None;
            return refused(
                RefuseReason::UnknownType,
                format!("type {:#x} is not a GroundControl record type", r.kind),
            );
        };
        match t {
            NetCmdType::PingRequest => Verdict::Reply(Record::ping_response(r)),
            NetCmdType::ExtParam1 | NetCmdType::ExtParam2 => self.store_param(t, r),
            NetCmdType::ExtParamAck => Verdict::Ignored,
            t if t.is_server_to_client() => {
                self.last_param_context = None;
                refused(
                    RefuseReason::WrongDirection,
                    format!("{t} is sent by the server, not by clients"),
                )
            }
            t if t.is_command() => {
                let mut verdict = self.command(t, r);
                self.last_param_context = None;
                if let Verdict::Refused(refusal) = &mut verdict {
                    refusal.reply = refusal_reply(r);
                }
                verdict
            }
            // DATA_BLOB, CLIENT_INFO.
            t => {
                self.last_param_context = None;
                if self.privileged {
                    refused(
                        RefuseReason::Unsupported,
                        format!("{t} has no content defined by the interface"),
                    )
                } else {
                    refused(
                        RefuseReason::NotPrivileged,
                        format!("{t} needs a privileged client"),
                    )
                }
            }
        }
    }

    fn store_param(&mut self, t: NetCmdType, r: &Record) -> Verdict {
        if !self.pending.contains_key(&r.context) && self.pending.len() >= MAX_PENDING_CONTEXTS {
            return refused(
                RefuseReason::TooManyPending,
                format!(
                    "{t} for context {}: parameters for {MAX_PENDING_CONTEXTS} contexts are already waiting",
                    r.context
                ),
            );
        }
        let slot = self.pending.entry(r.context).or_default();
        let floats = r.float_params();
        if t == NetCmdType::ExtParam1 {
            slot.ext1 = Some(floats);
        } else {
            slot.ext2 = Some(floats);
        }
        self.last_param_context = Some(r.context);
        Verdict::Stored
    }

    /// The parameters for a command of `context`: its own, else those sent right
    /// before it for another context (the reference client's bitmask contexts).
    fn take_params(&mut self, context: i32) -> Pending {
        if let Some(p) = self.pending.remove(&context) {
            return p;
        }
        match self.last_param_context {
            Some(c) if c != context => self.pending.remove(&c).unwrap_or_default(),
            _ => Pending::default(),
        }
    }

    fn command(&mut self, t: NetCmdType, r: &Record) -> Verdict {
        let params = self.take_params(r.context);
        if !self.privileged && !t.is_ext_command() {
            return refused(
                RefuseReason::NotPrivileged,
                format!("{t} for drone {} needs a privileged client", r.context),
            );
        }
        let kind = match u8::try_from(t.id())
            .ok()
            .and_then(|k| SwarmCommandKind::try_from(k).ok())
        {
            Some(k) => k,
            None => {
                return refused(
                    RefuseReason::UnknownType,
                    format!("{t} has no swarm command"),
                )
            }
        };
        let drone = if is_global(kind) {
            ALL_DRONES
        } else {
            match u16::try_from(r.context) {
                Ok(d) if d != ALL_DRONES => d,
                _ => {
                    return refused(
                        RefuseReason::BadContext,
                        format!("{t}: context {} is not a drone id", r.context),
                    )
                }
            }
        };
        let mut cmd = SwarmCommand {
            client: self.client,
            drone,
            kind: kind.to_wire(),
            int1: r.int1,
            int2: r.int2,
            ..SwarmCommand::default()
        };
        if self.privileged {
            cmd.flags |= swarm_flags::PRIVILEGED;
        }
        match t.param_kind() {
            ParamKind::Floats => cmd.f[0..4].copy_from_slice(&r.float_params()),
            ParamKind::Longs => {
                let l = r.params.as_longs();
                cmd.d = [l[0] as u64, l[1] as u64];
            }
            ParamKind::Doubles => {
                let d = r.params.as_doubles();
                cmd.d = [d[0].to_bits(), d[1].to_bits()];
            }
        }
        if let Some(p) = params.ext1 {
            cmd.f[4..8].copy_from_slice(&p);
            cmd.flags |= swarm_flags::HAS_EXT1;
        }
        if let Some(p) = params.ext2 {
            cmd.f[8..12].copy_from_slice(&p);
            cmd.flags |= swarm_flags::HAS_EXT2;
        }
        if kind == SwarmCommandKind::ExtText {
            match unpack_text(r.int2, r.params.as_longs()) {
                Ok(text) => cmd.text = FixedStr::new(&text),
                Err(e) => {
                    return refused(
                        RefuseReason::InvalidValue,
                        format!("{t} for drone {drone}: {e}"),
                    )
                }
            }
        }
        if let Some(why) = non_finite(t, &cmd) {
            return refused(
                RefuseReason::InvalidValue,
                format!("{t} for drone {}: {why}", r.context),
            );
        }
        match cmd.validate() {
            Ok(()) => Verdict::Publish(Box::new(cmd)),
            Err(e) => {
                let reason = match e {
                    SwarmCommandError::MissingExtParam { .. } => RefuseReason::MissingExtParam,
                    SwarmCommandError::UnknownKind(_) => RefuseReason::UnknownType,
                    SwarmCommandError::OutOfRange { .. } | SwarmCommandError::BadText { .. } => {
                        RefuseReason::InvalidValue
                    }
                };
                refused(reason, format!("drone {}: {e}", r.context))
            }
        }
    }
}

/// The first NaN/±∞ among the numbers a command carries to the bus, whether or not
/// its kind gives them a meaning (`validate` range-checks the meaningful ones; the
/// others must still never reach a consumer as NaN/∞).
fn non_finite(t: NetCmdType, cmd: &SwarmCommand) -> Option<String> {
    if let Some((i, v)) = cmd.f.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Some(format!("float parameter {i} is {v}"));
    }
    if t.param_kind() == ParamKind::Doubles {
        for (i, bits) in cmd.d.iter().enumerate() {
            let v = f64::from_bits(*bits);
            if !v.is_finite() {
                return Some(format!("double parameter {i} is {v}"));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests;
