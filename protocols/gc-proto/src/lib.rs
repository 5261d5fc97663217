//! GroundControl's external interface (`../shared/specs/groundcontrol-external-interface.md`,
//! corrected by `../shared/specs/FACTS.md`): a pure codec, no I/O.
//!
//! Two wire formats, both little-endian and tightly packed:
//!
//! | where | unit | this crate |
//! |---|---|---|
//! | state server, TCP 8000, both directions | one fixed [`RECORD_LEN`]-byte record, no length prefix: `i32 type, i32 context, i32 intParam1, i32 intParam2`, then four f32, two f64 or two i64 — the type says which | [`Record`], [`Params`], [`RecordCodec`] (`tokio_util` `Decoder`/`Encoder`), [`NetCmdType`] |
//! | pose broadcast, UDP 6666 | one datagram per frame holding every drone's [`POSE_RECORD_LEN`]-byte record | [`PoseRecord`], [`encode_pose_datagram`], [`decode_pose_datagram`], [`pose_records`] |
//!
//! Records are fixed size, so a record whose type is unknown or whose values are
//! nonsense is still consumed whole and the stream stays in sync: [`RecordCodec`]
//! never fails on content, only the caller decides what a record means (the
//! groundcontrol-gateway refuses and counts). `CMD_EXT_TEXT` carries up to
//! [`TEXT_MAX_BYTES`] bytes of text in `intParam2` and the two i64: [`pack_text`],
//! [`unpack_text`].
//!
//! | file | content |
//! |---|---|
//! | `types.rs` | [`NetCmdType`]: every id of the spec and FACTS, names, parameter layout |
//! | `record.rs` | [`Record`], [`Params`]: one 32-byte record to and from bytes, constructors for the replies |
//! | `codec.rs` | [`RecordCodec`]: records from any chunking of a byte stream |
//! | `text.rs` | the `CMD_EXT_TEXT` packing |
//! | `pose.rs` | [`PoseRecord`] and whole datagrams |
#![forbid(unsafe_code)]

mod codec;
mod pose;
mod record;
mod text;
mod types;

pub use codec::{RecordCodec, RecordError};
pub use pose::{
    decode_pose_datagram, encode_pose_datagram, pose_records, PoseDatagramError, PoseRecord,
    POSE_FLAGS_MASK, POSE_FLAG_ACTIVE, POSE_FLAG_IDLE, POSE_RECORD_LEN,
};
pub use record::{Params, Record};
pub use text::{pack_text, unpack_text, TextError, TEXT_MAX_BYTES};
pub use types::{NetCmdType, ParamKind};

/// Bytes of one state-server record.
pub const RECORD_LEN: usize = 32;

/// The state server's TCP port.
pub const STATE_SERVER_PORT: u16 = 8000;

/// The pose broadcast's UDP port.
pub const POSE_BROADCAST_PORT: u16 = 6666;
