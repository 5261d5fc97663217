//! MAVLink 2 message signing (<https://mavlink.io/en/guide/message_signing.html>),
//! as pure functions over frame bytes and timestamps.
//!
//! A signed frame carries, after its checksum, a link id, a 48-bit timestamp (10 µs
//! units since 2015-01-01 00:00 UTC) and the first 6 bytes of SHA-256 over
//! `key ‖ STX ‖ header ‖ payload ‖ CRC ‖ link id ‖ timestamp`. A receiver accepts
//! a frame whose signature matches the shared 32-byte key and whose timestamp is
//! newer than the last one accepted from the same (system, component, link id)
//! stream ([`Streams`]); a stream's first frame must not be more than
//! [`MAX_STREAM_LAG`] older than the receiver's clock ([`Clock`]). Everything else
//! is refused ([`Refusal`]).
//!
//! [`Clock`] is the sender's and receiver's time: never behind the system clock,
//! moved forward to every timestamp accepted (as the spec says, so a companion
//! computer without a real-time clock still works with a ground station that has
//! one) and strictly increasing over the timestamps signed.
//!
//! [`sign`] signs an unsigned MAVLink 2 frame. Setting the "signed"
//! incompatibility flag changes the checksum input; the new CRC is derived from
//! the old one ([`crc_with_signed_flag`]), which works for every message id,
//! including ids the dialect does not know. MAVLink 1 frames cannot be signed.

use std::collections::HashMap;
use std::fmt;
use std::sync::{Mutex, MutexGuard, PoisonError};

use sha2::{Digest, Sha256};

use crate::raw::{RawFrame, IFLAG_SIGNED, MAX_FRAME, STX_V1, STX_V2, V2_HEADER};

pub use crate::raw::SIGNATURE_LEN;

/// Length of a signing key.
pub const KEY_LEN: usize = 32;
/// A new stream's first timestamp may lag our clock by this much (1 minute in 10 µs).
pub const MAX_STREAM_LAG: u64 = 60 * 100_000;
/// Streams remembered; beyond this the stalest is forgotten.
pub const MAX_STREAMS: usize = 1024;
const TIMESTAMP_MASK: u64 = (1 << 48) - 1;
/// 2015-01-01 00:00:00 UTC in Unix seconds.
const EPOCH_2015: u64 = 1_420_070_400;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The shared secret. Its `Debug` never shows the bytes.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; KEY_LEN]);

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("SigningKey(<redacted>)")
    }
}

/// Why a key was refused. Never contains key material.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// The key file could not be read (the caller reads it).
    #[error("cannot read the key file {path}: {reason}")]
    Read { path: String, reason: String },
    #[error("must hold the 32-byte key as 64 hex digits; found {found} characters")]
    Length { found: usize },
    #[error(
        "must hold the 32-byte key as 64 hex digits; found a character that is not a hex digit"
    )]
    NotHex,
    #[error("an all-zero key is not a secret")]
    AllZero,
}

impl SigningKey {
    /// A key from its bytes.
    pub fn new(bytes: [u8; KEY_LEN]) -> SigningKey {
        SigningKey(bytes)
    }

    /// 64 hex digits (either case), surrounding whitespace ignored.
    pub fn from_hex(text: &str) -> Result<SigningKey, KeyError> {
        let text = text.trim();
        let digits = text.as_bytes();
        if digits.len() != 2 * KEY_LEN {
            return Err(KeyError::Length {
                found: text.chars().count(),
            });
        }
        let nibble = |c: u8| -> Result<u8, KeyError> {
            match c {
                b'0'..=b'9' => Ok(c - b'0'),
                b'a'..=b'f' => Ok(c - b'a' + 10),
                b'A'..=b'F' => Ok(c - b'A' + 10),
                _ => Err(KeyError::NotHex),
            }
        };
        let mut key = [0u8; KEY_LEN];
        for (i, pair) in digits.chunks_exact(2).enumerate() {
            key[i] = nibble(pair[0])? << 4 | nibble(pair[1])?;
        }
        if key == [0u8; KEY_LEN] {
            return Err(KeyError::AllZero);
        }
        Ok(SigningKey(key))
    }
}

/// `t` as a MAVLink signing timestamp: 10 µs units since 2015-01-01 UTC, 48 bits
/// (0 for a clock before 2015).
pub fn timestamp_at(t: std::time::SystemTime) -> u64 {
    let micros = t
        .duration_since(std::time::SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros());
    let since = micros.saturating_sub(u128::from(EPOCH_2015) * 1_000_000) / 10;
    (since as u64) & TIMESTAMP_MASK
}

/// Why a frame from a signing endpoint was refused (metric label `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// A MAVLink 2 frame without a signature.
    Unsigned,
    /// MAVLink 1 cannot be signed.
    MavLink1,
    /// The signature does not match the key (or the bytes are not a signed frame).
    BadSignature,
    /// The timestamp is not newer than the last one accepted from its stream.
    Replayed,
    /// A new stream whose timestamp is more than a minute older than our clock.
    StaleTimestamp,
}

impl Refusal {
    pub const ALL: [Refusal; 5] = [
        Refusal::Unsigned,
        Refusal::MavLink1,
        Refusal::BadSignature,
        Refusal::Replayed,
        Refusal::StaleTimestamp,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Refusal::Unsigned => "unsigned",
            Refusal::MavLink1 => "mavlink1",
            Refusal::BadSignature => "bad_signature",
            Refusal::Replayed => "replayed",
            Refusal::StaleTimestamp => "stale_timestamp",
        }
    }
}

/// The parts of a signed MAVLink 2 frame the check needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Signed {
    pub system: u8,
    pub component: u8,
    pub link_id: u8,
    pub timestamp: u64,
}

/// Reads the signature block of `frame` without checking it. Any input is safe:
/// bytes that are not exactly one signed MAVLink 2 frame are refused.
pub fn signed_parts(frame: &[u8]) -> Result<Signed, Refusal> {
    match frame.first() {
        Some(&STX_V1) => return Err(Refusal::MavLink1),
        Some(&STX_V2) => {}
        _ => return Err(Refusal::BadSignature),
    }
    if frame.len() < V2_HEADER {
        return Err(Refusal::BadSignature);
    }
    if frame[2] & IFLAG_SIGNED == 0 {
        return Err(Refusal::Unsigned);
    }
    let total = V2_HEADER + usize::from(frame[1]) + 2 + SIGNATURE_LEN;
    if frame.len() != total {
        return Err(Refusal::BadSignature);
    }
    let block = &frame[total - SIGNATURE_LEN..];
    let mut ts = [0u8; 8];
    ts[..6].copy_from_slice(&block[1..7]);
    Ok(Signed {
        system: frame[5],
        component: frame[6],
        link_id: block[0],
        timestamp: u64::from_le_bytes(ts),
    })
}

/// The 48-bit signature of a signed frame: SHA-256 over the key and every byte of
/// the frame but the signature itself. `frame` must be at least 6 bytes.
fn signature_of(key: &SigningKey, frame: &[u8]) -> [u8; 6] {
    let covered = &frame[..frame.len().saturating_sub(6)];
    let digest = Sha256::new()
        .chain_update(key.0)
        .chain_update(covered)
        .finalize();
    let mut out = [0u8; 6];
    out.copy_from_slice(&digest[..6]);
    out
}

/// True if `frame` is one signed MAVLink 2 frame whose signature matches `key`.
pub fn signature_is_valid(key: &SigningKey, frame: &[u8]) -> bool {
    if signed_parts(frame).is_err() {
        return false;
    }
    let want = signature_of(key, frame);
    let got = &frame[frame.len() - 6..];
    // Compare without an early exit.
    want.iter().zip(got).fold(0u8, |acc, (a, b)| acc | (a ^ b)) == 0
}

/// One step of the MAVLink checksum (CRC-16/MCRF4XX) over `byte`.
fn crc_step(crc: u16, byte: u8) -> u16 {
    let mut tmp = byte ^ (crc & 0xFF) as u8;
    tmp ^= tmp << 4;
    let tmp = u16::from(tmp);
    (crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)
}

/// The checksum of an unsigned MAVLink 2 frame after setting its "signed" flag,
/// from its current checksum `crc` and its payload length.
///
/// The CRC is affine over GF(2): for inputs of equal length,
/// `crc(a) ^ crc(b) = crc₀(a ^ b)` with `crc₀` started at 0 instead of 0xFFFF. The
/// checksum input is `len, incompat, compat, seq, sys, comp, msgid[3], payload,
/// CRC_EXTRA`, so the flag is its second byte and the CRC_EXTRA (which we may not
/// know for this id) cancels out.
pub fn crc_with_signed_flag(crc: u16, payload_len: u8) -> u16 {
    let input_len = V2_HEADER - 1 + usize::from(payload_len) + 1;
    let mut delta = crc_step(crc_step(0, 0), IFLAG_SIGNED);
    for _ in 2..input_len {
        delta = crc_step(delta, 0);
    }
    crc ^ delta
}

/// `frame` signed with `key`, `link_id` and `timestamp`; `None` if it is not an
/// unsigned MAVLink 2 frame (MAVLink 1 and signed frames are sent unchanged).
pub fn sign(frame: &[u8], key: &SigningKey, link_id: u8, timestamp: u64) -> Option<RawFrame> {
    if frame.first() != Some(&STX_V2) || frame.len() < V2_HEADER || frame[2] != 0 {
        return None;
    }
    let len = V2_HEADER + usize::from(frame[1]) + 2;
    if frame.len() != len || len + SIGNATURE_LEN > MAX_FRAME {
        return None;
    }
    let mut out = [0u8; MAX_FRAME];
    out[..len].copy_from_slice(frame);
    out[2] |= IFLAG_SIGNED;
    let crc = u16::from_le_bytes([frame[len - 2], frame[len - 1]]);
    out[len - 2..len].copy_from_slice(&crc_with_signed_flag(crc, frame[1]).to_le_bytes());
    out[len] = link_id;
    out[len + 1..len + 7].copy_from_slice(&(timestamp & TIMESTAMP_MASK).to_le_bytes()[..6]);
    let total = len + SIGNATURE_LEN;
    let sig = signature_of(key, &out[..total]);
    out[total - 6..total].copy_from_slice(&sig);
    Some(RawFrame::copy_from(&out[..total]))
}

/// Our signing clock: never behind the system clock, never behind a timestamp we
/// accepted, and strictly increasing over the timestamps we sign.
#[derive(Debug, Default)]
pub struct Clock {
    last: Mutex<u64>,
}

impl Clock {
    /// The timestamp for the next frame we sign, `now` being the system clock's.
    pub fn next(&self, now: u64) -> u64 {
        let mut last = lock(&self.last);
        *last = (*last + 1).max(now) & TIMESTAMP_MASK;
        *last
    }

    /// Our local time for the staleness check.
    pub fn reference(&self, now: u64) -> u64 {
        (*lock(&self.last)).max(now)
    }

    /// A timestamp we accepted: our clock is never behind it.
    pub fn observe(&self, timestamp: u64) {
        let mut last = lock(&self.last);
        *last = (*last).max(timestamp);
    }
}

/// The last accepted timestamp per (system, component, link id) stream, over every
/// signing endpoint.
#[derive(Debug, Default)]
pub struct Streams {
    last: HashMap<(u8, u8, u8), u64>,
}

impl Streams {
    /// Checks one frame from the endpoint against `key`, `reference` being our clock
    /// ([`Clock::reference`]); on success records its timestamp and returns it. The
    /// signature is checked first, so only holders of the key can move a stream.
    pub fn check(
        &mut self,
        key: &SigningKey,
        frame: &[u8],
        reference: u64,
    ) -> Result<u64, Refusal> {
        let parts = signed_parts(frame)?;
        if !signature_is_valid(key, frame) {
            return Err(Refusal::BadSignature);
        }
        let stream = (parts.system, parts.component, parts.link_id);
        match self.last.get(&stream) {
            Some(&last) if parts.timestamp <= last => return Err(Refusal::Replayed),
            Some(_) => {}
            None if parts.timestamp.saturating_add(MAX_STREAM_LAG) < reference => {
                return Err(Refusal::StaleTimestamp)
            }
            None => {
                if self.last.len() >= MAX_STREAMS {
                    // Only key holders create streams; forget the stalest one.
                    if let Some(oldest) = self.last.iter().min_by_key(|(_, t)| **t).map(|(k, _)| *k)
                    {
                        self.last.remove(&oldest);
                    }
                }
            }
        }
        self.last.insert(stream, parts.timestamp);
        Ok(parts.timestamp)
    }

    pub fn len(&self) -> usize {
        self.last.len()
    }

    pub fn is_empty(&self) -> bool {
        self.last.is_empty()
    }
}

#[cfg(test)]
mod tests;
