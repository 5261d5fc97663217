//! Gimbal commands, answered the way ArduPilot's mount library answers them
//! (`AP_Mount::handle_command_do_mount_control`,
//! `handle_command_do_gimbal_manager_pitchyaw`). Every accepted request is
//! recorded in `Payload::mount`; while an ROI is set it is accepted but the ROI
//! keeps the camera (see `model::gimbal`).

use mavlink::dialects::ardupilotmega::MavResult;
use tracing::debug;

use super::command::Cmd;
use crate::model::{GimbalTarget, MountTarget, Vehicle, YawFrame};

/// MAV_MOUNT_MODE values DO_MOUNT_CONTROL carries in param7.
const MOUNT_MODE_RETRACT: u32 = 0;
const MOUNT_MODE_NEUTRAL: u32 = 1;
const MOUNT_MODE_MAVLINK_TARGETING: u32 = 2;
const MOUNT_MODE_RC_TARGETING: u32 = 3;
const MOUNT_MODE_HOME_LOCATION: u32 = 6;

/// GIMBAL_MANAGER_FLAGS.
const FLAG_RETRACT: u32 = 1;
const FLAG_NEUTRAL: u32 = 2;
const FLAG_YAW_LOCK: u32 = 16;
const FLAG_YAW_IN_VEHICLE_FRAME: u32 = 32;
const FLAG_YAW_IN_EARTH_FRAME: u32 = 64;

/// The simulated vehicle has one gimbal: device id 1 (0 addresses all).
const GIMBAL_DEVICE_ID: u32 = 1;

/// Retracted and neutral both mean level and forward on the simulated gimbal.
const NEUTRAL: GimbalTarget = GimbalTarget::Angles {
    pitch: 0.0,
    yaw: 0.0,
    yaw_frame: YawFrame::Vehicle,
};

/// DO_MOUNT_CONTROL: param1 pitch, param2 roll, param3 yaw (degrees, yaw
/// relative to the nose), param7 MAV_MOUNT_MODE.
pub(super) fn mount_control(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    use MavResult::*;
    let [pitch, roll, yaw, _] = cmd.p;
    let mode = cmd.p7;
    if !(mode >= 0.0 && mode.fract() == 0.0) {
        return MAV_RESULT_FAILED;
    }
    let target = match mode as u32 {
        MOUNT_MODE_RETRACT | MOUNT_MODE_NEUTRAL => NEUTRAL,
        MOUNT_MODE_MAVLINK_TARGETING => {
            // ArduPilot's guard against centidegrees (and NaN).
            if !(pitch.abs() <= 90.0 && roll.abs() <= 180.0 && yaw.abs() <= 360.0) {
                return MAV_RESULT_FAILED;
            }
            GimbalTarget::Angles {
                pitch: f64::from(pitch).to_radians(),
                yaw: f64::from(yaw).to_radians(),
                yaw_frame: YawFrame::Vehicle,
            }
        }
        // No RC on the simulator: the mount holds where it points.
        MOUNT_MODE_RC_TARGETING => GimbalTarget::Hold,
        // GPS_POINT, SYSID_TARGET, HOME_LOCATION: the mount's own location
        // targets are not simulated (DO_SET_ROI_LOCATION points it instead).
        m if m <= MOUNT_MODE_HOME_LOCATION => return MAV_RESULT_UNSUPPORTED,
        _ => return MAV_RESULT_FAILED,
    };
    v.payload_mut().mount = Some(MountTarget {
        pitch_deg: f64::from(pitch),
        roll_deg: f64::from(roll),
        yaw_deg: f64::from(yaw),
        pitch_rate_dps: f64::NAN,
        yaw_rate_dps: f64::NAN,
    });
    point(v, target);
    MAV_RESULT_ACCEPTED
}

/// Fastest rate DO_GIMBAL_MANAGER_PITCHYAW may ask for, deg/s (one turn a second);
/// the gimbal itself turns at most at its slew rate.
const MAX_RATE_DPS: f32 = 360.0;

/// DO_GIMBAL_MANAGER_PITCHYAW: param1 pitch, param2 yaw (degrees), param3/4
/// pitch/yaw rates (deg/s, used when an angle is NaN), param5
/// GIMBAL_MANAGER_FLAGS, param7 gimbal device id.
///
/// Rates turn the gimbal (no faster than its slew rate, stopping at the ends of
/// its travel) until the next angle or rate command; rates of 0 hold it where it
/// is. As ArduPilot: FAILED for another gimbal device or when neither both
/// angles nor both rates are given. Beyond ArduPilot: a rate that is infinite or
/// faster than 360 deg/s is DENIED.
pub(super) fn manager_pitchyaw(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    use MavResult::*;
    let [pitch, yaw, pitch_rate, yaw_rate] = cmd.p;
    let device = cmd.p7;
    if !(device == 0.0 || device == GIMBAL_DEVICE_ID as f32) {
        return MAV_RESULT_FAILED;
    }
    if !(cmd.p5 >= 0.0 && cmd.p5 <= f64::from(u32::MAX)) {
        return MAV_RESULT_FAILED;
    }
    let flags = cmd.p5 as u32;
    // Yaw is earth-fixed when locked or said so, unless it says vehicle frame.
    let yaw_frame = if flags & (FLAG_YAW_LOCK | FLAG_YAW_IN_EARTH_FRAME) != 0
        && flags & FLAG_YAW_IN_VEHICLE_FRAME == 0
    {
        YawFrame::Earth
    } else {
        YawFrame::Vehicle
    };
    let target = if flags & (FLAG_RETRACT | FLAG_NEUTRAL) != 0 {
        NEUTRAL
    } else if pitch.is_finite() && yaw.is_finite() {
        GimbalTarget::Angles {
            pitch: f64::from(pitch).to_radians(),
            yaw: f64::from(yaw).to_radians(),
            yaw_frame,
        }
    } else if !(pitch_rate.is_nan() || yaw_rate.is_nan()) {
        if !(pitch_rate.abs() <= MAX_RATE_DPS && yaw_rate.abs() <= MAX_RATE_DPS) {
            return MAV_RESULT_DENIED;
        }
        GimbalTarget::Rates {
            pitch: f64::from(pitch_rate).to_radians(),
            yaw: f64::from(yaw_rate).to_radians(),
        }
    } else {
        return MAV_RESULT_FAILED;
    };
    v.payload_mut().mount = Some(MountTarget {
        pitch_deg: f64::from(pitch),
        roll_deg: 0.0,
        yaw_deg: f64::from(yaw),
        pitch_rate_dps: f64::from(pitch_rate),
        yaw_rate_dps: f64::from(yaw_rate),
    });
    point(v, target);
    MAV_RESULT_ACCEPTED
}

fn point(v: &mut Vehicle, target: GimbalTarget) {
    if !v.point_gimbal(target) {
        debug!(?target, "gimbal target recorded; the ROI keeps the camera");
    }
}
