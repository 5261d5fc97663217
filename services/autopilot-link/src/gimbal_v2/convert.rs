//! Conversions and checks between MAVLink gimbal values and the pipeline's: angle
//! and rate limits, quaternions, lock flags, zoom types, ack results.

use super::*;

fn finite_or_nan(v: f32) -> bool {
    v.is_nan() || v.is_finite()
}

/// Checks angles (rad; NaN = leave) and rates (rad/s; NaN = none) against the
/// pipeline's limits: pitch ±90°, yaw ±180°.
pub(super) fn angles_ok(yaw: f32, pitch: f32, yaw_rate: f32, pitch_rate: f32) -> bool {
    let half = std::f32::consts::FRAC_PI_2 + 1e-4;
    let pi = std::f32::consts::PI + 1e-4;
    [yaw, pitch, yaw_rate, pitch_rate]
        .iter()
        .all(|v| finite_or_nan(*v))
        && (pitch.is_nan() || pitch.abs() <= half)
        && (yaw.is_nan() || yaw.abs() <= pi)
        && (yaw_rate.is_nan() || yaw_rate.abs() <= MAX_RATE)
        && (pitch_rate.is_nan() || pitch_rate.abs() <= MAX_RATE)
        && !(yaw.is_nan() && pitch.is_nan() && yaw_rate.is_nan() && pitch_rate.is_nan())
}

/// Yaw and pitch (rad) of a MAVLink gimbal quaternion `[w, x, y, z]` (roll dropped);
/// NaN/zero quaternion → `None`.
pub fn yaw_pitch_of(q: [f32; 4]) -> Option<(f32, f32)> {
    if q.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let q = Quaternion::new(q[0], q[1], q[2], q[3]);
    if q.norm() < 1e-6 {
        return None;
    }
    let (_roll, pitch, yaw) = UnitQuaternion::from_quaternion(q).euler_angles();
    Some((yaw, pitch))
}

/// The `GIMBAL_MANAGER_FLAGS` lock bits of a camera's `lock_flags`.
pub fn lock_flags(cam: &VirtualCamState) -> u32 {
    let mut f = 0;
    if cam.lock_flags & LOCK_ROLL != 0 {
        f |= FLAG_ROLL_LOCK;
    }
    if cam.lock_flags & LOCK_PITCH != 0 {
        f |= FLAG_PITCH_LOCK;
    }
    if cam.lock_flags & LOCK_YAW != 0 {
        f |= FLAG_YAW_LOCK | FLAG_YAW_IN_EARTH_FRAME;
    } else {
        f |= FLAG_YAW_IN_VEHICLE_FRAME;
    }
    f
}

/// The COMMAND_ACK result for a pipeline answer.
pub fn ack_of(result: VisionResult) -> MavResult {
    match result {
        VisionResult::Applied => MavResult::MAV_RESULT_ACCEPTED,
        VisionResult::Ignored => MavResult::MAV_RESULT_DENIED,
        VisionResult::Unsupported => MavResult::MAV_RESULT_UNSUPPORTED,
        VisionResult::Invalid | VisionResult::Failed => MavResult::MAV_RESULT_FAILED,
    }
}

pub(super) fn outcome_of(r: MavResult) -> &'static str {
    match r {
        MavResult::MAV_RESULT_ACCEPTED => "accepted",
        MavResult::MAV_RESULT_DENIED => "denied",
        MavResult::MAV_RESULT_UNSUPPORTED => "unsupported",
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED => "temporarily_rejected",
        _ => "failed",
    }
}
/// SET_CAMERA_ZOOM type and value → (CAMERA_ZOOM_TYPE, value), if valid.
pub(super) fn zoom(kind: f32, value: f32) -> Option<(u8, f32)> {
    if !kind.is_finite() || kind.fract() != 0.0 || !value.is_finite() {
        return None;
    }
    let ok = match kind as i32 {
        0 => value.abs() <= 100.0,
        1 => (-1.0..=1.0).contains(&value),
        2 => (0.0..=100.0).contains(&value),
        3 => value > 0.0 && value <= 2000.0,
        _ => false,
    };
    ok.then_some((kind as u8, value))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lock_flags_and_ack_mapping() {
        let mut cam = VirtualCamState::default();
        assert_eq!(lock_flags(&cam), FLAG_YAW_IN_VEHICLE_FRAME);
        cam.lock_flags = LOCK_YAW | LOCK_ROLL;
        assert_eq!(
            lock_flags(&cam),
            FLAG_YAW_LOCK | FLAG_YAW_IN_EARTH_FRAME | FLAG_ROLL_LOCK
        );
        assert_eq!(
            ack_of(VisionResult::Applied),
            MavResult::MAV_RESULT_ACCEPTED
        );
        assert_eq!(ack_of(VisionResult::Ignored), MavResult::MAV_RESULT_DENIED);
    }
}
