//! One state-server record: [`Record`] with its parameter union [`Params`], to and
//! from exactly [`RECORD_LEN`] bytes.
//!
//! | offset | field |
//! |---|---|
//! | 0 | `i32 type` |
//! | 4 | `i32 context` (one drone id) |
//! | 8 | `i32 intParam1` |
//! | 12 | `i32 intParam2` |
//! | 16 | `f32[4]`, `f64[2]` or `i64[2]`, by type ([`NetCmdType::param_kind`]) |

use crate::types::{NetCmdType, ParamKind};
use crate::RECORD_LEN;

/// The record's last 16 bytes, as the union member its type names.
///
/// Bit patterns survive decoding and encoding unchanged (a NaN stays the same NaN),
/// so a record can be forwarded or re-encoded byte for byte.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Params {
    Floats([f32; 4]),
    Doubles([f64; 2]),
    Longs([i64; 2]),
}

impl Default for Params {
    fn default() -> Self {
        Params::Floats([0.0; 4])
    }
}

impl Params {
    /// Reads 16 bytes as the member `kind`.
    pub fn from_bytes(kind: ParamKind, b: &[u8; 16]) -> Params {
        let w4 = |i: usize| [b[i], b[i + 1], b[i + 2], b[i + 3]];
        let w8 = |i: usize| {
            [
                b[i],
                b[i + 1],
                b[i + 2],
                b[i + 3],
                b[i + 4],
                b[i + 5],
                b[i + 6],
                b[i + 7],
            ]
        };
        match kind {
            ParamKind::Floats => Params::Floats([
                f32::from_le_bytes(w4(0)),
                f32::from_le_bytes(w4(4)),
                f32::from_le_bytes(w4(8)),
                f32::from_le_bytes(w4(12)),
            ]),
            ParamKind::Doubles => {
                Params::Doubles([f64::from_le_bytes(w8(0)), f64::from_le_bytes(w8(8))])
            }
            ParamKind::Longs => {
                Params::Longs([i64::from_le_bytes(w8(0)), i64::from_le_bytes(w8(8))])
            }
        }
    }

    /// The 16 bytes on the wire.
    pub fn to_bytes(&self) -> [u8; 16] {
        let mut out = [0u8; 16];
        match self {
            Params::Floats(f) => {
                for (chunk, v) in out.chunks_exact_mut(4).zip(f) {
                    chunk.copy_from_slice(&v.to_le_bytes());
                }
            }
            Params::Doubles(d) => {
                for (chunk, v) in out.chunks_exact_mut(8).zip(d) {
                    chunk.copy_from_slice(&v.to_le_bytes());
                }
            }
            Params::Longs(l) => {
                for (chunk, v) in out.chunks_exact_mut(8).zip(l) {
                    chunk.copy_from_slice(&v.to_le_bytes());
                }
            }
        }
        out
    }

    /// Which member this is.
    pub fn kind(&self) -> ParamKind {
        match self {
            Params::Floats(_) => ParamKind::Floats,
            Params::Doubles(_) => ParamKind::Doubles,
            Params::Longs(_) => ParamKind::Longs,
        }
    }

    /// The same 16 bytes read as four f32, whatever the member.
    pub fn as_floats(&self) -> [f32; 4] {
        match Params::from_bytes(ParamKind::Floats, &self.to_bytes()) {
            Params::Floats(f) => f,
            _ => unreachable!("from_bytes(Floats) is Floats"),
        }
    }

    /// The same 16 bytes read as two f64, whatever the member.
    pub fn as_doubles(&self) -> [f64; 2] {
        match Params::from_bytes(ParamKind::Doubles, &self.to_bytes()) {
            Params::Doubles(d) => d,
            _ => unreachable!("from_bytes(Doubles) is Doubles"),
        }
    }

    /// The same 16 bytes read as two i64, whatever the member.
    pub fn as_longs(&self) -> [i64; 2] {
        match Params::from_bytes(ParamKind::Longs, &self.to_bytes()) {
            Params::Longs(l) => l,
            _ => unreachable!("from_bytes(Longs) is Longs"),
        }
    }
}

/// One 32-byte record. `kind` is the raw type id: unknown ids are carried as they
/// are (their parameters read as floats) so the caller can count and refuse them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Record {
    /// `NetCmdType` id, possibly unknown ([`Record::net_type`]).
    pub kind: i32,
    /// The drone id the record is about.
    pub context: i32,
    pub int1: i32,
    pub int2: i32,
    pub params: Params,
}

impl Record {
    /// A record of type `t` with the parameter member its type uses, zeroed.
    pub fn new(t: NetCmdType, context: i32) -> Record {
        let params = Params::from_bytes(t.param_kind(), &[0; 16]);
        Record {
            kind: t.id(),
            context,
            int1: 0,
            int2: 0,
            params,
        }
    }

    /// A float record (every command but TEXT, `EXT_PARAM_1`/`_2`).
    pub fn floats(t: NetCmdType, context: i32, int1: i32, int2: i32, f: [f32; 4]) -> Record {
        Record {
            kind: t.id(),
            context,
            int1,
            int2,
            params: Params::Floats(f),
        }
    }

    /// `PING_REQUEST` with sequence `seq`; the reference client sends its last and
    /// maximum round-trip time (µs) in the doubles.
    pub fn ping_request(seq: i32, last_us: f64, max_us: f64) -> Record {
        Record {
            kind: NetCmdType::PingRequest.id(),
            context: 0,
            int1: seq,
            int2: 0,
            params: Params::Doubles([last_us, max_us]),
        }
    }

    /// The `PING_RESPONSE` to `request`: its context, integers and doubles echoed.
    pub fn ping_response(request: &Record) -> Record {
        Record {
            kind: NetCmdType::PingResponse.id(),
            params: Params::Doubles(request.params.as_doubles()),
            ..*request
        }
    }

    /// `ACK_CMD_SUCCESS` (or `ACK_CMD_TIMEOUT` when `success` is false): context =
    /// drone, intParam1 = the acknowledged command type.
    pub fn ack(success: bool, drone: i32, acknowledged: i32) -> Record {
        let t = if success {
            NetCmdType::AckCmdSuccess
        } else {
            NetCmdType::AckCmdTimeout
        };
        Record {
            int1: acknowledged,
            ..Record::new(t, drone)
        }
    }

    /// One answer to `CMD_EXT_CHECK_ALL_IDLE`: a record of that type with context =
    /// drone and intParam1 = 1 idle / 0 busy (what the reference client reads).
    pub fn idle_state(drone: i32, idle: bool) -> Record {
        Record {
            int1: i32::from(idle),
            ..Record::new(NetCmdType::CmdExtCheckAllIdle, drone)
        }
    }

    /// The type, if the protocol has it.
    pub fn net_type(&self) -> Option<NetCmdType> {
        NetCmdType::from_i32(self.kind)
    }

    /// The record's floats (the parameter bytes read as four f32).
    pub fn float_params(&self) -> [f32; 4] {
        self.params.as_floats()
    }

    /// Reads one record from exactly [`RECORD_LEN`] bytes. Never fails: every bit
    /// pattern is a record (unknown type ids included).
    pub fn decode(b: &[u8; RECORD_LEN]) -> Record {
        let i = |o: usize| i32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        let kind = i(0);
        let mut params = [0u8; 16];
        params.copy_from_slice(&b[16..32]);
        Record {
            kind,
            context: i(4),
            int1: i(8),
            int2: i(12),
            params: Params::from_bytes(NetCmdType::param_kind_of(kind), &params),
        }
    }

    /// The first record of `bytes`, if it holds one whole.
    pub fn from_prefix(bytes: &[u8]) -> Option<Record> {
        bytes.first_chunk::<RECORD_LEN>().map(Record::decode)
    }

    /// The record's [`RECORD_LEN`] bytes. The parameter member is written as it is,
    /// even if it is not the one the type uses.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut out = [0u8; RECORD_LEN];
        out[0..4].copy_from_slice(&self.kind.to_le_bytes());
        out[4..8].copy_from_slice(&self.context.to_le_bytes());
        out[8..12].copy_from_slice(&self.int1.to_le_bytes());
        out[12..16].copy_from_slice(&self.int2.to_le_bytes());
        out[16..32].copy_from_slice(&self.params.to_bytes());
        out
    }
}

impl std::fmt::Display for Record {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.net_type() {
            Some(t) => write!(f, "{t}")?,
            None => write!(f, "type {:#x}", self.kind)?,
        }
        write!(
            f,
            " context={} int1={} int2={}",
            self.context, self.int1, self.int2
        )?;
        match self.params {
            Params::Floats(v) => write!(f, " f={v:?}"),
            Params::Doubles(v) => write!(f, " d={v:?}"),
            Params::Longs(v) => write!(f, " l={v:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_member_follows_the_type() {
        let mut b = [0u8; RECORD_LEN];
        b[16..24].copy_from_slice(&1.5f64.to_le_bytes());
        assert_eq!(Record::decode(&b).params, Params::Doubles([1.5, 0.0]));
        b[0] = 0xB3;
        assert_eq!(
            Record::decode(&b).params,
            Params::Longs([1.5f64.to_bits() as i64, 0])
        );
        b[0] = 0xA6;
        assert!(matches!(Record::decode(&b).params, Params::Floats(_)));
    }

    #[test]
    fn reinterpretation_keeps_bits() {
        let p = Params::Longs([-1, 0x3F80_0000]);
        let f = p.as_floats();
        assert!(f[0].is_nan());
        assert_eq!(f[2], 1.0);
        assert_eq!(Params::Floats(f).to_bytes(), p.to_bytes());
        assert_eq!(Params::Floats(f).as_longs(), [-1, 0x3F80_0000]);
    }

    #[test]
    fn replies() {
        let req = Record::ping_request(41, 120.5, 900.0);
        let resp = Record::ping_response(&req);
        assert_eq!(resp.net_type(), Some(NetCmdType::PingResponse));
        assert_eq!(resp.int1, 41);
        assert_eq!(resp.params, Params::Doubles([120.5, 900.0]));
        let ack = Record::ack(false, 3, 0xA6);
        assert_eq!((ack.kind, ack.context, ack.int1), (0x05, 3, 0xA6));
        let idle = Record::idle_state(7, true);
        assert_eq!((idle.kind, idle.context, idle.int1), (0xAC, 7, 1));
        assert!(Record::from_prefix(&[0; 31]).is_none());
    }
}
