//! The `.tlog` format and our file names (pure).
//!
//! A telemetry log is a sequence of records, each an 8-byte **big-endian** count
//! of microseconds since the Unix epoch followed by one MAVLink frame exactly as it
//! was on the wire — what MAVProxy, QGroundControl and mavlink-router write
//! (mavlink-router's `TLog::write_msg`: `htobe64(now_usec)` then the frame;
//! pymavlink's `mavlogfile` reads the stamp with `struct.unpack('>Q', …)`).
//!
//! Our files are `skymesh-v<vehicle>-<YYYYMMDD>T<HHMMSS>.<mmm>Z[-<n>].tlog` (UTC,
//! the moment the file was opened; `-<n>` only if that name was taken), with
//! `.part` appended while being written. Retention only ever deletes names of this
//! exact shape for its own vehicle.

use std::io::{self, Read, Seek, SeekFrom};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// A finished log.
pub const SUFFIX: &str = ".tlog";
/// Appended to [`SUFFIX`] while the file is being written.
pub const PART: &str = ".part";
/// Bytes before each frame: the timestamp.
pub const STAMP_LEN: usize = 8;

/// Microseconds since the Unix epoch (0 for a clock before it).
pub fn micros(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

/// The 8 bytes written before a frame received or sent at `t`.
pub fn stamp(t: SystemTime) -> [u8; STAMP_LEN] {
    micros(t).to_be_bytes()
}

/// The civil UTC date (year, month 1..=12, day 1..=31) of `days` since 1970-01-01
/// (Howard Hinnant's `civil_from_days`).
fn civil(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// `YYYYMMDDTHHMMSS.mmmZ` for `t` (UTC).
pub fn utc_stamp(t: SystemTime) -> String {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or(Duration::ZERO);
    let secs = d.as_secs() as i64;
    let (year, month, day) = civil(secs.div_euclid(86_400));
    let s = secs.rem_euclid(86_400);
    format!(
        "{year:04}{month:02}{day:02}T{:02}{:02}{:02}.{:03}Z",
        s / 3600,
        s / 60 % 60,
        s % 60,
        d.subsec_millis()
    )
}

/// The name of a finished log of `vehicle` opened at `stamp` ([`utc_stamp`]);
/// `n` > 0 disambiguates two files opened in the same millisecond.
pub fn file_name(vehicle: u8, stamp: &str, n: u32) -> String {
    if n == 0 {
        format!("skymesh-v{vehicle}-{stamp}{SUFFIX}")
    } else {
        format!("skymesh-v{vehicle}-{stamp}-{n}{SUFFIX}")
    }
}

/// One of our files, recognised by its name.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct OurName {
    /// `YYYYMMDDTHHMMSS.mmmZ`: sorts in time order.
    pub stamp: String,
    pub n: u32,
    /// Still being written (or left by a crash): ends in `.tlog.part`.
    pub part: bool,
}

/// `name` parsed if it is one of `vehicle`'s logs ([`file_name`], optionally with
/// [`PART`]); `None` for anything else, which is never touched.
pub fn parse_name(vehicle: u8, name: &str) -> Option<OurName> {
    let rest = name.strip_prefix(&format!("skymesh-v{vehicle}-"))?;
    let (rest, part) = match rest.strip_suffix(PART) {
        Some(r) => (r, true),
        None => (rest, false),
    };
    let rest = rest.strip_suffix(SUFFIX)?;
    let (stamp, n) = match rest.split_once('-') {
        Some((stamp, n)) => {
            if n.is_empty() || !n.bytes().all(|b| b.is_ascii_digit()) || n.starts_with('0') {
                return None;
            }
            (stamp, n.parse().ok()?)
        }
        None => (rest, 0),
    };
    let b = stamp.as_bytes();
    let digits = |r: std::ops::Range<usize>| b[r].iter().all(u8::is_ascii_digit);
    let shaped = b.len() == 20
        && digits(0..8)
        && b[8] == b'T'
        && digits(9..15)
        && b[15] == b'.'
        && digits(16..19)
        && b[19] == b'Z';
    shaped.then(|| OurName {
        stamp: stamp.to_string(),
        n,
        part,
    })
}

/// The length of the longest prefix of the `len`-byte log `r` made of whole
/// records (a crash can leave half a record at the end of a `.part` file: it is
/// cut there). Stops at the first record whose frame does not start with a MAVLink
/// magic byte. Reads only the records' headers.
pub fn whole_records<R: Read + Seek>(r: &mut R, len: u64) -> io::Result<u64> {
    // A stamp and the 3 header bytes that give a frame's length; the shortest
    // record (MAVLink 1, empty payload) is 16 bytes, longer than this.
    const HEAD: usize = STAMP_LEN + 3;
    let mut at = 0u64;
    let mut head = [0u8; HEAD];
    r.seek(SeekFrom::Start(0))?;
    while at + HEAD as u64 <= len {
        r.read_exact(&mut head)?;
        let Some(frame) = frame_len(&head[STAMP_LEN..]) else {
            break;
        };
        let record = (STAMP_LEN + frame) as u64;
        if at + record > len {
            break;
        }
        r.seek_relative(record as i64 - HEAD as i64)?;
        at += record;
    }
    Ok(at)
}

/// The length of the MAVLink frame at the start of `b` as its header declares it
/// (`None` for no magic byte or a header cut short).
pub fn frame_len(b: &[u8]) -> Option<usize> {
    match *b.first()? {
        // MAVLink 2: 10-byte header, payload, CRC, 13-byte signature if flagged.
        0xFD => {
            let (len, incompat) = (usize::from(*b.get(1)?), *b.get(2)?);
            Some(10 + len + 2 + if incompat & 1 != 0 { 13 } else { 0 })
        }
        // MAVLink 1: 6-byte header, payload, CRC.
        0xFE => Some(6 + usize::from(*b.get(1)?) + 2),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_are_big_endian_microseconds() {
        let t = UNIX_EPOCH + Duration::from_micros(0x0102_0304_0506_0708);
        assert_eq!(stamp(t), [1, 2, 3, 4, 5, 6, 7, 8]);
    }

    #[test]
    fn utc_names_and_their_parse() {
        let t = UNIX_EPOCH + Duration::from_millis(1_796_000_000_123);
        // 2026-11-30 00:53:20.123 UTC.
        assert_eq!(utc_stamp(t), "20261130T005320.123Z");
        assert_eq!(utc_stamp(UNIX_EPOCH), "19700101T000000.000Z");
        // A leap day.
        let leap = UNIX_EPOCH + Duration::from_secs(951_782_400);
        assert_eq!(utc_stamp(leap), "20000229T000000.000Z");
        let name = file_name(3, &utc_stamp(t), 0);
        assert_eq!(name, "skymesh-v3-20261130T005320.123Z.tlog");
        let parsed = parse_name(3, &name).unwrap();
        assert_eq!((parsed.n, parsed.part), (0, false));
        let part = format!("{}{PART}", file_name(3, &utc_stamp(t), 2));
        assert_eq!(
            parse_name(3, &part),
            Some(OurName {
                stamp: "20261130T005320.123Z".into(),
                n: 2,
                part: true
            })
        );
    }

    #[test]
    fn other_files_are_not_ours() {
        for name in [
            "skymesh-v1-20261130T033320.123Z.tlog",
            "flight.tlog",
            "skymesh-v12-20261130T033320.123Z.tlog",
            "skymesh-v1-20261130T033320.123Z.tlog.bak",
            "skymesh-v1-20261130T033320Z.tlog",
            "skymesh-v1-20261130T033320.123Z-.tlog",
            "skymesh-v1-20261130T033320.123Z-01.tlog",
            "skymesh-v1-20261130T0333201123Z.tlog",
        ] {
            assert_eq!(parse_name(2, name), None, "{name}");
        }
    }

    #[test]
    fn a_torn_last_record_is_cut() {
        // v2 HEARTBEAT-sized frame (9-byte payload): 8 + 21 bytes per record.
        let mut frame = vec![0xFD, 9, 0, 0, 0, 1, 1, 0, 0, 0];
        frame.extend([0; 11]);
        let mut log = Vec::new();
        for _ in 0..3 {
            log.extend([0u8; 8]);
            log.extend(&frame);
        }
        let whole = |b: &[u8]| whole_records(&mut io::Cursor::new(b), b.len() as u64).unwrap();
        assert_eq!(whole(&log), 87);
        assert_eq!(whole(&log[..80]), 58);
        assert_eq!(whole(&log[..60]), 58);
        assert_eq!(whole(&log[..5]), 0);
        // A MAVLink 1 frame, then a record that is not MAVLink.
        let mut v1 = vec![0u8; 8];
        v1.extend([0xFE, 2, 0, 1, 1, 0, 7, 7, 0, 0]);
        v1.extend([0u8; 8]);
        v1.extend([0x55; 12]);
        assert_eq!(whole(&v1), 18);
        assert_eq!(frame_len(&[0xFD, 5, 1]), Some(10 + 5 + 2 + 13));
    }
}
