//! The queue core: every drone's queue, the execution of its commands through
//! `VehicleCommand`s, and the `SwarmState`. Pure: no I/O, every time is a
//! `CLOCK_MONOTONIC` nanosecond count passed in, so it is tested with a fake
//! vehicle model and without sleeping.
//!
//! The service feeds it [`Swarm::handle_command`] (swarm commands),
//! [`Swarm::handle_state`] / [`Swarm::handle_status`] / [`Swarm::handle_ack`] (per
//! drone, from its vehicle's topics) and calls [`Swarm::tick`] at the tick rate; it
//! publishes what [`Swarm::take_outputs`] and [`Swarm::pop_reply`] hand out and the
//! state [`Swarm::fill_state`] writes.

mod commands;
mod drone;
mod emergency;
mod fence;
mod hardware;
mod replies;
mod send;
mod start;
#[cfg(test)]
mod tests;
mod tick;
mod vehicle;

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use skymesh_ipc_types::arbiter::{FencePolygon, MAX_FENCE_VERTICES};
use skymesh_ipc_types::{
    swarm_flags, AckResult, ArbiterEvent, ArbiterEventKind, AuthorityDomain, Command, CommandAck,
    CommandKind, CommandSource, FenceKind, FixedStr, FlightMode, GeofenceSet, HardwareOp,
    HardwareRequest, LcdOp, RefusalReason, SwarmCommand, SwarmCommandKind, SwarmReply, SwarmResult,
    SwarmState, VehicleCommand, VehicleState, VehicleStatus, ALL_DRONES, SWARM_MAX_DRONES,
};

use crate::anim::{AnimLibrary, Keyframe};
use crate::config::{BoxPolicy, Settings};
use crate::metrics::Metrics;
use crate::site::{heading_of_yaw, wrap_deg};

pub use drone::{
    Aabb, Drone, Exec, FenceRequest, Pose, Queued, Running, TakeoffStep, LANDING_SLOW_BELOW_M,
};
use drone::{AnimRun, Owner, Pending, SideOp, MAX_PENDING};

use SwarmCommandKind as K;

/// Replies waiting to be published at most; older ones are dropped (and counted).
pub const MAX_REPLIES_WAITING: usize = 16_384;
/// Fastest LED updates sent to the hardware service.
const LED_PERIOD_NS: u64 = 100_000_000;
/// Waypoint-follow and animation targets: speed floor above the path's own speed.
const STREAM_SPEED_MARGIN_MPS: f32 = 0.5;
/// A streamed speed differing less than this from the last one sent is not re-sent.
const SPEED_RESEND_MPS: f32 = 0.1;
/// A geofence the arbiter has not decided on within this time is answered
/// `Timeout` (the arbiter answers at once when it runs; it may not run).
pub const FENCE_ANSWER_TIMEOUT_NS: u64 = 2_000_000_000;

/// What the queue wants published, besides replies and state.
#[derive(Debug, Default)]
pub struct Outputs {
    /// For `topics::vehicle_command(c.vehicle_id)`.
    pub commands: Vec<VehicleCommand>,
    /// For `topics::vehicle_geofence(g.vehicle_id)`.
    pub geofences: Vec<Box<GeofenceSet>>,
    /// For `topics::hardware_request()`.
    pub hardware: Vec<HardwareRequest>,
}

impl Outputs {
    pub fn is_empty(&self) -> bool {
        self.commands.is_empty() && self.geofences.is_empty() && self.hardware.is_empty()
    }
}

/// Every drone's queue.
#[derive(Debug)]
pub struct Swarm {
    cfg: Settings,
    drones: Vec<Drone>,
    by_id: HashMap<u16, usize>,
    /// Drone index by vehicle id.
    by_vehicle: [Option<u16>; 256],
    anims: AnimLibrary,
    next_command_id: u32,
    next_token: u64,
    start_ns: u64,
    out: Outputs,
    replies: VecDeque<SwarmReply>,
    metrics: Metrics,
    hw_index: Option<usize>,
    hw_request_id: u32,
    hw_last: Option<[u8; 3]>,
    hw_last_ns: u64,
    /// The `GeofenceSet::request_id` of the next fence sent (never 0).
    next_fence_request: u32,
    /// Set while a command for every drone is applied that is answered once.
    quiet: bool,
}

fn secs(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

fn ns_of_s(s: f32) -> u64 {
    (f64::from(s.max(0.0)) * 1e9) as u64
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>().sqrt()
}

fn dist_xy(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

fn is_follow(k: SwarmCommandKind) -> bool {
    matches!(k, K::ExtWaypointFollow | K::ExtWaypointFollowColor)
}

/// Commands an inactive drone refuses (landing is always allowed).
fn needs_active(kind: SwarmCommandKind, cmd: &SwarmCommand) -> bool {
    match kind {
        K::ExtGoExternal
        | K::ExtWaypoint
        | K::ExtWaypointFollow
        | K::ExtWaypointFollowColor
        | K::SetManualTarget => true,
        K::ExtVehicleCmd => cmd.int1 != 4,
        K::ExtPlaybackAnim => cmd.f[2] >= 0.5,
        K::MotorsCmd => cmd.int1 == 1,
        _ => false,
    }
}

/// Commands refused during the emergency stop (the arbiter would refuse their
/// vehicle commands anyway).
fn moves(kind: SwarmCommandKind, cmd: &SwarmCommand) -> bool {
    needs_active(kind, cmd) || matches!(kind, K::ExtGoHome | K::ExtGoHomeAtPosition)
}

/// Commands that cannot fail for a drone: sent for every drone (GroundControl sends
/// the global ones without a context), they are answered once, with drone
/// `ALL_DRONES`, instead of once per drone.
fn answered_once(kind: SwarmCommandKind) -> bool {
    matches!(
        kind,
        K::ExtSetBoundingBox
            | K::ExtTimecode
            | K::ExtTimecodeActive
            | K::ExtVideo
            | K::ExtVideoCmd
            | K::ExtResetTrackingToFrame
            | K::ExtSetActive
            | K::SetActive
            | K::CtrlMode
            | K::ColorMode
            | K::ManualColorMode
            | K::SetGroup
            | K::SetClockTimeout
            | K::SetCalibrationOffset
            | K::SetAnimColorIntensity
            | K::ResetAnimPosition
    )
}

/// A command of the queue's that ends its position target at the arbiter (which
/// then no longer brakes when the queue's flight authority lapses): any motion or
/// flight-state command but a heading, a region of interest or home, and the
/// emergency stop. Mirrors the arbiter's own bookkeeping.
fn ends_target(kind: CommandKind) -> bool {
    kind == CommandKind::EmergencyStop
        || (kind.authority() == Some(AuthorityDomain::Flight)
            && !kind.is_authority_request()
            && !matches!(
                kind,
                CommandKind::VelocityNed
                    | CommandKind::SetYaw
                    | CommandKind::SetRoi
                    | CommandKind::ClearRoi
                    | CommandKind::SetHome
            ))
}

fn refusal_text(ack: &CommandAck) -> String {
    let kind = CommandKind::try_from(ack.kind).map_or("command", CommandKind::as_str);
    let reason = ack.reason().map_or("refused", RefusalReason::as_str);
    let detail = ack.detail.as_str();
    if detail.is_empty() {
        format!("{kind} refused: {reason}")
    } else {
        format!("{kind} refused: {reason}: {detail}")
    }
}

fn lerp3(a: [f32; 3], b: [f32; 3], u: f32) -> [f32; 3] {
    [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * u)
}

impl Swarm {
    /// The queue for `cfg.drones`, animations from `anims`, started at `now_ns`.
    pub fn new(cfg: Settings, anims: AnimLibrary, metrics: Metrics, now_ns: u64) -> Swarm {
        let drones: Vec<Drone> = cfg.drones.iter().map(Drone::new).collect();
        let by_id = drones.iter().enumerate().map(|(i, d)| (d.id, i)).collect();
        let mut by_vehicle = [None; 256];
        for (i, d) in drones.iter().enumerate() {
            by_vehicle[usize::from(d.vehicle_id)] = Some(i as u16);
        }
        let hw_index = cfg
            .hardware_drone
            .and_then(|id| drones.iter().position(|d| d.id == id));
        Swarm {
            cfg,
            drones,
            by_id,
            by_vehicle,
            anims,
            next_command_id: 1,
            next_token: 1,
            start_ns: now_ns,
            out: Outputs::default(),
            replies: VecDeque::new(),
            metrics,
            hw_index,
            hw_request_id: 1,
            hw_last: None,
            hw_last_ns: 0,
            next_fence_request: 1,
            quiet: false,
        }
    }

    pub fn settings(&self) -> &Settings {
        &self.cfg
    }

    pub fn len(&self) -> usize {
        self.drones.len()
    }

    pub fn is_empty(&self) -> bool {
        self.drones.is_empty()
    }

    /// Drone `idx` (configuration order).
    pub fn drone(&self, idx: usize) -> &Drone {
        &self.drones[idx]
    }

    /// The index of the drone flying vehicle `vehicle_id`.
    pub fn index_of_vehicle(&self, vehicle_id: u8) -> Option<usize> {
        self.by_vehicle[usize::from(vehicle_id)].map(usize::from)
    }

    pub fn anims_mut(&mut self) -> &mut AnimLibrary {
        &mut self.anims
    }

    /// What to publish on the vehicle, geofence and hardware topics.
    pub fn take_outputs(&mut self) -> Outputs {
        std::mem::take(&mut self.out)
    }

    /// The oldest reply waiting to be published.
    pub fn pop_reply(&mut self) -> Option<SwarmReply> {
        self.replies.pop_front()
    }

    /// Replies waiting to be published.
    pub fn replies_waiting(&self) -> usize {
        self.replies.len()
    }

    fn token(&mut self) -> u64 {
        self.next_token += 1;
        self.next_token
    }

    /// Every drone's state at `now` into `out`.
    pub fn fill_state(&self, now: u64, out: &mut SwarmState) {
        let n = self.drones.len().min(SWARM_MAX_DRONES);
        out.count = n as u16;
        out.time_s = now.saturating_sub(self.start_ns) as f64 / 1e9;
        for (slot, d) in out.drones.iter_mut().zip(&self.drones) {
            *slot = d.snapshot(now, &self.cfg);
        }
    }
}
