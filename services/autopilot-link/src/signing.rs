//! MAVLink 2 message signing on router endpoints
//! (<https://mavlink.io/en/guide/message_signing.html>); the signing itself is
//! [`mavlink_frame::signing`].
//!
//! An endpoint listed in `[signing] endpoints` only lets in MAVLink 2 frames that
//! carry a valid signature made with the shared 32-byte key, whose timestamp is
//! newer than the last one accepted from the same (system, component, link id)
//! stream on any signing endpoint (replay protection: one table serves them all,
//! so a frame seen on one endpoint cannot be replayed on another); a stream's
//! first frame must not be more than one minute older than our clock. Everything
//! else is refused ([`Refusal`]): never routed to the autopilot, the other
//! endpoints or the virtual gimbals. Unsigned RADIO_STATUS is refused too (the
//! spec allows accepting it because a telemetry radio injects it; no radio sits
//! between a ground station and a network endpoint).
//!
//! Our clock ([`Clock`]) is the system clock, moved forward to every timestamp we
//! accept and to every timestamp we sign: the timestamps we sign strictly increase
//! across every endpoint.
//!
//! Frames sent to a signing endpoint are signed with that endpoint's link id (its
//! index in `endpoints`) unless they are already signed (an autopilot that signs:
//! forwarded unchanged) or MAVLink 1 (cannot be signed: forwarded unchanged).
//!
//! Frames accepted from a signing endpoint are forwarded as received, signature
//! included (what mavlink-router does): the framer ([`mavlink_frame::FrameParser`],
//! used by this router and vehicle-sim) and ArduPilot accept signed frames
//! (ArduPilot checks the signature if it has signing set up itself).
//!
//! [`EndpointSigning`] adds the metrics and the rate-limited log to the pure parts.

use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant, SystemTime};

use mavlink_frame::signing::{sign, timestamp_at, Clock, KeyError, Refusal, SigningKey, Streams};
use mavlink_frame::{RawFrame, STX_V2};
use skymesh_runtime::{Counter, Stats};

/// A key file longer than this is not a key file (read no further).
pub const MAX_KEY_FILE: u64 = 1024;
/// At most one warning per endpoint this often about refused frames.
pub const LOG_EVERY: Duration = Duration::from_secs(10);

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Reads a key file holding 64 hex digits. Only a regular file is read, and at
/// most [`MAX_KEY_FILE`] bytes of it (a path to a device or a pipe must neither
/// hang nor fill memory).
pub fn load_key(path: &Path) -> Result<SigningKey, KeyError> {
    let bytes = skymesh_runtime::config::read_regular_file(path, MAX_KEY_FILE).map_err(|e| {
        KeyError::Read {
            path: path.display().to_string(),
            reason: e.to_string(),
        }
    })?;
    let text = std::str::from_utf8(&bytes).map_err(|_| KeyError::NotHex)?;
    SigningKey::from_hex(text)
}

/// Signing settings (`[signing]`), validated.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SigningSettings {
    pub key: SigningKey,
    /// Indices into `Settings::endpoints` of the endpoints that require signing.
    pub endpoints: Vec<usize>,
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
    use mavlink::dialects::ardupilotmega::{MavCmd, MavMessage, COMMAND_LONG_DATA};
    use mavlink::MavHeader;

    fn key() -> SigningKey {
        SigningKey::new(std::array::from_fn(|i| i as u8))
    }

    fn signed(ts: u64, link: u8) -> RawFrame {
        let header = MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: 7,
        };
        let command = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 1,
            target_component: 1,
            ..COMMAND_LONG_DATA::DEFAULT
        });
        sign(
            RawFrame::encode(header, &command).as_bytes(),
            &key(),
            link,
            ts,
        )
        .unwrap()
    }

    #[test]
    fn key_files_are_read_only_if_regular() {
        let e = load_key(Path::new("/nonexistent/key")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/key"), "{e}");
        // Devices are refused without reading them.
        for dev in ["/dev/zero", "/dev/null"] {
            let e = load_key(Path::new(dev)).unwrap_err();
            assert!(e.to_string().contains("regular file"), "{e}");
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("key");
        std::fs::write(&path, format!("{}\n", "0f".repeat(32))).unwrap();
        assert_eq!(load_key(&path).unwrap(), SigningKey::new([0x0f; 32]));
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
    fn refusals_are_logged_at_most_once_per_period() {
        let t = Instant::now();
        let mut l = LogLimit::default();
        assert_eq!(l.allow(t), Some(0));
        assert_eq!(l.allow(t + Duration::from_secs(1)), None);
        assert_eq!(l.allow(t + Duration::from_secs(2)), None);
        assert_eq!(l.allow(t + LOG_EVERY), Some(2));
    }
}
