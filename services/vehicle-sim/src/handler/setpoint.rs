//! SET_POSITION_TARGET_LOCAL_NED / SET_POSITION_TARGET_GLOBAL_INT → a
//! [`GuidedTarget`] in local NED, following ArduCopter's reading of
//! `type_mask` and frames (GCS_MAVLINK_Copter::handle_message_set_position_target_*).

// The *_INT and BODY_* frames are deprecated in MAVLink but still sent by
// ground stations and honoured by ArduPilot.
#![allow(deprecated)]

use mavlink::dialects::ardupilotmega::{
    MavFrame, PositionTargetTypemask as Mask, SET_POSITION_TARGET_GLOBAL_INT_DATA,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use nalgebra::Vector3;
use tracing::debug;

use crate::model::{GeoPoint, GuidedTarget, NotGuided, Vehicle};

/// Why a setpoint was dropped without effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Ignored {
    /// A frame ArduCopter does not accept for this message.
    Frame(MavFrame),
    /// Force setpoints are not supported (ArduCopter drops them too).
    ForceSet,
    /// Latitude/longitude out of range.
    BadLatLon,
}

/// The type_mask read as ArduCopter does: position/velocity/acceleration are
/// used only when none of their three axes is ignored.
struct Use {
    pos: bool,
    vel: bool,
    acc: bool,
    yaw: bool,
    yaw_rate: bool,
    force: bool,
}

impl Use {
    fn from(mask: Mask) -> Self {
        let all = |bits: Mask| mask.contains(bits);
        Self {
            pos: !all(Mask::POSITION_TARGET_TYPEMASK_X_IGNORE
                | Mask::POSITION_TARGET_TYPEMASK_Y_IGNORE
                | Mask::POSITION_TARGET_TYPEMASK_Z_IGNORE),
            vel: !all(Mask::POSITION_TARGET_TYPEMASK_VX_IGNORE
                | Mask::POSITION_TARGET_TYPEMASK_VY_IGNORE
                | Mask::POSITION_TARGET_TYPEMASK_VZ_IGNORE),
            acc: !all(Mask::POSITION_TARGET_TYPEMASK_AX_IGNORE
                | Mask::POSITION_TARGET_TYPEMASK_AY_IGNORE
                | Mask::POSITION_TARGET_TYPEMASK_AZ_IGNORE),
            yaw: !mask.contains(Mask::POSITION_TARGET_TYPEMASK_YAW_IGNORE),
            yaw_rate: !mask.contains(Mask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE),
            force: mask.contains(Mask::POSITION_TARGET_TYPEMASK_FORCE_SET),
        }
    }

    fn check(&self) -> Result<(), Ignored> {
        if self.force && self.acc {
            return Err(Ignored::ForceSet);
        }
        if self.acc && !self.pos && !self.vel {
            // Acceleration-only control is not simulated: the target becomes
            // empty, which stops and holds like ArduCopter's invalid-input case.
            debug!("acceleration setpoints are not simulated; holding position");
        }
        Ok(())
    }

    fn yaw_parts(&self, yaw: f32, yaw_rate: f32) -> (Option<f64>, Option<f64>) {
        let finite = |x: f32| x.is_finite().then_some(f64::from(x));
        (
            if self.yaw { finite(yaw) } else { None },
            if self.yaw_rate {
                finite(yaw_rate)
            } else {
                None
            },
        )
    }
}

/// SET_POSITION_TARGET_LOCAL_NED → target.
pub(super) fn local_ned(
    v: &Vehicle,
    d: &SET_POSITION_TARGET_LOCAL_NED_DATA,
) -> Result<GuidedTarget, Ignored> {
    let u = Use::from(d.type_mask);
    u.check()?;
    let here = v.position_ned();
    let yaw_now = v.attitude().yaw;
    let p = Vector3::new(f64::from(d.x), f64::from(d.y), f64::from(d.z));
    let vel = Vector3::new(f64::from(d.vx), f64::from(d.vy), f64::from(d.vz));
    let (pos, vel, body) = match d.coordinate_frame {
        MavFrame::MAV_FRAME_LOCAL_NED => (p, vel, false),
        MavFrame::MAV_FRAME_LOCAL_OFFSET_NED => (here + p, vel, false),
        // ArduCopter treats both body frames as "offset from here, rotated by yaw".
        MavFrame::MAV_FRAME_BODY_NED | MavFrame::MAV_FRAME_BODY_OFFSET_NED => (
            here + rotate_by_yaw(&p, yaw_now),
            rotate_by_yaw(&vel, yaw_now),
            true,
        ),
        other => return Err(Ignored::Frame(other)),
    };
    let (yaw, yaw_rate) = u.yaw_parts(d.yaw, d.yaw_rate);
    Ok(GuidedTarget {
        pos: u.pos.then_some(pos),
        vel: u.vel.then_some(vel),
        yaw,
        yaw_rate,
        yaw_relative: body,
    })
}

/// SET_POSITION_TARGET_GLOBAL_INT → target.
pub(super) fn global_int(
    v: &Vehicle,
    d: &SET_POSITION_TARGET_GLOBAL_INT_DATA,
) -> Result<GuidedTarget, Ignored> {
    let u = Use::from(d.type_mask);
    u.check()?;
    let pos = if u.pos {
        let lat = f64::from(d.lat_int) / 1e7;
        let lon = f64::from(d.lon_int) / 1e7;
        Some(
            global_to_ned(v, lat, lon, f64::from(d.alt), d.coordinate_frame).ok_or(
                match d.coordinate_frame {
                    f if is_global(f) => Ignored::BadLatLon,
                    f => Ignored::Frame(f),
                },
            )?,
        )
    } else if is_global(d.coordinate_frame) {
        None
    } else {
        return Err(Ignored::Frame(d.coordinate_frame));
    };
    let vel = Vector3::new(f64::from(d.vx), f64::from(d.vy), f64::from(d.vz));
    let (yaw, yaw_rate) = u.yaw_parts(d.yaw, d.yaw_rate);
    Ok(GuidedTarget {
        pos,
        vel: u.vel.then_some(vel),
        yaw,
        yaw_rate,
        yaw_relative: false,
    })
}

fn is_global(frame: MavFrame) -> bool {
    matches!(
        frame,
        MavFrame::MAV_FRAME_GLOBAL
            | MavFrame::MAV_FRAME_GLOBAL_INT
            | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT
            | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
            | MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT
            | MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT_INT
    )
}

/// A global location → local NED. Altitude is MSL for GLOBAL(_INT), above home
/// for RELATIVE_ALT, and above the (flat) ground for TERRAIN_ALT — which, with
/// home on the ground, is the same as relative. `None` for a non-global frame
/// or an impossible latitude/longitude.
pub(super) fn global_to_ned(
    v: &Vehicle,
    lat: f64,
    lon: f64,
    alt: f64,
    frame: MavFrame,
) -> Option<Vector3<f64>> {
    if !((-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon)) {
        return None;
    }
    let origin_alt = v.frame().origin().alt_msl_m;
    let alt_msl = match frame {
        MavFrame::MAV_FRAME_GLOBAL | MavFrame::MAV_FRAME_GLOBAL_INT => alt,
        MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT => {
            v.home_geo().map_or(origin_alt, |h| h.alt_msl_m) + alt
        }
        MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT | MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT_INT => {
            origin_alt + alt
        }
        _ => return None,
    };
    Some(v.frame().to_ned(&GeoPoint {
        lat_deg: lat,
        lon_deg: lon,
        alt_msl_m: alt_msl,
    }))
}

/// Rotate a body-frame (forward/right/down) vector by heading into NED.
fn rotate_by_yaw(b: &Vector3<f64>, yaw: f64) -> Vector3<f64> {
    let (s, c) = yaw.sin_cos();
    Vector3::new(b.x * c - b.y * s, b.x * s + b.y * c, b.z)
}

/// Give a decoded setpoint to the vehicle; ArduCopter drops setpoints silently
/// outside GUIDED, so only the log says why.
pub(super) fn apply(v: &mut Vehicle, target: Result<GuidedTarget, Ignored>, what: &str) {
    match target {
        Ok(t) => {
            if let Err(NotGuided(mode)) = v.guided_target(t) {
                debug!(message = what, %mode, "setpoint ignored outside GUIDED");
            }
        }
        Err(why) => debug!(message = what, ?why, "setpoint ignored"),
    }
}
