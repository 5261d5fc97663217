//! The tap and the writer thread in a temp dir: sessions, files, rotation,
//! retention, overflow, errors, recovery.

use std::path::Path;
use std::time::{Duration, UNIX_EPOCH};

use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, ATTITUDE_DATA, HEARTBEAT_DATA,
};
use mavlink::MavHeader;
use skymesh_ipc_types::ServiceStats;

use super::format::{frame_len, STAMP_LEN};
use super::*;

fn settings(dir: &Path, mode: TlogMode) -> TlogSettings {
    TlogSettings {
        dir: dir.to_path_buf(),
        mode,
        vehicle_id: 1,
        limits: Limits {
            max_files: 100,
            max_total: 1 << 40,
            min_free: 0,
        },
        max_file_bytes: 1 << 30,
        queue_frames: 4096,
        flush_interval: Duration::from_secs(1),
    }
}

fn frame(sys: u8, comp: u8, msg: &MavMessage) -> RawFrame {
    let header = MavHeader {
        system_id: u32::from(sys),
        component_id: comp,
        sequence: 0,
    };
    RawFrame::encode(header, msg)
}

fn heartbeat(armed: bool) -> RawFrame {
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    if armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    let hb = HEARTBEAT_DATA {
        custom_mode: 4,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    };
    frame(1, 1, &MavMessage::HEARTBEAT(hb))
}

fn attitude(t: u32) -> RawFrame {
    // A last field not zero: MAVLink 2 sends the whole 28-byte payload.
    let a = ATTITUDE_DATA {
        time_boot_ms: t,
        yawspeed: 1.0,
        ..Default::default()
    };
    frame(1, 1, &MavMessage::ATTITUDE(a))
}

/// Our logs of vehicle 1 in `dir`, oldest first.
fn logs(dir: &Path) -> Vec<String> {
    let mut v: Vec<_> = files(dir)
        .into_iter()
        .filter_map(|n| format::parse_name(1, &n).map(|p| (p, n)))
        .collect();
    v.sort();
    v.into_iter().map(|(_, n)| n).collect()
}

/// Every file in `dir`, sorted.
fn files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    v.sort();
    v
}

/// The records of a log: (µs stamp, frame bytes); every byte must belong to one.
fn records(path: &Path) -> Vec<(u64, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let stamp = u64::from_be_bytes(bytes[at..at + STAMP_LEN].try_into().unwrap());
        let len = frame_len(&bytes[at + STAMP_LEN..]).expect("a MAVLink frame");
        out.push((stamp, bytes[at + STAMP_LEN..at + STAMP_LEN + len].to_vec()));
        at += STAMP_LEN + len;
    }
    assert_eq!(at, bytes.len(), "{}: a torn record", path.display());
    out
}

fn metric(stats: &Stats, name: &str, labels: &str) -> Option<f64> {
    let mut out = Box::<ServiceStats>::default();
    stats.snapshot_into(&mut out);
    out.entries()
        .iter()
        .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
        .map(|e| e.value)
}

#[test]
fn a_connection_is_one_log_of_both_directions_with_big_endian_stamps() {
    let dir = tempfile::tempdir().unwrap();
    let stats = Stats::new();
    let (tap, recorder) = start(&settings(dir.path(), TlogMode::Connection), &stats).unwrap();
    // Not connected: nothing recorded.
    tap.from_autopilot(&attitude(1));
    let before = micros_now();
    tap.connected();
    tap.from_autopilot(&heartbeat(false));
    tap.from_autopilot(&attitude(2));
    let ours = frame(1, 191, &MavMessage::ATTITUDE(ATTITUDE_DATA::default()));
    tap.to_autopilot(&ours);
    tap.disconnected();
    tap.from_autopilot(&attitude(3));
    recorder.finish();
    let after = micros_now();

    let names = files(dir.path());
    assert_eq!(names.len(), 1, "{names:?}");
    assert!(format::parse_name(1, &names[0]).is_some_and(|n| !n.part));
    let recs = records(&dir.path().join(&names[0]));
    let frames: Vec<&[u8]> = recs.iter().map(|(_, f)| f.as_slice()).collect();
    assert_eq!(
        frames,
        vec![
            heartbeat(false).as_bytes(),
            attitude(2).as_bytes(),
            ours.as_bytes()
        ]
    );
    for (stamp, _) in &recs {
        assert!(
            (before..=after).contains(stamp),
            "{before} <= {stamp} <= {after}"
        );
    }
    assert_eq!(
        metric(&stats, "skymesh_autopilot_tlog_frames_total", ""),
        Some(3.0)
    );
    assert_eq!(
        metric(&stats, "skymesh_autopilot_tlog_recording", ""),
        Some(0.0)
    );
}

fn micros_now() -> u64 {
    format::micros(SystemTime::now())
}

#[test]
fn arming_mode_records_each_flight_from_arming_to_disarming() {
    let dir = tempfile::tempdir().unwrap();
    let stats = Stats::new();
    let (tap, recorder) = start(&settings(dir.path(), TlogMode::Arming), &stats).unwrap();
    tap.connected();
    tap.from_autopilot(&heartbeat(false));
    tap.from_autopilot(&attitude(1));
    // A ground station's armed-looking heartbeat is not the autopilot's.
    let gcs = match heartbeat(true).decode().unwrap() {
        MavMessage::HEARTBEAT(mut hb) => {
            hb.autopilot = MavAutopilot::MAV_AUTOPILOT_INVALID;
            frame(1, 1, &MavMessage::HEARTBEAT(hb))
        }
        _ => unreachable!(),
    };
    tap.from_autopilot(&gcs);
    tap.from_autopilot(&attitude(2));
    // Flight 1.
    tap.from_autopilot(&heartbeat(true));
    tap.from_autopilot(&attitude(10));
    tap.from_autopilot(&heartbeat(true));
    tap.from_autopilot(&heartbeat(false));
    tap.from_autopilot(&attitude(11));
    // Flight 2, ended by the connection.
    tap.from_autopilot(&heartbeat(true));
    tap.from_autopilot(&attitude(20));
    tap.disconnected();
    tap.from_autopilot(&attitude(21));
    // Armed heartbeats while not connected start nothing (the link is down).
    tap.from_autopilot(&heartbeat(true));
    recorder.finish();

    let names = logs(dir.path());
    assert_eq!(names.len(), 2, "{names:?}");
    let first: Vec<Vec<u8>> = records(&dir.path().join(&names[0]))
        .into_iter()
        .map(|(_, f)| f)
        .collect();
    let want = |fs: &[RawFrame]| fs.iter().map(|f| f.as_bytes().to_vec()).collect::<Vec<_>>();
    assert_eq!(
        first,
        want(&[
            heartbeat(true),
            attitude(10),
            heartbeat(true),
            heartbeat(false)
        ])
    );
    let second: Vec<Vec<u8>> = records(&dir.path().join(&names[1]))
        .into_iter()
        .map(|(_, f)| f)
        .collect();
    assert_eq!(second, want(&[heartbeat(true), attitude(20)]));
}

#[test]
fn long_recordings_rotate_and_retention_keeps_the_newest() {
    let dir = tempfile::tempdir().unwrap();
    let stats = Stats::new();
    let mut s = settings(dir.path(), TlogMode::Connection);
    // One ATTITUDE record is 8 + 40 bytes: a file takes three.
    s.max_file_bytes = 130;
    s.limits.max_files = 2;
    // Somebody else's file is never deleted.
    std::fs::write(dir.path().join("notes.tlog"), b"mine").unwrap();
    let (tap, recorder) = start(&s, &stats).unwrap();
    tap.connected();
    for t in 0..10 {
        tap.from_autopilot(&attitude(t));
    }
    tap.disconnected();
    recorder.finish();
    let names = files(dir.path());
    assert_eq!(names.len(), 3, "{names:?}");
    assert!(names.contains(&"notes.tlog".to_string()));
    let ours = logs(dir.path());
    // 10 frames: files of 3, 3, 3, 1; the two newest are kept.
    let kept: Vec<usize> = ours
        .iter()
        .map(|n| records(&dir.path().join(n)).len())
        .collect();
    assert_eq!(kept, vec![3, 1]);
    assert_eq!(
        metric(&stats, "skymesh_autopilot_tlog_files_deleted_total", ""),
        Some(2.0)
    );
}

#[test]
fn a_full_queue_drops_and_counts_instead_of_waiting() {
    let stats = Stats::new();
    // A queue nobody drains: exactly its capacity is taken.
    let (tx, rx) = sync_channel(64);
    let tap = Tap {
        tx,
        shared: Arc::new(Shared::default()),
        mode: TlogMode::Connection,
        vehicle_id: 1,
        metrics: TlogMetrics::new(&stats),
    };
    tap.connected();
    for t in 0..100 {
        tap.from_autopilot(&attitude(t));
    }
    assert_eq!(rx.try_iter().count(), 64);
    assert_eq!(
        metric(&stats, "skymesh_autopilot_tlog_dropped_frames_total", ""),
        Some(36.0)
    );
}

#[test]
fn an_io_error_ends_the_recording_not_the_caller() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"x").unwrap();
    let stats = Stats::new();
    // The directory cannot be created under a regular file.
    let (tap, recorder) =
        start(&settings(&file.join("tlog"), TlogMode::Connection), &stats).unwrap();
    tap.connected();
    for t in 0..10 {
        tap.from_autopilot(&attitude(t));
    }
    recorder.finish();
    // Frames after the writer is gone are not an error either.
    tap.from_autopilot(&attitude(11));
    assert_eq!(
        metric(&stats, "skymesh_autopilot_tlog_errors_total", "reason=io"),
        Some(1.0)
    );
    assert_eq!(files(dir.path()), vec!["a-file".to_string()]);
}

#[test]
fn a_log_left_by_a_crash_is_cut_after_its_last_whole_record_and_renamed() {
    let dir = tempfile::tempdir().unwrap();
    let name = format::file_name(1, &format::utc_stamp(UNIX_EPOCH), 0);
    let mut bytes = Vec::new();
    for t in 0..2 {
        bytes.extend(5u64.to_be_bytes());
        bytes.extend(attitude(t).as_bytes());
    }
    bytes.extend(5u64.to_be_bytes());
    bytes.extend(&attitude(2).as_bytes()[..7]);
    std::fs::write(dir.path().join(format!("{name}{}", format::PART)), &bytes).unwrap();
    // Another vehicle's `.part` is its own service's business.
    let other = format!(
        "{}{}",
        format::file_name(2, "20260101T000000.000Z", 0),
        format::PART
    );
    std::fs::write(dir.path().join(&other), b"half").unwrap();
    let stats = Stats::new();
    let (_tap, recorder) = start(&settings(dir.path(), TlogMode::Connection), &stats).unwrap();
    recorder.finish();
    assert_eq!(files(dir.path()), vec![name.clone(), other]);
    let recs = records(&dir.path().join(&name));
    assert_eq!(recs.len(), 2);
    assert_eq!(recs[1], (5, attitude(1).as_bytes().to_vec()));
}
