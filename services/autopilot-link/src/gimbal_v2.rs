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
//!   `lock_flags`. The workspace's `mavlink` build emits no MAVLink 2 extension
//!   fields, so `delta_yaw` and `gimbal_device_id` of ATTITUDE_STATUS (and the
//!   COMMAND_ACK target) are not sent.
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

/// Who may control a camera: `(0, 0)` = nobody set.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Control {
    pub primary: (u8, u8),
    pub secondary: (u8, u8),
}

impl Control {
    /// Whether `who` may aim the camera.
    pub fn allows(&self, who: (u8, u8)) -> bool {
        let set = |c: (u8, u8)| c != (0, 0);
        if !set(self.primary) && !set(self.secondary) {
            return true;
        }
        who == self.primary || who == self.secondary
    }

    /// Applies DO_GIMBAL_MANAGER_CONFIGURE params 1–4 from `sender`; `Err` names
    /// the bad parameter.
    pub fn configure(&mut self, params: [f32; 4], sender: (u8, u8)) -> Result<(), &'static str> {
        let mut next = *self;
        let slots: [(&mut u8, u8, u8, &'static str); 4] = [
            (
                &mut next.primary.0,
                sender.0,
                self.primary.0,
                "sysid primary",
            ),
            (
                &mut next.primary.1,
                sender.1,
                self.primary.1,
                "compid primary",
            ),
            (
                &mut next.secondary.0,
                sender.0,
                self.secondary.0,
                "sysid secondary",
            ),
            (
                &mut next.secondary.1,
                sender.1,
                self.secondary.1,
                "compid secondary",
            ),
        ];
        let holds_primary = self.primary == sender;
        let holds_secondary = self.secondary == sender;
        for (i, (slot, own, _, name)) in slots.into_iter().enumerate() {
            let p = params[i];
            if !p.is_finite() || p.fract() != 0.0 || !(-3.0..=255.0).contains(&p) {
                return Err(name);
            }
            match p as i32 {
                -1 => {}
                -2 => *slot = own,
                -3 => {
                    let holds = if i < 2 {
                        holds_primary
                    } else {
                        holds_secondary
                    };
                    if holds {
                        *slot = 0;
                    }
                }
                v => *slot = v as u8,
            }
        }
        *self = next;
        Ok(())
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

fn finite_or_nan(v: f32) -> bool {
    v.is_nan() || v.is_finite()
}

/// Checks angles (rad; NaN = leave) and rates (rad/s; NaN = none) against the
/// pipeline's limits: pitch ±90°, yaw ±180°.
fn angles_ok(yaw: f32, pitch: f32, yaw_rate: f32, pitch_rate: f32) -> bool {
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

fn outcome_of(r: MavResult) -> &'static str {
    match r {
        MavResult::MAV_RESULT_ACCEPTED => "accepted",
        MavResult::MAV_RESULT_DENIED => "denied",
        MavResult::MAV_RESULT_UNSUPPORTED => "unsupported",
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED => "temporarily_rejected",
        _ => "failed",
    }
}

/// A frame the router delivered to the virtual gimbals, decoded, with its sender.
#[derive(Debug, Clone, Copy)]
pub struct Incoming<'a> {
    pub from: (u8, u8),
    pub msg: &'a MavMessage,
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

    /// When [`poll`](Self::poll) has something to do next. With no camera shown and
    /// none still marked announced, a telemetry slot would send nothing: no slot is
    /// due until a new [`on_state`](Self::on_state) shows a camera (the service
    /// waits for every `VisionState` and asks again after it), so a mesh without a
    /// vision pipeline does not wake 10 times a second for nothing.
    pub fn next_deadline_ns(&self, now_ns: u64) -> u64 {
        let slot = if self.slots_idle(now_ns) {
            u64::MAX
        } else {
            self.next_slot_ns
        };
        self.pending
            .values()
            .map(|p| p.deadline_ns)
            .fold(slot, u64::min)
    }

    /// True when a telemetry slot at `now_ns` would do nothing.
    fn slots_idle(&self, now_ns: u64) -> bool {
        self.slots.iter().all(|s| !s.announced) && self.active(now_ns).is_empty()
    }

    fn time_boot_ms(&self, now_ns: u64) -> u32 {
        (now_ns.saturating_sub(self.boot_ns) / 1_000_000) as u32
    }

    /// Telemetry and reply timeouts.
    pub fn poll(&mut self, now_ns: u64, out: &mut Output) {
        let expired: Vec<u64> = self
            .pending
            .iter()
            .filter(|(_, p)| p.deadline_ns <= now_ns)
            .map(|(id, _)| *id)
            .collect();
        for id in expired {
            if let Some(p) = self.pending.remove(&id) {
                self.finish(p.waiting, MavResult::MAV_RESULT_FAILED, out);
                out.warnings.push((
                    "no_reply",
                    "the vision pipeline did not answer within 1 s".to_string(),
                ));
            }
        }
        if now_ns < self.next_slot_ns {
            return;
        }
        let k = self.slot_index;
        self.slot_index += 1;
        self.next_slot_ns = if self.next_slot_ns + SLOT_NS <= now_ns {
            now_ns + SLOT_NS
        } else {
            self.next_slot_ns + SLOT_NS
        };
        let active = self.active(now_ns);
        // Cameras that left the layout announce themselves again when they return.
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if !active.iter().any(|(a, _)| *a == i) {
                slot.announced = false;
            }
        }
        for (i, component) in active {
            if k.is_multiple_of(10) {
                out.sends.push((component, heartbeat()));
            }
            if !self.slots[i].announced {
                self.slots[i].announced = true;
                out.sends.push((component, self.information(i, now_ns)));
            }
            if k.is_multiple_of(2) {
                if let Some(m) = self.status(i, now_ns) {
                    out.sends.push((component, m));
                }
            }
            if let Some(m) = self.attitude(i, now_ns) {
                out.sends.push((component, m));
            }
        }
    }

    /// GIMBAL_MANAGER_INFORMATION of camera `i`.
    pub fn information(&self, i: usize, now_ns: u64) -> MavMessage {
        let pi = std::f32::consts::PI;
        let half = std::f32::consts::FRAC_PI_2;
        MavMessage::GIMBAL_MANAGER_INFORMATION(GIMBAL_MANAGER_INFORMATION_DATA {
            time_boot_ms: self.time_boot_ms(now_ns),
            cap_flags: GimbalManagerCapFlags::from_bits_truncate(CAP_FLAGS),
            roll_min: 0.0,
            roll_max: 0.0,
            pitch_min: -half,
            pitch_max: half,
            yaw_min: -pi,
            yaw_max: pi,
            gimbal_device_id: self.slots[i].component,
        })
    }

    /// GIMBAL_MANAGER_STATUS of camera `i` (needs a fresh state).
    pub fn status(&self, i: usize, now_ns: u64) -> Option<MavMessage> {
        let cam = self.fresh_view(now_ns)?.cams[i];
        let c = self.slots[i].control;
        Some(MavMessage::GIMBAL_MANAGER_STATUS(
            GIMBAL_MANAGER_STATUS_DATA {
                time_boot_ms: self.time_boot_ms(now_ns),
                flags: GimbalManagerFlags::from_bits_truncate(lock_flags(&cam)),
                gimbal_device_id: self.slots[i].component,
                primary_control_sysid: c.primary.0,
                primary_control_compid: c.primary.1,
                secondary_control_sysid: c.secondary.0,
                secondary_control_compid: c.secondary.1,
            },
        ))
    }

    /// GIMBAL_DEVICE_ATTITUDE_STATUS of camera `i`: earth frame (see the module doc).
    pub fn attitude(&self, i: usize, now_ns: u64) -> Option<MavMessage> {
        let cam = self.fresh_view(now_ns)?.cams[i];
        let flags = (lock_flags(&cam) & (FLAG_ROLL_LOCK | FLAG_PITCH_LOCK | FLAG_YAW_LOCK))
            | FLAG_YAW_IN_EARTH_FRAME;
        Some(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(
            GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
                target_system: 0,
                target_component: 0,
                time_boot_ms: self.time_boot_ms(now_ns),
                flags: GimbalDeviceFlags::from_bits_truncate(flags as u16),
                q: cam.ned_from_cam_q,
                angular_velocity_x: f32::NAN,
                angular_velocity_y: f32::NAN,
                angular_velocity_z: f32::NAN,
                failure_flags: GimbalDeviceErrorFlags::empty(),
            },
        ))
    }

    fn control_for(&mut self, kind: VisionControlKind, cam: usize) -> VisionControl {
        let id = self.next_request;
        self.next_request = self.next_request.wrapping_add(1).max(1);
        VisionControl {
            request_id: id,
            kind: kind.to_wire(),
            origin: VisionOrigin::GimbalV2.to_wire(),
            stream: self.stream as u8,
            cam: cam as u8,
            ..VisionControl::default()
        }
    }

    fn remember(&mut self, id: u64, waiting: Waiting, now_ns: u64) {
        if self.pending.len() >= MAX_PENDING {
            // The oldest entry is answered FAILED by poll anyway; make room.
            if let Some(oldest) = self
                .pending
                .iter()
                .min_by_key(|(_, p)| p.deadline_ns)
                .map(|(k, _)| *k)
            {
                self.pending.remove(&oldest);
            }
        }
        self.pending.insert(
            id,
            Pending {
                waiting,
                deadline_ns: now_ns + REPLY_TIMEOUT_NS,
            },
        );
    }

    fn finish(&self, waiting: Waiting, result: MavResult, out: &mut Output) {
        match waiting {
            Waiting::Command {
                to,
                component,
                command,
                msg,
            } => {
                out.sends.push((component, ack(command, result, to)));
                out.counts.push((msg, outcome_of(result)));
            }
            Waiting::Counted { msg } => out.counts.push((msg, outcome_of(result))),
        }
    }

    /// The pipeline's answer to one of our requests (others' replies are ignored).
    pub fn on_reply(&mut self, reply: &VisionReply, out: &mut Output) {
        if let Some(p) = self.pending.remove(&reply.request_id) {
            let result = reply.result();
            if result != VisionResult::Applied {
                out.warnings.push((
                    "refused",
                    format!(
                        "the vision pipeline answered {}: {}",
                        result.as_str(),
                        reply.message.as_str()
                    ),
                ));
            }
            self.finish(p.waiting, ack_of(result), out);
        }
    }

    /// The cameras a message/command addressed to `target_component` with device id
    /// `device` means (empty: not for us).
    fn cams_for(&self, target_component: u8, device: u8) -> Vec<usize> {
        match self.cam_of(target_component) {
            Some(i) if device == 0 || device == target_component => vec![i],
            Some(_) => Vec::new(),
            None if target_component == 0 => match device {
                0 => (0..self.slots.len()).collect(),
                d => self.cam_of(d).into_iter().collect(),
            },
            None => Vec::new(),
        }
    }

    /// A decoded frame delivered to the virtual cameras. `home_alt_msl` is the
    /// autopilot's home altitude, if known.
    pub fn handle(
        &mut self,
        incoming: Incoming<'_>,
        home_alt_msl: Option<f32>,
        now_ns: u64,
        out: &mut Output,
    ) {
        let from = incoming.from;
        match incoming.msg {
            MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(m) => {
                if !self.for_our_system(m.target_system) {
                    return;
                }
                let flags = m.flags.bits();
                let (yaw, pitch) = yaw_pitch_of(m.q).unwrap_or((f32::NAN, f32::NAN));
                let q_set = !m.q.iter().any(|v| v.is_nan());
                if q_set && yaw.is_nan() {
                    out.counts.push(("set_attitude", "invalid"));
                    return;
                }
                for cam in self.cams_for(m.target_component, m.gimbal_device_id) {
                    self.attitude_message(
                        "set_attitude",
                        cam,
                        from,
                        flags,
                        [yaw, pitch, m.angular_velocity_z, m.angular_velocity_y],
                        now_ns,
                        out,
                    );
                }
            }
            MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(m) => {
                if !self.for_our_system(m.target_system) {
                    return;
                }
                for cam in self.cams_for(m.target_component, m.gimbal_device_id) {
                    self.attitude_message(
                        "set_pitchyaw",
                        cam,
                        from,
                        m.flags.bits(),
                        [m.yaw, m.pitch, m.yaw_rate, m.pitch_rate],
                        now_ns,
                        out,
                    );
                }
            }
            MavMessage::COMMAND_LONG(c) => {
                let p = [
                    c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
                ];
                self.command(
                    from,
                    c.target_component,
                    c.command,
                    p,
                    None,
                    home_alt_msl,
                    now_ns,
                    out,
                );
            }
            MavMessage::COMMAND_INT(c) => {
                let p = [
                    c.param1, c.param2, c.param3, c.param4, c.x as f32, c.y as f32, c.z,
                ];
                self.command(
                    from,
                    c.target_component,
                    c.command,
                    p,
                    Some((c.frame, c.x, c.y)),
                    home_alt_msl,
                    now_ns,
                    out,
                );
            }
            _ => {}
        }
    }

    fn for_our_system(&self, target_system: u8) -> bool {
        target_system == 0 || target_system == self.system
    }

    /// SET_ATTITUDE / SET_PITCHYAW: `v` = yaw, pitch, yaw rate, pitch rate (rad, rad/s).
    #[allow(clippy::too_many_arguments)]
    fn attitude_message(
        &mut self,
        msg: &'static str,
        cam: usize,
        from: (u8, u8),
        flags: u32,
        v: [f32; 4],
        now_ns: u64,
        out: &mut Output,
    ) {
        if !self.slots[cam].control.allows(from) {
            out.counts.push((msg, "not_in_control"));
            out.warnings.push((
                "not_in_control",
                format!("{msg} from {from:?} dropped: another controller is configured"),
            ));
            return;
        }
        match self.attitude_control(cam, flags, v) {
            Decision::Ask(c) => {
                self.remember(c.request_id, Waiting::Counted { msg }, now_ns);
                out.controls.push(c);
            }
            Decision::Answer(r, why) => {
                out.counts.push((msg, outcome_of(r)));
                out.warnings
                    .push(("invalid", format!("{msg} dropped: {why}")));
            }
        }
    }

    /// A GimbalAttitude for camera `cam`, or why not.
    fn attitude_control(&mut self, cam: usize, flags: u32, v: [f32; 4]) -> Decision {
        if flags & FLAG_RETRACT != 0 {
            return Decision::Answer(
                MavResult::MAV_RESULT_UNSUPPORTED,
                "retract is not supported",
            );
        }
        let [mut yaw, mut pitch, yaw_rate, pitch_rate] = v;
        let mut flags = flags;
        if flags & FLAG_NEUTRAL != 0 {
            (yaw, pitch) = (0.0, 0.0);
            flags &= !(FLAG_YAW_LOCK | FLAG_YAW_IN_EARTH_FRAME);
        }
        if !angles_ok(yaw, pitch, yaw_rate, pitch_rate) {
            return Decision::Answer(
                MavResult::MAV_RESULT_DENIED,
                "angle or rate not finite, out of range, or nothing set",
            );
        }
        let mut c = self.control_for(VisionControlKind::GimbalAttitude, cam);
        c.gimbal_flags = flags;
        c.yaw_rad = yaw;
        c.pitch_rad = pitch;
        c.yaw_rate_rps = yaw_rate;
        c.pitch_rate_rps = pitch_rate;
        Decision::Ask(c)
    }

    #[allow(clippy::too_many_arguments)]
    fn command(
        &mut self,
        from: (u8, u8),
        target_component: u8,
        command: MavCmd,
        p: [f32; 7],
        int: Option<(MavFrame, i32, i32)>,
        home_alt_msl: Option<f32>,
        now_ns: u64,
        out: &mut Output,
    ) {
        let Some(cam) = self.cam_of(target_component) else {
            // Broadcast commands are the autopilot's to answer.
            return;
        };
        let component = target_component;
        let (msg, decision) = match command {
            MavCmd::MAV_CMD_REQUEST_MESSAGE => {
                let id = p[0];
                let sent = match id as u32 {
                    _ if !id.is_finite() || id.fract() != 0.0 || id < 0.0 => None,
                    MSG_GIMBAL_MANAGER_INFORMATION => Some(self.information(cam, now_ns)),
                    MSG_GIMBAL_MANAGER_STATUS => self.status(cam, now_ns),
                    MSG_GIMBAL_DEVICE_ATTITUDE_STATUS => self.attitude(cam, now_ns),
                    _ => None,
                };
                let result = match sent {
                    Some(m) => {
                        out.sends.push((component, m));
                        MavResult::MAV_RESULT_ACCEPTED
                    }
                    None if [MSG_GIMBAL_MANAGER_STATUS, MSG_GIMBAL_DEVICE_ATTITUDE_STATUS]
                        .contains(&(id as u32)) =>
                    {
                        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
                    }
                    None => MavResult::MAV_RESULT_UNSUPPORTED,
                };
                (
                    "request_message",
                    Decision::Answer(result, "message not provided"),
                )
            }
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE => {
                let d = if !self.device_ok(p[6], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else {
                    match self.slots[cam]
                        .control
                        .configure([p[0], p[1], p[2], p[3]], from)
                    {
                        Ok(()) => Decision::Answer(MavResult::MAV_RESULT_ACCEPTED, ""),
                        Err(_) => Decision::Answer(
                            MavResult::MAV_RESULT_DENIED,
                            "control ids must be integers -3..=255",
                        ),
                    }
                };
                ("configure", d)
            }
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW => {
                let d = if !self.device_ok(p[6], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else if !self.slots[cam].control.allows(from) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "not in control")
                } else if !p[4].is_finite() || p[4] < 0.0 || p[4] > u32::MAX as f32 {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "bad flags")
                } else {
                    let r = |d: f32| d.to_radians();
                    self.attitude_control(cam, p[4] as u32, [r(p[1]), r(p[0]), r(p[3]), r(p[2])])
                };
                ("pitchyaw", d)
            }
            MavCmd::MAV_CMD_DO_SET_ROI_LOCATION => {
                let d = if !self.device_ok(p[0], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else if !self.slots[cam].control.allows(from) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "not in control")
                } else {
                    self.roi(cam, p, int, home_alt_msl)
                };
                ("roi_location", d)
            }
            MavCmd::MAV_CMD_DO_SET_ROI_NONE => {
                let d = if !self.device_ok(p[0], component) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "wrong gimbal device id")
                } else if !self.slots[cam].control.allows(from) {
                    Decision::Answer(MavResult::MAV_RESULT_DENIED, "not in control")
                } else {
                    Decision::Ask(self.control_for(VisionControlKind::RoiNone, cam))
                };
                ("roi_none", d)
            }
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM => {
                let camera_ok = p[2].is_nan()
                    || p[2] == 0.0
                    || p[2] == f32::from(component)
                    || (1.0..=6.0).contains(&p[2]) && p[2].fract() == 0.0;
                let d = match zoom(p[0], p[1]) {
                    _ if !camera_ok => {
                        Decision::Answer(MavResult::MAV_RESULT_DENIED, "another camera's id")
                    }
                    Some((mode, value)) => {
                        let mut c = self.control_for(VisionControlKind::Zoom, cam);
                        c.zoom_mode = mode;
                        c.value = value;
                        Decision::Ask(c)
                    }
                    None => {
                        Decision::Answer(MavResult::MAV_RESULT_DENIED, "bad zoom type or value")
                    }
                };
                ("zoom", d)
            }
            _ => (
                "unsupported_command",
                Decision::Answer(MavResult::MAV_RESULT_UNSUPPORTED, "not implemented"),
            ),
        };
        match decision {
            Decision::Ask(c) => {
                self.remember(
                    c.request_id,
                    Waiting::Command {
                        to: from,
                        component,
                        command,
                        msg,
                    },
                    now_ns,
                );
                out.controls.push(c);
            }
            Decision::Answer(result, why) => {
                if result != MavResult::MAV_RESULT_ACCEPTED {
                    out.warnings
                        .push(("refused", format!("{msg} from {from:?}: {why}")));
                }
                out.sends.push((component, ack(command, result, from)));
                out.counts.push((msg, outcome_of(result)));
            }
        }
    }

    fn device_ok(&self, p: f32, component: u8) -> bool {
        p.is_nan() || p == 0.0 || p == f32::from(component)
    }

    fn roi(
        &mut self,
        cam: usize,
        p: [f32; 7],
        int: Option<(MavFrame, i32, i32)>,
        home_alt_msl: Option<f32>,
    ) -> Decision {
        let (lat, lon, relative) = match int {
            Some((frame, x, y)) => {
                let relative = match frame {
                    MavFrame::MAV_FRAME_GLOBAL => false,
                    MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT => true,
                    // The superseded *_INT synonyms (5, 6), still sent by many.
                    #[allow(deprecated)]
                    MavFrame::MAV_FRAME_GLOBAL_INT => false,
                    #[allow(deprecated)]
                    MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT => true,
                    _ => {
                        return Decision::Answer(
                            MavResult::MAV_RESULT_UNSUPPORTED,
                            "only global MSL or relative-altitude frames",
                        )
                    }
                };
                (f64::from(x) * 1e-7, f64::from(y) * 1e-7, relative)
            }
            None => (f64::from(p[4]), f64::from(p[5]), true),
        };
        let alt = p[6];
        if !lat.is_finite()
            || !lon.is_finite()
            || lat.abs() > 90.0
            || lon.abs() > 180.0
            || !alt.is_finite()
            || !(-1000.0..=20_000.0).contains(&alt)
        {
            return Decision::Answer(MavResult::MAV_RESULT_DENIED, "location out of range");
        }
        let alt_msl = if relative {
            match home_alt_msl {
                Some(h) => h + alt,
                None => {
                    return Decision::Answer(
                        MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
                        "home is not known yet (relative altitude)",
                    )
                }
            }
        } else {
            alt
        };
        let mut c = self.control_for(VisionControlKind::RoiLocation, cam);
        c.lat_deg = lat;
        c.lon_deg = lon;
        c.alt_msl_m = alt_msl;
        Decision::Ask(c)
    }

    /// An accepted camera/gimbal `VehicleCommand` for the virtual cameras (origin
    /// `Payload`); `None` for commands that do not concern them.
    pub fn forward_payload(
        &mut self,
        command: &Command,
        now_ns: u64,
        out: &mut Output,
    ) -> Option<()> {
        let all = 255usize;
        let c = match *command {
            Command::CameraZoom {
                camera,
                mode,
                value,
            } => {
                let cam = if camera == 0 {
                    all
                } else {
                    usize::from(camera - 1)
                };
                let mut c = self.control_for(VisionControlKind::Zoom, cam);
                c.zoom_mode = mode.to_wire();
                c.value = value;
                c
            }
            Command::Gimbal { pitch_deg, yaw_deg } => {
                // Autopilot-link sends these with YAW_IN_VEHICLE_FRAME; camera 0.
                let mut c = self.control_for(VisionControlKind::GimbalAttitude, 0);
                c.gimbal_flags = FLAG_YAW_IN_VEHICLE_FRAME;
                c.pitch_rad = pitch_deg.to_radians();
                c.yaw_rad = yaw_deg.to_radians();
                c
            }
            Command::GimbalRate {
                pitch_rate_dps,
                yaw_rate_dps,
            } => {
                let mut c = self.control_for(VisionControlKind::GimbalAttitude, 0);
                c.gimbal_flags = FLAG_YAW_IN_VEHICLE_FRAME;
                c.pitch_rate_rps = pitch_rate_dps.to_radians();
                c.yaw_rate_rps = yaw_rate_dps.to_radians();
                c
            }
            Command::CameraCapture => self.control_for(VisionControlKind::ImageCapture, all),
            Command::RecordStart => self.control_for(VisionControlKind::RecordStart, all),
            Command::RecordStop => self.control_for(VisionControlKind::RecordStop, all),
            _ => return None,
        };
        let c = VisionControl {
            origin: VisionOrigin::Payload.to_wire(),
            ..c
        };
        self.remember(c.request_id, Waiting::Counted { msg: "payload" }, now_ns);
        out.controls.push(c);
        Some(())
    }
}

/// SET_CAMERA_ZOOM type and value → (CAMERA_ZOOM_TYPE, value), if valid.
fn zoom(kind: f32, value: f32) -> Option<(u8, f32)> {
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

/// Our HEARTBEAT as a gimbal.
pub fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GIMBAL,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// COMMAND_ACK for `command` to `to` (the workspace's `mavlink` build does not emit
/// MAVLink 2 extension fields, so `target_system`/`target_component` stay 0: the
/// ack is addressed by routing only).
pub fn ack(command: MavCmd, result: MavResult, _to: (u8, u8)) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA { command, result })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        COMMAND_INT_DATA, COMMAND_LONG_DATA, GIMBAL_MANAGER_SET_ATTITUDE_DATA,
        GIMBAL_MANAGER_SET_PITCHYAW_DATA,
    };
    use mavlink::Message as _;
    use skymesh_ipc_types::{FixedStr, ZoomMode};

    const SYS: u8 = 1;
    const GCS: (u8, u8) = (255, 190);
    const OTHER: (u8, u8) = (254, 190);
    const T0: u64 = 10_000_000_000;

    fn gimbals() -> GimbalV2 {
        GimbalV2::new(
            SYS,
            &VisionSettings {
                components: vec![154, 171, 172, 173],
                ..VisionSettings::default()
            },
            1000,
            T0,
        )
    }

    fn state(active: &[usize], stamp_ns: u64) -> VisionState {
        let mut s = VisionState::default();
        s.header.stamp_ns = stamp_ns;
        s.stream_count = 1;
        s.streams[0].configured = 1;
        for &i in active {
            s.streams[0].cams[i].active = 1;
            s.streams[0].cams[i].lock_flags = LOCK_YAW | LOCK_PITCH;
            s.streams[0].cams[i].ned_from_cam_q = [0.9, 0.1, -0.3, 0.3];
        }
        s
    }

    fn handle(g: &mut GimbalV2, from: (u8, u8), msg: MavMessage, home: Option<f32>) -> Output {
        let mut out = Output::default();
        g.handle(Incoming { from, msg: &msg }, home, T0, &mut out);
        out
    }

    fn long(target: u8, command: MavCmd, p: [f32; 7]) -> MavMessage {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: SYS,
            target_component: target,
            command,
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            ..COMMAND_LONG_DATA::DEFAULT
        })
    }

    fn roi_int(frame: MavFrame, z: f32) -> MavMessage {
        MavMessage::COMMAND_INT(COMMAND_INT_DATA {
            target_system: SYS,
            target_component: 154,
            frame,
            command: MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
            x: 473_977_420,
            y: 85_455_940,
            z,
            ..COMMAND_INT_DATA::DEFAULT
        })
    }

    fn pitchyaw_msg(target: u8, device: u8, pitch: f32, yaw: f32) -> MavMessage {
        MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
            target_system: SYS,
            target_component: target,
            flags: GimbalManagerFlags::from_bits_truncate(FLAG_YAW_LOCK),
            gimbal_device_id: device,
            pitch,
            yaw,
            pitch_rate: f32::NAN,
            yaw_rate: f32::NAN,
        })
    }

    fn acks(out: &Output) -> Vec<(u8, MavCmd, MavResult)> {
        out.sends
            .iter()
            .filter_map(|(c, m)| match m {
                MavMessage::COMMAND_ACK(a) => Some((*c, a.command, a.result)),
                _ => None,
            })
            .collect()
    }

    fn reply(id: u64, result: VisionResult) -> VisionReply {
        VisionReply {
            request_id: id,
            result: result.to_wire(),
            message: FixedStr::new("why"),
            ..VisionReply::default()
        }
    }

    #[test]
    fn no_slot_is_due_while_no_camera_is_shown() {
        let mut g = gimbals();
        // Nothing shown, nothing announced: no telemetry slot to wait for.
        assert_eq!(g.next_deadline_ns(T0), u64::MAX);
        // A camera shown: slots run, and the first announces it.
        g.on_state(&state(&[1], T0));
        let due = g.next_deadline_ns(T0);
        assert!(due <= T0 + SLOT_NS);
        let mut out = Output::default();
        g.poll(due.max(T0), &mut out);
        assert!(!out.sends.is_empty());
        // The state goes stale: one more slot un-announces the camera (so it
        // announces itself again when it returns), then nothing is due.
        let stale = T0 + STATE_FRESH_NS;
        let due = g.next_deadline_ns(stale);
        assert_ne!(due, u64::MAX);
        let mut out = Output::default();
        g.poll(stale.max(due), &mut out);
        assert!(out.sends.is_empty());
        assert_eq!(g.next_deadline_ns(stale + SLOT_NS), u64::MAX);
    }

    #[test]
    fn configure_sets_leaves_and_releases_control() {
        let mut c = Control::default();
        assert!(c.allows(GCS) && c.allows(OTHER));
        c.configure([-2.0, -2.0, -1.0, -1.0], GCS).unwrap();
        assert_eq!(c.primary, GCS);
        assert!(c.allows(GCS) && !c.allows(OTHER));
        // -1 leaves, explicit ids set the secondary.
        c.configure([-1.0, -1.0, 254.0, 190.0], OTHER).unwrap();
        assert_eq!((c.primary, c.secondary), (GCS, OTHER));
        assert!(c.allows(OTHER));
        // -3 releases only what the sender holds.
        c.configure([-3.0, -3.0, -1.0, -1.0], OTHER).unwrap();
        assert_eq!(c.primary, GCS);
        c.configure([-3.0, -3.0, -3.0, -3.0], GCS).unwrap();
        assert_eq!(c.primary, (0, 0));
        assert_eq!(c.secondary, OTHER);
        // 0 = nobody.
        c.configure([-1.0, -1.0, 0.0, 0.0], GCS).unwrap();
        assert_eq!(c, Control::default());
        // Bad values change nothing.
        for bad in [f32::NAN, -4.0, 256.0, 1.5, f32::INFINITY] {
            assert!(c.configure([bad, -1.0, -1.0, -1.0], GCS).is_err());
            assert_eq!(c, Control::default());
        }
    }

    #[test]
    fn set_pitchyaw_becomes_a_gimbal_attitude_for_its_camera() {
        let mut g = gimbals();
        let out = handle(&mut g, GCS, pitchyaw_msg(171, 0, -0.5, 1.0), None);
        assert_eq!(out.controls.len(), 1);
        let c = out.controls[0];
        assert_eq!(c.kind, VisionControlKind::GimbalAttitude.to_wire());
        assert_eq!(c.origin, VisionOrigin::GimbalV2.to_wire());
        assert_eq!((c.stream, c.cam), (0, 1));
        assert_eq!((c.yaw_rad, c.pitch_rad), (1.0, -0.5));
        assert!(c.yaw_rate_rps.is_nan() && c.pitch_rate_rps.is_nan());
        assert_eq!(c.gimbal_flags, FLAG_YAW_LOCK);
        assert!(acks(&out).is_empty(), "messages are not acked");
        // The reply is counted.
        let mut out = Output::default();
        g.on_reply(&reply(c.request_id, VisionResult::Applied), &mut out);
        assert_eq!(out.counts, vec![("set_pitchyaw", "accepted")]);
        // Out of range or NaN everywhere: dropped, nothing asked.
        for (p, y) in [
            (2.0, 0.0),
            (0.0, 4.0),
            (f32::NAN, f32::NAN),
            (f32::INFINITY, 0.0),
        ] {
            let out = handle(&mut g, GCS, pitchyaw_msg(171, 0, p, y), None);
            assert!(out.controls.is_empty(), "{p} {y}");
            assert_eq!(out.counts, vec![("set_pitchyaw", "denied")]);
        }
    }

    #[test]
    fn broadcast_messages_pick_cameras_by_device_id() {
        let mut g = gimbals();
        let all = handle(&mut g, GCS, pitchyaw_msg(0, 0, 0.1, 0.2), None);
        assert_eq!(
            all.controls.iter().map(|c| c.cam).collect::<Vec<_>>(),
            [0, 1, 2, 3]
        );
        let one = handle(&mut g, GCS, pitchyaw_msg(0, 172, 0.1, 0.2), None);
        assert_eq!(one.controls.iter().map(|c| c.cam).collect::<Vec<_>>(), [2]);
        // A real gimbal's device id, another component, a wrong device: not ours.
        assert!(handle(&mut g, GCS, pitchyaw_msg(0, 100, 0.1, 0.2), None)
            .controls
            .is_empty());
        assert!(handle(&mut g, GCS, pitchyaw_msg(1, 0, 0.1, 0.2), None)
            .controls
            .is_empty());
        assert!(handle(&mut g, GCS, pitchyaw_msg(154, 171, 0.1, 0.2), None)
            .controls
            .is_empty());
    }

    #[test]
    fn set_attitude_takes_yaw_and_pitch_from_the_quaternion_and_rates() {
        let mut g = gimbals();
        let (yaw, pitch) = (0.5f32, -0.3f32);
        let q = UnitQuaternion::from_euler_angles(0.2, pitch, yaw);
        let msg = |q: [f32; 4], rates: [f32; 3]| {
            MavMessage::GIMBAL_MANAGER_SET_ATTITUDE(GIMBAL_MANAGER_SET_ATTITUDE_DATA {
                target_system: SYS,
                target_component: 154,
                flags: GimbalManagerFlags::from_bits_truncate(FLAG_YAW_IN_EARTH_FRAME),
                gimbal_device_id: 0,
                q,
                angular_velocity_x: rates[0],
                angular_velocity_y: rates[1],
                angular_velocity_z: rates[2],
            })
        };
        let qa = [q.w, q.i, q.j, q.k];
        let out = handle(&mut g, GCS, msg(qa, [f32::NAN; 3]), None);
        let c = out.controls[0];
        assert!((c.yaw_rad - yaw).abs() < 1e-5 && (c.pitch_rad - pitch).abs() < 1e-5);
        assert_eq!(c.gimbal_flags, FLAG_YAW_IN_EARTH_FRAME);
        // NaN quaternion + rates: rates only (x = roll rate ignored).
        let out = handle(&mut g, GCS, msg([f32::NAN; 4], [9.0, 0.1, -0.2]), None);
        let c = out.controls[0];
        assert!(c.yaw_rad.is_nan() && c.pitch_rad.is_nan());
        assert_eq!((c.yaw_rate_rps, c.pitch_rate_rps), (-0.2, 0.1));
        // A zero quaternion is invalid; a rate beyond 360°/s too.
        let out = handle(&mut g, GCS, msg([0.0; 4], [f32::NAN; 3]), None);
        assert!(out.controls.is_empty());
        assert_eq!(out.counts, vec![("set_attitude", "invalid")]);
        let out = handle(&mut g, GCS, msg([f32::NAN; 4], [0.0, 0.0, 7.0]), None);
        assert!(out.controls.is_empty());
    }

    #[test]
    fn pitchyaw_command_is_acked_by_the_pipeline_answer() {
        let cases = [
            (VisionResult::Applied, MavResult::MAV_RESULT_ACCEPTED),
            (VisionResult::Ignored, MavResult::MAV_RESULT_DENIED),
            (VisionResult::Unsupported, MavResult::MAV_RESULT_UNSUPPORTED),
            (VisionResult::Invalid, MavResult::MAV_RESULT_FAILED),
            (VisionResult::Failed, MavResult::MAV_RESULT_FAILED),
        ];
        for (result, expected) in cases {
            let mut g = gimbals();
            let cmd = long(
                172,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [-30.0, 45.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
            );
            let out = handle(&mut g, GCS, cmd, None);
            assert!(acks(&out).is_empty(), "no ack before the pipeline answers");
            let c = out.controls[0];
            assert_eq!(c.cam, 2);
            assert!((c.pitch_rad + 30f32.to_radians()).abs() < 1e-6);
            assert!((c.yaw_rad - 45f32.to_radians()).abs() < 1e-6);
            let mut out = Output::default();
            // Someone else's reply changes nothing.
            g.on_reply(&reply(c.request_id + 99, result), &mut out);
            assert!(out.sends.is_empty());
            g.on_reply(&reply(c.request_id, result), &mut out);
            assert_eq!(
                acks(&out),
                vec![(172, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, expected)]
            );
            // Answered once only.
            let mut again = Output::default();
            g.on_reply(&reply(c.request_id, result), &mut again);
            assert!(again.sends.is_empty());
        }
    }

    #[test]
    fn no_reply_within_a_second_is_failed() {
        let mut g = gimbals();
        let cmd = long(154, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]);
        let out = handle(&mut g, GCS, cmd, None);
        assert_eq!(out.controls[0].kind, VisionControlKind::RoiNone.to_wire());
        let mut out = Output::default();
        g.poll(T0 + REPLY_TIMEOUT_NS - 1, &mut out);
        assert!(acks(&out).is_empty());
        g.poll(T0 + REPLY_TIMEOUT_NS, &mut out);
        assert_eq!(
            acks(&out),
            vec![(
                154,
                MavCmd::MAV_CMD_DO_SET_ROI_NONE,
                MavResult::MAV_RESULT_FAILED
            )]
        );
    }

    #[test]
    fn bad_values_are_denied_without_asking_the_pipeline() {
        let mut g = gimbals();
        let bad = [
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [f32::INFINITY, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [-95.0, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                [0.0, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 171.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
                [2.0, 150.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
                [9.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
                [2.0, 50.0, 100.0, 0.0, 0.0, 0.0, 0.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
                [0.0, 0.0, 0.0, 0.0, 95.0, 8.0, 10.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
                [0.0, 0.0, 0.0, 0.0, 47.0, f32::NAN, 10.0],
            ),
            long(
                154,
                MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
                [1.5, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0],
            ),
        ];
        for cmd in bad {
            let out = handle(&mut g, GCS, cmd.clone(), Some(400.0));
            assert!(out.controls.is_empty(), "{cmd:?}");
            assert_eq!(acks(&out).len(), 1, "{cmd:?}");
            assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_DENIED, "{cmd:?}");
        }
        // Retract and unknown commands are unsupported.
        let retract = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [0.0, 0.0, f32::NAN, f32::NAN, 1.0, 0.0, 0.0],
        );
        assert_eq!(
            acks(&handle(&mut g, GCS, retract, None))[0].2,
            MavResult::MAV_RESULT_UNSUPPORTED
        );
        let other = long(154, MavCmd::MAV_CMD_DO_SET_SERVO, [0.0; 7]);
        let out = handle(&mut g, GCS, other, None);
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_UNSUPPORTED);
        assert_eq!(out.counts, vec![("unsupported_command", "unsupported")]);
        // Commands to other components (the autopilot's) are not ours to answer.
        let out = handle(
            &mut g,
            GCS,
            long(1, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]),
            None,
        );
        assert!(out.sends.is_empty() && out.controls.is_empty());
    }

    #[test]
    fn a_primary_controller_excludes_everybody_else() {
        let mut g = gimbals();
        let cfg = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
            [-2.0, -2.0, -1.0, -1.0, 0.0, 0.0, 0.0],
        );
        let out = handle(&mut g, GCS, cfg, None);
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!(g.control(0).unwrap().primary, GCS);
        // Reflected in the status.
        g.on_state(&state(&[0], T0));
        let Some(MavMessage::GIMBAL_MANAGER_STATUS(s)) = g.status(0, T0) else {
            panic!("status");
        };
        assert_eq!((s.primary_control_sysid, s.primary_control_compid), GCS);
        // Another ground station: commands denied, messages dropped and counted.
        let cmd = long(
            154,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [0.0, 0.0, f32::NAN, f32::NAN, 0.0, 0.0, 0.0],
        );
        let out = handle(&mut g, OTHER, cmd.clone(), None);
        assert!(out.controls.is_empty());
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_DENIED);
        let roi = long(154, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.0; 7]);
        assert_eq!(
            acks(&handle(&mut g, OTHER, roi, None))[0].2,
            MavResult::MAV_RESULT_DENIED
        );
        let out = handle(&mut g, OTHER, pitchyaw_msg(154, 0, 0.0, 0.0), None);
        assert!(out.controls.is_empty());
        assert_eq!(out.counts, vec![("set_pitchyaw", "not_in_control")]);
        // Zoom is not gimbal control; the controller itself goes through; camera 1 is free.
        let zoom = long(
            154,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [2.0, 50.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(handle(&mut g, OTHER, zoom, None).controls.len(), 1);
        assert_eq!(handle(&mut g, GCS, cmd, None).controls.len(), 1);
        assert_eq!(
            handle(&mut g, OTHER, pitchyaw_msg(171, 0, 0.0, 0.0), None)
                .controls
                .len(),
            1
        );
    }

    #[test]
    fn roi_altitudes_follow_the_frame() {
        let mut g = gimbals();
        let msl = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL, 500.0),
            None,
        );
        let c = msl.controls[0];
        assert_eq!(c.kind, VisionControlKind::RoiLocation.to_wire());
        assert!((c.lat_deg - 47.397742).abs() < 1e-9 && (c.lon_deg - 8.545594).abs() < 1e-9);
        assert_eq!(c.alt_msl_m, 500.0);
        let rel = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 20.0),
            Some(400.0),
        );
        assert_eq!(rel.controls[0].alt_msl_m, 420.0);
        let no_home = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 20.0),
            None,
        );
        assert!(no_home.controls.is_empty());
        assert_eq!(
            acks(&no_home)[0].2,
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED
        );
        let terrain = handle(
            &mut g,
            GCS,
            roi_int(MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT, 20.0),
            Some(400.0),
        );
        assert_eq!(acks(&terrain)[0].2, MavResult::MAV_RESULT_UNSUPPORTED);
        // COMMAND_LONG: degrees in params 5/6, altitude above home.
        let cmd = long(
            154,
            MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
            [0.0, 0.0, 0.0, 0.0, 47.5, 8.5, 30.0],
        );
        let c = handle(&mut g, GCS, cmd, Some(400.0)).controls[0];
        assert_eq!(
            (c.lat_deg as f32, c.lon_deg as f32, c.alt_msl_m),
            (47.5, 8.5, 430.0)
        );
    }

    #[test]
    fn zoom_command_carries_type_and_value() {
        let mut g = gimbals();
        let cmd = long(
            173,
            MavCmd::MAV_CMD_SET_CAMERA_ZOOM,
            [1.0, -1.0, 173.0, 0.0, 0.0, 0.0, 0.0],
        );
        let c = handle(&mut g, GCS, cmd, None).controls[0];
        assert_eq!(c.kind, VisionControlKind::Zoom.to_wire());
        assert_eq!((c.cam, c.zoom_mode, c.value), (3, 1, -1.0));
    }

    #[test]
    fn telemetry_only_for_active_cameras_of_a_fresh_state() {
        let mut g = gimbals();
        let mut out = Output::default();
        g.poll(T0, &mut out);
        assert!(out.sends.is_empty(), "no state, no telemetry");
        g.on_state(&state(&[0, 1], T0));
        let mut out = Output::default();
        g.poll(T0 + SLOT_NS, &mut out);
        let from = |out: &Output, c: u8, name: &str| {
            out.sends
                .iter()
                .filter(|(comp, m)| *comp == c && m.message_name() == name)
                .count()
        };
        for c in [154, 171] {
            assert_eq!(from(&out, c, "GIMBAL_MANAGER_INFORMATION"), 1);
            assert_eq!(from(&out, c, "GIMBAL_DEVICE_ATTITUDE_STATUS"), 1);
        }
        assert!(out.sends.iter().all(|(c, _)| [154, 171].contains(c)));
        // Over one second: 1 heartbeat, 5 status, 10 attitude per camera; info once.
        let mut out = Output::default();
        for k in 2..12 {
            g.poll(T0 + k * SLOT_NS, &mut out);
        }
        assert_eq!(from(&out, 154, "HEARTBEAT"), 1);
        assert_eq!(from(&out, 154, "GIMBAL_MANAGER_STATUS"), 5);
        assert_eq!(from(&out, 171, "GIMBAL_DEVICE_ATTITUDE_STATUS"), 10);
        assert_eq!(from(&out, 154, "GIMBAL_MANAGER_INFORMATION"), 0);
        let Some(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(a)) = g.attitude(0, T0) else {
            panic!("attitude");
        };
        assert_eq!(a.q, [0.9, 0.1, -0.3, 0.3]);
        let f = u32::from(a.flags.bits());
        assert_eq!(f, FLAG_YAW_IN_EARTH_FRAME | FLAG_YAW_LOCK | FLAG_PITCH_LOCK);
        let Some(MavMessage::HEARTBEAT(h)) = out
            .sends
            .iter()
            .map(|(_, m)| m)
            .find(|m| m.message_name() == "HEARTBEAT")
            .cloned()
        else {
            panic!("heartbeat");
        };
        assert_eq!(h.mavtype, MavType::MAV_TYPE_GIMBAL);
        assert_eq!(h.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
        // Stale (2 s after its stamp): silent.
        let mut out = Output::default();
        g.poll(T0 + STATE_FRESH_NS, &mut out);
        assert!(out.sends.is_empty());
    }

    #[test]
    fn information_is_sent_on_request() {
        let mut g = gimbals();
        let req = long(
            171,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [280.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        let out = handle(&mut g, GCS, req, None);
        let Some((171, MavMessage::GIMBAL_MANAGER_INFORMATION(i))) = out.sends.first().cloned()
        else {
            panic!("{:?}", out.sends);
        };
        assert_eq!(i.gimbal_device_id, 171);
        assert_eq!(i.cap_flags.bits(), CAP_FLAGS);
        assert!((i.pitch_min + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert!((i.yaw_max - std::f32::consts::PI).abs() < 1e-6);
        assert_eq!(acks(&out)[0].2, MavResult::MAV_RESULT_ACCEPTED);
        let req = long(
            171,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [259.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(
            acks(&handle(&mut g, GCS, req, None))[0].2,
            MavResult::MAV_RESULT_UNSUPPORTED
        );
    }

    #[test]
    fn payload_commands_map_cameras_and_origin() {
        let mut g = gimbals();
        let mut out = Output::default();
        let zoom = |camera| Command::CameraZoom {
            camera,
            mode: ZoomMode::Range,
            value: 40.0,
        };
        g.forward_payload(&zoom(0), T0, &mut out).unwrap();
        g.forward_payload(&zoom(2), T0, &mut out).unwrap();
        g.forward_payload(
            &Command::Gimbal {
                pitch_deg: -90.0,
                yaw_deg: 10.0,
            },
            T0,
            &mut out,
        )
        .unwrap();
        g.forward_payload(&Command::RecordStart, T0, &mut out)
            .unwrap();
        assert!(g
            .forward_payload(
                &Command::Servo {
                    channel: 9,
                    pwm_us: 1500
                },
                T0,
                &mut out
            )
            .is_none());
        let cams: Vec<u8> = out.controls.iter().map(|c| c.cam).collect();
        assert_eq!(cams, [255, 1, 0, 255]);
        assert!(out
            .controls
            .iter()
            .all(|c| c.origin == VisionOrigin::Payload.to_wire()));
        assert_eq!(
            (out.controls[0].zoom_mode, out.controls[0].value),
            (2, 40.0)
        );
        let g1 = out.controls[2];
        assert_eq!(g1.gimbal_flags, FLAG_YAW_IN_VEHICLE_FRAME);
        assert!((g1.pitch_rad + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert_eq!(
            out.controls[3].kind,
            VisionControlKind::RecordStart.to_wire()
        );
        // Request ids are unique.
        let mut ids: Vec<u64> = out.controls.iter().map(|c| c.request_id).collect();
        ids.dedup();
        assert_eq!(ids.len(), 4);
    }

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
