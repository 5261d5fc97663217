//! A GoPro HERO4 Black behind the Solo gimbal's MAVLink GoPro bridge: capture
//! mode, shutter, the settings the bridge exposes (GOPRO_COMMAND), a battery and
//! a clock. Pure: stepped with an explicit `dt`.
//!
//! Values are MAVLink's enums as bytes (`GOPRO_SET_REQUEST.value`), checked
//! against the enum's range; anything else is refused and changes nothing.
//! Simplifications: resolution/frame-rate combinations a real HERO4 does not
//! offer are accepted (only each value's range is checked), and MULTI_SHOT
//! behaves like BURST (the HERO4's default multi-shot sub-mode).

use mavlink::dialects::ardupilotmega::{
    GoproBurstRate, GoproCaptureMode, GoproCommand, GoproFieldOfView, GoproFrameRate, GoproModel,
    GoproPhotoResolution, GoproProtuneColour, GoproProtuneExposure, GoproProtuneGain,
    GoproProtuneSharpness, GoproProtuneWhiteBalance, GoproResolution,
};

/// Seconds between photos in TIME_LAPSE (the HERO4's default interval).
pub const TIME_LAPSE_INTERVAL_S: f64 = 0.5;

/// Battery use, percent per second: recording, merely on, and charging (gain).
const DRAIN_RECORDING_PCT_S: f64 = 1.0 / 60.0;
const DRAIN_IDLE_PCT_S: f64 = 0.25 / 60.0;
const CHARGE_PCT_S: f64 = 1.0 / 60.0;

/// Photos per burst for each GOPRO_BURST_RATE.
const BURST_PHOTOS: [u64; 9] = [3, 5, 10, 10, 10, 30, 30, 30, 30];

/// Bit 0 of VIDEO_SETTINGS `value[3]` (GOPRO_VIDEO_SETTINGS_TV_MODE): PAL.
const VIDEO_FLAG_PAL: u8 = 1;

/// Why a request was refused (answered GOPRO_REQUEST_FAILED).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GoProRefusal {
    /// The camera is off; only POWER is answered.
    #[error("the GoPro is powered off")]
    PoweredOff,
    /// BATTERY and MODEL can only be read.
    #[error("{0:?} is read-only")]
    ReadOnly(GoproCommand),
    /// A value outside the command's enum (or an unknown flag bit).
    #[error("{command:?} value {value:?} is out of range")]
    OutOfRange {
        /// The command.
        command: GoproCommand,
        /// The four value bytes as sent.
        value: [u8; 4],
    },
    /// Settings and mode cannot change while recording.
    #[error("{0:?} refused while recording")]
    Busy(GoproCommand),
    /// The battery is empty; the camera cannot power on.
    #[error("the GoPro battery is empty")]
    BatteryEmpty,
}

/// Video settings (GOPRO_COMMAND_VIDEO_SETTINGS), as MAVLink enum values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VideoSettings {
    /// GOPRO_RESOLUTION.
    pub resolution: u8,
    /// GOPRO_FRAME_RATE.
    pub frame_rate: u8,
    /// GOPRO_FIELD_OF_VIEW.
    pub field_of_view: u8,
    /// PAL (true) or NTSC.
    pub pal: bool,
}

/// Protune settings, as MAVLink enum values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Protune {
    /// Protune on.
    pub enabled: bool,
    /// GOPRO_PROTUNE_WHITE_BALANCE.
    pub white_balance: u8,
    /// GOPRO_PROTUNE_COLOUR.
    pub colour: u8,
    /// GOPRO_PROTUNE_GAIN.
    pub gain: u8,
    /// GOPRO_PROTUNE_SHARPNESS.
    pub sharpness: u8,
    /// GOPRO_PROTUNE_EXPOSURE.
    pub exposure: u8,
}

/// What the GOPRO_HEARTBEAT reports; a change triggers an immediate heartbeat.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoProHeartbeat {
    /// Powered on (CONNECTED) or off (DISCONNECTED).
    pub powered: bool,
    /// Capture mode (UNKNOWN while off).
    pub capture_mode: GoproCaptureMode,
    /// Recording video or a time lapse.
    pub recording: bool,
}

/// The simulated HERO4 Black.
#[derive(Debug, Clone, PartialEq)]
pub struct GoPro {
    powered: bool,
    mode: GoproCaptureMode,
    recording: bool,
    photos_taken: u64,
    video: VideoSettings,
    low_light: bool,
    photo_resolution: u8,
    burst_rate: u8,
    protune: Protune,
    charging: bool,
    battery_pct: f64,
    /// Camera clock: seconds since the epoch as last set, plus time since.
    clock_base: u32,
    /// Whole microseconds, so the clock does not drift from summing `dt`s.
    since_clock_set_us: u64,
    /// Time since the last time-lapse photo.
    lapse_s: f64,
}

impl Default for GoPro {
    /// On, in video mode, 1080p30 wide NTSC, full battery.
    fn default() -> Self {
        Self {
            powered: true,
            mode: GoproCaptureMode::GOPRO_CAPTURE_MODE_VIDEO,
            recording: false,
            photos_taken: 0,
            video: VideoSettings {
                resolution: GoproResolution::GOPRO_RESOLUTION_1080p as u8,
                frame_rate: GoproFrameRate::GOPRO_FRAME_RATE_30 as u8,
                field_of_view: GoproFieldOfView::GOPRO_FIELD_OF_VIEW_WIDE as u8,
                pal: false,
            },
            low_light: false,
            photo_resolution: GoproPhotoResolution::GOPRO_PHOTO_RESOLUTION_12MP_WIDE as u8,
            burst_rate: GoproBurstRate::GOPRO_BURST_RATE_10_IN_1_SECOND as u8,
            protune: Protune {
                enabled: false,
                white_balance: GoproProtuneWhiteBalance::GOPRO_PROTUNE_WHITE_BALANCE_AUTO as u8,
                colour: GoproProtuneColour::GOPRO_PROTUNE_COLOUR_STANDARD as u8,
                gain: GoproProtuneGain::GOPRO_PROTUNE_GAIN_400 as u8,
                sharpness: GoproProtuneSharpness::GOPRO_PROTUNE_SHARPNESS_HIGH as u8,
                exposure: GoproProtuneExposure::GOPRO_PROTUNE_EXPOSURE_ZERO as u8,
            },
            charging: false,
            battery_pct: 100.0,
            clock_base: 0,
            since_clock_set_us: 0,
            lapse_s: 0.0,
        }
    }
}

/// Capture modes a client may select (PLAYBACK, SETUP and UNKNOWN are states
/// the camera reports, not modes to capture in).
fn capture_mode(v: u8) -> Option<GoproCaptureMode> {
    use GoproCaptureMode::*;
    Some(match v {
        0 => GOPRO_CAPTURE_MODE_VIDEO,
        1 => GOPRO_CAPTURE_MODE_PHOTO,
        2 => GOPRO_CAPTURE_MODE_BURST,
        3 => GOPRO_CAPTURE_MODE_TIME_LAPSE,
        4 => GOPRO_CAPTURE_MODE_MULTI_SHOT,
        _ => return None,
    })
}

/// `v` if it is at most `max` (the enum's last value).
fn upto(v: u8, max: u8) -> Option<u8> {
    (v <= max).then_some(v)
}

fn flag(v: u8) -> Option<bool> {
    match v {
        0 => Some(false),
        1 => Some(true),
        _ => None,
    }
}

impl GoPro {
    /// Advance by `dt` seconds: battery, clock, time-lapse photos. Returns true
    /// when what the heartbeat reports changed (the battery ran out).
    pub fn step(&mut self, dt: f64) -> bool {
        if !(dt > 0.0 && dt.is_finite()) {
            return false;
        }
        self.since_clock_set_us += (dt * 1e6).round() as u64;
        if !self.powered {
            return false;
        }
        if self.recording && self.mode == GoproCaptureMode::GOPRO_CAPTURE_MODE_TIME_LAPSE {
            self.lapse_s += dt;
            while self.lapse_s >= TIME_LAPSE_INTERVAL_S {
                self.lapse_s -= TIME_LAPSE_INTERVAL_S;
                self.photos_taken += 1;
            }
        }
        let rate = if self.charging {
            -CHARGE_PCT_S
        } else if self.recording {
            DRAIN_RECORDING_PCT_S
        } else {
            DRAIN_IDLE_PCT_S
        };
        self.battery_pct = (self.battery_pct - rate * dt).clamp(0.0, 100.0);
        if self.battery_pct <= 0.0 {
            self.powered = false;
            self.recording = false;
            return true;
        }
        false
    }

    /// What GOPRO_HEARTBEAT reports.
    pub fn heartbeat(&self) -> GoProHeartbeat {
        GoProHeartbeat {
            powered: self.powered,
            capture_mode: if self.powered {
                self.mode
            } else {
                GoproCaptureMode::GOPRO_CAPTURE_MODE_UNKNOWN
            },
            recording: self.powered && self.recording,
        }
    }

    /// Recording video or a time lapse.
    pub fn recording(&self) -> bool {
        self.recording
    }

    /// Photos taken since start (single, burst and time-lapse frames).
    pub fn photos_taken(&self) -> u64 {
        self.photos_taken
    }

    /// Current capture mode.
    pub fn capture_mode(&self) -> GoproCaptureMode {
        self.mode
    }

    /// Video settings.
    pub fn video(&self) -> VideoSettings {
        self.video
    }

    /// Protune settings.
    pub fn protune(&self) -> Protune {
        self.protune
    }

    /// Battery, percent.
    pub fn battery_percent(&self) -> f64 {
        self.battery_pct
    }

    /// GOPRO_SET_REQUEST. `Ok(true)` when what the heartbeat reports changed.
    pub fn set(&mut self, command: GoproCommand, value: [u8; 4]) -> Result<bool, GoProRefusal> {
        use GoproCommand::*;
        let before = self.heartbeat();
        let bad = || GoProRefusal::OutOfRange { command, value };
        if command == GOPRO_COMMAND_POWER {
            let on = flag(value[0]).ok_or_else(bad)?;
            if on && !self.powered && self.battery_pct <= 0.0 {
                return Err(GoProRefusal::BatteryEmpty);
            }
            self.powered = on;
            if !on {
                self.recording = false;
            }
            return Ok(self.heartbeat() != before);
        }
        if !self.powered {
            return Err(GoProRefusal::PoweredOff);
        }
        // A recording camera takes only the shutter, its clock and charging.
        let allowed_while_recording = matches!(
            command,
            GOPRO_COMMAND_SHUTTER
                | GOPRO_COMMAND_TIME
                | GOPRO_COMMAND_CHARGING
                | GOPRO_COMMAND_BATTERY
                | GOPRO_COMMAND_MODEL
        );
        if self.recording && !allowed_while_recording {
            return Err(GoProRefusal::Busy(command));
        }
        match command {
            GOPRO_COMMAND_POWER => {}
            GOPRO_COMMAND_CAPTURE_MODE => self.mode = capture_mode(value[0]).ok_or_else(bad)?,
            GOPRO_COMMAND_SHUTTER => self.shutter(flag(value[0]).ok_or_else(bad)?),
            GOPRO_COMMAND_BATTERY | GOPRO_COMMAND_MODEL => {
                return Err(GoProRefusal::ReadOnly(command))
            }
            GOPRO_COMMAND_VIDEO_SETTINGS => {
                if value[3] & !VIDEO_FLAG_PAL != 0 {
                    return Err(bad());
                }
                self.video = VideoSettings {
                    resolution: upto(
                        value[0],
                        GoproResolution::GOPRO_RESOLUTION_4k_SUPERVIEW as u8,
                    )
                    .ok_or_else(bad)?,
                    frame_rate: upto(value[1], GoproFrameRate::GOPRO_FRAME_RATE_12_5 as u8)
                        .ok_or_else(bad)?,
                    field_of_view: upto(
                        value[2],
                        GoproFieldOfView::GOPRO_FIELD_OF_VIEW_NARROW as u8,
                    )
                    .ok_or_else(bad)?,
                    pal: value[3] & VIDEO_FLAG_PAL != 0,
                };
            }
            GOPRO_COMMAND_LOW_LIGHT => self.low_light = flag(value[0]).ok_or_else(bad)?,
            GOPRO_COMMAND_PHOTO_RESOLUTION => {
                self.photo_resolution = upto(
                    value[0],
                    GoproPhotoResolution::GOPRO_PHOTO_RESOLUTION_12MP_WIDE as u8,
                )
                .ok_or_else(bad)?
            }
            GOPRO_COMMAND_PHOTO_BURST_RATE => {
                self.burst_rate = upto(
                    value[0],
                    GoproBurstRate::GOPRO_BURST_RATE_30_IN_6_SECOND as u8,
                )
                .ok_or_else(bad)?
            }
            GOPRO_COMMAND_PROTUNE => self.protune.enabled = flag(value[0]).ok_or_else(bad)?,
            GOPRO_COMMAND_PROTUNE_WHITE_BALANCE => {
                self.protune.white_balance = upto(
                    value[0],
                    GoproProtuneWhiteBalance::GOPRO_PROTUNE_WHITE_BALANCE_RAW as u8,
                )
                .ok_or_else(bad)?
            }
            GOPRO_COMMAND_PROTUNE_COLOUR => {
                self.protune.colour = upto(
                    value[0],
                    GoproProtuneColour::GOPRO_PROTUNE_COLOUR_NEUTRAL as u8,
                )
                .ok_or_else(bad)?
            }
            GOPRO_COMMAND_PROTUNE_GAIN => {
                self.protune.gain = upto(value[0], GoproProtuneGain::GOPRO_PROTUNE_GAIN_6400 as u8)
                    .ok_or_else(bad)?
            }
            GOPRO_COMMAND_PROTUNE_SHARPNESS => {
                self.protune.sharpness = upto(
                    value[0],
                    GoproProtuneSharpness::GOPRO_PROTUNE_SHARPNESS_HIGH as u8,
                )
                .ok_or_else(bad)?
            }
            GOPRO_COMMAND_PROTUNE_EXPOSURE => {
                self.protune.exposure = upto(
                    value[0],
                    GoproProtuneExposure::GOPRO_PROTUNE_EXPOSURE_POS_5_0 as u8,
                )
                .ok_or_else(bad)?
            }
            GOPRO_COMMAND_TIME => {
                self.clock_base = u32::from_le_bytes(value);
                self.since_clock_set_us = 0;
            }
            GOPRO_COMMAND_CHARGING => self.charging = flag(value[0]).ok_or_else(bad)?,
        }
        Ok(self.heartbeat() != before)
    }

    /// SHUTTER: start/stop recording in VIDEO and TIME_LAPSE; in the photo
    /// modes 1 takes a photo (or a burst) and 0 does nothing.
    fn shutter(&mut self, press: bool) {
        use GoproCaptureMode::*;
        match self.mode {
            GOPRO_CAPTURE_MODE_VIDEO => self.recording = press,
            GOPRO_CAPTURE_MODE_TIME_LAPSE => {
                if press && !self.recording {
                    // The first frame is taken at once.
                    self.photos_taken += 1;
                    self.lapse_s = 0.0;
                }
                self.recording = press;
            }
            GOPRO_CAPTURE_MODE_PHOTO if press => self.photos_taken += 1,
            GOPRO_CAPTURE_MODE_BURST | GOPRO_CAPTURE_MODE_MULTI_SHOT if press => {
                self.photos_taken += BURST_PHOTOS
                    .get(usize::from(self.burst_rate))
                    .copied()
                    .unwrap_or(1);
            }
            _ => {}
        }
    }

    /// GOPRO_GET_REQUEST: the current value's four bytes.
    pub fn get(&self, command: GoproCommand) -> Result<[u8; 4], GoProRefusal> {
        use GoproCommand::*;
        if command != GOPRO_COMMAND_POWER && !self.powered {
            return Err(GoProRefusal::PoweredOff);
        }
        let one = |v: u8| [v, 0, 0, 0];
        Ok(match command {
            GOPRO_COMMAND_POWER => one(u8::from(self.powered)),
            GOPRO_COMMAND_CAPTURE_MODE => one(self.mode as u8),
            GOPRO_COMMAND_SHUTTER => one(u8::from(self.recording)),
            GOPRO_COMMAND_BATTERY => one(self.battery_pct.round() as u8),
            GOPRO_COMMAND_MODEL => one(GoproModel::GOPRO_MODEL_HERO_4_BLACK as u8),
            GOPRO_COMMAND_VIDEO_SETTINGS => [
                self.video.resolution,
                self.video.frame_rate,
                self.video.field_of_view,
                if self.video.pal { VIDEO_FLAG_PAL } else { 0 },
            ],
            GOPRO_COMMAND_LOW_LIGHT => one(u8::from(self.low_light)),
            GOPRO_COMMAND_PHOTO_RESOLUTION => one(self.photo_resolution),
            GOPRO_COMMAND_PHOTO_BURST_RATE => one(self.burst_rate),
            GOPRO_COMMAND_PROTUNE => one(u8::from(self.protune.enabled)),
            GOPRO_COMMAND_PROTUNE_WHITE_BALANCE => one(self.protune.white_balance),
            GOPRO_COMMAND_PROTUNE_COLOUR => one(self.protune.colour),
            GOPRO_COMMAND_PROTUNE_GAIN => one(self.protune.gain),
            GOPRO_COMMAND_PROTUNE_SHARPNESS => one(self.protune.sharpness),
            GOPRO_COMMAND_PROTUNE_EXPOSURE => one(self.protune.exposure),
            GOPRO_COMMAND_TIME => {
                let now = u64::from(self.clock_base) + self.since_clock_set_us / 1_000_000;
                u32::try_from(now).unwrap_or(u32::MAX).to_le_bytes()
            }
            GOPRO_COMMAND_CHARGING => one(u8::from(self.charging)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use GoproCommand::*;

    fn run(g: &mut GoPro, secs: f64) -> bool {
        let mut changed = false;
        for _ in 0..(secs * 100.0).round() as usize {
            changed |= g.step(0.01);
        }
        changed
    }

    #[test]
    fn command_ids_are_mavlinks() {
        // The ids the Solo app and the bridge use.
        assert_eq!(GOPRO_COMMAND_POWER as u8, 0);
        assert_eq!(GOPRO_COMMAND_CAPTURE_MODE as u8, 1);
        assert_eq!(GOPRO_COMMAND_SHUTTER as u8, 2);
        assert_eq!(GOPRO_COMMAND_VIDEO_SETTINGS as u8, 5);
        assert_eq!(GOPRO_COMMAND_PROTUNE_EXPOSURE as u8, 14);
        assert_eq!(GOPRO_COMMAND_CHARGING as u8, 16);
    }

    #[test]
    fn video_shutter_toggles_recording() {
        let mut g = GoPro::default();
        assert_eq!(g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]), Ok(true));
        assert!(g.heartbeat().recording);
        assert_eq!(g.get(GOPRO_COMMAND_SHUTTER), Ok([1, 0, 0, 0]));
        // Starting again changes nothing; mode changes wait for the stop.
        assert_eq!(g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]), Ok(false));
        assert_eq!(
            g.set(GOPRO_COMMAND_CAPTURE_MODE, [1, 0, 0, 0]),
            Err(GoProRefusal::Busy(GOPRO_COMMAND_CAPTURE_MODE))
        );
        assert_eq!(g.set(GOPRO_COMMAND_SHUTTER, [0, 0, 0, 0]), Ok(true));
        assert!(!g.recording());
        assert_eq!(g.photos_taken(), 0);
    }

    #[test]
    fn photo_burst_and_time_lapse_count_photos() {
        let mut g = GoPro::default();
        assert_eq!(g.set(GOPRO_COMMAND_CAPTURE_MODE, [1, 0, 0, 0]), Ok(true));
        assert_eq!(g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]), Ok(false));
        assert_eq!(g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]), Ok(false));
        assert_eq!(g.photos_taken(), 2);
        assert!(!g.recording(), "a photo is not a recording");
        assert_eq!(g.set(GOPRO_COMMAND_CAPTURE_MODE, [2, 0, 0, 0]), Ok(true));
        assert_eq!(
            g.set(GOPRO_COMMAND_PHOTO_BURST_RATE, [5, 0, 0, 0]),
            Ok(false)
        );
        g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]).expect("burst");
        assert_eq!(g.photos_taken(), 32);
        g.set(GOPRO_COMMAND_CAPTURE_MODE, [3, 0, 0, 0])
            .expect("time lapse");
        assert_eq!(g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]), Ok(true));
        run(&mut g, 2.2);
        g.set(GOPRO_COMMAND_SHUTTER, [0, 0, 0, 0]).expect("stop");
        // One at once, then one every 0.5 s.
        assert_eq!(g.photos_taken(), 32 + 5);
    }

    #[test]
    fn out_of_range_and_read_only_are_refused_and_change_nothing() {
        let mut g = GoPro::default();
        let before = g.clone();
        for (cmd, value) in [
            (GOPRO_COMMAND_CAPTURE_MODE, [5, 0, 0, 0]),
            (GOPRO_COMMAND_CAPTURE_MODE, [255, 0, 0, 0]),
            (GOPRO_COMMAND_SHUTTER, [2, 0, 0, 0]),
            (GOPRO_COMMAND_POWER, [7, 0, 0, 0]),
            (GOPRO_COMMAND_VIDEO_SETTINGS, [14, 0, 0, 0]),
            (GOPRO_COMMAND_VIDEO_SETTINGS, [3, 14, 0, 0]),
            (GOPRO_COMMAND_VIDEO_SETTINGS, [3, 4, 3, 0]),
            (GOPRO_COMMAND_VIDEO_SETTINGS, [3, 4, 0, 2]),
            (GOPRO_COMMAND_PHOTO_RESOLUTION, [5, 0, 0, 0]),
            (GOPRO_COMMAND_PHOTO_BURST_RATE, [9, 0, 0, 0]),
            (GOPRO_COMMAND_PROTUNE_WHITE_BALANCE, [5, 0, 0, 0]),
            (GOPRO_COMMAND_PROTUNE_COLOUR, [2, 0, 0, 0]),
            (GOPRO_COMMAND_PROTUNE_GAIN, [5, 0, 0, 0]),
            (GOPRO_COMMAND_PROTUNE_SHARPNESS, [3, 0, 0, 0]),
            (GOPRO_COMMAND_PROTUNE_EXPOSURE, [21, 0, 0, 0]),
            (GOPRO_COMMAND_LOW_LIGHT, [2, 0, 0, 0]),
            (GOPRO_COMMAND_CHARGING, [2, 0, 0, 0]),
        ] {
            assert_eq!(
                g.set(cmd, value),
                Err(GoProRefusal::OutOfRange {
                    command: cmd,
                    value
                }),
                "{cmd:?} {value:?}"
            );
        }
        for cmd in [GOPRO_COMMAND_BATTERY, GOPRO_COMMAND_MODEL] {
            assert_eq!(g.set(cmd, [50, 0, 0, 0]), Err(GoProRefusal::ReadOnly(cmd)));
        }
        assert_eq!(g, before);
    }

    #[test]
    fn settings_round_trip() {
        let mut g = GoPro::default();
        g.set(GOPRO_COMMAND_VIDEO_SETTINGS, [8, 2, 1, 1])
            .expect("4K 24 medium PAL");
        assert_eq!(g.get(GOPRO_COMMAND_VIDEO_SETTINGS), Ok([8, 2, 1, 1]));
        assert!(g.video().pal);
        g.set(GOPRO_COMMAND_PROTUNE, [1, 0, 0, 0]).expect("protune");
        g.set(GOPRO_COMMAND_PROTUNE_EXPOSURE, [20, 0, 0, 0])
            .expect("+5 EV");
        assert_eq!(g.get(GOPRO_COMMAND_PROTUNE), Ok([1, 0, 0, 0]));
        assert_eq!(g.get(GOPRO_COMMAND_PROTUNE_EXPOSURE), Ok([20, 0, 0, 0]));
        assert_eq!(g.get(GOPRO_COMMAND_MODEL), Ok([4, 0, 0, 0]));
        assert_eq!(g.get(GOPRO_COMMAND_BATTERY), Ok([100, 0, 0, 0]));
        g.set(GOPRO_COMMAND_TIME, 1_700_000_000u32.to_le_bytes())
            .expect("time");
        run(&mut g, 3.0);
        assert_eq!(
            g.get(GOPRO_COMMAND_TIME),
            Ok(1_700_000_003u32.to_le_bytes())
        );
    }

    #[test]
    fn power_off_answers_only_power_and_the_battery_can_run_out() {
        let mut g = GoPro::default();
        g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]).expect("record");
        assert_eq!(g.set(GOPRO_COMMAND_POWER, [0, 0, 0, 0]), Ok(true));
        let hb = g.heartbeat();
        assert!(!hb.powered && !hb.recording);
        assert_eq!(
            hb.capture_mode,
            GoproCaptureMode::GOPRO_CAPTURE_MODE_UNKNOWN
        );
        assert_eq!(
            g.get(GOPRO_COMMAND_CAPTURE_MODE),
            Err(GoProRefusal::PoweredOff)
        );
        assert_eq!(g.get(GOPRO_COMMAND_POWER), Ok([0, 0, 0, 0]));
        assert_eq!(g.set(GOPRO_COMMAND_POWER, [1, 0, 0, 0]), Ok(true));

        g.set(GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]).expect("record");
        // 1 %/min while recording: empty after 100 minutes.
        assert!(!run(&mut g, 99.0 * 60.0));
        assert!(run(&mut g, 2.0 * 60.0));
        assert!(!g.heartbeat().powered);
        assert_eq!(
            g.set(GOPRO_COMMAND_POWER, [1, 0, 0, 0]),
            Err(GoProRefusal::BatteryEmpty)
        );
    }
}
