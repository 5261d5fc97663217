//! MAVLink gimbal protocol v2 for the vision pipeline's virtual cameras (issue 8).
//! Pure: no I/O; every instant is a monotonic nanosecond count passed in.
//!
//! Each virtual camera `i` of the configured stream is a MAVLink gimbal manager and
//! gimbal device in one component (`[vision] components[i]`, our system id). While
//! the pipeline's `VisionState` is fresh ([`STATE_FRESH_NS`]) and the camera is
//! active in the stream's layout, it sends HEARTBEAT (1 Hz, `MAV_TYPE_GIMBAL`),
//! GIMBAL_MANAGER_STATUS (5 Hz), GIMBAL_DEVICE_ATTITUDE_STATUS (10 Hz) and
//! GIMBAL_MANAGER_INFORMATION (once when it appears, and on MAV_CMD_REQUEST_MESSAGE).
//!
//! Conventions we chose (and the flags say so):
//! - Attitude is reported in the earth frame: `q` = the view's camera → NED
//!   quaternion (`VirtualCamState::ned_from_cam_q`; its camera frame, x along the
//!   optical axis, y right, z down, is MAVLink's gimbal frame), flag
//!   `GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME`. Lock flags mirror the camera's
//!   `lock_flags`. ATTITUDE_STATUS's `delta_yaw`/`delta_yaw_velocity` are NaN
//!   (unknown) and its `gimbal_device_id` 0 (the device is the sender).
//!   COMMAND_ACKs carry the commander in `target_system`/`target_component`.
//! - `gimbal_device_id`: manager and device are one component; INFORMATION and
//!   STATUS name the component itself as the device, and ATTITUDE_STATUS comes from
//!   that component, so ground stations pair them. Addressing a device accepts 0
//!   (all) or that component id.
//! - Pitch is always from the horizon (the pipeline's convention), whatever the
//!   PITCH_LOCK flag says; roll of a commanded quaternion and the roll rate are
//!   ignored (views have no roll axis).
//! - Yaw is global with YAW_LOCK or YAW_IN_EARTH_FRAME, else relative to the heading.
//! - NEUTRAL aims forward and level (vehicle frame); RETRACT is unsupported.
//! - Control (DO_GIMBAL_MANAGER_CONFIGURE): anyone may configure; while a primary
//!   (or secondary) controller is set, attitude and ROI input from anybody else is
//!   denied (commands) or dropped and counted (messages). Zoom is not gimbal
//!   control and is always accepted. Camera commands forwarded from the other
//!   gateways (origin `Payload`) passed the arbiter's payload authority instead.
//! - Commands are answered from the addressed component: ACCEPTED after the
//!   pipeline's `Applied`; DENIED for `Ignored`, not in control, or values that
//!   are not finite or out of range (never sent to the pipeline); UNSUPPORTED for
//!   `Unsupported` and commands we do not implement; FAILED for `Failed`,
//!   `Invalid`, or no reply within [`REPLY_TIMEOUT_NS`]; TEMPORARILY_REJECTED for a
//!   relative-altitude ROI while home is unknown.
//! - DO_SET_ROI_LOCATION altitude: COMMAND_INT frames GLOBAL / GLOBAL_INT are MSL,
//!   GLOBAL_RELATIVE_ALT(_INT) are above home (home from the autopilot's
//!   HOME_POSITION); terrain frames are unsupported. COMMAND_LONG has no frame and
//!   is read as above home, as ArduPilot does.

mod command;
mod control;
mod convert;
mod handle;
mod payload;
mod requests;
mod telemetry;
#[cfg(test)]
mod test_support;

use std::collections::HashMap;

use mavlink::dialects::ardupilotmega::{
    GimbalDeviceErrorFlags, GimbalDeviceFlags, GimbalManagerCapFlags, GimbalManagerFlags,
    MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag, MavResult, MavState, MavType,
    COMMAND_ACK_DATA, GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, GIMBAL_MANAGER_INFORMATION_DATA,
    GIMBAL_MANAGER_STATUS_DATA, HEARTBEAT_DATA,
};
use nalgebra::{Quaternion, UnitQuaternion};
use skymesh_ipc_types::{
    Command, VirtualCamState, VisionControl, VisionControlKind, VisionOrigin, VisionReply,
    VisionResult, VisionState, LOCK_PITCH, LOCK_ROLL, LOCK_YAW, VISION_MAX_CAMS,
    VISION_MAX_STREAMS,
};

pub use control::Control;
pub use convert::{ack_of, lock_flags, yaw_pitch_of};
use convert::{angles_ok, outcome_of, zoom};
pub use telemetry::{ack, heartbeat};

/// A `VisionState` older than this (by its publish stamp) means no pipeline: the
/// virtual cameras go silent.
pub const STATE_FRESH_NS: u64 = 2_000_000_000;
/// A command the pipeline has not answered within this is answered FAILED.
pub const REPLY_TIMEOUT_NS: u64 = 1_000_000_000;
/// The telemetry slot: attitude every slot, status every 2nd, heartbeat every 10th.
pub const SLOT_NS: u64 = 100_000_000;
/// Largest angular rate accepted, rad/s (360°/s).
const MAX_RATE: f32 = 2.0 * std::f32::consts::PI;
/// Pending requests kept at most (replies that never come are timed out anyway).
const MAX_PENDING: usize = 256;

/// MAVLink message ids we answer MAV_CMD_REQUEST_MESSAGE for.
pub const MSG_GIMBAL_MANAGER_INFORMATION: u32 = 280;
pub const MSG_GIMBAL_MANAGER_STATUS: u32 = 281;
pub const MSG_GIMBAL_DEVICE_ATTITUDE_STATUS: u32 = 285;

/// `GIMBAL_MANAGER_FLAGS` bits.
pub const FLAG_RETRACT: u32 = 1;
pub const FLAG_NEUTRAL: u32 = 2;
pub const FLAG_ROLL_LOCK: u32 = 4;
pub const FLAG_PITCH_LOCK: u32 = 8;
pub const FLAG_YAW_LOCK: u32 = 16;
pub const FLAG_YAW_IN_VEHICLE_FRAME: u32 = 32;
pub const FLAG_YAW_IN_EARTH_FRAME: u32 = 64;

/// The capabilities we honour (GIMBAL_MANAGER_CAP_FLAGS).
pub const CAP_FLAGS: u32 = 2 // HAS_NEUTRAL
    | 32 // HAS_PITCH_AXIS
    | 128 // HAS_PITCH_LOCK (pitch is always from the horizon)
    | 256 // HAS_YAW_AXIS
    | 512 // HAS_YAW_FOLLOW
    | 1024 // HAS_YAW_LOCK
    | 4096 // SUPPORTS_YAW_IN_EARTH_FRAME
    | 131_072; // CAN_POINT_LOCATION_GLOBAL

/// The `[vision]` settings this module needs.
#[derive(Debug, Clone, PartialEq)]
pub struct VisionSettings {
    pub enabled: bool,
    /// Index of the pipeline stream whose virtual cameras we serve.
    pub stream: u8,
    /// Component id of virtual camera 0, 1, …
    pub components: Vec<u8>,
    /// Also send accepted camera/gimbal `VehicleCommand`s to the virtual cameras.
    pub forward_payload: bool,
}

impl Default for VisionSettings {
    fn default() -> Self {
        VisionSettings {
            enabled: false,
            stream: 0,
            components: vec![171, 172, 173, 174],
            forward_payload: true,
        }
    }
}

/// What one call produced: messages to send (from a virtual component), controls
/// to publish, and (message, outcome) counts for the metrics.
#[derive(Debug, Default)]
pub struct Output {
    /// (our component, message): sent to every endpoint.
    pub sends: Vec<(u8, MavMessage)>,
    pub controls: Vec<VisionControl>,
    /// (`msg`, `outcome`) label pairs, one per decision.
    pub counts: Vec<(&'static str, &'static str)>,
    /// (key, text) for rate-limited warnings.
    pub warnings: Vec<(&'static str, String)>,
}

/// A frame the router delivered to the virtual gimbals, decoded, with its sender.
#[derive(Debug, Clone, Copy)]
pub struct Incoming<'a> {
    pub from: (u8, u8),
    pub msg: &'a MavMessage,
}

#[derive(Debug, Clone, Copy)]
enum Waiting {
    /// A COMMAND_* to answer with COMMAND_ACK.
    Command {
        to: (u8, u8),
        component: u8,
        command: MavCmd,
        msg: &'static str,
    },
    /// A message (no ack) or a forwarded payload command: only counted.
    Counted { msg: &'static str },
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    waiting: Waiting,
    deadline_ns: u64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Slot {
    component: u8,
    control: Control,
    /// INFORMATION was sent since the camera (re)appeared.
    announced: bool,
}

/// The last state of our stream.
#[derive(Debug, Clone, Copy)]
struct View {
    cams: [VirtualCamState; VISION_MAX_CAMS],
    stamp_ns: u64,
}

/// The gimbal managers of the virtual cameras; see the module documentation.
#[derive(Debug)]
pub struct GimbalV2 {
    system: u8,
    stream: usize,
    slots: Vec<Slot>,
    view: Option<View>,
    pending: HashMap<u64, Pending>,
    next_request: u64,
    /// Start of the next telemetry slot and its index.
    next_slot_ns: u64,
    slot_index: u64,
    boot_ns: u64,
}

/// A command's immediate answer or "sent to the pipeline".
enum Decision {
    Ask(VisionControl),
    Answer(MavResult, &'static str),
}

impl GimbalV2 {
    /// `seed` makes request ids unique across restarts (process id, time).
    pub fn new(system: u8, settings: &VisionSettings, seed: u64, now_ns: u64) -> GimbalV2 {
        let slots = settings
            .components
            .iter()
            .take(VISION_MAX_CAMS)
            .map(|&component| Slot {
                component,
                ..Slot::default()
            })
            .collect();
        GimbalV2 {
            system,
            stream: usize::from(settings.stream).min(VISION_MAX_STREAMS - 1),
            slots,
            view: None,
            pending: HashMap::new(),
            next_request: seed.max(1),
            next_slot_ns: now_ns,
            slot_index: 0,
            boot_ns: now_ns,
        }
    }

    /// Our virtual components.
    pub fn components(&self) -> Vec<u8> {
        self.slots.iter().map(|s| s.component).collect()
    }

    /// The camera index of `component`.
    pub fn cam_of(&self, component: u8) -> Option<usize> {
        self.slots.iter().position(|s| s.component == component)
    }

    /// The control of camera `cam`.
    pub fn control(&self, cam: usize) -> Option<Control> {
        self.slots.get(cam).map(|s| s.control)
    }

    /// A new `VisionState`.
    pub fn on_state(&mut self, state: &VisionState) {
        let Some(stream) = state.streams().get(self.stream) else {
            self.view = None;
            return;
        };
        self.view = Some(View {
            cams: stream.cams,
            stamp_ns: state.header.stamp_ns,
        });
    }

    fn fresh_view(&self, now_ns: u64) -> Option<&View> {
        self.view
            .as_ref()
            .filter(|v| now_ns.saturating_sub(v.stamp_ns) < STATE_FRESH_NS)
    }

    /// The cameras shown now: (index, component).
    pub fn active(&self, now_ns: u64) -> Vec<(usize, u8)> {
        let Some(view) = self.fresh_view(now_ns) else {
            return Vec::new();
        };
        self.slots
            .iter()
            .enumerate()
            .filter(|(i, _)| view.cams[*i].active == 1)
            .map(|(i, s)| (i, s.component))
            .collect()
    }
}
