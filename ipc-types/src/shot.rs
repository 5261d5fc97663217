//! Samples between the Solo app gateway and the shot engine, and button events.
//!
//! The gateway owns the transports (TCP 5507, UDP 14558): framing, the one-app rule,
//! malformed-input accounting. It forwards each *decoded and validated* app message
//! as an [`AppMessage`] (the message's Solo type id and its little-endian value, at
//! most [`APP_VALUE_CAPACITY`] bytes) and the engine answers with [`AppMessage`]s the
//! gateway writes to the app. Both sides read the value with the `solo-proto` codec,
//! so the engine never sees a byte the gateway has not checked, and the engine's
//! vocabulary is the Solo app protocol it implements (it *is* the ShotManager).

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

/// The largest Solo message value carried on the bus. Every fixed-length message of
/// the protocol fits; the only longer ones are SHOTMANAGER_ERROR text (truncated by
/// the engine) and GEOFENCE_SET_DATA JSON (translated by the gateway).
pub const APP_VALUE_CAPACITY: usize = 240;

/// One Solo app message on the bus, either direction.
///
/// Topics: [`crate::topics::shot_from_app`] (gateway → engine) and
/// [`crate::topics::shot_to_app`] (engine → gateway).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.AppMessage.v1")]
#[repr(C)]
pub struct AppMessage {
    pub header: SampleHeader,
    /// From the gateway: the app connection it came from (1, 2, …; follow-stream
    /// datagrams carry the session of the connected app, or 0 with none). To the
    /// gateway: 0 = whichever app is connected now, else only that session.
    pub session: u32,
    /// Solo message type id (`messageType` on the wire).
    pub msg_type: u32,
    /// Bytes of `value` in use.
    pub len: u32,
    /// See [`app_flags`].
    pub flags: u32,
    pub value: [u8; APP_VALUE_CAPACITY],
}
crate::assert_layout!(AppMessage, size = 24 + 16 + APP_VALUE_CAPACITY, align = 8);

/// Flag bits of [`AppMessage::flags`].
pub mod app_flags {
    /// The message arrived on the UDP follow stream, not the TCP connection.
    pub const FOLLOW_STREAM: u32 = 0x01;
}

impl Default for AppMessage {
    fn default() -> Self {
        AppMessage {
            header: SampleHeader::default(),
            session: 0,
            msg_type: 0,
            len: 0,
            flags: 0,
            value: [0; APP_VALUE_CAPACITY],
        }
    }
}

/// A message value longer than [`APP_VALUE_CAPACITY`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("message type {msg_type}: value of {len} bytes exceeds the bus capacity of {APP_VALUE_CAPACITY}")]
pub struct ValueTooLong {
    pub msg_type: u32,
    pub len: usize,
}

impl AppMessage {
    pub fn new(session: u32, msg_type: u32, value: &[u8]) -> Result<Self, ValueTooLong> {
        if value.len() > APP_VALUE_CAPACITY {
            return Err(ValueTooLong {
                msg_type,
                len: value.len(),
            });
        }
        let mut m = AppMessage {
            session,
            msg_type,
            len: value.len() as u32,
            ..AppMessage::default()
        };
        m.value[..value.len()].copy_from_slice(value);
        Ok(m)
    }

    /// The value bytes; a `len` beyond capacity (another process wrote garbage) is clamped.
    pub fn value(&self) -> &[u8] {
        &self.value[..(self.len as usize).min(APP_VALUE_CAPACITY)]
    }

    pub fn is_follow_stream(&self) -> bool {
        self.flags & app_flags::FOLLOW_STREAM != 0
    }
}

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

crate::impl_sample!(AppMessage, AppSession, ButtonEvent, ShotStatus);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn app_message_round_trips_its_value() {
        let m = AppMessage::new(3, 2, &[1, 2, 3]).unwrap();
        assert_eq!(m.value(), &[1, 2, 3]);
        assert_eq!(m.msg_type, 2);
        assert!(AppMessage::new(1, 1000, &[0; APP_VALUE_CAPACITY + 1]).is_err());
        assert!(AppMessage::new(1, 1000, &[0; APP_VALUE_CAPACITY]).is_ok());
    }

    #[test]
    fn a_forged_length_is_clamped() {
        let mut m = AppMessage::new(1, 2, &[9; 20]).unwrap();
        m.len = u32::MAX;
        assert_eq!(m.value().len(), APP_VALUE_CAPACITY);
    }

    #[test]
    fn button_events_are_checked() {
        let mut e = ButtonEvent::new(1, Button::A, ButtonEventKind::Press);
        assert_eq!(e.button(), Ok(Button::A));
        e.button = 77;
        assert!(e.button().is_err());
    }
}
