//! The app connection and button samples of the shot path, and the engine's status.
//! What apps ask of the shot engine and what it answers are protocol-neutral
//! ([`crate::shot_api`]); gateways translate their wire protocols into them.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

/// The app connection as the gateway sees it: published on every connect and
/// disconnect and once a second, so an engine that restarts learns it within a second.
///
/// Topic: [`crate::topics::shot_app_session`] (latest value).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.AppSession.v1")]
#[repr(C)]
pub struct AppSession {
    pub header: SampleHeader,
    /// Current (or, when disconnected, last) session number; 0 = never connected.
    pub session: u32,
    /// 1 while an app is connected.
    pub connected: u8,
    pub reserved: [u8; 3],
    /// The app's `address:port`.
    pub peer: FixedStr<48>,
}
crate::assert_layout!(AppSession, size = 24 + 8 + 48, align = 8);

wire_enum! {
    /// Controller buttons, numbered as the Solo app protocol numbers them.
    pub enum Button: u8 {
        Power = 0 => "power",
        Fly = 1 => "fly",
        Rtl = 2 => "rtl",
        Loiter = 3 => "loiter",
        A = 4 => "a",
        B = 5 => "b",
        Preset1 = 6 => "preset1",
        Preset2 = 7 => "preset2",
        CameraClick = 8 => "camera_click",
        /// The pause button (Solo's controller has one; the app sends SOLO_PAUSE).
        Pause = 9 => "pause",
    }
}

wire_enum! {
    /// What happened to a button, numbered as the Solo app protocol numbers them.
    pub enum ButtonEventKind: u8 {
        Press = 0 => "press",
        Release = 1 => "release",
        ClickRelease = 2 => "click_release",
        Hold = 3 => "hold",
        LongHold = 4 => "long_hold",
        DoubleClick = 5 => "double_click",
    }
}

/// A button event from the controller hardware (via the IMC gateway) or a tool.
///
/// Topic: [`crate::topics::input_buttons`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("skymesh.ButtonEvent.v1")]
#[repr(C)]
pub struct ButtonEvent {
    pub header: SampleHeader,
    /// Vehicle the controller flies.
    pub vehicle_id: u8,
    /// [`Button`] as stored on the wire.
    pub button: u8,
    /// [`ButtonEventKind`] as stored on the wire.
    pub event: u8,
    pub reserved: [u8; 5],
}
crate::assert_layout!(ButtonEvent, size = 32, align = 8);

impl ButtonEvent {
    pub fn new(vehicle_id: u8, button: Button, event: ButtonEventKind) -> Self {
        ButtonEvent {
            vehicle_id,
            button: button.to_wire(),
            event: event.to_wire(),
            ..Default::default()
        }
    }

    pub fn button(&self) -> Result<Button, crate::UnknownValue> {
        Button::try_from(self.button)
    }

    pub fn event(&self) -> Result<ButtonEventKind, crate::UnknownValue> {
        ButtonEventKind::try_from(self.event)
    }
}

wire_enum! {
    /// Where the shot engine is within its current shot.
    pub enum ShotPhase: u8 {
        /// No shot.
        Idle = 0 => "idle",
        /// In a shot, waiting for the app or the pilot (locations, recorded points, ROI).
        Setup = 1 => "setup",
        /// Flying the shot.
        Running = 2 => "running",
        /// Flying the shot with cruise speed 0.
        Paused = 3 => "paused",
    }
}

/// What the shot engine is doing, on change and at 5 Hz.
///
/// Topic: [`crate::topics::shot_status`] (latest value).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.ShotStatus.v1")]
#[repr(C)]
pub struct ShotStatus {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// Solo shot index (−1 none, 0 selfie, 1 orbit, 2 cable cam, 5 follow, …); the
    /// Site Scan shots, which have none in the protocol, are 100 inspect, 101 scan,
    /// 102 survey.
    pub shot: i8,
    /// [`ShotPhase`] as stored on the wire.
    pub phase: u8,
    /// 1 while an app is connected (as last told by the gateway).
    pub app_connected: u8,
    /// 1 while the engine holds (or last asked for) flight authority.
    pub has_authority: u8,
    /// 1 if a region of interest is set (`roi_*` valid).
    pub roi_valid: u8,
    pub reserved: [u8; 2],
    /// Cruise speed of the shot, m/s (signed for cable cam direction).
    pub cruise_speed_mps: f32,
    /// Shot-specific progress: orbit radius (m), cable/selfie parameter 0..1.
    pub progress: f32,
    pub roi_lat_deg: f64,
    pub roi_lon_deg: f64,
    /// Region of interest altitude above home, m.
    pub roi_alt_rel_m: f32,
    pub reserved2: u32,
    /// Why the last shot ended (empty while in a shot).
    pub last_exit: FixedStr<32>,
}
crate::assert_layout!(ShotStatus, size = 96, align = 8);

impl ShotStatus {
    pub fn phase(&self) -> ShotPhase {
        ShotPhase::try_from(self.phase).unwrap_or(ShotPhase::Idle)
    }
}

crate::impl_sample!(AppSession, ButtonEvent, ShotStatus);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn button_events_are_checked() {
        let mut e = ButtonEvent::new(1, Button::A, ButtonEventKind::Press);
        assert_eq!(e.button(), Ok(Button::A));
        e.button = 77;
        assert!(e.button().is_err());
    }
}
