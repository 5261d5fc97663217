//! skymesh swarm-queue: GroundControl's per-drone command queues, executed on
//! MAVLink drones through the arbiter.
//!
//! `groundcontrol-gateway` cuts the state server's records, checks privilege and
//! publishes one validated `SwarmCommand` per drone (or for every drone) on
//! `skymesh/swarm/command`. This service keeps, per drone, a current command and a
//! FIFO queue, executes them only through `VehicleCommand`s from source
//! `SwarmQueue` (the emergency stop too) on each vehicle's command topic,
//! answers every command with exactly one `SwarmReply` (success, timeout or refused
//! with a reason; `CHECK_ALL_IDLE` with one idle state per drone), and publishes
//! every drone's `SwarmState` at `tick_hz` (pose, target, colour, `DroneState`,
//! flags, queue) from which the gateway builds the pose broadcast (once a second
//! at rest: nothing to fly and no reader watching, see `service`).
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] (`deploy/swarm-queue.toml`) |
//! | [`site`] | site frame (x east, y north, z up around the origin) ↔ geodetic; yaw and attitude conventions |
//! | [`core`] | the queues and their execution (pure; time passed in) |
//! | [`anim`] | the per-drone keyframe file format and its loading |
//! | [`metrics`] | `skymesh_swarm_*` series |
//! | [`ipc`] | bus ports |
//! | [`fake`] | a kinematic fleet for the tests and the benchmark |
//! | `service` | the tick loop |
//!
//! # Queue semantics
//!
//! Queued commands (`GO_EXTERNAL`, `GO_HOME`, `GO_HOME_AT_POSITION`, `PAUSE`,
//! `COLOR`, `COLOR_GRADIENT`, `WAYPOINT`, `WAYPOINT_FOLLOW(_COLOR)`,
//! `PLAYBACK_ANIM`) wait in the drone's queue (at most `queue_capacity`; more are
//! refused "queue full") and run one at a time; everything else is applied at once.
//! A command leaves when its finishing condition is met and is answered then.
//! Queued commands are checked on receipt (parameters again, drone, privilege,
//! bounding box, animation file) and again when they start (a position from the
//! vehicle, flying); a refusal at either point is the command's one reply.
//!
//! `EXT_WAYPOINT`, `EXT_WAYPOINT_FOLLOW` (the first of a stream), `EXT_GO_HOME`,
//! `SET_MANUAL_TARGET` and a flown `EXT_PLAYBACK_ANIM` send `SetMode(Guided)` and
//! wait for its acceptance before their first position target, also when the last
//! `VehicleStatus` says GUIDED: it repeats a heartbeat up to a second old, and a
//! LOITER chosen since would make the vehicle ignore the target. A manual target that
//! replaces a running position command asks only when the status shows another mode.
//!
//! Flight authority: the arbiter gives it to the source of each flight command it
//! admits and takes it from a source silent for its `authority_timeout_s` (5 s by
//! default), braking the position target (`GoTo`, `Takeoff`) that source was flying.
//! While a drone's current command flies such a target (a climbing takeoff, a
//! waypoint, a follow, `GO_HOME`'s flight home, a flown animation) and no flight
//! command went to its vehicle for `authority_keepalive_ms` (1 s), the queue sends
//! `GrabFlightAuthority`; nothing for a drone at rest, pausing or landing. A refused
//! keep-alive (`NoAuthority`: a higher source such as the operator took the
//! vehicle) ends the command `Refused` with the arbiter's reason, as any refused
//! vehicle command does, and the queue sends nothing more for it.
//!
//! | command | execution | finishes (reply) |
//! |---|---|---|
//! | `EXT_GO_EXTERNAL` | `SetMode(Guided)` → `Arm` → `Takeoff(takeoff_alt_m)`, each after the previous one's acceptance | height above home ≥ `takeoff_alt_m − waypoint_tolerance_m`; at once if already flying (armed, above `landed_alt_m`); `Timeout` after `timeouts.takeoff_s` |
//! | `EXT_GO_HOME` | `GoTo` home's x, y at the current height, then `Land` | landed or disarmed; at once when disarmed; `Timeout` after the waypoint time, then `timeouts.land_s` |
//! | `EXT_GO_HOME_AT_POSITION` | `Land` | landed or disarmed; at once when disarmed; `Timeout` after `timeouts.land_s` |
//! | `EXT_WAYPOINT` | `GoTo` (site → geodetic, yaw `int1/100` CCW → compass heading, speed `f[3]` or `default_speed_mps`) | within `waypoint_tolerance_m` (3-D); `Timeout` after `waypoint_base_s + waypoint_factor × distance / speed` |
//! | `EXT_WAYPOINT_FOLLOW`, `_COLOR` | replaces the running (or else a queued) follow in place: the replaced one is answered `Success` ("replaced by a newer follow"), the drone re-targets at once (targets streamed at most at `setpoint_hz`) | never by itself: `HALT` ends it (`Refused` "halted") |
//! | `EXT_PAUSE` | nothing sent (the vehicle holds its guided target) | after `f[0]` s |
//! | `EXT_COLOR`, `EXT_COLOR_GRADIENT` | colour fades linearly from the current (or the gradient's first) colour | after `f[0]` s |
//! | `EXT_PLAYBACK_ANIM` | frames `int1..=int2` (−1 = last) of `drone_<id>.csv` at speed `f[1]`: position interpolated and streamed as `GoTo` (at most `setpoint_hz`, speed 1.5 × the path's speed + 0.5, at least `default_speed_mps`) when `f[2]` (choreography) is set, colours × intensity when `f[3]` is set and the colour mode is not manual; loops when `f[0]` is set | at the last frame; a loop only after `ANIM_CANCEL_LOOP` (at the end of the current loop) or by `HALT` |
//!
//! Immediate commands:
//!
//! | command | meaning on a MAVLink drone | reply |
//! |---|---|---|
//! | `EXT_HALT` | current command and queue cleared (each answered `Refused` "halted"); `Brake` unless known disarmed | `Success` |
//! | `EXT_HALT_AND_SAVE_CUR_CMD` | as `HALT`, but the current command is kept in the saved slot (unanswered; an older saved one is answered `Refused`) | `Success` |
//! | `EXT_PUSH_SAVED_CMD` | the saved command goes to the end of the queue and runs again from its start | `Success`; `Refused` "no saved command" |
//! | `EXT_CHECK_ALL_IDLE` | — | one `IdleState` per drone (`ALL_DRONES`) or for the one drone: 1 = no current command and an empty queue |
//! | `EXT_ANIM_CANCEL_LOOP` | the playing animation ends after its current loop; queued animations lose their loop flag | `Success`; `Refused` "no animation playing" |
//! | `EXT_ANIM_ADJ_PLAYBACK_SPEED`, `SET_ANIM_PLAYBACK_SPEED` | the playing animation's speed | `Success`; `Refused` "no animation playing" |
//! | `SET_ANIM_PLAYBACK_TIME` | the playing animation jumps to `f[0]` s after its first keyframe (clamped to the frames played) | as above |
//! | `SET_ANIM_COLOR_INTENSITY` | animation colours are multiplied by `f[0]` (now and later) | `Success` |
//! | `EXT_SET_ACTIVE`, `SET_ACTIVE` | inactive drones refuse "inactive" takeoff, waypoints, follow, manual target, flown animations, rotation and arming; landing, colour, pause stay allowed; running commands continue | `Success` |
//! | `EXT_SET_BOUNDING_BOX` | the drone's box (min from `EXT_PARAM_1`, max from the record): later waypoints, follows and manual targets outside it are clamped to its nearest point (logged) with `bounding_box = "clamp"`, refused "outside the bounding box" with `"refuse"`; animation points are always clamped | `Success` |
//! | `EXT_SET_HOME_POSITION_COORDINATE` | the queue's home (for `GO_HOME`) and `Command::SetHome` to the vehicle (RTL goes there; home keeps its altitude) | after the vehicle's ack: `Success`, `Refused` with its reason, `Timeout` after `timeouts.ack_s` |
//! | `EXT_TEXT` | stored; for `hardware_drone` written to the LCD (line 0, the rest on line 1, which is otherwise cleared) | `Success` |
//! | `EXT_VEHICLECMD` | no rotating base: the body turns, `Command::SetYaw` (`int1` 1 relative: `f[0]` CCW; 2 absolute: CCW from east); `relative_rotation_deg` records the rotation commanded (relative accumulates, absolute sets); 4 (void) does nothing | after the vehicle's ack; void: `Success` |
//! | `EXT_RESET_TRACKING_TO_FRAME`, `EXT_VIDEO`, `EXT_VIDEO_CMD`, `EXT_TIMECODE`, `EXT_TIMECODE_ACTIVE` | recorded and logged (GPS/EKF tracking needs no reset; no video player) | `Success` |
//! | `EMERGENCY_MODE` `int1 ≠ 0` | `Command::EmergencyStop` from the queue's own source `SwarmQueue` (the arbiter brakes, safety takes flight authority, the queue is one of the stop's engagers), current command and queue cleared ("emergency mode"); flag `EMERGENCY` once the arbiter took the stop (its ack, or its `EmergencyStop` event naming `swarm_queue`: a refused stop sets nothing); motion commands refused "emergency mode" while it is in force or being engaged | after the vehicle's ack |
//! | `EMERGENCY_MODE` `int1 = 0` | `Command::ReleaseEmergency` from `SwarmQueue`: withdraws the queue's own stop only (sent whatever the flag says: the arbiter knows whether one is engaged, also from before a restart); another source's stop (a DJI pilot's) stays, and the vehicle stays stopped until its last engager released or an operator cleared it. Never `ReleaseFlightAuthority`. The flag also drops on the arbiter's `EmergencyReleased` (by the queue) and `EmergencyCleared` events | after the ack (`Refused` with the arbiter's reason when the queue had no stop engaged) |
//! | `MOTORS_CMD` | 1 → `Arm`, 0 → `Disarm` (the autopilot refuses to disarm in the air) | after the vehicle's ack |
//! | `SET_MANUAL_TARGET` | replaces the current command (answered `Refused` "replaced by a manual target") with a waypoint to `f[0..3]`, now; the queue stays | as `WAYPOINT` |
//! | `RESET_HOME_POSITION` | home = the drone's tracked position, then as `SET_HOME_POSITION_COORDINATE` | after the ack; `Refused` without a position |
//! | `RESET_HOME_TO_SETUP` | home = the drone's configured `home`, else the autopilot's home as first reported | after the ack |
//! | `RESET_HOME_POSITION_TO_ANIM` | home = the animation's first keyframe + animation offset | after the ack |
//! | `RESET_ANIM_POSITION` | animation offset = 0 | `Success` |
//! | `RESET_ANIM_POSITION_TO_DRONE` | animation offset = tracked position − first keyframe (the animation starts where the drone is) | `Success` |
//! | `SET_CALIBRATION_OFFSET` | `f[0..3]` added to the tracked position (and taken off every target sent) | `Success` |
//! | `SET_GEOFENCE`, `RECONFIGURE_GEOFENCE` | a keep-in box: published as the vehicle's `GeofenceSet` (source `SwarmQueue`, a fresh `request_id`; one 4-vertex keep-in polygon, floor/ceiling above home) for the arbiter to enforce — it is the queue's own fence, kept beside other sources' — and, once the arbiter took it, intersected with the bounding box for the queue's own checks | on the arbiter's decision event with that `request_id` (`skymesh/vehicle/{id}/arbiter_events`): `GeofenceUpdated` → `Success`, `GeofenceInvalid` → `Refused` with its reason (the previous box stays); none within 2 s → `Timeout`; `Refused` at once for an empty box |
//! | `SET_GEOFENCE_POSITION` | the geofence box moved to centre on `f[0..3]` | as above; `Refused` "no geofence set" |
//! | `COLOR_MODE`, `MANUAL_COLOR_MODE` | `int1 ≠ 0`: manual colours (animations do not change the LEDs); 0: animation colours | `Success` |
//! | `CTRL_MODE`, `SET_GROUP`, `SET_CLOCK_TIMEOUT` | recorded and logged | `Success` |
//! | `WAKE_UP`, `ENABLE_SAFETY_PILOT`, `RESET_TRACKING_TO_SETUP` | none: a MAVLink drone is awake when powered, its safety pilot is the RC transmitter, its tracking is GPS/EKF | `Refused` "not meaningful for a MAVLink drone" |
//!
//! A command for `ALL_DRONES` is applied to every drone and answered per drone,
//! except those that cannot fail for a drone (`EXT_SET_BOUNDING_BOX`,
//! `EXT_TIMECODE(_ACTIVE)`, `EXT_VIDEO(_CMD)`, `EXT_RESET_TRACKING_TO_FRAME`,
//! `(EXT_)SET_ACTIVE`, `CTRL_MODE`, `(MANUAL_)COLOR_MODE`, `SET_GROUP`,
//! `SET_CLOCK_TIMEOUT`, `SET_CALIBRATION_OFFSET`, `SET_ANIM_COLOR_INTENSITY`,
//! `RESET_ANIM_POSITION`): one `Success` with drone `ALL_DRONES` (GroundControl
//! sends the global ones as one record, and a timecode every frame would otherwise
//! cost a reply per drone per frame). Unknown drone ids are refused "unknown drone"; a privileged kind without the
//! gateway's `PRIVILEGED` flag is refused; a vehicle's refusal (its `CommandAck`)
//! ends the command that sent it with `Refused` and the reason ("arm refused:
//! denied: ..."), and the drone goes on with its queue.
//!
//! # `DroneState`
//!
//! | condition (first that applies) | state |
//! |---|---|
//! | no `VehicleState` or no `VehicleStatus` received yet | `NONE` |
//! | disarmed, `GO_EXTERNAL` running | `TAKEOFF_WAIT` |
//! | disarmed | `ON_GROUND` |
//! | armed and landed (≤ `landed_alt_m` above home, vertical speed < 0.3 m/s), `GO_EXTERNAL` running | `TAKEOFF_MOTORS_ON` |
//! | armed and landed | `LANDING_MOTORS_OFF` |
//! | flying, `GO_EXTERNAL` running | `TAKEOFF` |
//! | flying and landing (`GO_HOME_AT_POSITION`, the landing part of `GO_HOME`, or the autopilot in LAND), above 2 m | `LANDING_FAST` |
//! | … at or below 2 m | `LANDING_SLOW` |
//! | flying | `FOLLOW_TARGET` |
//!
//! Flags: `IDLE` (no current command, empty queue), `ACTIVE`, `POSE_VALID` (a valid
//! position younger than `pose_timeout_s`), `HAS_SAVED`, `EMERGENCY`, `LINK_DOWN`
//! (no status yet, none for `link_timeout_s`, or the autopilot link reports down).
#![forbid(unsafe_code)]

pub mod anim;
pub mod config;
pub mod core;
pub mod fake;
pub mod fdlimit;
pub mod ipc;
pub mod metrics;
mod service;
pub mod site;

use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::{Bus, CancellationToken, Context, Stats};

pub use crate::core::{Outputs, Swarm};
pub use config::{RawConfig, Settings};

/// The service entry point for `service_main`.
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let (bus, stats, shutdown) = (ctx.bus.clone(), ctx.stats.clone(), ctx.shutdown.clone());
    run_with(settings, bus, stats, shutdown, || ctx.ready()).await
}

/// Runs the queue on `bus` until `shutdown` is cancelled; `ready` is called once
/// every port is open.
///
/// Subscribes to `skymesh/swarm/command` and, per drone,
/// `skymesh/vehicle/{vehicle_id}/{state,status,command_ack,arbiter_events}`; publishes
/// `skymesh/swarm/{reply,state}`, `skymesh/vehicle/{vehicle_id}/{command,geofence}`
/// and (with a `hardware_drone`) `skymesh/hardware/request`.
pub async fn run_with(
    settings: Settings,
    bus: Bus,
    stats: Stats,
    shutdown: CancellationToken,
    ready: impl FnOnce(),
) -> anyhow::Result<()> {
    match fdlimit::raise_nofile_limit() {
        Ok((before, now)) if before != now => {
            tracing::info!(before, now, "raised the open file limit")
        }
        Ok(_) => {}
        Err(e) => tracing::warn!(error = %e, "cannot raise the open file limit"),
    }
    let ids: Vec<u16> = settings.drones.iter().map(|d| d.id).collect();
    // Before the ports: see `metrics` on the stats sample's capacity.
    let metrics = metrics::Metrics::new(&stats, &ids);
    let mut anims = anim::AnimLibrary::new(&settings.animations_dir);
    let loaded = anims.load_all(ids.iter().copied());
    tracing::info!(dir = %settings.animations_dir.display(), loaded, "animations");
    let fds = fdlimit::open_fds();
    let ports = ipc::Ports::open(&bus, &settings)?;
    tracing::info!(
        drones = ids.len(),
        fds_for_ports = ?fds.zip(fdlimit::open_fds()).map(|(a, b)| b.saturating_sub(a)),
        tick = ?settings.tick_period,
        "swarm-queue starting"
    );
    let swarm = Swarm::new(settings, anims, metrics.clone(), monotonic_ns());
    ready();
    service::run_loop(swarm, ports, metrics, shutdown).await
}
