//! Signing tests: keys, timestamps, the CRC shortcut, signatures, replay rules.

use std::time::{Duration, SystemTime};

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
        let mut p = crate::FrameParser::new();
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
