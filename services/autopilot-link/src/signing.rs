//! MAVLink 2 message signing on router endpoints
//! (<https://mavlink.io/en/guide/message_signing.html>).
//!
//! An endpoint listed in `[signing] endpoints` only lets in MAVLink 2 frames that
//! carry a valid signature made with the shared 32-byte key: the first 6 bytes of
//! SHA-256 over `key ‖ STX ‖ header ‖ payload ‖ CRC ‖ link id ‖ timestamp`. The
//! timestamp (10 µs units since 2015-01-01 00:00 UTC, 48 bits) must be newer than
//! the last one accepted from the same (system, component, link id) stream on any
//! signing endpoint (replay protection: one table serves them all, so a frame seen
//! on one endpoint cannot be replayed on another); a stream's first frame must not
//! be more than one minute older than our clock. Everything else is refused ([`Refusal`]): never
//! routed to the autopilot, the other endpoints or the virtual gimbals. Unsigned
//! RADIO_STATUS is refused too (the spec allows accepting it because a telemetry
//! radio injects it; no radio sits between a ground station and a network endpoint).
//!
//! Our clock ([`Clock`]) is the system clock, moved forward to every timestamp we
//! accept (as the spec says, so a companion computer without a real-time clock
//! still works with a ground station that has one) and to every timestamp we sign:
//! the timestamps we sign strictly increase across every endpoint.
//!
//! Frames sent to a signing endpoint are signed with that endpoint's link id (its
//! index in `endpoints`) unless they are already signed (an autopilot that signs:
//! forwarded unchanged) or MAVLink 1 (cannot be signed: forwarded unchanged).
//! Setting the "signed" incompatibility flag changes the checksum input; the new
//! CRC is derived from the old one ([`crc_with_signed_flag`]), which works for every
//! message id, including ids our dialect does not know.
//!
//! Frames accepted from a signing endpoint are forwarded as received, signature
//! included (what mavlink-router does): autopilot-link's own parser
//! ([`crate::frame::FrameParser`]), vehicle-sim's decoder and ArduPilot accept
//! signed frames (ArduPilot checks the signature if it has signing set up itself).
//!
//! The pure parts ([`sign`], [`Streams::check`], [`Clock`]) take bytes and
//! instants; [`EndpointSigning`] adds the metrics and the rate-limited log.

use std::collections::HashMap;
use std::fmt;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant, SystemTime};

use sha2::{Digest, Sha256};
use skymesh_runtime::{Counter, Stats};

use crate::frame::{RawFrame, MAX_FRAME, STX_V1, STX_V2};

/// Length of a signing key.
pub const KEY_LEN: usize = 32;
/// A key file longer than this is not a key file (read no further).
pub const MAX_KEY_FILE: u64 = 1024;
/// Link id (1) + timestamp (6) + signature (6).
pub const SIGNATURE_LEN: usize = 13;
const V2_HEADER: usize = 10;
const IFLAG_SIGNED: u8 = 0x01;
/// A new stream's first timestamp may lag our clock by this much (1 minute in 10 µs).
pub const MAX_STREAM_LAG: u64 = 60 * 100_000;
/// Streams remembered (one table for every endpoint); beyond this the stalest is
/// forgotten.
pub const MAX_STREAMS: usize = 1024;
/// At most one warning per endpoint this often about refused frames.
pub const LOG_EVERY: Duration = Duration::from_secs(10);
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

    /// Reads a key file holding 64 hex digits. Only a regular file is read, and at
    /// most [`MAX_KEY_FILE`] bytes of it (a path to a device or a pipe must neither
    /// hang nor fill memory).
    pub fn load(path: &Path) -> Result<SigningKey, KeyError> {
        let bytes =
            skymesh_runtime::config::read_regular_file(path, MAX_KEY_FILE).map_err(|e| {
                KeyError::Read {
                    path: path.display().to_string(),
                    reason: e.to_string(),
                }
            })?;
        let text = std::str::from_utf8(&bytes).map_err(|_| KeyError::NotHex)?;
        SigningKey::from_hex(text)
    }
}

/// Signing settings (`[signing]`), validated.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SigningSettings {
    pub key: SigningKey,
    /// Indices into `Settings::endpoints` of the endpoints that require signing.
    pub endpoints: Vec<usize>,
}

/// `t` as a MAVLink signing timestamp: 10 µs units since 2015-01-01 UTC, 48 bits
/// (0 for a clock before 2015).
pub fn timestamp_at(t: SystemTime) -> u64 {
    let micros = t
        .duration_since(SystemTime::UNIX_EPOCH)
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
    Some(RawFrame::from_wire(&out[..total]))
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

/// What the endpoints share: the key, our clock and the one replay table.
///
/// The replay table is shared so a frame accepted on one endpoint cannot be
/// replayed on another: a ground station's signed frame captured on endpoint A
/// (a radio link, a Wi-Fi `udpin`) and sent again on endpoint B has a timestamp
/// that is not newer than its stream's last one, whichever endpoint saw it. A
/// ground station that sends the same frame over two links on purpose (redundant
/// links) gets the second copy refused as `replayed`, which is what the spec's
/// per-stream rule makes of it.
#[derive(Debug)]
pub struct Signing {
    key: SigningKey,
    clock: Clock,
    streams: Mutex<Streams>,
}

impl Signing {
    pub fn new(key: SigningKey) -> Arc<Signing> {
        Arc::new(Signing {
            key,
            clock: Clock::default(),
            streams: Mutex::new(Streams::default()),
        })
    }
}

/// Warns at most once per [`LOG_EVERY`], counting what it held back.
#[derive(Debug, Default)]
struct LogLimit {
    last: Option<Instant>,
    held: u64,
}

impl LogLimit {
    /// `Some(held back since the last warning)` if a warning may be logged now.
    fn allow(&mut self, now: Instant) -> Option<u64> {
        if self.last.is_some_and(|t| now.duration_since(t) < LOG_EVERY) {
            self.held += 1;
            return None;
        }
        self.last = Some(now);
        Some(std::mem::take(&mut self.held))
    }
}

/// Signing on one endpoint: checks what comes in, signs what goes out, counts
/// refusals in `skymesh_router_frames_dropped_total{endpoint,reason}`.
#[derive(Debug)]
pub struct EndpointSigning {
    shared: Arc<Signing>,
    link_id: u8,
    stats: Stats,
    label: String,
    refused: [OnceLock<Counter>; Refusal::ALL.len()],
    log: Mutex<LogLimit>,
}

impl EndpointSigning {
    /// Endpoint `label` signing with `link_id`.
    pub fn new(shared: Arc<Signing>, link_id: u8, stats: &Stats, label: String) -> Self {
        EndpointSigning {
            shared,
            link_id,
            stats: stats.clone(),
            label,
            refused: Default::default(),
            log: Mutex::new(LogLimit::default()),
        }
    }

    pub fn link_id(&self) -> u8 {
        self.link_id
    }

    /// True if `frame` may be routed; otherwise it is counted and (rate-limited) logged.
    pub fn accept(&self, frame: &RawFrame) -> bool {
        let now = timestamp_at(SystemTime::now());
        let reference = self.shared.clock.reference(now);
        let checked =
            lock(&self.shared.streams).check(&self.shared.key, frame.as_bytes(), reference);
        match checked {
            Ok(timestamp) => {
                self.shared.clock.observe(timestamp);
                true
            }
            Err(reason) => {
                self.refuse(reason, frame);
                false
            }
        }
    }

    fn refuse(&self, reason: Refusal, frame: &RawFrame) {
        let i = Refusal::ALL.iter().position(|r| *r == reason).unwrap_or(0);
        self.refused[i]
            .get_or_init(|| {
                self.stats.counter(
                    "skymesh_router_frames_dropped_total",
                    &[("endpoint", &self.label), ("reason", reason.as_str())],
                )
            })
            .inc();
        if let Some(held) = lock(&self.log).allow(Instant::now()) {
            tracing::warn!(
                endpoint = %self.label,
                reason = reason.as_str(),
                message_id = frame.message_id(),
                source = ?(frame.system_id(), frame.component_id()),
                also_refused_since_last_warning = held,
                "refusing a frame on a signing endpoint"
            );
        }
    }

    /// `frame` as it goes out on this endpoint: signed with our link id and the next
    /// timestamp, or unchanged if it is already signed or MAVLink 1.
    pub fn outgoing(&self, frame: &RawFrame) -> RawFrame {
        let bytes = frame.as_bytes();
        if bytes.first() != Some(&STX_V2) || frame.is_signed() {
            return *frame;
        }
        let timestamp = self.shared.clock.next(timestamp_at(SystemTime::now()));
        sign(bytes, &self.shared.key, self.link_id, timestamp).unwrap_or(*frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        MavCmd, MavMessage, COMMAND_LONG_DATA, PARAM_VALUE_DATA, SYSTEM_TIME_DATA,
    };
    use mavlink::{MavHeader, Message};

    fn key() -> SigningKey {
        SigningKey::new(std::array::from_fn(|i| i as u8))
    }

    fn header(seq: u8) -> MavHeader {
        MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: seq,
        }
    }

    fn command() -> MavMessage {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 1,
            target_component: 1,
            param1: 1.0,
            param2: 4.0,
            ..COMMAND_LONG_DATA::DEFAULT
        })
    }

    fn signed(ts: u64, link: u8) -> RawFrame {
        sign(
            RawFrame::encode(header(7), &command()).as_bytes(),
            &key(),
            link,
            ts,
        )
        .unwrap()
    }

    const T: u64 = 300_000_000_000;

    #[test]
    fn keys_parse_from_hex_and_are_never_shown() {
        let hex = "000102030405060708090a0b0c0d0e0f101112131415161718191A1B1C1D1E1F\n";
        assert_eq!(SigningKey::from_hex(hex).unwrap(), key());
        assert_eq!(format!("{:?}", key()), "SigningKey(<redacted>)");
        assert_eq!(
            SigningKey::from_hex("abcd").unwrap_err(),
            KeyError::Length { found: 4 }
        );
        assert_eq!(
            SigningKey::from_hex(&"g".repeat(64)).unwrap_err(),
            KeyError::NotHex
        );
        assert_eq!(
            SigningKey::from_hex(&"0".repeat(64)).unwrap_err(),
            KeyError::AllZero
        );
        // Multi-byte characters are counted, not sliced.
        assert!(SigningKey::from_hex(&"é".repeat(32)).is_err());
        let e = SigningKey::load(Path::new("/nonexistent/key")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/key"), "{e}");
        // Devices are refused without reading them.
        for dev in ["/dev/zero", "/dev/null"] {
            let e = SigningKey::load(Path::new(dev)).unwrap_err();
            assert!(e.to_string().contains("regular file"), "{e}");
        }
    }

    #[test]
    fn timestamps_count_10_us_since_2015() {
        let epoch = SystemTime::UNIX_EPOCH + Duration::from_secs(EPOCH_2015);
        assert_eq!(timestamp_at(epoch), 0);
        assert_eq!(timestamp_at(epoch + Duration::from_secs(1)), 100_000);
        assert_eq!(timestamp_at(SystemTime::UNIX_EPOCH), 0, "before 2015");
    }

    #[test]
    fn the_new_crc_equals_a_recomputation_for_every_length() {
        for len in [0usize, 1, 9, 20, 33, 200, 255] {
            let payload: Vec<u8> = (0..len).map(|i| (i * 37 + 11) as u8).collect();
            let mut input = vec![len as u8, 0, 0, 5, 1, 1, 22, 0, 0];
            input.extend_from_slice(&payload);
            for extra in [0u8, 50, 220] {
                let before = mavlink::calculate_crc(&input, extra);
                let mut flagged = input.clone();
                flagged[1] = IFLAG_SIGNED;
                let after = mavlink::calculate_crc(&flagged, extra);
                assert_eq!(
                    crc_with_signed_flag(before, len as u8),
                    after,
                    "{len}/{extra}"
                );
            }
        }
    }

    #[test]
    fn signed_frames_verify_and_parse_with_the_dialect() {
        for msg in [
            command(),
            MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA::DEFAULT),
            MavMessage::PARAM_VALUE(PARAM_VALUE_DATA::DEFAULT),
        ] {
            let raw = RawFrame::encode(header(1), &msg);
            let f = sign(raw.as_bytes(), &key(), 2, T).unwrap();
            assert!(f.is_signed());
            assert_eq!(f.as_bytes().len(), raw.as_bytes().len() + SIGNATURE_LEN);
            assert!(signature_is_valid(&key(), f.as_bytes()));
            assert!(!signature_is_valid(&SigningKey::new([7; 32]), f.as_bytes()));
            assert_eq!(
                signed_parts(f.as_bytes()).unwrap(),
                Signed {
                    system: 255,
                    component: 190,
                    link_id: 2,
                    timestamp: T
                }
            );
            // The checksum is right for the new flags: our own parser takes it.
            let mut p = crate::frame::FrameParser::new();
            p.push(f.as_bytes());
            assert_eq!(p.next_frame(), Some(f));
            assert_eq!(p.take_malformed(), 0);
            assert_eq!(f.decode().unwrap().message_id(), msg.message_id());
            // Already signed and MAVLink 1 frames are not signed again.
            assert!(sign(f.as_bytes(), &key(), 2, T).is_none());
        }
        let mut v1 = Vec::new();
        mavlink::write_v1_msg(&mut v1, header(1), &command()).unwrap();
        assert!(sign(&v1, &key(), 0, T).is_none());
        assert_eq!(signed_parts(&v1), Err(Refusal::MavLink1));
    }

    #[test]
    fn streams_refuse_replays_stale_starts_and_bad_signatures() {
        let mut s = Streams::default();
        let unsigned = RawFrame::encode(header(1), &command());
        assert_eq!(
            s.check(&key(), unsigned.as_bytes(), T),
            Err(Refusal::Unsigned)
        );
        // A new stream more than a minute behind our clock.
        let old = signed(T - MAX_STREAM_LAG - 1, 0);
        assert_eq!(
            s.check(&key(), old.as_bytes(), T),
            Err(Refusal::StaleTimestamp)
        );
        // Within the minute: accepted; once more: a replay; newer: accepted.
        let first = signed(T - MAX_STREAM_LAG, 0);
        assert_eq!(s.check(&key(), first.as_bytes(), T), Ok(T - MAX_STREAM_LAG));
        assert_eq!(s.check(&key(), first.as_bytes(), T), Err(Refusal::Replayed));
        assert_eq!(s.check(&key(), signed(T + 5, 0).as_bytes(), T), Ok(T + 5));
        assert_eq!(
            s.check(&key(), signed(T + 4, 0).as_bytes(), T),
            Err(Refusal::Replayed)
        );
        // Another link id is another stream (its own first contact).
        assert_eq!(s.check(&key(), signed(T, 1).as_bytes(), T), Ok(T));
        // A wrong key never moves a stream, whatever its timestamp.
        let mut forged = signed(T + 100, 0).as_bytes().to_vec();
        let n = forged.len();
        forged[n - 1] ^= 1;
        assert_eq!(s.check(&key(), &forged, T), Err(Refusal::BadSignature));
        assert_eq!(s.check(&key(), signed(T + 6, 0).as_bytes(), T), Ok(T + 6));
        // A payload changed after signing.
        let mut tampered = signed(T + 7, 0).as_bytes().to_vec();
        tampered[V2_HEADER + 2] ^= 0x40;
        assert_eq!(s.check(&key(), &tampered, T), Err(Refusal::BadSignature));
        assert_eq!(s.len(), 2);
    }

    /// One replay table for every endpoint: a frame accepted on endpoint A is
    /// refused on endpoint B, counted there; a newer frame is accepted on B.
    #[test]
    fn a_frame_accepted_on_one_endpoint_is_a_replay_on_another() {
        let stats = Stats::new();
        let shared = Signing::new(key());
        let a = EndpointSigning::new(shared.clone(), 0, &stats, "a".into());
        let b = EndpointSigning::new(shared, 1, &stats, "b".into());
        let now = timestamp_at(SystemTime::now());
        let frame = signed(now, 7);
        assert!(a.accept(&frame));
        assert!(!b.accept(&frame), "replayed on another endpoint");
        assert_eq!(
            stats.value(
                "skymesh_router_frames_dropped_total",
                "endpoint=b,reason=replayed"
            ),
            Some(1.0)
        );
        assert!(b.accept(&signed(now + 1, 7)));
        assert!(!a.accept(&signed(now + 1, 7)));
    }

    #[test]
    fn streams_stay_bounded() {
        let mut s = Streams::default();
        for i in 0..(MAX_STREAMS + 10) {
            let msg = MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA::DEFAULT);
            let h = MavHeader {
                system_id: (i / 200) as u32 + 1,
                component_id: (i % 200) as u8,
                sequence: 0,
            };
            let f = sign(
                RawFrame::encode(h, &msg).as_bytes(),
                &key(),
                0,
                T + i as u64,
            )
            .unwrap();
            assert!(s.check(&key(), f.as_bytes(), T).is_ok());
            assert!(s.len() <= MAX_STREAMS);
        }
    }

    #[test]
    fn the_clock_is_strictly_increasing_and_follows_accepted_timestamps() {
        let c = Clock::default();
        assert_eq!(c.next(100), 100);
        assert_eq!(
            c.next(100),
            101,
            "same system time: still strictly increasing"
        );
        assert_eq!(c.next(50), 102, "system clock stepped back");
        c.observe(1_000);
        assert_eq!(c.reference(500), 1_000);
        assert_eq!(c.next(500), 1_001);
        assert_eq!(c.reference(5_000), 5_000);
    }

    /// Fuzz safety: no input makes the check or the signer panic.
    #[test]
    fn truncated_and_random_input_never_panics() {
        let good = signed(T, 0);
        let bytes = good.as_bytes();
        let mut s = Streams::default();
        for cut in 0..bytes.len() {
            assert!(s.check(&key(), &bytes[..cut], T).is_err(), "cut at {cut}");
            assert!(!signature_is_valid(&key(), &bytes[..cut]));
            let _ = sign(&bytes[..cut], &key(), 0, T);
        }
        let mut rng = fastrand::Rng::with_seed(11);
        for _ in 0..20_000 {
            let n = rng.usize(0..300);
            let mut junk: Vec<u8> = (0..n).map(|_| rng.u8(..)).collect();
            if n > 2 && rng.bool() {
                junk[0] = STX_V2;
                junk[2] = rng.u8(0..2);
                junk[1] = (n.saturating_sub(V2_HEADER + 2 + SIGNATURE_LEN)) as u8;
            }
            let _ = s.check(&key(), &junk, T);
            let _ = sign(&junk, &key(), 0, T);
        }
        assert_eq!(s.check(&key(), bytes, T), Ok(T));
    }

    #[test]
    fn refusals_are_logged_at_most_once_per_period() {
        let t = Instant::now();
        let mut l = LogLimit::default();
        assert_eq!(l.allow(t), Some(0));
        assert_eq!(l.allow(t + Duration::from_secs(1)), None);
        assert_eq!(l.allow(t + Duration::from_secs(2)), None);
        assert_eq!(l.allow(t + LOG_EVERY), Some(2));
    }
}
