//! Payload requests the simulator records: servo outputs, the last mount/gimbal
//! target asked for and MAVLink camera-protocol counters; tests and operators
//! read these back to see what a client asked for. The gimbal that moves is
//! [`super::Gimbal`], the GoPro behind the gimbal's bridge [`super::GoPro`]; the
//! camera's zoom ([`Zoom`]) moves with sim time.

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
    /// The camera's zoom (MAV_CMD_SET_CAMERA_ZOOM).
    pub zoom: Zoom,
}

/// One zoom step (CAMERA_ZOOM_TYPE step), percent of the zoom range.
pub const ZOOM_STEP_PCT: f64 = 1.0;

/// Continuous zoom at full rate (value ±1), percent of the range per second.
pub const ZOOM_RATE_PCT_S: f64 = 20.0;

/// Most steps one command may ask for (the whole range).
pub const MAX_ZOOM_STEPS: f64 = 100.0 / ZOOM_STEP_PCT;

/// The simulated camera's zoom, 0 % (widest) ..= 100 % (longest), as
/// MAV_CMD_SET_CAMERA_ZOOM sets it: steps of [`ZOOM_STEP_PCT`], a continuous zoom
/// at up to [`ZOOM_RATE_PCT_S`] until stopped or at a limit, or a level. Each
/// command replaces a continuous zoom in progress.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Zoom {
    level_pct: f64,
    /// −1..=1 of [`ZOOM_RATE_PCT_S`]; 0 = not zooming.
    rate: f64,
}

/// Why a zoom command was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ZoomRefusal {
    /// Steps not finite or more than [`MAX_ZOOM_STEPS`] either way.
    Steps(f64),
    /// A continuous rate that is not a number.
    Rate(f64),
    /// A level outside 0..=100 %.
    Level(f64),
}

impl Zoom {
    /// Zoom level, percent of the range.
    pub fn level_pct(&self) -> f64 {
        self.level_pct
    }

    /// Continuous zoom rate, −1..=1 (0 = not zooming).
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// `steps` steps in (+) or out (−), stopping at the ends.
    pub fn step_by(&mut self, steps: f64) -> Result<(), ZoomRefusal> {
        if !(steps.is_finite() && steps.abs() <= MAX_ZOOM_STEPS) {
            return Err(ZoomRefusal::Steps(steps));
        }
        self.rate = 0.0;
        self.level_pct = (self.level_pct + steps * ZOOM_STEP_PCT).clamp(0.0, 100.0);
        Ok(())
    }

    /// Keep zooming in (+), out (−) or stop (0); values beyond ±1 are clipped, as
    /// MAVLink's CAMERA_ZOOM_TYPE continuous says.
    pub fn continuous(&mut self, rate: f64) -> Result<(), ZoomRefusal> {
        if !rate.is_finite() {
            return Err(ZoomRefusal::Rate(rate));
        }
        self.rate = rate.clamp(-1.0, 1.0);
        Ok(())
    }

    /// Go to `pct` percent of the range.
    pub fn set_level(&mut self, pct: f64) -> Result<(), ZoomRefusal> {
        if !(0.0..=100.0).contains(&pct) {
            return Err(ZoomRefusal::Level(pct));
        }
        self.rate = 0.0;
        self.level_pct = pct;
        Ok(())
    }

    /// Advance a continuous zoom by `dt` seconds; it stops at either end.
    pub fn step(&mut self, dt: f64) {
        if self.rate == 0.0 {
            return;
        }
        self.level_pct += self.rate * ZOOM_RATE_PCT_S * dt;
        if !(0.0..=100.0).contains(&self.level_pct) {
            self.level_pct = self.level_pct.clamp(0.0, 100.0);
            self.rate = 0.0;
        }
    }
}
