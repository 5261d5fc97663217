//! One DRC session, pure: the seq rules, stick freshness, the heartbeat timeout and
//! the stick → setpoint conversion. Time is passed in (`Instant`), so every rule is
//! tested without a clock; the async task ([`super::task`]) only wakes it at
//! [`Session::next_deadline`] and does what it answers.
//!
//! drone_control is decided in this order (the first that applies answers):
//!
//! | check | result |
//! |---|---|
//! | the arbiter does not give us (`dji_drc`) flight authority | 319030 |
//! | `seq` lower than the last accepted one (0 always restarts the count) | 319033 |
//! | the stick stream went stale and the link braked (see below) | 319034, not flown |
//! | the autopilot link is down, or its status older than [`STATUS_MAX_AGE`] | `VEHICLE_UNAVAILABLE` |
//! | the vehicle is in RTL, SmartRTL or LAND (the joystick is invalid there, as DJI's `joystick_invalid_notify` reasons say; sticks never take a vehicle out of a return or a landing) | `WRONG_STATE` |
//! | a horizontal stick without a known vehicle yaw | `VEHICLE_UNAVAILABLE` |
//! | otherwise | 0: a `VelocityNed` setpoint (and `SetMode(Guided)` first when needed) |
//!
//! Result 0 means the setpoint was published to the arbiter (the reply does not wait
//! for its `CommandAck`, which would cost a round trip on every stick). What the
//! arbiter does with it is counted (`skymesh_dji_drc_stick_commands_total{result}`),
//! timed (delay_info_push) and, for the geofence, reported as joystick_invalid_notify
//! reason 3; a lost authority shows in the next drone_control's 319030.
//!
//! Staleness: while the last accepted stick was non-zero, no drone_control for
//! `stick_max_age` makes the link brake at once (a timer, not the next message) and
//! the next drone_control is answered 319034 and not flown: the cloud's stream
//! restarts with the one after it. A zero stick is a hover, so a pause after it is
//! not stale. Equal seqs are accepted (QoS 1 may deliver a message twice; flying the
//! same stick twice is harmless).

use std::time::{Duration, Instant};

use dji_proto::{codes, DroneControl};
use skymesh_ipc_types::{Command, FlightMode};

use crate::link::Snapshot;

/// A `VehicleStatus` older than this (it comes on change and at 1 Hz) means the
/// autopilot link (or autopilot-link itself) is gone.
pub const STATUS_MAX_AGE: Duration = Duration::from_secs(3);
/// At most one `SetMode(Guided)` per this period while sticks move a vehicle in
/// another mode.
pub const GUIDED_REQUEST_EVERY: Duration = Duration::from_secs(2);

/// What a stick decision needs to know of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleView {
    /// The arbiter says `dji_drc` holds flight authority.
    pub holds_flight: bool,
    /// Autopilot heartbeats arrive and the status is fresh.
    pub available: bool,
    pub mode: FlightMode,
    pub armed: bool,
    /// Yaw (rad, clockwise from north): the attitude's, else the heading over ground.
    pub yaw_rad: Option<f32>,
}

impl VehicleView {
    /// From the link's latest samples at `now_ns` (`CLOCK_MONOTONIC`).
    pub fn from_snapshot(snap: &Snapshot, now_ns: u64) -> Self {
        let status = snap.status;
        let max_age_ns = u64::try_from(STATUS_MAX_AGE.as_nanos()).unwrap_or(u64::MAX);
        let available =
            status.is_some_and(|s| s.is_link_up() && s.header.age_ns(now_ns) <= max_age_ns);
        let yaw_rad = snap.state.and_then(|s| {
            if s.attitude_valid != 0 && s.yaw_rad.is_finite() {
                Some(s.yaw_rad)
            } else if s.position_valid != 0 && s.heading_deg.is_finite() {
                Some(s.heading_deg.to_radians())
            } else {
                None
            }
        });
        VehicleView {
            holds_flight: snap.holds_flight(),
            available,
            mode: status.map_or(FlightMode::Unknown, |s| s.flight_mode()),
            armed: status.is_some_and(|s| s.is_armed()),
            yaw_rad,
        }
    }
}

/// The answer to one drone_control.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StickDecision {
    /// Not flown; `data.result` is this code.
    Refuse(u32),
    /// Fly: send `SetMode(Guided)` first when `set_guided`, then `setpoint`.
    Fly { set_guided: bool, setpoint: Command },
}

/// What became due at a [`Session::poll`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Due {
    /// The moving stick stream went stale: brake now (the next drone_control gets 319034).
    Brake,
    /// No heart_beat for the timeout: leave DRC mode (brake first if
    /// [`Session::sticks_active`]).
    HeartbeatTimeout,
}

/// The limits of a session (from `DrcConfig`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionLimits {
    pub stick_max_age: Duration,
    pub heartbeat_timeout: Duration,
}

/// One DRC session, from drc_mode_enter to leaving.
#[derive(Debug)]
pub struct Session {
    limits: SessionLimits,
    last_heartbeat: Instant,
    /// seq of the last drone_control flown.
    last_seq: Option<i64>,
    last_stick_at: Option<Instant>,
    /// The last stick flown was non-zero.
    sticks_active: bool,
    /// Braked for staleness; the next drone_control past the authority and seq
    /// checks is answered 319034.
    stale_pending: bool,
    last_guided_request: Option<Instant>,
}

impl Session {
    /// A session entered at `now` (the heartbeat timeout counts from here).
    pub fn new(limits: SessionLimits, now: Instant) -> Self {
        Session {
            limits,
            last_heartbeat: now,
            last_seq: None,
            last_stick_at: None,
            sticks_active: false,
            stale_pending: false,
            last_guided_request: None,
        }
    }

    /// The last stick flown moves the vehicle (leaving must brake).
    pub fn sticks_active(&self) -> bool {
        self.sticks_active
    }

    /// When [`Session::poll`] next has something to do.
    pub fn next_deadline(&self) -> Instant {
        let heartbeat = self.last_heartbeat + self.limits.heartbeat_timeout;
        match self.last_stick_at.filter(|_| self.sticks_active) {
            Some(t) => heartbeat.min(t + self.limits.stick_max_age),
            None => heartbeat,
        }
    }

    /// What is due at `now`: the heartbeat timeout first (leaving brakes anyway),
    /// then a stale stick stream.
    pub fn poll(&mut self, now: Instant) -> Option<Due> {
        if now >= self.last_heartbeat + self.limits.heartbeat_timeout {
            return Some(Due::HeartbeatTimeout);
        }
        let stale = self
            .last_stick_at
            .is_some_and(|t| self.sticks_active && now >= t + self.limits.stick_max_age);
        if stale {
            self.sticks_active = false;
            self.stale_pending = true;
            return Some(Due::Brake);
        }
        None
    }

    pub fn heart_beat(&mut self, now: Instant) {
        self.last_heartbeat = now;
    }

    /// An emergency stop was sent: the vehicle brakes; the stream is over.
    pub fn emergency_stop(&mut self) {
        self.sticks_active = false;
        self.stale_pending = false;
    }

    /// Decide one drone_control at `now` (call [`Session::poll`] first).
    pub fn drone_control(
        &mut self,
        now: Instant,
        stick: &DroneControl,
        vehicle: &VehicleView,
    ) -> StickDecision {
        if !vehicle.holds_flight {
            return StickDecision::Refuse(codes::NO_FLIGHT_AUTHORITY);
        }
        if stick.seq != 0 && self.last_seq.is_some_and(|last| stick.seq < last) {
            return StickDecision::Refuse(codes::SEQ_OUT_OF_ORDER);
        }
        if self.stale_pending {
            self.stale_pending = false;
            return StickDecision::Refuse(codes::STICK_STALE);
        }
        if !vehicle.available {
            return StickDecision::Refuse(codes::VEHICLE_UNAVAILABLE);
        }
        if matches!(
            vehicle.mode,
            FlightMode::Rtl | FlightMode::SmartRtl | FlightMode::Land
        ) {
            return StickDecision::Refuse(codes::WRONG_STATE);
        }
        let horizontal = stick.x != 0.0 || stick.y != 0.0;
        let moving = horizontal || stick.h != 0.0 || stick.w != 0.0;
        let yaw = match vehicle.yaw_rad {
            Some(yaw) => yaw,
            None if horizontal => return StickDecision::Refuse(codes::VEHICLE_UNAVAILABLE),
            None => 0.0,
        };
        let due = self
            .last_guided_request
            .is_none_or(|t| now.saturating_duration_since(t) >= GUIDED_REQUEST_EVERY);
        let set_guided = moving && vehicle.mode != FlightMode::Guided && due;
        if set_guided {
            self.last_guided_request = Some(now);
        }
        self.last_seq = Some(stick.seq);
        self.last_stick_at = Some(now);
        self.sticks_active = moving;
        StickDecision::Fly {
            set_guided,
            setpoint: stick_setpoint(stick, yaw),
        }
    }
}

/// The document's body-frame stick (y forward +, x LEFT +, h up +, w clockwise deg/s)
/// as a NED velocity with a yaw rate, rotated by the vehicle's yaw `yaw_rad`
/// (clockwise from north). A zero stick is a zero velocity: hold.
pub fn stick_setpoint(stick: &DroneControl, yaw_rad: f32) -> Command {
    let forward = stick.y;
    let right = -stick.x;
    let (sin, cos) = f64::from(yaw_rad).sin_cos();
    let north = forward * cos - right * sin;
    let east = forward * sin + right * cos;
    Command::VelocityNed {
        vel_ned_mps: [north as f32, east as f32, -stick.h as f32],
        yaw_rate_dps: Some(stick.w as f32),
    }
}
