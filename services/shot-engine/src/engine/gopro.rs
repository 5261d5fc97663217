//! The GoPro: the state the app sees (GOPRO_V1_STATE / GOPRO_V2_STATE) and the
//! requests it makes.
//!
//! The model: status, recording and capture mode come from `PayloadState` (the
//! gimbal's GOPRO_HEARTBEAT, published by autopilot-link); `gimbal_enabled` is 1
//! while the gimbal reports its attitude; the settings fields (resolution, frame rate,
//! field of view, low light, photo resolution, burst rate, protune) change when one of
//! our `GoProSet` commands is answered accepted (the GoPro bridge has no "get all
//! settings", so what we set is what we know). Disabled (GOPRO_SET_ENABLED 0,
//! persisted) → requests are refused with SHOTMANAGER_ERROR and the state reports
//! status 0 (no GoPro). Whenever the state the app would see changes (and on app
//! connect, and on GOPRO_REQUEST_STATE) the engine sends V1 then V2 (V1 is the same
//! content with version 1).
//!
//! Requests: GOPRO_SET_REQUEST {command, value} → `GoProSet {command, [value,0,0,0]}`
//! (the legacy request sets only the first byte; a value above 255 is refused);
//! GOPRO_SET_EXTENDED_REQUEST → `GoProSet` with its four bytes; commands above 31
//! (MAVLink GOPRO_COMMAND) are refused. Each `GoProSet` follows a
//! `GrabPayloadAuthority`; payload authority is released once no request is pending
//! and no shot is flying. GOPRO_RECORD 0 stop / 1 start / 2 toggle: in video (and
//! time-lapse) mode → SHUTTER (command 2) with 0/1, toggle from the current recording
//! flag; in photo, burst and multi-shot mode → SHUTTER 1 (one capture; stop does
//! nothing); in any other or an unknown mode it is refused.

use std::collections::BTreeMap;

use skymesh_ipc_types::shot_api::{GoProState, ShotEvent};
use skymesh_ipc_types::{Command, CommandAck, GoProStatus};

use super::Engine;

/// MAVLink GOPRO_COMMAND ids the model follows.
pub mod cmd {
    pub const SHUTTER: u8 = 2;
    pub const VIDEO_SETTINGS: u8 = 5;
    pub const LOW_LIGHT: u8 = 6;
    pub const PHOTO_RESOLUTION: u8 = 7;
    pub const PHOTO_BURST_RATE: u8 = 8;
    pub const PROTUNE: u8 = 9;
    pub const PROTUNE_WHITE_BALANCE: u8 = 10;
    pub const PROTUNE_COLOUR: u8 = 11;
    pub const PROTUNE_GAIN: u8 = 12;
    pub const PROTUNE_SHARPNESS: u8 = 13;
    pub const PROTUNE_EXPOSURE: u8 = 14;
    /// The highest MAVLink GOPRO_COMMAND.
    pub const MAX: u16 = 31;
}

/// MAVLink GOPRO_CAPTURE_MODE values.
pub mod mode {
    pub const VIDEO: u8 = 0;
    pub const PHOTO: u8 = 1;
    pub const BURST: u8 = 2;
    pub const TIME_LAPSE: u8 = 3;
    pub const MULTI_SHOT: u8 = 4;
    pub const UNKNOWN: u8 = 255;
}

/// More pending requests than this means acks are being lost: the oldest is dropped.
const MAX_PENDING: usize = 32;

#[derive(Debug)]
pub(crate) struct GoPro {
    enabled: bool,
    /// Settings learned from accepted requests (status/recording/mode come from the payload).
    settings: GoProState,
    /// Requests waiting for their ack: command id → (GoPro command, value).
    pending: BTreeMap<u32, (u8, [u8; 4])>,
    /// The state last sent to the app.
    sent: Option<GoProState>,
}

impl GoPro {
    pub fn new(enabled: bool) -> GoPro {
        GoPro {
            enabled,
            settings: GoProState::default(),
            pending: BTreeMap::new(),
            sent: None,
        }
    }

    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    fn apply(&mut self, command: u8, v: [u8; 4]) {
        let s = &mut self.settings;
        match command {
            // Capture mode and recording are what the GoPro reports (PayloadState).
            cmd::VIDEO_SETTINGS => {
                s.video_resolution = v[0];
                s.video_fps = v[1];
                s.video_fov = v[2];
                s.ntsc_pal = v[3];
            }
            cmd::LOW_LIGHT => s.video_low_light = v[0],
            cmd::PHOTO_RESOLUTION => s.photo_resolution = v[0],
            cmd::PHOTO_BURST_RATE => s.photo_burst_rate = v[0],
            cmd::PROTUNE => s.video_protune = v[0],
            cmd::PROTUNE_WHITE_BALANCE => s.video_white_balance = v[0],
            cmd::PROTUNE_COLOUR => s.video_color = v[0],
            cmd::PROTUNE_GAIN => s.video_gain = v[0],
            cmd::PROTUNE_SHARPNESS => s.video_sharpness = v[0],
            cmd::PROTUNE_EXPOSURE => s.video_exposure = v[0],
            _ => {}
        }
    }
}

impl Engine {
    /// The state the app sees (version 2).
    pub fn gopro_state(&self) -> GoProState {
        let mut s = self.gopro.settings;
        s.version = 2;
        s.status = GoProStatus::Disconnected.to_wire();
        match self.inputs.payload.as_ref() {
            Some(p) => {
                if self.gopro.enabled {
                    s.status = p.gopro_status().to_wire();
                }
                s.recording = p.gopro_recording;
                s.capture_mode = p.gopro_capture_mode;
                s.gimbal_enabled = p.is_gimbal_valid().into();
            }
            None => s.capture_mode = mode::UNKNOWN,
        }
        if !self.gopro.enabled {
            s.recording = 0;
        }
        s
    }

    /// GOPRO_V1_STATE then GOPRO_V2_STATE.
    pub(crate) fn gopro_send_state(&mut self) {
        let v2 = self.gopro_state();
        self.gopro.sent = Some(v2);
        let v1 = GoProState { version: 1, ..v2 };
        self.out.app(ShotEvent::GoProV1State(v1));
        self.out.app(ShotEvent::GoProV2State(v2));
    }

    /// Sends the state if it changed since the app last got it.
    pub(crate) fn gopro_sync(&mut self) {
        if self.out.app_connected && self.gopro.sent != Some(self.gopro_state()) {
            self.gopro_send_state();
        }
    }

    pub(crate) fn gopro_set_enabled(&mut self, enabled: bool) {
        self.gopro.enabled = enabled;
        self.persist(|s| s.gopro_enabled = enabled);
        tracing::info!(enabled, "GoPro communication");
        self.gopro_sync();
    }

    /// Refused (and the app told) while the GoPro is disabled.
    fn gopro_allowed(&mut self) -> bool {
        if !self.gopro.enabled {
            self.out
                .error("gopro: GoPro communication is disabled (GOPRO_SET_ENABLED 0)");
        }
        self.gopro.enabled
    }

    /// Sends one `GoProSet` (after grabbing payload authority).
    pub(crate) fn gopro_set(&mut self, command: u16, value: [u8; 4]) {
        if !self.gopro_allowed() {
            return;
        }
        if command > cmd::MAX {
            self.out.error(&format!(
                "gopro: command {command} is out of range (0..={})",
                cmd::MAX
            ));
            return;
        }
        let command = command as u8;
        self.out.command(Command::GrabPayloadAuthority);
        self.payload_used = true;
        if let Some(id) = self.out.command(Command::GoProSet { command, value }) {
            self.gopro.pending.insert(id, (command, value));
            while self.gopro.pending.len() > MAX_PENDING {
                self.gopro.pending.pop_first();
            }
        }
    }

    /// GOPRO_SET_REQUEST: only the first value byte.
    pub(crate) fn gopro_set_request(&mut self, command: u16, value: u16) {
        match u8::try_from(value) {
            Ok(v) => self.gopro_set(command, [v, 0, 0, 0]),
            Err(_) => self.out.error(&format!(
                "gopro: value {value} does not fit GOPRO_SET_REQUEST (0..=255); use the extended request"
            )),
        }
    }

    /// GOPRO_RECORD 0 stop, 1 start, 2 toggle.
    pub(crate) fn gopro_record(&mut self, what: u32) {
        if !self.gopro_allowed() {
            return;
        }
        if what > 2 {
            self.out.error(&format!(
                "gopro: record {what} is not 0 (stop), 1 (start) or 2 (toggle)"
            ));
            return;
        }
        let state = self.gopro_state();
        match state.capture_mode {
            mode::VIDEO | mode::TIME_LAPSE => {
                let on = match what {
                    0 => 0,
                    1 => 1,
                    _ => u8::from(state.recording == 0),
                };
                self.gopro_set(cmd::SHUTTER.into(), [on, 0, 0, 0]);
            }
            mode::PHOTO | mode::BURST | mode::MULTI_SHOT => {
                if what == 0 {
                    tracing::debug!("gopro: stop in a photo mode does nothing");
                } else {
                    self.gopro_set(cmd::SHUTTER.into(), [1, 0, 0, 0]);
                }
            }
            other => self.out.error(&format!(
                "gopro: cannot record in capture mode {other} (unknown or not a capture mode)"
            )),
        }
    }

    /// An ack for one of our GoPro requests: true if it was one.
    pub(crate) fn gopro_ack(&mut self, ack: &CommandAck, accepted: bool) -> bool {
        let Some((command, value)) = self.gopro.pending.remove(&ack.command_id) else {
            return false;
        };
        if accepted {
            self.gopro.apply(command, value);
            self.gopro_sync();
        } else {
            let reason = ack.reason().map_or("refused", |r| r.as_str());
            self.out.error(&format!(
                "gopro: request {command} refused ({reason}: {})",
                ack.detail.as_str()
            ));
        }
        self.release_payload_if_idle(true);
        true
    }
}
