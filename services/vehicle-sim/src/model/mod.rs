//! The simulated multicopter: a pure point-mass model in a local NED frame,
//! stepped with an explicit `dt`. No clock, no I/O: the server steps it at
//! [`crate::config::PHYSICS_HZ`] and tests step it as fast as they like.
//!
//! Inputs are the methods in `commands.rs` (arm, set mode, setpoints, …);
//! outputs are the accessors here plus a queue of [`Event`]s (status texts,
//! home changes) the server turns into MAVLink.

mod battery;
mod commands;
pub mod control;
mod focus;
pub mod geo;
pub mod gimbal;
pub mod gopro;
mod guidance;
mod mode;
pub mod motors;
mod params;
mod payload;
mod yaw;

use mavlink::dialects::ardupilotmega::MavSeverity;
use nalgebra::Vector3;

pub use battery::Battery;
pub use commands::{
    ArmRefusal, DisarmRefusal, GuidedTarget, HomeRefusal, ModeRefusal, NotGuided, SpeedKind,
    TakeoffRefusal, HOME_MAX_FROM_ORIGIN_M,
};
pub use control::Attitude;
pub use focus::{Focus, FocusControl, FocusRefusal, FOCUS_RATE_PCT_S, FOCUS_STEP_PCT, MIN_FOCUS_M};
pub use geo::{GeoPoint, LocalFrame};
pub use gimbal::{Gimbal, GimbalAttitude, GimbalTarget, YawFrame};
pub use gopro::{GoPro, GoProHeartbeat, GoProRefusal};
pub use mode::FlightMode;
pub use motors::{MotorTestRefusal, MotorTestRequest, TestThrottle};
pub use params::{VehicleParams, CMAC_GEOID_UNDULATION_M};
pub use payload::{
    CameraMode, CaptureRefusal, ImageSequence, MountTarget, Payload, Zoom, ZoomRefusal, MAX_IMAGES,
    MAX_ZOOM_STEPS, ZOOM_RATE_PCT_S, ZOOM_STEP_PCT,
};
pub use yaw::YawMode;

use control::{tilt_for, track_velocity, update_attitude, GRAVITY};
use guidance::Guidance;

/// Ground contact this long, without a climb demand, counts as landed (the
/// ArduCopter land detector needs about a second).
const LAND_DETECT_S: f64 = 1.0;

/// Height below which the vehicle counts as touching the ground, metres.
const GROUND_CONTACT_M: f64 = 0.02;

/// Throttle (0..1) that holds a hover (MOT_THST_HOVER).
const HOVER_THROTTLE: f64 = 0.4;

/// Current drawn disarmed (avionics) and armed on the ground (motors at spin-arm), A.
const IDLE_CURRENT_A: f64 = 0.3;
const SPIN_ARM_CURRENT_A: f64 = 1.5;

/// Impact speed above which touching down disarmed is reported as a crash, m/s.
const CRASH_SPEED_MPS: f64 = 3.0;

/// Horizontal drag while falling unpowered, 1/s.
const FALL_DRAG_PER_S: f64 = 0.3;

/// Something the ground should hear about.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A STATUSTEXT.
    Text {
        /// Severity.
        severity: MavSeverity,
        /// At most 50 characters go on the wire.
        text: String,
    },
    /// Home was set or moved (ArduPilot then sends HOME_POSITION).
    HomeChanged,
    /// What the GoPro heartbeat reports changed (the bridge then sends one at once).
    GoProChanged,
}

/// DO_CHANGE_SPEED overrides; cleared on every mode change, as ArduCopter
/// re-initialises its waypoint controller.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct SpeedOverride {
    xy: Option<f64>,
    up: Option<f64>,
    down: Option<f64>,
}

/// The simulated vehicle.
#[derive(Debug, Clone)]
pub struct Vehicle {
    params: VehicleParams,
    frame: LocalFrame,
    time_s: f64,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    accel: Vector3<f64>,
    att: Attitude,
    /// Specific thrust, m/s² (GRAVITY in a hover, 0 unpowered).
    thrust: f64,
    armed: bool,
    mode: FlightMode,
    landed: bool,
    home: Option<Vector3<f64>>,
    /// Set by DO_SET_HOME: arming leaves home where it is.
    home_locked: bool,
    ekf_ready: bool,
    gps_override: Option<bool>,
    guidance: Guidance,
    yaw_mode: YawMode,
    speed_override: SpeedOverride,
    roi: Option<Vector3<f64>>,
    ground_contact_s: f64,
    landed_armed_s: f64,
    battery: Battery,
    payload: Payload,
    gimbal: Gimbal,
    /// `None` when no GoPro is fitted (`VehicleParams::gopro` false).
    gopro: Option<GoPro>,
    /// The ground motor test running, if any.
    motor_test: Option<motors::MotorTest>,
    events: Vec<Event>,
}

impl Vehicle {
    /// A disarmed vehicle on the ground at the origin in STABILIZE (ArduCopter's
    /// boot mode).
    pub fn new(params: VehicleParams) -> Self {
        let battery = Battery::new(
            params.battery_cells,
            params.battery_capacity_mah,
            params.battery_initial_fraction,
        );
        let mut v = Self {
            frame: LocalFrame::new(params.home),
            time_s: 0.0,
            pos: Vector3::zeros(),
            vel: Vector3::zeros(),
            accel: Vector3::zeros(),
            att: Attitude {
                yaw: geo::wrap_pi(params.initial_heading_rad),
                ..Attitude::default()
            },
            thrust: 0.0,
            armed: false,
            mode: FlightMode::Stabilize,
            landed: true,
            home: None,
            home_locked: false,
            ekf_ready: false,
            gps_override: None,
            guidance: Guidance::Manual { z: 0.0 },
            yaw_mode: YawMode::Hold,
            speed_override: SpeedOverride::default(),
            roi: None,
            ground_contact_s: 0.0,
            landed_armed_s: 0.0,
            battery,
            payload: Payload::default(),
            gimbal: Gimbal::new(params.gimbal_slew_rate),
            gopro: params.gopro.then(GoPro::default),
            motor_test: None,
            events: Vec::new(),
            params,
        };
        v.update_estimator();
        v
    }

    /// Advance the simulation by `dt` seconds.
    pub fn step(&mut self, dt: f64) {
        if !(dt > 0.0 && dt.is_finite()) {
            return;
        }
        self.time_s += dt;
        self.update_estimator();
        let yaw = if self.armed {
            self.fly(dt)
        } else {
            self.fall(dt);
            self.att.yaw
        };
        let (roll_t, pitch_t, thrust) = if self.armed && !self.landed {
            tilt_for(&self.accel, &self.vel, yaw)
        } else {
            (0.0, 0.0, 0.0)
        };
        self.thrust = thrust;
        self.att = update_attitude(&self.att, roll_t, pitch_t, yaw, dt);
        self.battery.step(self.current_draw(), dt);
        let aim = self
            .roi
            .map(|roi| gimbal::aim_at(&self.pos, &roi, self.att.yaw));
        self.gimbal.step(self.att.yaw, aim, dt);
        self.payload.step(dt);
        self.step_motor_test();
        if let Some(gopro) = &mut self.gopro {
            if gopro.step(dt) {
                self.events.push(Event::GoProChanged);
            }
        }
    }

    /// GPS fix and EKF readiness follow sim time; the EKF setting its origin
    /// also sets home, as on ArduPilot.
    fn update_estimator(&mut self) {
        if !self.ekf_ready && self.gps_fix() && self.time_s >= self.params.ekf_ready_after_s {
            self.ekf_ready = true;
            self.say(MavSeverity::MAV_SEVERITY_INFO, "EKF3 IMU0 is using GPS");
            if self.home.is_none() {
                self.set_home_here();
            }
        }
    }

    /// Powered flight for one step; returns the new heading.
    fn fly(&mut self, dt: f64) -> f64 {
        let demand = self.demand(dt);
        if self.landed {
            if !demand.lift_off {
                self.sit_on_ground();
                self.landed_armed_s += dt;
                if self.landed_armed_s >= self.params.disarm_delay_s {
                    self.disarm_now();
                }
                return self.att.yaw;
            }
            self.landed = false;
            self.ground_contact_s = 0.0;
        }
        let limits = self.limits();
        let new_vel = track_velocity(&self.vel, &demand.vel, limits.accel, dt);
        self.accel = (new_vel - self.vel) / dt;
        self.pos += (self.vel + new_vel) * (0.5 * dt);
        self.vel = new_vel;
        let rate = self.yaw_mode.step(
            &self.pos,
            self.att.yaw,
            self.time_s,
            self.params.max_yaw_rate,
            dt,
        );
        let yaw = geo::wrap_pi(self.att.yaw + rate * dt);

        // The ground is flat at the origin's altitude (z = 0).
        if self.pos.z > 0.0 {
            self.pos.z = 0.0;
            if self.vel.z > 0.0 {
                self.vel.z = 0.0;
                self.accel.z = 0.0;
            }
        }
        // A target at ground level is approached exponentially and never quite
        // reached, so "on the ground" is within a couple of centimetres.
        let near_ground = self.pos.z >= -GROUND_CONTACT_M;
        if near_ground && demand.vel.z >= -0.05 {
            self.ground_contact_s += dt;
        } else {
            self.ground_contact_s = 0.0;
        }
        if self.ground_contact_s >= LAND_DETECT_S {
            self.touch_down();
        }
        yaw
    }

    /// Land detector fired: stop, and disarm at once in LAND/RTL.
    fn touch_down(&mut self) {
        self.sit_on_ground();
        self.landed = true;
        self.landed_armed_s = 0.0;
        self.guidance = Guidance::Hold(self.pos);
        self.yaw_mode = YawMode::Hold;
        if self.mode.disarms_on_landing() {
            self.disarm_now();
        }
    }

    fn sit_on_ground(&mut self) {
        self.pos.z = 0.0;
        self.vel = Vector3::zeros();
        self.accel = Vector3::zeros();
    }

    /// Unpowered: on the ground nothing moves; in the air it falls.
    fn fall(&mut self, dt: f64) {
        if self.landed {
            self.sit_on_ground();
            return;
        }
        let drag = Vector3::new(self.vel.x, self.vel.y, 0.0) * -FALL_DRAG_PER_S;
        self.accel = Vector3::new(0.0, 0.0, GRAVITY) + drag;
        let new_vel = self.vel + self.accel * dt;
        self.pos += (self.vel + new_vel) * (0.5 * dt);
        self.vel = new_vel;
        if self.pos.z >= 0.0 {
            let impact = self.vel.z;
            self.sit_on_ground();
            self.landed = true;
            if impact > CRASH_SPEED_MPS {
                self.say(
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    &format!("Crash: hit the ground at {impact:.1} m/s"),
                );
            }
        }
    }

    fn current_draw(&self) -> f64 {
        match (self.armed, self.landed) {
            (false, _) => IDLE_CURRENT_A,
            (true, true) => SPIN_ARM_CURRENT_A,
            // Rotor power grows with thrust^1.5 (momentum theory).
            (true, false) => self.params.hover_current_a * (self.thrust / GRAVITY).powf(1.5),
        }
    }

    fn set_home_here(&mut self) {
        self.home = Some(Vector3::new(self.pos.x, self.pos.y, self.pos.z));
        self.events.push(Event::HomeChanged);
    }

    /// Queue a STATUSTEXT for every link.
    pub fn say(&mut self, severity: MavSeverity, text: &str) {
        self.events.push(Event::Text {
            severity,
            text: text.to_owned(),
        });
    }

    /// Take the events queued since the last call.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// Sim time since start ("boot"), seconds.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }
    /// Position, local NED metres from the EKF origin.
    pub fn position_ned(&self) -> Vector3<f64> {
        self.pos
    }
    /// Velocity, NED m/s.
    pub fn velocity_ned(&self) -> Vector3<f64> {
        self.vel
    }
    /// Position as latitude/longitude/MSL altitude.
    pub fn position_geo(&self) -> GeoPoint {
        self.frame.to_geo(&self.pos)
    }
    /// The local frame (EKF origin).
    pub fn frame(&self) -> &LocalFrame {
        &self.frame
    }
    /// Attitude and body rates.
    pub fn attitude(&self) -> Attitude {
        self.att
    }
    /// Heading, radians in [0, 2π).
    pub fn heading(&self) -> f64 {
        geo::wrap_2pi(self.att.yaw)
    }
    /// Motors armed.
    pub fn armed(&self) -> bool {
        self.armed
    }
    /// Current flight mode.
    pub fn mode(&self) -> FlightMode {
        self.mode
    }
    /// On the ground (land detector).
    pub fn landed(&self) -> bool {
        self.landed
    }
    /// Home in local NED, once set.
    pub fn home_ned(&self) -> Option<Vector3<f64>> {
        self.home
    }
    /// Home as latitude/longitude/MSL altitude, once set.
    pub fn home_geo(&self) -> Option<GeoPoint> {
        self.home.map(|h| self.frame.to_geo(&h))
    }
    /// Altitude above home (or the origin before home is set), metres. Moving home
    /// up or down (DO_SET_HOME) shifts it by as much.
    pub fn relative_alt(&self) -> f64 {
        self.home.map_or(0.0, |h| h.z) - self.pos.z
    }
    /// Height above the (flat) ground, metres.
    pub fn height_above_ground(&self) -> f64 {
        -self.pos.z
    }
    /// The EKF has a position.
    pub fn ekf_ready(&self) -> bool {
        self.ekf_ready
    }
    /// GPS has a 3D fix.
    pub fn gps_fix(&self) -> bool {
        self.gps_override
            .unwrap_or(self.time_s >= self.params.ekf_ready_after_s * 0.5)
    }
    /// Force the GPS fix on or off (`None` = follow the start-up timing).
    pub fn set_gps_override(&mut self, fix: Option<bool>) {
        self.gps_override = fix;
    }
    /// Throttle output, 0..=1.
    pub fn throttle(&self) -> f64 {
        (HOVER_THROTTLE * self.thrust / GRAVITY).clamp(0.0, 1.0)
    }
    /// The battery.
    pub fn battery(&self) -> &Battery {
        &self.battery
    }
    /// Recorded payload commands.
    pub fn payload(&self) -> &Payload {
        &self.payload
    }
    /// Record payload commands.
    pub fn payload_mut(&mut self) -> &mut Payload {
        &mut self.payload
    }
    /// Current region of interest, local NED.
    pub fn roi(&self) -> Option<Vector3<f64>> {
        self.roi
    }
    /// The camera gimbal.
    pub fn gimbal(&self) -> &Gimbal {
        &self.gimbal
    }
    /// The GoPro, if one is fitted.
    pub fn gopro(&self) -> Option<&GoPro> {
        self.gopro.as_ref()
    }
    /// Model parameters.
    pub fn params(&self) -> &VehicleParams {
        &self.params
    }
}

#[cfg(test)]
mod tests;
