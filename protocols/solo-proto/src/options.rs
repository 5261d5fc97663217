//! Per-shot options (cable cam, follow, orbit/selfie, pano, zipline, rewind), pano
//! progress and the zipline lock. Most are sent both ways: the app sets them and
//! ShotManager reports what it uses. Ranges the reference ShotManager clamps itself
//! (pano field of view and lens, rewind distance) are only checked for finiteness
//! here; the engine clamps them like the reference does.

use bytes::{BufMut, BytesMut};

use crate::error::DecodeError;
use crate::ids;
use crate::message::SoloMessage;
use crate::wire::Reader;

pub(crate) fn encode(msg: &SoloMessage, dst: &mut BytesMut) {
    use SoloMessage as M;
    match msg {
        M::CableCamOptions {
            cam_interpolation,
            yaw_direction_cw,
            cruise_speed,
        } => {
            dst.put_u16_le(*cam_interpolation);
            dst.put_u16_le(*yaw_direction_cw);
            dst.put_f32_le(*cruise_speed);
        }
        M::FollowOptions {
            cruise_speed,
            look_at,
        } => {
            dst.put_f32_le(*cruise_speed);
            dst.put_i32_le(*look_at);
        }
        M::FollowOptionsV2 {
            cruise_speed,
            look_at,
            follow_preference,
        } => {
            dst.put_f32_le(*cruise_speed);
            dst.put_i32_le(*look_at);
            dst.put_i32_le(*follow_preference);
        }
        M::ShotOptions { cruise_speed } => dst.put_f32_le(*cruise_speed),
        M::PanoOptions {
            pano_type,
            run_state,
            cylinder_fov,
            deg_second_yaw,
            lens_fov,
        } => {
            dst.put_u8(*pano_type);
            dst.put_u8(*run_state);
            dst.put_i16_le(*cylinder_fov);
            dst.put_f32_le(*deg_second_yaw);
            dst.put_f32_le(*lens_fov);
        }
        M::ZiplineOptions {
            cruise_speed,
            is_3d,
            cam_pointing,
        } => {
            dst.put_f32_le(*cruise_speed);
            dst.put_u8(*is_3d);
            dst.put_u8(*cam_pointing);
        }
        M::RewindOptions {
            enabled,
            hover,
            rewind_distance,
        } => {
            dst.put_u8(*enabled);
            dst.put_u8(*hover);
            dst.put_f32_le(*rewind_distance);
        }
        M::PanoState { index, total } => {
            dst.put_u8(*index);
            dst.put_u8(*total);
        }
        M::ZiplineLock => {}
        other => debug_assert!(false, "{} is not an options message", other.name()),
    }
}

pub(crate) fn decode(r: &mut Reader<'_>) -> Result<SoloMessage, DecodeError> {
    Ok(match r.msg_type() {
        ids::CABLE_CAM_OPTIONS => SoloMessage::CableCamOptions {
            cam_interpolation: r.u16_in("cam_interpolation", 0, 1)?,
            yaw_direction_cw: r.u16_in("yaw_direction", 0, 1)?,
            cruise_speed: r.speed("cruise_speed")?,
        },
        ids::FOLLOW_OPTIONS => SoloMessage::FollowOptions {
            cruise_speed: r.speed("cruise_speed")?,
            look_at: r.i32_in("look_at", 0, 1)?,
        },
        ids::FOLLOW_OPTIONS_V2 => SoloMessage::FollowOptionsV2 {
            cruise_speed: r.speed("cruise_speed")?,
            look_at: r.i32_in("look_at", 0, 1)?,
            follow_preference: r.i32_in("follow_preference", 0, 2)?,
        },
        // Signed: orbit and cable cam use the sign for the direction of travel.
        ids::SHOT_OPTIONS => SoloMessage::ShotOptions {
            cruise_speed: r.speed("cruise_speed")?,
        },
        ids::PANO_OPTIONS => SoloMessage::PanoOptions {
            pano_type: r.u8_in("pano_type", 0, 2)?,
            // 0 setup, 1 run; the reference's own state also has 2 (exit), which it
            // may report, so it is accepted.
            run_state: r.u8_in("run_state", 0, 2)?,
            // The reference clamps to 91..=360 when the pano starts.
            cylinder_fov: r.i16()?,
            // The reference limits the video yaw rate to ±60 °/s itself.
            deg_second_yaw: r.f32("deg_second_yaw")?,
            // The reference clamps to 60..=180.
            lens_fov: r.f32("lens_fov")?,
        },
        ids::ZIPLINE_OPTIONS => SoloMessage::ZiplineOptions {
            cruise_speed: r.speed("cruise_speed")?,
            is_3d: r.u8_in("is_3d", 0, 1)?,
            cam_pointing: r.u8_in("cam_pointing", 0, 1)?,
        },
        ids::REWIND_OPTIONS => SoloMessage::RewindOptions {
            enabled: r.u8_in("enabled", 0, 1)?,
            hover: r.u8_in("hover", 0, 1)?,
            // The reference clamps to 10..=60 m.
            rewind_distance: r.f32("rewind_distance")?,
        },
        ids::PANO_STATE => SoloMessage::PanoState {
            index: r.u8()?,
            total: r.u8()?,
        },
        ids::ZIPLINE_LOCK => SoloMessage::ZiplineLock,
        other => return Err(DecodeError::UnknownType(other)),
    })
}
