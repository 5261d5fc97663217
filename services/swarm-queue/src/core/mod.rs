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

mod drone;
#[cfg(test)]
mod tests;

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

    // ---- replies -------------------------------------------------------------

    fn reply(
        &mut self,
        cmd: &SwarmCommand,
        drone: u16,
        result: SwarmResult,
        value: i32,
        why: &str,
    ) {
        if self.quiet {
            return;
        }
        let kind = SwarmCommandKind::try_from(cmd.kind).ok();
        self.metrics.reply(kind, result);
        let name = kind.map_or("unknown", SwarmCommandKind::as_str);
        match result {
            SwarmResult::Refused => {
                tracing::info!(
                    drone,
                    kind = name,
                    request = cmd.request_id,
                    reason = why,
                    "refused"
                )
            }
            SwarmResult::Timeout => {
                tracing::warn!(
                    drone,
                    kind = name,
                    request = cmd.request_id,
                    reason = why,
                    "timed out"
                )
            }
            _ => {
                tracing::debug!(drone, kind = name, request = cmd.request_id, result = %result, "reply")
            }
        }
        if self.replies.len() >= MAX_REPLIES_WAITING {
            self.replies.pop_front();
            self.metrics.replies_dropped.inc();
        }
        self.replies.push_back(SwarmReply {
            request_id: cmd.request_id,
            client: cmd.client,
            drone,
            kind: cmd.kind,
            result: result.to_wire(),
            value,
            reason: FixedStr::new(why),
            ..SwarmReply::default()
        });
    }

    fn refuse(&mut self, cmd: &SwarmCommand, drone: u16, why: &str) {
        self.reply(cmd, drone, SwarmResult::Refused, 0, why);
    }

    fn success(&mut self, cmd: &SwarmCommand, drone: u16) {
        self.reply(cmd, drone, SwarmResult::Success, 0, "");
    }

    // ---- vehicle commands ----------------------------------------------------

    /// Sends `command` to drone `idx`'s vehicle; `owner` waits for its ack. Keeps
    /// the arbiter's view of the queue's position target and the time of the last
    /// flight command (see [`Swarm::keepalive`]).
    fn send(
        &mut self,
        idx: usize,
        source: CommandSource,
        command: &Command,
        owner: Owner,
        now: u64,
    ) -> Result<u32, String> {
        let id = self.next_command_id;
        self.next_command_id = self.next_command_id.wrapping_add(1).max(1);
        let d = &mut self.drones[idx];
        let c = VehicleCommand::new(d.vehicle_id, source, id, command)
            .map_err(|e| format!("{}: {e}", command.kind()))?;
        self.out.commands.push(c);
        let kind = command.kind();
        if kind.authority() == Some(AuthorityDomain::Flight) {
            d.flight_sent_ns = Some(now);
        }
        match (kind, owner) {
            (CommandKind::GoTo | CommandKind::Takeoff, Owner::Current(token)) => {
                d.target_token = Some(token)
            }
            (k, _) if ends_target(k) => d.target_token = None,
            _ => {}
        }
        if d.pending.len() >= MAX_PENDING {
            d.pending.pop_front();
        }
        d.pending.push_back(Pending {
            command_id: id,
            owner,
        });
        Ok(id)
    }

    /// A position target for drone `idx` at site point `target` (GroundControl's
    /// frame: the calibration offset is taken off), facing `yaw` (CCW from east).
    fn goto(
        &mut self,
        idx: usize,
        target: [f32; 3],
        yaw: Option<f32>,
        speed: Option<f32>,
        owner: Owner,
        now: u64,
    ) -> Result<u32, String> {
        let d = &self.drones[idx];
        let pose = d
            .fresh_pose(now, &self.cfg)
            .ok_or("no position from the vehicle")?;
        let v = [0, 1, 2].map(|i| f64::from(target[i] - d.calibration[i]));
        let (lat_deg, lon_deg) = self.cfg.site.to_geodetic(v[0], v[1]);
        let alt_rel_m = self.cfg.site.alt_rel_of_z(v[2], pose.home_alt_msl) as f32;
        let cmd = Command::GoTo {
            lat_deg,
            lon_deg,
            alt_rel_m,
            yaw_deg: yaw.map(heading_of_yaw),
            speed_mps: speed,
        };
        let id = self.send(idx, CommandSource::SwarmQueue, &cmd, owner, now)?;
        let s = &mut self.drones[idx].stream;
        s.last_ns = Some(now);
        if speed.is_some() {
            s.last_speed = speed;
        }
        Ok(id)
    }

    /// `speed` if it differs from the last speed sent to drone `idx`.
    fn changed_speed(&self, idx: usize, speed: f32) -> Option<f32> {
        match self.drones[idx].stream.last_speed {
            Some(l) if (l - speed).abs() < SPEED_RESEND_MPS => None,
            _ => Some(speed),
        }
    }

    /// A streamed target may go out (a tenth of the period early: ticks jitter).
    fn stream_due(&self, idx: usize, now: u64) -> bool {
        let period = secs(self.cfg.setpoint_period);
        self.drones[idx]
            .stream
            .last_ns
            .is_none_or(|t| now.saturating_sub(t) >= period - period / 10)
    }

    /// An immediate command answered by the vehicle: the reply waits for its ack.
    fn side_command(
        &mut self,
        idx: usize,
        cmd: &SwarmCommand,
        source: CommandSource,
        command: &Command,
        now: u64,
    ) {
        let token = self.token();
        match self.send(idx, source, command, Owner::Side(token), now) {
            Ok(_) => {
                let deadline_ns = now + secs(self.cfg.timeouts.ack);
                self.drones[idx].side.push(SideOp {
                    token,
                    cmd: *cmd,
                    deadline_ns,
                });
            }
            Err(e) => {
                let id = self.drones[idx].id;
                self.refuse(cmd, id, &e);
            }
        }
    }

    /// Brakes drone `idx` unless it is known to be disarmed.
    fn brake(&mut self, idx: usize, now: u64) {
        if self.drones[idx].armed() != Some(false) {
            if let Err(e) = self.send(
                idx,
                CommandSource::SwarmQueue,
                &Command::Brake,
                Owner::Nobody,
                now,
            ) {
                tracing::warn!(drone = self.drones[idx].id, error = %e, "brake not sent");
            }
        }
    }

    // ---- vehicle samples -----------------------------------------------------

    /// The newest `VehicleState` of drone `idx`'s vehicle.
    pub fn handle_state(&mut self, idx: usize, s: &VehicleState, _now: u64) {
        let d = &mut self.drones[idx];
        if s.vehicle_id != d.vehicle_id {
            return;
        }
        let mut pose = Pose::from_state(&self.cfg.site, s);
        if !pose.position_valid {
            // No fix (yet): keep the last valid position rather than report the
            // drone at latitude 0, longitude 0; the attitude is still new.
            let last = d.pose.filter(|p| p.position_valid);
            pose.site = last.map_or([0.0; 3], |p| p.site);
            pose.alt_rel = last.map_or(0.0, |p| p.alt_rel);
            pose.home_alt_msl = last.map_or(self.cfg.site.origin().2, |p| p.home_alt_msl);
            pose.stamp_ns = last.map_or(0, |p| p.stamp_ns);
        }
        d.pose = Some(pose);
    }

    /// A `VehicleStatus` of drone `idx`'s vehicle.
    pub fn handle_status(&mut self, idx: usize, s: &VehicleStatus, now: u64) {
        let site = self.cfg.site;
        let d = &mut self.drones[idx];
        if s.vehicle_id != d.vehicle_id {
            return;
        }
        d.status = Some(*s);
        d.status_rx_ns = now;
        if d.autopilot_home.is_none()
            && s.home_valid == 1
            && s.home_lat_deg.is_finite()
            && s.home_lon_deg.is_finite()
            && s.home_alt_msl_m.is_finite()
        {
            let [x, y] = site.to_site_xy(s.home_lat_deg, s.home_lon_deg);
            d.autopilot_home = Some([
                x as f32,
                y as f32,
                site.z_of_msl(f64::from(s.home_alt_msl_m)) as f32,
            ]);
        }
    }

    /// A `CommandAck` from drone `idx`'s vehicle.
    pub fn handle_ack(&mut self, idx: usize, ack: &CommandAck, now: u64) {
        if ack.source != CommandSource::SwarmQueue.to_wire() {
            return;
        }
        let d = &mut self.drones[idx];
        if ack.vehicle_id != d.vehicle_id {
            return;
        }
        let Some(pos) = d
            .pending
            .iter()
            .position(|p| p.command_id == ack.command_id)
        else {
            return;
        };
        match ack.result() {
            Some(AckResult::InProgress) => {}
            Some(AckResult::Accepted) | Some(AckResult::Limited) => {
                let owner = d.pending.remove(pos).map_or(Owner::Nobody, |p| p.owner);
                self.accepted(idx, owner, ack.command_id, now);
            }
            _ => {
                let owner = d.pending.remove(pos).map_or(Owner::Nobody, |p| p.owner);
                self.vehicle_refused(idx, owner, &refusal_text(ack), now);
            }
        }
    }

    fn accepted(&mut self, idx: usize, owner: Owner, id: u32, now: u64) {
        match owner {
            Owner::Current(token) => {
                let d = &mut self.drones[idx];
                let Some(mut r) = d.current.take_if(|r| r.token == token) else {
                    return;
                };
                if r.awaiting == Some(id) {
                    r.awaiting = None;
                    if let Err(e) = self.next_takeoff_step(idx, &mut r, now) {
                        self.finish(idx, r, SwarmResult::Refused, &e);
                        return;
                    }
                    self.drones[idx].current = Some(r);
                    // Send what waited for this (a position after GUIDED) at once.
                    self.step_current(idx, now);
                } else {
                    self.drones[idx].current = Some(r);
                }
            }
            Owner::Side(token) => {
                let d = &mut self.drones[idx];
                if let Some(pos) = d.side.iter().position(|s| s.token == token) {
                    let op = d.side.remove(pos);
                    if op.cmd.kind == K::EmergencyMode.to_wire() {
                        // The arbiter took (or withdrew) this queue's own stop.
                        d.emergency = op.cmd.int1 != 0;
                    }
                    let id = d.id;
                    self.success(&op.cmd, id);
                }
            }
            Owner::Nobody => {}
        }
    }

    /// An `ArbiterEvent` of drone `idx`'s vehicle: the decision on a geofence this
    /// queue sent (matched by `request_id`), and the state of its own emergency stop
    /// (engaged: also when the stop's ack says it failed to confirm the brake;
    /// released by this queue; ended by its last engager or an operator's clear).
    pub fn handle_event(&mut self, idx: usize, e: &ArbiterEvent, _now: u64) {
        let d = &mut self.drones[idx];
        if e.vehicle_id != d.vehicle_id {
            return;
        }
        let ours = e.source == CommandSource::SwarmQueue.to_wire();
        match e.event_kind() {
            Some(ArbiterEventKind::EmergencyStop) if ours => d.emergency = true,
            Some(ArbiterEventKind::EmergencyReleased) if ours => d.emergency = false,
            Some(ArbiterEventKind::EmergencyCleared) => {
                if d.emergency {
                    tracing::warn!(drone = d.id, detail = %e.detail.as_str(), "emergency stop ended by the arbiter");
                }
                d.emergency = false;
            }
            Some(
                kind @ (ArbiterEventKind::GeofenceUpdated | ArbiterEventKind::GeofenceInvalid),
            ) if ours && e.request_id != 0 => {
                let Some(pos) = d
                    .fence_requests
                    .iter()
                    .position(|r| r.request_id == e.request_id)
                else {
                    return;
                };
                let r = d.fence_requests.remove(pos);
                let id = d.id;
                if kind == ArbiterEventKind::GeofenceUpdated {
                    tracing::info!(drone = id, min = ?r.fence.min, max = ?r.fence.max, "geofence set");
                    d.fence = Some(r.fence);
                    self.success(&r.cmd, id);
                } else {
                    let why = format!("geofence refused: {}", e.detail.as_str());
                    self.refuse(&r.cmd, id, &why);
                }
            }
            _ => {}
        }
    }

    fn vehicle_refused(&mut self, idx: usize, owner: Owner, why: &str, _now: u64) {
        let id = self.drones[idx].id;
        match owner {
            Owner::Current(token) => {
                if let Some(r) = self.drones[idx].current.take_if(|r| r.token == token) {
                    self.finish(idx, r, SwarmResult::Refused, why);
                }
            }
            Owner::Side(token) => {
                let d = &mut self.drones[idx];
                if let Some(pos) = d.side.iter().position(|s| s.token == token) {
                    let op = d.side.remove(pos);
                    self.refuse(&op.cmd, id, why);
                }
            }
            Owner::Nobody => tracing::warn!(drone = id, reason = why, "vehicle refused"),
        }
    }

    /// `GO_EXTERNAL`: the command after the one just accepted.
    fn next_takeoff_step(&mut self, idx: usize, r: &mut Running, now: u64) -> Result<(), String> {
        let Exec::Takeoff { step, .. } = &mut r.exec else {
            return Ok(());
        };
        let owner = Owner::Current(r.token);
        let src = CommandSource::SwarmQueue;
        match *step {
            TakeoffStep::Mode => {
                r.awaiting =
                    Some(self.send(idx, src, &Command::Arm { force: false }, owner, now)?);
                *step = TakeoffStep::Arm;
            }
            TakeoffStep::Arm => {
                let alt_rel_m = self.cfg.takeoff_alt_m;
                r.awaiting =
                    Some(self.send(idx, src, &Command::Takeoff { alt_rel_m }, owner, now)?);
                *step = TakeoffStep::Takeoff;
            }
            TakeoffStep::Takeoff => *step = TakeoffStep::Climb,
            TakeoffStep::Climb => {}
        }
        Ok(())
    }

    // ---- swarm commands ------------------------------------------------------

    /// One `SwarmCommand` from the gateway: validated again, then applied to its
    /// drone or to every drone.
    pub fn handle_command(&mut self, cmd: &SwarmCommand, now: u64) {
        self.metrics.received.inc();
        let kind = match cmd.kind() {
            Ok(k) => k,
            Err(e) => return self.refuse(cmd, cmd.drone, &e.to_string()),
        };
        if let Err(e) = cmd.validate() {
            return self.refuse(cmd, cmd.drone, &e.to_string());
        }
        if !kind.is_ext() && !cmd.has(swarm_flags::PRIVILEGED) {
            return self.refuse(
                cmd,
                cmd.drone,
                "privileged command from an unprivileged client",
            );
        }
        if cmd.drone == ALL_DRONES && answered_once(kind) {
            self.quiet = true;
            for idx in 0..self.drones.len() {
                self.apply(idx, cmd, kind, now);
            }
            self.quiet = false;
            self.success(cmd, ALL_DRONES);
        } else if cmd.drone == ALL_DRONES {
            for idx in 0..self.drones.len() {
                self.apply(idx, cmd, kind, now);
            }
        } else if let Some(&idx) = self.by_id.get(&cmd.drone) {
            self.apply(idx, cmd, kind, now);
        } else {
            self.refuse(cmd, cmd.drone, "unknown drone");
        }
    }

    fn apply(&mut self, idx: usize, cmd: &SwarmCommand, kind: SwarmCommandKind, now: u64) {
        let id = self.drones[idx].id;
        if needs_active(kind, cmd) && !self.drones[idx].active {
            return self.refuse(cmd, id, "inactive");
        }
        if moves(kind, cmd) && self.in_emergency(idx) {
            return self.refuse(cmd, id, "emergency mode");
        }
        match kind {
            K::ExtGoExternal
            | K::ExtGoHome
            | K::ExtGoHomeAtPosition
            | K::ExtPause
            | K::ExtColor
            | K::ExtColorGradient => self.enqueue(idx, *cmd, kind, None, now),
            K::ExtWaypoint => {
                let mut c = *cmd;
                if let Err(e) = self.fit_box(idx, &mut c) {
                    return self.refuse(cmd, id, &e);
                }
                self.enqueue(idx, c, kind, None, now);
            }
            K::ExtWaypointFollow | K::ExtWaypointFollowColor => self.follow(idx, cmd, kind, now),
            K::SetManualTarget => self.manual_target(idx, cmd, now),
            K::ExtPlaybackAnim => self.playback(idx, cmd, now),
            K::ExtHalt => {
                self.halt(idx, false, "halted", now);
                self.success(cmd, id);
            }
            K::ExtHaltAndSaveCurCmd => {
                self.halt(idx, true, "halted", now);
                self.success(cmd, id);
            }
            K::ExtPushSavedCmd => self.push_saved(idx, cmd, now),
            K::ExtCheckAllIdle => {
                let idle = i32::from(self.drones[idx].idle());
                self.reply(cmd, id, SwarmResult::IdleState, idle, "");
            }
            K::ExtAnimCancelLoop => self.cancel_loop(idx, cmd),
            K::ExtAnimAdjPlaybackSpeed | K::SetAnimPlaybackSpeed => match self.running_anim(idx) {
                Some(a) => {
                    a.speed = cmd.f[0];
                    self.success(cmd, id);
                }
                None => self.refuse(cmd, id, "no animation playing"),
            },
            K::SetAnimPlaybackTime => match self.running_anim(idx) {
                Some(a) => {
                    let start = a.anim.frames()[0].time_s;
                    a.time = (start + f64::from(cmd.f[0])).clamp(a.t0, a.t1);
                    self.success(cmd, id);
                }
                None => self.refuse(cmd, id, "no animation playing"),
            },
            K::SetAnimColorIntensity => {
                self.drones[idx].anim_intensity = cmd.f[0];
                self.success(cmd, id);
            }
            K::ExtSetActive | K::SetActive => {
                self.drones[idx].active = cmd.int1 == 1;
                tracing::info!(drone = id, active = cmd.int1 == 1, "active set");
                self.success(cmd, id);
            }
            K::ExtSetBoundingBox => {
                let b = Aabb {
                    min: [cmd.f[4], cmd.f[5], cmd.f[6]],
                    max: [cmd.f[0], cmd.f[1], cmd.f[2]],
                };
                tracing::info!(drone = id, min = ?b.min, max = ?b.max, "bounding box set");
                self.drones[idx].bbox = Some(b);
                self.success(cmd, id);
            }
            K::ExtSetHomePositionCoordinate => {
                let home = cmd.position();
                self.drones[idx].home_yaw = cmd.f[3];
                self.set_home(idx, cmd, home, now);
            }
            K::ResetHomePosition => match self.drones[idx].tracking() {
                Some(p) if self.drones[idx].fresh_pose(now, &self.cfg).is_some() => {
                    self.set_home(idx, cmd, p, now)
                }
                _ => self.refuse(cmd, id, "no position from the vehicle"),
            },
            K::ResetHomeToSetup => {
                let d = &self.drones[idx];
                match d.setup_home.or(d.autopilot_home) {
                    Some(h) => self.set_home(idx, cmd, h, now),
                    None => self.refuse(cmd, id, "no setup home"),
                }
            }
            K::ResetHomePositionToAnim => match self.anims.get(id) {
                Ok(a) => {
                    let off = self.drones[idx].anim_offset;
                    let p = a.frames()[0].pos;
                    self.set_home(idx, cmd, [0, 1, 2].map(|i| p[i] + off[i]), now);
                }
                Err(e) => self.refuse(cmd, id, &e),
            },
            K::ResetAnimPosition => {
                self.drones[idx].anim_offset = [0.0; 3];
                self.success(cmd, id);
            }
            K::ResetAnimPositionToDrone => {
                let anim = self.anims.get(id);
                let d = &mut self.drones[idx];
                match (anim, d.tracking()) {
                    (Err(e), _) => self.refuse(cmd, id, &e),
                    (Ok(_), None) => self.refuse(cmd, id, "no position from the vehicle"),
                    (Ok(a), Some(t)) => {
                        let p = a.frames()[0].pos;
                        d.anim_offset = [0, 1, 2].map(|i| t[i] - p[i]);
                        tracing::info!(drone = id, offset = ?d.anim_offset, "animation offset set");
                        self.success(cmd, id);
                    }
                }
            }
            K::ExtText => {
                let text = cmd.text.as_str().to_string();
                if self.hw_index == Some(idx) {
                    self.lcd(&text);
                }
                tracing::info!(drone = id, text = %text, "text");
                self.drones[idx].text = text;
                self.success(cmd, id);
            }
            K::ExtVehicleCmd => self.rotate(idx, cmd, now),
            K::EmergencyMode => self.emergency(idx, cmd, now),
            K::MotorsCmd => {
                let c = if cmd.int1 == 1 {
                    Command::Arm { force: false }
                } else {
                    Command::Disarm { force: false }
                };
                self.side_command(idx, cmd, CommandSource::SwarmQueue, &c, now);
            }
            K::SetCalibrationOffset => {
                self.drones[idx].calibration = cmd.position();
                tracing::info!(drone = id, offset = ?cmd.position(), "calibration offset set");
                self.success(cmd, id);
            }
            K::SetGeofence | K::ReconfigureGeofence => {
                let b = Aabb {
                    min: [cmd.f[4], cmd.f[5], cmd.f[6]],
                    max: [cmd.f[0], cmd.f[1], cmd.f[2]],
                };
                self.set_fence(idx, cmd, b, now);
            }
            K::SetGeofencePosition => match self.drones[idx].fence {
                Some(f) => {
                    let c = cmd.position();
                    let half = [0, 1, 2].map(|i| (f.max[i] - f.min[i]) / 2.0);
                    let b = Aabb {
                        min: [0, 1, 2].map(|i| c[i] - half[i]),
                        max: [0, 1, 2].map(|i| c[i] + half[i]),
                    };
                    self.set_fence(idx, cmd, b, now);
                }
                None => self.refuse(cmd, id, "no geofence set"),
            },
            K::ColorMode | K::ManualColorMode => {
                self.drones[idx].manual_color = cmd.int1 != 0;
                tracing::info!(drone = id, manual = cmd.int1 != 0, "colour source set");
                self.success(cmd, id);
            }
            K::CtrlMode => {
                self.drones[idx].ctrl_mode = cmd.int1;
                tracing::info!(drone = id, mode = cmd.int1, "control mode recorded");
                self.success(cmd, id);
            }
            K::SetGroup => {
                self.drones[idx].group = cmd.int1;
                tracing::info!(drone = id, group = cmd.int1, "group recorded");
                self.success(cmd, id);
            }
            K::SetClockTimeout => {
                self.drones[idx].clock_timeout_ms = cmd.int1;
                tracing::info!(drone = id, ms = cmd.int1, "clock timeout recorded");
                self.success(cmd, id);
            }
            K::ExtResetTrackingToFrame => {
                self.drones[idx].tracking_frame = Some(cmd.int1);
                tracing::info!(
                    drone = id,
                    frame = cmd.int1,
                    "reset tracking to frame recorded (GPS/EKF tracking needs no reset)"
                );
                self.success(cmd, id);
            }
            K::ExtVideo | K::ExtVideoCmd | K::ExtTimecode | K::ExtTimecodeActive => {
                tracing::info!(drone = id, kind = kind.as_str(), int1 = cmd.int1, int2 = cmd.int2, f = ?&cmd.f[..4], d = ?cmd.d, "recorded");
                self.success(cmd, id);
            }
            K::WakeUp | K::EnableSafetyPilot | K::ResetTrackingToSetup => {
                self.refuse(cmd, id, "not meaningful for a MAVLink drone")
            }
        }
    }

    /// Applies the drone's box (bounding box ∩ geofence) to a position command.
    fn fit_box(&self, idx: usize, cmd: &mut SwarmCommand) -> Result<(), String> {
        let d = &self.drones[idx];
        let b = match d.limits() {
            Ok(None) => return Ok(()),
            Ok(Some(b)) => b,
            Err(e) => return Err(e.to_string()),
        };
        let p = cmd.position();
        if b.contains(p) {
            return Ok(());
        }
        match self.cfg.bounding_box {
            BoxPolicy::Refuse => Err("outside the bounding box".into()),
            BoxPolicy::Clamp => {
                let c = b.clamp(p);
                tracing::info!(drone = d.id, from = ?p, to = ?c, "waypoint clamped into the bounding box");
                cmd.f[..3].copy_from_slice(&c);
                Ok(())
            }
        }
    }

    fn enqueue(
        &mut self,
        idx: usize,
        cmd: SwarmCommand,
        kind: SwarmCommandKind,
        anim: Option<std::sync::Arc<crate::anim::Animation>>,
        now: u64,
    ) {
        let d = &mut self.drones[idx];
        if d.queue.len() >= self.cfg.queue_capacity {
            let id = d.id;
            return self.refuse(&cmd, id, "queue full");
        }
        d.queue.push_back(Queued { cmd, kind, anim });
        self.advance(idx, now);
    }

    fn follow(&mut self, idx: usize, cmd: &SwarmCommand, kind: SwarmCommandKind, now: u64) {
        let id = self.drones[idx].id;
        let mut c = *cmd;
        if let Err(e) = self.fit_box(idx, &mut c) {
            return self.refuse(cmd, id, &e);
        }
        let default_speed = self.cfg.default_speed_mps;
        let d = &mut self.drones[idx];
        let new = Queued {
            cmd: c,
            kind,
            anim: None,
        };
        if let Some(r) = d.current.as_mut().filter(|r| is_follow(r.q.kind)) {
            let old = std::mem::replace(&mut r.q, new);
            if let Exec::Waypoint {
                target,
                yaw,
                speed,
                dirty,
                ..
            } = &mut r.exec
            {
                *target = c.position();
                *yaw = c.int1 as f32 / 100.0;
                *speed = if c.f[3] > 0.0 { c.f[3] } else { default_speed };
                *dirty = true;
            }
            if kind == K::ExtWaypointFollowColor {
                d.color = c.rgb1();
            }
            self.reply(
                &old.cmd,
                id,
                SwarmResult::Success,
                0,
                "replaced by a newer follow",
            );
            self.step_current(idx, now);
            return;
        }
        if let Some(q) = d.queue.iter_mut().find(|q| is_follow(q.kind)) {
            let old = std::mem::replace(q, new);
            self.reply(
                &old.cmd,
                id,
                SwarmResult::Success,
                0,
                "replaced by a newer follow",
            );
            return;
        }
        self.enqueue(idx, c, kind, None, now);
    }

    fn manual_target(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        let mut c = *cmd;
        if let Err(e) = self.fit_box(idx, &mut c) {
            return self.refuse(cmd, id, &e);
        }
        let mut steering = false;
        if let Some(r) = self.drones[idx].current.take() {
            steering = matches!(r.exec, Exec::Waypoint { .. });
            self.reply(
                &r.q.cmd,
                id,
                SwarmResult::Refused,
                0,
                "replaced by a manual target",
            );
        }
        self.start(
            idx,
            Queued {
                cmd: c,
                kind: K::SetManualTarget,
                anim: None,
            },
            now,
            steering,
        );
    }

    fn playback(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        let anim = match self.anims.get(id) {
            Ok(a) => a,
            Err(e) => return self.refuse(cmd, id, &e),
        };
        let n = anim.len();
        let first = cmd.int1 as usize;
        if first >= n {
            return self.refuse(
                cmd,
                id,
                &format!("first frame {first} beyond the {n} frames"),
            );
        }
        if cmd.int2 >= 0 && (cmd.int2 as usize) < first {
            return self.refuse(cmd, id, "last frame before the first");
        }
        self.enqueue(idx, *cmd, K::ExtPlaybackAnim, Some(anim), now);
    }

    fn running_anim(&mut self, idx: usize) -> Option<&mut AnimRun> {
        match self.drones[idx].current.as_mut().map(|r| &mut r.exec) {
            Some(Exec::Anim(a)) => Some(a),
            _ => None,
        }
    }

    fn cancel_loop(&mut self, idx: usize, cmd: &SwarmCommand) {
        let id = self.drones[idx].id;
        let mut any = false;
        if let Some(a) = self.running_anim(idx) {
            a.cancel = true;
            any = true;
        }
        for q in self.drones[idx].queue.iter_mut() {
            if q.kind == K::ExtPlaybackAnim {
                q.cmd.f[0] = 0.0;
                any = true;
            }
        }
        if any {
            self.success(cmd, id);
        } else {
            self.refuse(cmd, id, "no animation playing");
        }
    }

    /// Clears the current command (saved when `save`) and the queue, and brakes.
    fn halt(&mut self, idx: usize, save: bool, why: &str, now: u64) {
        let id = self.drones[idx].id;
        let current = self.drones[idx].current.take();
        let queued: Vec<Queued> = self.drones[idx].queue.drain(..).collect();
        if let Some(r) = current {
            if save {
                tracing::info!(
                    drone = id,
                    kind = r.q.kind.as_str(),
                    "current command saved"
                );
                if let Some(old) = self.drones[idx].saved.replace(r.q) {
                    self.refuse(&old.cmd, id, "saved command replaced by a newer one");
                }
            } else {
                self.refuse(&r.q.cmd, id, why);
            }
        }
        for q in queued {
            self.refuse(&q.cmd, id, why);
        }
        self.brake(idx, now);
    }

    fn push_saved(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        let d = &mut self.drones[idx];
        let Some(saved) = d.saved.take() else {
            return self.refuse(cmd, id, "no saved command");
        };
        if d.queue.len() >= self.cfg.queue_capacity {
            d.saved = Some(saved);
            return self.refuse(cmd, id, "queue full");
        }
        d.queue.push_back(saved);
        self.success(cmd, id);
        self.advance(idx, now);
    }

    fn set_home(&mut self, idx: usize, cmd: &SwarmCommand, home: [f32; 3], now: u64) {
        let d = &mut self.drones[idx];
        d.home = Some(home);
        tracing::info!(drone = d.id, home = ?home, "home set");
        // Home keeps its altitude: the vehicle measures heights from it, and a home
        // moved up to a hovering drone would put the ground below zero.
        let alt_msl_m =
            d.pose
                .map(|p| p.home_alt_msl)
                .or_else(|| {
                    d.status
                        .filter(|s| s.home_valid == 1)
                        .map(|s| f64::from(s.home_alt_msl_m))
                })
                .unwrap_or_else(|| self.cfg.site.msl_of_z(f64::from(home[2]))) as f32;
        let v = [0, 1].map(|i| f64::from(home[i] - d.calibration[i]));
        let (lat_deg, lon_deg) = self.cfg.site.to_geodetic(v[0], v[1]);
        let c = Command::SetHome {
            lat_deg,
            lon_deg,
            alt_msl_m,
        };
        self.side_command(idx, cmd, CommandSource::SwarmQueue, &c, now);
    }

    /// `EXT_VEHICLECMD`: `int1` 1 relative, 2 absolute rotation, 4 void.
    fn rotate(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let rot = cmd.f[0];
        let c = match cmd.int1 {
            1 => {
                // Relative, CCW positive; CONDITION_YAW turns clockwise positive.
                let r = wrap_deg(rot);
                let d = &mut self.drones[idx];
                d.relative_rotation = wrap_deg(d.relative_rotation + r);
                Command::SetYaw {
                    yaw_deg: -r,
                    rate_dps: 0.0,
                    relative: true,
                }
            }
            2 => {
                self.drones[idx].relative_rotation = wrap_deg(rot);
                Command::SetYaw {
                    yaw_deg: heading_of_yaw(rot),
                    rate_dps: 0.0,
                    relative: false,
                }
            }
            _ => {
                let id = self.drones[idx].id;
                tracing::debug!(drone = id, "void vehicle command");
                return self.success(cmd, id);
            }
        };
        self.side_command(idx, cmd, CommandSource::SwarmQueue, &c, now);
    }

    /// `EMERGENCY_MODE`: 1 engages an emergency stop under this queue's own source;
    /// 0 withdraws it (`ReleaseEmergency`: another source's stop stays, and the
    /// arbiter, not this queue, knows whether ours is still engaged: it may be from
    /// before a restart). The drone's flag follows the arbiter's answers.
    fn emergency(&mut self, idx: usize, cmd: &SwarmCommand, now: u64) {
        let id = self.drones[idx].id;
        if cmd.int1 != 0 {
            tracing::warn!(drone = id, "emergency mode: emergency stop");
            let current = self.drones[idx].current.take();
            let queued: Vec<Queued> = self.drones[idx].queue.drain(..).collect();
            for q in current.map(|r| r.q).into_iter().chain(queued) {
                self.refuse(&q.cmd, id, "emergency mode");
            }
            self.side_command(
                idx,
                cmd,
                CommandSource::SwarmQueue,
                &Command::EmergencyStop,
                now,
            );
        } else {
            tracing::warn!(
                drone = id,
                "emergency mode ended: the queue withdraws its emergency stop"
            );
            self.side_command(
                idx,
                cmd,
                CommandSource::SwarmQueue,
                &Command::ReleaseEmergency,
                now,
            );
        }
    }

    /// The drone's emergency mode: its stop in force, or being engaged.
    fn in_emergency(&self, idx: usize) -> bool {
        let d = &self.drones[idx];
        d.emergency
            || d.side
                .iter()
                .any(|s| s.cmd.kind == K::EmergencyMode.to_wire() && s.cmd.int1 != 0)
    }

    /// Sends the keep-in box `b` to the arbiter; the reply waits for its decision.
    fn set_fence(&mut self, idx: usize, cmd: &SwarmCommand, b: Aabb, now: u64) {
        let id = self.drones[idx].id;
        match self.geofence_sample(idx, &b) {
            Ok(mut g) => {
                let request_id = self.next_fence_request;
                self.next_fence_request = self.next_fence_request.wrapping_add(1).max(1);
                g.request_id = request_id;
                tracing::debug!(drone = id, request_id, min = ?b.min, max = ?b.max, "geofence sent");
                self.drones[idx].fence_requests.push(FenceRequest {
                    request_id,
                    cmd: *cmd,
                    fence: b,
                    deadline_ns: now + FENCE_ANSWER_TIMEOUT_NS,
                });
                self.out.geofences.push(Box::new(g));
            }
            Err(e) => self.refuse(cmd, id, &e),
        }
    }

    /// The keep-in box `b` (site frame) as the arbiter's geofence for drone `idx`.
    fn geofence_sample(&self, idx: usize, b: &Aabb) -> Result<GeofenceSet, String> {
        if (0..3).any(|i| b.min[i] >= b.max[i]) {
            return Err("geofence box is empty".into());
        }
        let d = &self.drones[idx];
        let site = &self.cfg.site;
        let home_alt = d
            .pose
            .map(|p| p.home_alt_msl)
            .or_else(|| {
                d.status
                    .filter(|s| s.home_valid == 1)
                    .map(|s| f64::from(s.home_alt_msl_m))
            })
            .unwrap_or(site.origin().2);
        let c = d.calibration;
        let mut poly = FencePolygon {
            kind: FenceKind::KeepIn.to_wire(),
            vertex_count: 4,
            ..FencePolygon::default()
        };
        let corners = [
            (b.min[0], b.min[1]),
            (b.max[0], b.min[1]),
            (b.max[0], b.max[1]),
            (b.min[0], b.max[1]),
        ];
        debug_assert!(corners.len() <= MAX_FENCE_VERTICES);
        for (v, (x, y)) in poly.vertices.iter_mut().zip(corners) {
            let (lat, lon) = site.to_geodetic(f64::from(x - c[0]), f64::from(y - c[1]));
            *v = [lat, lon];
        }
        let mut g = GeofenceSet {
            vehicle_id: d.vehicle_id,
            enabled: 1,
            polygon_count: 1,
            source: CommandSource::SwarmQueue.to_wire(),
            ceiling_m: site.alt_rel_of_z(f64::from(b.max[2] - c[2]), home_alt) as f32,
            floor_m: site.alt_rel_of_z(f64::from(b.min[2] - c[2]), home_alt) as f32,
            ..GeofenceSet::default()
        };
        g.polygons[0] = poly;
        g.polygons().map_err(|e| format!("geofence: {e}"))?;
        Ok(g)
    }

    // ---- hardware ------------------------------------------------------------

    fn hw_request(&mut self, op: HardwareOp) -> HardwareRequest {
        let id = self.hw_request_id;
        self.hw_request_id = self.hw_request_id.wrapping_add(1);
        HardwareRequest::new(id, op)
    }

    fn lcd(&mut self, text: &str) {
        let w = self.cfg.lcd_width;
        let line0: String = text.chars().take(w).collect();
        let line1: String = text.chars().skip(w).collect();
        for (op, t) in [(LcdOp::WriteLine0, line0), (LcdOp::WriteLine1, line1)] {
            let mut r = self.hw_request(HardwareOp::Lcd);
            r.sub_op = op.to_wire();
            r.text = FixedStr::new(&t);
            self.out.hardware.push(r);
        }
    }

    /// The hardware drone's colour to its LEDs, at most every 100 ms, only on change.
    /// The hardware drone's colour as LED bytes (`None` without a hardware drone).
    fn led_bytes(&self) -> Option<[u8; 3]> {
        let idx = self.hw_index?;
        Some(
            self.drones[idx]
                .color
                .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
        )
    }

    fn leds(&mut self, now: u64) {
        let Some(bytes) = self.led_bytes() else {
            return;
        };
        if self.hw_last == Some(bytes) || now.saturating_sub(self.hw_last_ns) < LED_PERIOD_NS {
            return;
        }
        for (i, name) in ["red", "green", "blue"].into_iter().enumerate() {
            if self.hw_last.is_some_and(|l| l[i] == bytes[i]) {
                continue;
            }
            let mut r = self.hw_request(HardwareOp::LedSet);
            r.name = FixedStr::new(name);
            r.value = bytes[i];
            self.out.hardware.push(r);
        }
        self.hw_last = Some(bytes);
        self.hw_last_ns = now;
    }

    // ---- execution -----------------------------------------------------------

    /// Whether a tick would only refresh the state: no drone has a command running,
    /// queued or waiting for its vehicle's answer (a side command), no reply or
    /// output waits to be published, and the LEDs show the hardware drone's colour.
    /// Then nothing the queue does depends on when it next ticks: a swarm command
    /// ends the rest as it arrives.
    pub fn at_rest(&self) -> bool {
        self.drones
            .iter()
            .all(|d| d.idle() && d.side.is_empty() && d.fence_requests.is_empty())
            && self.replies.is_empty()
            && self.out.is_empty()
            && self.led_bytes().is_none_or(|b| self.hw_last == Some(b))
    }

    /// Steps every drone: side-command timeouts, the current command, the next
    /// command when the current one finished; LEDs; gauges.
    pub fn tick(&mut self, now: u64) {
        let mut flying = 0;
        for idx in 0..self.drones.len() {
            self.expire_side(idx, now);
            self.step_current(idx, now);
            self.advance(idx, now);
            self.keepalive(idx, now);
            let d = &self.drones[idx];
            if d.armed() == Some(true)
                && d.pose
                    .as_ref()
                    .is_some_and(|p| !p.landed(self.cfg.landed_alt_m))
            {
                flying += 1;
            }
            if let Some(g) = self.metrics.queue_depth.get(idx) {
                g.set(d.queue.len() as f64);
            }
        }
        self.metrics.flying.set(f64::from(flying));
        self.leds(now);
    }

    /// Keeps the queue's flight authority while drone `idx`'s current command flies
    /// a position target: the arbiter takes authority from a source silent for its
    /// authority timeout (5 s by default) and then brakes that source's `GoTo` /
    /// `Takeoff`, so a climb or a waypoint leg longer than that would stop halfway.
    /// A `GrabFlightAuthority` goes out when no flight command was sent for
    /// `authority_keepalive` (a tenth early: ticks jitter); streamed targets (a
    /// follow being dragged, an animation) are their own keep-alive. Owned by the
    /// command: refused (`NoAuthority` when a higher source holds authority, or an
    /// emergency stop), it ends the command with the arbiter's reason, as any
    /// refused command of it does. Nothing is sent for a drone without such a
    /// command (at rest, pausing, landing).
    fn keepalive(&mut self, idx: usize, now: u64) {
        let period = secs(self.cfg.authority_keepalive);
        let d = &self.drones[idx];
        let Some(token) = d.current.as_ref().map(|r| r.token) else {
            return;
        };
        if d.target_token != Some(token)
            || d.flight_sent_ns
                .is_some_and(|t| now.saturating_sub(t) < period - period / 10)
        {
            return;
        }
        let grab = Command::GrabFlightAuthority;
        if let Err(e) = self.send(
            idx,
            CommandSource::SwarmQueue,
            &grab,
            Owner::Current(token),
            now,
        ) {
            tracing::warn!(drone = self.drones[idx].id, error = %e, "authority keep-alive not sent");
        }
    }

    fn expire_side(&mut self, idx: usize, now: u64) {
        self.expire_fences(idx, now);
        if self.drones[idx].side.iter().all(|s| s.deadline_ns > now) {
            return;
        }
        let id = self.drones[idx].id;
        let (late, keep): (Vec<SideOp>, Vec<SideOp>) = self.drones[idx]
            .side
            .drain(..)
            .partition(|s| s.deadline_ns <= now);
        self.drones[idx].side = keep;
        for op in late {
            self.reply(
                &op.cmd,
                id,
                SwarmResult::Timeout,
                0,
                "no answer from the vehicle",
            );
        }
    }

    /// Geofences the arbiter did not decide on in time: `Timeout` (the drone's
    /// fence stays what the arbiter last took).
    fn expire_fences(&mut self, idx: usize, now: u64) {
        let d = &mut self.drones[idx];
        if d.fence_requests.iter().all(|r| r.deadline_ns > now) {
            return;
        }
        let id = d.id;
        let (late, keep): (Vec<FenceRequest>, Vec<FenceRequest>) = d
            .fence_requests
            .drain(..)
            .partition(|r| r.deadline_ns <= now);
        d.fence_requests = keep;
        for r in late {
            self.reply(
                &r.cmd,
                id,
                SwarmResult::Timeout,
                0,
                "no geofence decision from the arbiter",
            );
        }
    }

    /// Starts queued commands until one keeps running (or the queue is empty).
    fn advance(&mut self, idx: usize, now: u64) {
        let mut budget = self.drones[idx].queue.len();
        while self.drones[idx].current.is_none() && budget > 0 {
            budget -= 1;
            let Some(q) = self.drones[idx].queue.pop_front() else {
                break;
            };
            self.start(idx, q, now, false);
        }
    }

    fn finish(&mut self, idx: usize, r: Running, result: SwarmResult, why: &str) {
        let id = self.drones[idx].id;
        self.reply(&r.q.cmd, id, result, 0, why);
    }

    /// Makes `q` drone `idx`'s current command (or answers it at once).
    ///
    /// A command that moves the vehicle asks for GUIDED first, also when the last
    /// status says GUIDED: that status repeats a heartbeat up to a second old, and
    /// someone (the pilot, a ground station) may have switched to LOITER since. A
    /// position target sent in LOITER is ignored, and the command would wait out its
    /// deadline. ArduCopter accepts a request for the mode it is in and changes
    /// nothing. The exception is `steering`, true for a manual target that replaces a
    /// running position command, as a dragged target does many times a second: it asks
    /// only when the status shows another mode (the command it replaces asked), so a
    /// fast stream is not held up by an acknowledgement per target.
    fn start(&mut self, idx: usize, q: Queued, now: u64, steering: bool) {
        let token = self.token();
        let id = self.drones[idx].id;
        let cfg = &self.cfg;
        let d = &self.drones[idx];
        let pose = d.fresh_pose(now, cfg).copied();
        let tracking = d.tracking();
        let armed = d.armed();
        let flying = armed == Some(true) && pose.is_some_and(|p| !p.landed(cfg.landed_alt_m));
        let ask_guided = !steering
            || d.status
                .is_some_and(|s| s.flight_mode() != FlightMode::Guided);
        let refuse_motion = || -> Option<&'static str> {
            if pose.is_none() {
                Some("no position from the vehicle")
            } else if armed.is_none() {
                Some("no status from the vehicle")
            } else if !flying {
                Some("not flying: take off first")
            } else {
                None
            }
        };
        let c = q.cmd;
        let mut deadline_ns = None;
        let mut guided_first = false;
        let exec = match q.kind {
            K::ExtGoExternal => {
                if armed == Some(true) && pose.is_some_and(|p| p.alt_rel > cfg.landed_alt_m) {
                    return self.reply(&c, id, SwarmResult::Success, 0, "already flying");
                }
                let target = match (tracking, pose) {
                    (Some(t), Some(p)) => [t[0], t[1], t[2] - p.alt_rel + cfg.takeoff_alt_m],
                    _ => [0.0, 0.0, cfg.takeoff_alt_m],
                };
                deadline_ns = Some(now + secs(cfg.timeouts.takeoff));
                Exec::Takeoff {
                    step: TakeoffStep::Mode,
                    target,
                }
            }
            K::ExtWaypoint
            | K::SetManualTarget
            | K::ExtWaypointFollow
            | K::ExtWaypointFollowColor => {
                if let Some(why) = refuse_motion() {
                    return self.reply(&c, id, SwarmResult::Refused, 0, why);
                }
                let target = c.position();
                let speed = if c.f[3] > 0.0 {
                    c.f[3]
                } else {
                    cfg.default_speed_mps
                };
                let follow = is_follow(q.kind);
                if !follow {
                    let d = tracking.map_or(0.0, |t| dist(t, target));
                    deadline_ns = Some(
                        now + secs(cfg.timeouts.waypoint_base)
                            + ns_of_s(cfg.timeouts.waypoint_factor * d / speed),
                    );
                }
                guided_first = ask_guided;
                Exec::Waypoint {
                    target,
                    yaw: c.int1 as f32 / 100.0,
                    speed,
                    follow,
                    dirty: true,
                }
            }
            K::ExtGoHome => {
                if armed == Some(false) {
                    return self.reply(&c, id, SwarmResult::Success, 0, "on the ground");
                }
                if let Some(why) = refuse_motion() {
                    return self.reply(&c, id, SwarmResult::Refused, 0, why);
                }
                let Some(home) = d.home.or(d.setup_home).or(d.autopilot_home) else {
                    return self.reply(&c, id, SwarmResult::Refused, 0, "no home position");
                };
                let t = tracking.unwrap_or(home);
                let target = [home[0], home[1], t[2]];
                let dh = dist_xy(t, target);
                deadline_ns = Some(
                    now + secs(cfg.timeouts.waypoint_base)
                        + ns_of_s(cfg.timeouts.waypoint_factor * dh / cfg.default_speed_mps),
                );
                guided_first = ask_guided;
                Exec::GoHome {
                    target,
                    sent: false,
                    landing: false,
                }
            }
            K::ExtGoHomeAtPosition => {
                if armed == Some(false) {
                    return self.reply(&c, id, SwarmResult::Success, 0, "on the ground");
                }
                let target = match (tracking, pose) {
                    (Some(t), Some(p)) => [t[0], t[1], t[2] - p.alt_rel],
                    (Some(t), None) => t,
                    _ => [0.0; 3],
                };
                deadline_ns = Some(now + secs(cfg.timeouts.land));
                Exec::Land { target }
            }
            K::ExtPause => Exec::Pause {
                until_ns: now + ns_of_s(c.f[0]),
            },
            K::ExtColor => Exec::Color {
                from: d.color,
                to: c.rgb1(),
                start_ns: now,
                dur_ns: ns_of_s(c.f[0]),
            },
            K::ExtColorGradient => Exec::Color {
                from: c.rgb1(),
                to: c.rgb2(),
                start_ns: now,
                dur_ns: ns_of_s(c.f[0]),
            },
            K::ExtPlaybackAnim => {
                let Some(anim) = q.anim.clone() else {
                    return self.reply(&c, id, SwarmResult::Refused, 0, "no animation loaded");
                };
                let use_pos = c.f[2] >= 0.5;
                if use_pos {
                    if let Some(why) = refuse_motion() {
                        return self.reply(&c, id, SwarmResult::Refused, 0, why);
                    }
                }
                let n = anim.len();
                let first = (c.int1.max(0) as usize).min(n - 1);
                let last = if c.int2 < 0 {
                    n - 1
                } else {
                    (c.int2 as usize).clamp(first, n - 1)
                };
                let t0 = anim.frames()[first].time_s;
                let t1 = anim.frames()[last].time_s;
                guided_first = use_pos && ask_guided;
                Exec::Anim(AnimRun {
                    point: anim.frames()[first],
                    anim,
                    t0,
                    t1,
                    time: t0,
                    last_ns: now,
                    looping: c.f[0] >= 0.5,
                    cancel: false,
                    speed: c.f[1],
                    use_pos,
                    use_color: c.f[3] >= 0.5,
                    frame: first,
                })
            }
            other => {
                return self.reply(
                    &c,
                    id,
                    SwarmResult::Refused,
                    0,
                    &format!("{other} cannot be queued"),
                )
            }
        };
        if q.kind == K::ExtWaypointFollowColor {
            self.drones[idx].color = c.rgb1();
        }
        let kind = q.kind;
        let mut r = Running {
            q,
            token,
            started_ns: now,
            deadline_ns,
            exec,
            awaiting: None,
        };
        let first = match (&r.exec, guided_first) {
            (Exec::Takeoff { .. }, _) | (_, true) => Some(Command::SetMode(FlightMode::Guided)),
            (Exec::Land { .. }, _) => Some(Command::Land),
            _ => None,
        };
        if let Some(cmd) = first {
            match self.send(
                idx,
                CommandSource::SwarmQueue,
                &cmd,
                Owner::Current(token),
                now,
            ) {
                Ok(cid) => {
                    if !matches!(cmd, Command::Land) {
                        r.awaiting = Some(cid);
                    }
                }
                Err(e) => return self.finish(idx, r, SwarmResult::Refused, &e),
            }
        }
        tracing::debug!(
            drone = id,
            kind = kind.as_str(),
            request = r.q.cmd.request_id,
            "started"
        );
        self.drones[idx].current = Some(r);
        self.step_current(idx, now);
    }

    fn step_current(&mut self, idx: usize, now: u64) {
        let Some(mut r) = self.drones[idx].current.take() else {
            return;
        };
        match self.step(idx, &mut r, now) {
            None => self.drones[idx].current = Some(r),
            Some((result, why)) => self.finish(idx, r, result, &why),
        }
    }

    /// One step of the running command `r` of drone `idx`; `Some` when it ends.
    fn step(&mut self, idx: usize, r: &mut Running, now: u64) -> Option<(SwarmResult, String)> {
        if let Some(dl) = r.deadline_ns {
            if now >= dl {
                let s = (dl - r.started_ns) as f64 / 1e9;
                return Some((
                    SwarmResult::Timeout,
                    format!("{} not finished in {s:.0} s", r.q.kind),
                ));
            }
        }
        let tol = self.cfg.waypoint_tolerance_m;
        let landed_alt = self.cfg.landed_alt_m;
        let token = r.token;
        let awaiting = r.awaiting;
        let d = &self.drones[idx];
        let pose = d.fresh_pose(now, &self.cfg).copied();
        let tracking = d.tracking();
        let landed = d.armed() == Some(false) || pose.is_some_and(|p| p.landed(landed_alt));
        match &mut r.exec {
            Exec::Takeoff { step, .. } => {
                if *step == TakeoffStep::Climb
                    && pose.is_some_and(|p| p.alt_rel >= self.cfg.takeoff_alt_m - tol)
                {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Waypoint {
                target,
                yaw,
                speed,
                follow,
                dirty,
            } => {
                if awaiting.is_none() && *dirty && (!*follow || self.stream_due(idx, now)) {
                    let spd = if *follow {
                        self.changed_speed(idx, *speed)
                    } else {
                        Some(*speed)
                    };
                    let (t, y) = (*target, *yaw);
                    if let Err(e) = self.goto(idx, t, Some(y), spd, Owner::Current(token), now) {
                        return Some((SwarmResult::Refused, e));
                    }
                    *dirty = false;
                }
                if !*follow && tracking.is_some_and(|p| dist(p, *target) <= tol) && pose.is_some() {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::GoHome {
                target,
                sent,
                landing,
            } => {
                if *landing {
                    if landed {
                        return Some((SwarmResult::Success, String::new()));
                    }
                } else if awaiting.is_none() {
                    if !*sent {
                        let t = *target;
                        let speed = Some(self.cfg.default_speed_mps);
                        if let Err(e) = self.goto(idx, t, None, speed, Owner::Current(token), now) {
                            return Some((SwarmResult::Refused, e));
                        }
                        *sent = true;
                    }
                    if pose.is_some() && tracking.is_some_and(|p| dist_xy(p, *target) <= tol) {
                        if let Err(e) = self.send(
                            idx,
                            CommandSource::SwarmQueue,
                            &Command::Land,
                            Owner::Current(token),
                            now,
                        ) {
                            return Some((SwarmResult::Refused, e));
                        }
                        *landing = true;
                        if let (Some(t), Some(p)) = (tracking, pose) {
                            *target = [t[0], t[1], t[2] - p.alt_rel];
                        }
                        r.deadline_ns = Some(now + secs(self.cfg.timeouts.land));
                    }
                }
            }
            Exec::Land { .. } => {
                if landed {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Pause { until_ns } => {
                if now >= *until_ns {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Color {
                from,
                to,
                start_ns,
                dur_ns,
            } => {
                let u = if *dur_ns == 0 {
                    1.0
                } else {
                    (now.saturating_sub(*start_ns) as f64 / *dur_ns as f64).min(1.0) as f32
                };
                self.drones[idx].color = lerp3(*from, *to, u);
                if u >= 1.0 {
                    return Some((SwarmResult::Success, String::new()));
                }
            }
            Exec::Anim(a) => return self.step_anim(idx, a, token, awaiting, now),
        }
        None
    }

    fn step_anim(
        &mut self,
        idx: usize,
        a: &mut AnimRun,
        token: u64,
        awaiting: Option<u32>,
        now: u64,
    ) -> Option<(SwarmResult, String)> {
        let dt = now.saturating_sub(a.last_ns) as f64 / 1e9;
        a.last_ns = now;
        a.time += dt * f64::from(a.speed);
        let mut done = false;
        if a.time >= a.t1 {
            let len = a.t1 - a.t0;
            if a.looping && !a.cancel && len > 0.0 {
                a.time = a.t0 + (a.time - a.t0) % len;
            } else if a.looping && !a.cancel {
                a.time = a.t1;
            } else {
                a.time = a.t1;
                done = true;
            }
        }
        let (k, frame) = a.anim.sample(a.time);
        let d = &self.drones[idx];
        let off = d.anim_offset;
        let mut pos = [0, 1, 2].map(|i| k.pos[i] + off[i]);
        if let Ok(Some(b)) = d.limits() {
            pos = b.clamp(pos);
        }
        a.frame = frame;
        a.point = Keyframe { pos, ..k };
        if a.use_color && !d.manual_color {
            let i = d.anim_intensity;
            self.drones[idx].color = k.rgb.map(|c| c * i);
        }
        if a.use_pos && awaiting.is_none() && (done || self.stream_due(idx, now)) {
            let path = a.anim.speed_at(a.time) * a.speed;
            let speed = (path * 1.5 + STREAM_SPEED_MARGIN_MPS)
                .max(self.cfg.default_speed_mps)
                .min(skymesh_ipc_types::swarm::SWARM_MAX_SPEED_MPS);
            let spd = self.changed_speed(idx, speed);
            if let Err(e) = self.goto(idx, pos, Some(k.yaw_deg), spd, Owner::Current(token), now) {
                return Some((SwarmResult::Refused, e));
            }
        }
        done.then(|| (SwarmResult::Success, String::new()))
    }

    // ---- state ---------------------------------------------------------------

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
