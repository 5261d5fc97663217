//! Payload requests the simulator records: servo outputs, the last mount/gimbal
//! target asked for and MAVLink camera-protocol counters; tests and operators
//! read these back to see what a client asked for. The gimbal that moves is
//! [`super::Gimbal`], the GoPro behind the gimbal's bridge [`super::GoPro`].

use std::collections::BTreeMap;

/// The last gimbal/mount target a client asked for (also while an ROI overrides it).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MountTarget {
    /// Pitch, degrees (negative down).
    pub pitch_deg: f64,
    /// Roll, degrees.
    pub roll_deg: f64,
    /// Yaw, degrees.
    pub yaw_deg: f64,
    /// Pitch rate, degrees/s (gimbal manager only; NaN when not given).
    pub pitch_rate_dps: f64,
    /// Yaw rate, degrees/s (gimbal manager only; NaN when not given).
    pub yaw_rate_dps: f64,
}

/// Recorded payload commands.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Payload {
    /// Servo channel → PWM µs from MAV_CMD_DO_SET_SERVO.
    pub servos: BTreeMap<u8, u16>,
    /// Last mount/gimbal target.
    pub mount: Option<MountTarget>,
    /// Images "taken" (MAV_CMD_IMAGE_START_CAPTURE counts the requested total).
    pub images_captured: u64,
    /// Interval of a running image sequence, seconds (None when stopped).
    pub image_interval_s: Option<f64>,
    /// A video capture is running.
    pub video_recording: bool,
    /// Video captures started.
    pub video_starts: u64,
}
