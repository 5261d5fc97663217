//! Site Scan shots (inspect, scan, survey): all app → ShotManager.

use bytes::{BufMut, BytesMut};

use crate::error::DecodeError;
use crate::ids;
use crate::message::SoloMessage;
use crate::wire::{check_lat_lon, Reader};

pub(crate) fn encode(msg: &SoloMessage, dst: &mut BytesMut) {
    use SoloMessage as M;
    match msg {
        M::InspectStart { takeoff_alt_m } => dst.put_f32_le(*takeoff_alt_m),
        M::InspectSetWaypoint {
            lat_deg: a,
            lon_deg: b,
            alt_m: c,
        }
        | M::InspectMoveGimbal {
            pitch_deg: a,
            roll_deg: b,
            yaw_deg: c,
        }
        | M::InspectMoveVehicle {
            vx: a,
            vy: b,
            vz: c,
        } => {
            dst.put_f32_le(*a);
            dst.put_f32_le(*b);
            dst.put_f32_le(*c);
        }
        M::ScanStart | M::SurveyStart => {}
        other => debug_assert!(false, "{} is not a site scan message", other.name()),
    }
}

pub(crate) fn decode(r: &mut Reader<'_>) -> Result<SoloMessage, DecodeError> {
    Ok(match r.msg_type() {
        ids::INSPECT_START => SoloMessage::InspectStart {
            takeoff_alt_m: r.f32("takeoff_alt")?,
        },
        ids::INSPECT_SET_WAYPOINT => {
            let lat_deg = r.f32("latitude")?;
            let lon_deg = r.f32("longitude")?;
            check_lat_lon(
                r.msg_type(),
                "waypoint",
                f64::from(lat_deg),
                f64::from(lon_deg),
            )?;
            SoloMessage::InspectSetWaypoint {
                lat_deg,
                lon_deg,
                alt_m: r.f32("altitude")?,
            }
        }
        // The spec gives pitch 0..−90 and yaw 0..360 as the meaning, not as limits
        // the app keeps; the engine clamps.
        ids::INSPECT_MOVE_GIMBAL => SoloMessage::InspectMoveGimbal {
            pitch_deg: r.f32("pitch")?,
            roll_deg: r.f32("roll")?,
            yaw_deg: r.f32("yaw")?,
        },
        ids::INSPECT_MOVE_VEHICLE => SoloMessage::InspectMoveVehicle {
            vx: r.speed("vx")?,
            vy: r.speed("vy")?,
            vz: r.speed("vz")?,
        },
        ids::SCAN_START => SoloMessage::ScanStart,
        ids::SURVEY_START => SoloMessage::SurveyStart,
        other => return Err(DecodeError::UnknownType(other)),
    })
}
