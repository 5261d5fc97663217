//! The pose broadcast: one UDP datagram per frame holding every drone's
//! [`POSE_RECORD_LEN`]-byte [`PoseRecord`], little-endian, tightly packed, no header
//! (the spec's C# `ObjectInfo`; FACTS.md: 84 bytes, the spec's "72" is stale).
//!
//! | offset | field | offset | field |
//! |---|---|---|---|
//! | 0 | `u16 id` | 36 | `f32 colorR, colorG, colorB` |
//! | 2 | `u8 type` (0 UAV, 1 UGV, 2 unknown) | 48 | `f32 timestamp` (s) |
//! | 3 | `u8 liveness` (0 undecided, 1 live, 2 simulated) | 52 | `f32 quaternion x, y, z, w` |
//! | 4 | `f32 trackingX, Y, Z` (site m) | 68 | `u32 frameCount` |
//! | 16 | `f32 trackingOrientation` (CCW yaw, deg) | 72 | `i32 DroneState` |
//! | 20 | `f32 targetX, Y, Z` | 76 | `u32 flags` (0x01 idle, 0x02 active) |
//! | 32 | `f32 targetOrientation` | 80 | `f32 relativeRotation` (deg) |

/// Bytes of one pose record.
pub const POSE_RECORD_LEN: usize = 84;
/// Pose flag: ready for commands.
pub const POSE_FLAG_IDLE: u32 = 0x01;
/// Pose flag: enabled in GroundControl (`SET_ACTIVE`).
pub const POSE_FLAG_ACTIVE: u32 = 0x02;
/// The flag bits GroundControl defines.
pub const POSE_FLAGS_MASK: u32 = POSE_FLAG_IDLE | POSE_FLAG_ACTIVE;

/// One drone's pose record.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseRecord {
    pub id: u16,
    /// 0 UAV, 1 UGV, 2 unknown.
    pub object_type: u8,
    /// 0 undecided, 1 live, 2 simulated.
    pub liveness: u8,
    /// Tracked position, site frame (x east, y north, z up), metres.
    pub tracking: [f32; 3],
    /// Tracked yaw, CCW degrees.
    pub tracking_yaw_deg: f32,
    /// Waypoint position, site frame, metres.
    pub target: [f32; 3],
    /// Waypoint yaw, CCW degrees.
    pub target_yaw_deg: f32,
    /// LED colour, 0..1.
    pub color: [f32; 3],
    /// Data timestamp, seconds.
    pub timestamp: f32,
    /// Attitude quaternion x, y, z, w.
    pub quaternion: [f32; 4],
    pub frame_count: u32,
    /// GroundControl `DroneState` (NONE 0 … LANDING_MOTORS_OFF 16).
    pub drone_state: i32,
    /// [`POSE_FLAG_IDLE`], [`POSE_FLAG_ACTIVE`].
    pub flags: u32,
    /// Rotation of a rotating base relative to the body, degrees.
    pub relative_rotation_deg: f32,
}

/// A datagram that is not a whole number of pose records.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("pose datagram of {len} bytes is not a multiple of {POSE_RECORD_LEN}")]
pub struct PoseDatagramError {
    pub len: usize,
}

fn put_f32s(out: &mut [u8], at: usize, v: &[f32]) {
    for (i, x) in v.iter().enumerate() {
        out[at + 4 * i..at + 4 * i + 4].copy_from_slice(&x.to_le_bytes());
    }
}

fn f32_at(b: &[u8; POSE_RECORD_LEN], at: usize) -> f32 {
    f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u32_at(b: &[u8; POSE_RECORD_LEN], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

impl PoseRecord {
    /// Writes the record's bytes.
    pub fn encode_into(&self, out: &mut [u8; POSE_RECORD_LEN]) {
        out[0..2].copy_from_slice(&self.id.to_le_bytes());
        out[2] = self.object_type;
        out[3] = self.liveness;
        put_f32s(out, 4, &self.tracking);
        put_f32s(out, 16, &[self.tracking_yaw_deg]);
        put_f32s(out, 20, &self.target);
        put_f32s(out, 32, &[self.target_yaw_deg]);
        put_f32s(out, 36, &self.color);
        put_f32s(out, 48, &[self.timestamp]);
        put_f32s(out, 52, &self.quaternion);
        out[68..72].copy_from_slice(&self.frame_count.to_le_bytes());
        out[72..76].copy_from_slice(&self.drone_state.to_le_bytes());
        out[76..80].copy_from_slice(&self.flags.to_le_bytes());
        put_f32s(out, 80, &[self.relative_rotation_deg]);
    }

    /// The record's bytes.
    pub fn encode(&self) -> [u8; POSE_RECORD_LEN] {
        let mut out = [0u8; POSE_RECORD_LEN];
        self.encode_into(&mut out);
        out
    }

    /// Reads one record. Never fails: every bit pattern is a record.
    pub fn decode(b: &[u8; POSE_RECORD_LEN]) -> PoseRecord {
        let f3 = |at: usize| [f32_at(b, at), f32_at(b, at + 4), f32_at(b, at + 8)];
        PoseRecord {
            id: u16::from_le_bytes([b[0], b[1]]),
            object_type: b[2],
            liveness: b[3],
            tracking: f3(4),
            tracking_yaw_deg: f32_at(b, 16),
            target: f3(20),
            target_yaw_deg: f32_at(b, 32),
            color: f3(36),
            timestamp: f32_at(b, 48),
            quaternion: [f32_at(b, 52), f32_at(b, 56), f32_at(b, 60), f32_at(b, 64)],
            frame_count: u32_at(b, 68),
            drone_state: u32_at(b, 72) as i32,
            flags: u32_at(b, 76),
            relative_rotation_deg: f32_at(b, 80),
        }
    }
}

/// Replaces the contents of `buf` with one datagram of `records`. Allocates only
/// when `buf` has less capacity than the datagram needs, so a buffer kept between
/// frames is allocated once.
pub fn encode_pose_datagram<'a>(
    records: impl IntoIterator<Item = &'a PoseRecord>,
    buf: &mut Vec<u8>,
) {
    buf.clear();
    let mut one = [0u8; POSE_RECORD_LEN];
    for r in records {
        r.encode_into(&mut one);
        buf.extend_from_slice(&one);
    }
}

/// The records of one datagram, without allocating. The length must be a multiple
/// of [`POSE_RECORD_LEN`] (an empty datagram holds no record).
pub fn pose_records(
    datagram: &[u8],
) -> Result<impl ExactSizeIterator<Item = PoseRecord> + '_, PoseDatagramError> {
    if !datagram.len().is_multiple_of(POSE_RECORD_LEN) {
        return Err(PoseDatagramError {
            len: datagram.len(),
        });
    }
    Ok(datagram
        .chunks_exact(POSE_RECORD_LEN)
        .map(|c| PoseRecord::decode(c.try_into().expect("chunks_exact gives whole records"))))
}

/// Every record of one datagram.
pub fn decode_pose_datagram(datagram: &[u8]) -> Result<Vec<PoseRecord>, PoseDatagramError> {
    Ok(pose_records(datagram)?.collect())
}
