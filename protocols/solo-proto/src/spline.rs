//! Multipoint cable cam (SOLO_SPLINE_*): record and play a path of keypoints, seek
//! along it, and ShotManager's playback status and duration estimates.

use bytes::{BufMut, BytesMut};

use crate::error::DecodeError;
use crate::ids;
use crate::message::SoloMessage;
use crate::wire::Reader;

/// One keypoint (SOLO_SPLINE_POINT), 44 bytes in this order: `i16 version, f32
/// absAltRef, i32 index, f64 lat, f64 lon, f32 alt, f32 pitch, f32 yaw, f32
/// uPosition, i16 status`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplinePoint {
    /// Layout version; the reference only loads version 0 (the engine decides).
    pub version: i16,
    /// Absolute altitude of home when the path was recorded, metres.
    pub abs_alt_ref_m: f32,
    /// Keypoint index, from 0. Not range-checked here: ShotManager echoes whatever
    /// the app sent in its failure reply.
    pub index: i32,
    pub lat_deg: f64,
    pub lon_deg: f64,
    /// Relative altitude, metres.
    pub alt_m: f32,
    pub pitch_deg: f32,
    pub yaw_deg: f32,
    /// Parametric position along the path (meaningful in play mode only).
    pub u_position: f32,
    /// ShotManager's verdict: ≥ 0 success; −1 mode error, −2 too close / duplicate,
    /// −3 duplicate index, below that unspecified failure.
    pub status: i16,
}

fn put_point(p: &SplinePoint, dst: &mut BytesMut) {
    dst.put_i16_le(p.version);
    dst.put_f32_le(p.abs_alt_ref_m);
    dst.put_i32_le(p.index);
    dst.put_f64_le(p.lat_deg);
    dst.put_f64_le(p.lon_deg);
    dst.put_f32_le(p.alt_m);
    dst.put_f32_le(p.pitch_deg);
    dst.put_f32_le(p.yaw_deg);
    dst.put_f32_le(p.u_position);
    dst.put_i16_le(p.status);
}

fn read_point(r: &mut Reader<'_>) -> Result<SplinePoint, DecodeError> {
    Ok(SplinePoint {
        version: r.i16()?,
        abs_alt_ref_m: r.f32("abs_alt_ref")?,
        index: r.i32()?,
        lat_deg: r.lat("latitude")?,
        lon_deg: r.lon("longitude")?,
        alt_m: r.f32("altitude")?,
        pitch_deg: r.f32("pitch")?,
        yaw_deg: r.f32("yaw")?,
        u_position: r.f32("u_position")?,
        status: r.i16()?,
    })
}

pub(crate) fn encode(msg: &SoloMessage, dst: &mut BytesMut) {
    use SoloMessage as M;
    match msg {
        M::SplinePoint(p) => put_point(p, dst),
        M::SplineSeek {
            u_position,
            cruise_state,
        }
        | M::SplinePlaybackStatus {
            u_position,
            cruise_state,
        } => {
            dst.put_f32_le(*u_position);
            dst.put_i32_le(*cruise_state);
        }
        M::SplinePathSettings {
            camera_control,
            desired_time_s,
        } => {
            dst.put_u32_le(*camera_control);
            dst.put_f32_le(*desired_time_s);
        }
        M::SplineDurations {
            min_time_s,
            max_time_s,
        } => {
            dst.put_f32_le(*min_time_s);
            dst.put_f32_le(*max_time_s);
        }
        M::SplineAttach(index) => dst.put_u32_le(*index),
        M::SplineRecord | M::SplinePlay => {}
        other => debug_assert!(false, "{} is not a spline message", other.name()),
    }
}

pub(crate) fn decode(r: &mut Reader<'_>) -> Result<SoloMessage, DecodeError> {
    Ok(match r.msg_type() {
        ids::SPLINE_RECORD => SoloMessage::SplineRecord,
        ids::SPLINE_PLAY => SoloMessage::SplinePlay,
        ids::SPLINE_POINT => SoloMessage::SplinePoint(read_point(r)?),
        // The spec says u is normalised to 0..1; the reference clamps it, so only
        // finiteness is required here.
        ids::SPLINE_SEEK => SoloMessage::SplineSeek {
            u_position: r.f32("u_position")?,
            cruise_state: r.i32_in("cruise_state", -1, 1)?,
        },
        ids::SPLINE_PLAYBACK_STATUS => SoloMessage::SplinePlaybackStatus {
            u_position: r.f32("u_position")?,
            cruise_state: r.i32_in("cruise_state", -1, 1)?,
        },
        ids::SPLINE_PATH_SETTINGS => SoloMessage::SplinePathSettings {
            camera_control: r.u32_in("camera_control", 0, 1)?,
            desired_time_s: r.f32("desired_time")?,
        },
        ids::SPLINE_DURATIONS => SoloMessage::SplineDurations {
            min_time_s: r.f32("min_time")?,
            max_time_s: r.f32("max_time")?,
        },
        ids::SPLINE_ATTACH => SoloMessage::SplineAttach(r.u32()?),
        other => return Err(DecodeError::UnknownType(other)),
    })
}
