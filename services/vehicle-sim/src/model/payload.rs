//! Payload requests the simulator records: servo outputs, the last mount/gimbal
//! target asked for and MAVLink camera-protocol counters; tests and operators
//! read these back to see what a client asked for. The gimbal that moves is
//! [`super::Gimbal`], the GoPro behind the gimbal's bridge [`super::GoPro`]; the
//! MAVLink camera's zoom ([`Zoom`]), focus ([`Focus`]) and image sequence
//! ([`ImageSequence`]) move with sim time ([`Payload::step`]); its mode
//! ([`CameraMode`]) is recorded (captures do not depend on it, as on ArduPilot,
//! whose camera backends take a photo or a video in any mode).

use std::collections::BTreeMap;

use super::focus::Focus;

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
    /// Images taken (MAV_CMD_IMAGE_START_CAPTURE: the first at once, the rest of a
    /// sequence one per interval).
    pub images_captured: u64,
    /// The running interval or continuous image sequence (None when stopped).
    pub image_sequence: Option<ImageSequence>,
    /// A video capture is running.
    pub video_recording: bool,
    /// Video captures started.
    pub video_starts: u64,
    /// The camera's mode (MAV_CMD_SET_CAMERA_MODE).
    pub camera_mode: CameraMode,
    /// The camera's zoom (MAV_CMD_SET_CAMERA_ZOOM).
    pub zoom: Zoom,
    /// The camera's focus (MAV_CMD_SET_CAMERA_FOCUS).
    pub focus: Focus,
}

impl Payload {
    /// Advance the camera by `dt` seconds: zoom, focus, image sequence.
    pub fn step(&mut self, dt: f64) {
        if !(dt > 0.0 && dt.is_finite()) {
            return;
        }
        self.zoom.step(dt);
        self.focus.step(dt);
        if let Some(seq) = &mut self.image_sequence {
            let (taken, done) = seq.step(dt);
            self.images_captured = self.images_captured.saturating_add(taken);
            if done {
                self.image_sequence = None;
            }
        }
    }

    /// MAV_CMD_IMAGE_START_CAPTURE: `total` images (0 = until stopped) `interval_s`
    /// apart. The first is taken at once; with no interval a finite total is taken
    /// at once (the simulated camera needs no time). A single image leaves a
    /// running sequence alone; a new sequence replaces it.
    pub fn start_capture(&mut self, interval_s: f64, total: f64) -> Result<(), CaptureRefusal> {
        if !(total.is_finite() && total >= 0.0 && total.fract() == 0.0 && total <= MAX_IMAGES) {
            return Err(CaptureRefusal::Total(total));
        }
        if !(interval_s.is_finite() && interval_s >= 0.0) {
            return Err(CaptureRefusal::Interval(interval_s));
        }
        let total = total as u64;
        if total == 0 && interval_s == 0.0 {
            return Err(CaptureRefusal::Interval(interval_s));
        }
        if total == 1 || (total > 1 && interval_s == 0.0) {
            self.images_captured = self.images_captured.saturating_add(total);
            return Ok(());
        }
        self.images_captured = self.images_captured.saturating_add(1);
        self.image_sequence = Some(ImageSequence {
            interval_s,
            remaining: (total > 0).then(|| total - 1),
            since_last_s: 0.0,
        });
        Ok(())
    }

    /// MAV_CMD_IMAGE_STOP_CAPTURE: end the running sequence. Returns whether one ran.
    pub fn stop_capture(&mut self) -> bool {
        self.image_sequence.take().is_some()
    }
}

/// The MAVLink camera's mode, numbered as MAVLink CAMERA_MODE.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum CameraMode {
    /// Still photos (the mode a camera starts in).
    #[default]
    Image,
    /// Video.
    Video,
    /// Still photos with survey settings.
    ImageSurvey,
}

impl CameraMode {
    /// From MAV_CMD_SET_CAMERA_MODE param2; `None` for anything MAVLink does not define.
    pub fn from_param(p: f32) -> Option<Self> {
        match p {
            0.0 => Some(CameraMode::Image),
            1.0 => Some(CameraMode::Video),
            2.0 => Some(CameraMode::ImageSurvey),
            _ => None,
        }
    }
}

/// Most images one MAV_CMD_IMAGE_START_CAPTURE may ask for.
pub const MAX_IMAGES: f64 = 1_000_000.0;

/// A running image sequence: one photo every `interval_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageSequence {
    /// Seconds between photos (> 0).
    pub interval_s: f64,
    /// Photos still to take; `None` = until MAV_CMD_IMAGE_STOP_CAPTURE.
    pub remaining: Option<u64>,
    /// Time since the last photo.
    since_last_s: f64,
}

impl ImageSequence {
    /// Photos taken during `dt`, and whether the sequence is complete.
    fn step(&mut self, dt: f64) -> (u64, bool) {
        self.since_last_s += dt;
        // Counted, not looped: a tiny interval costs nothing (`as` saturates).
        let due = (self.since_last_s / self.interval_s).floor() as u64;
        let taken = self.remaining.map_or(due, |r| due.min(r));
        self.since_last_s -= taken as f64 * self.interval_s;
        if let Some(r) = &mut self.remaining {
            *r -= taken;
        }
        (taken, self.remaining == Some(0))
    }
}

/// Why MAV_CMD_IMAGE_START_CAPTURE was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CaptureRefusal {
    /// The total is not a whole number in 0..=[`MAX_IMAGES`].
    Total(f64),
    /// The interval is negative or not a number, or 0 for an endless sequence.
    Interval(f64),
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

#[cfg(test)]
mod tests {
    use super::*;

    fn run(p: &mut Payload, secs: f64) {
        for _ in 0..(secs / 0.01).round() as usize {
            p.step(0.01);
        }
    }

    #[test]
    fn interval_sequence_takes_one_photo_per_interval_until_stopped() {
        let mut p = Payload::default();
        p.start_capture(2.0, 0.0).unwrap();
        assert_eq!(p.images_captured, 1, "the first at once");
        run(&mut p, 5.0);
        assert_eq!(p.images_captured, 3, "at 2 s and 4 s");
        assert!(p.stop_capture());
        run(&mut p, 10.0);
        assert_eq!(p.images_captured, 3, "stopped");
        assert!(!p.stop_capture(), "nothing left to stop");
    }

    #[test]
    fn finite_sequence_ends_by_itself_and_single_photos_leave_it_running() {
        let mut p = Payload::default();
        p.start_capture(1.0, 3.0).unwrap();
        run(&mut p, 0.5);
        p.start_capture(0.0, 1.0).unwrap();
        assert_eq!(p.images_captured, 2);
        run(&mut p, 10.0);
        assert_eq!(p.images_captured, 4, "1 + 2 more + the single one");
        assert_eq!(p.image_sequence, None);
        // No interval: a finite total at once.
        p.start_capture(0.0, 5.0).unwrap();
        assert_eq!((p.images_captured, p.image_sequence), (9, None));
    }

    #[test]
    fn capture_refusals_change_nothing() {
        let mut p = Payload::default();
        for (interval, total) in [
            (0.0, 0.0),
            (-1.0, 0.0),
            (f64::NAN, 3.0),
            (1.0, -1.0),
            (1.0, 2.5),
            (1.0, f64::INFINITY),
            (1.0, MAX_IMAGES + 1.0),
        ] {
            assert!(
                p.start_capture(interval, total).is_err(),
                "{interval} {total}"
            );
        }
        assert_eq!((p.images_captured, p.image_sequence), (0, None));
    }
}
