//! Inputs to the model: arming, modes, takeoff, guided setpoints, speed, yaw,
//! ROI, gimbal targets and GoPro settings. Each either changes the vehicle or says why it refused, in
//! ArduCopter's terms; mapping refusals to MAV_RESULT is the handler's job.

use mavlink::dialects::ardupilotmega::{GoproCommand, MavSeverity};
use nalgebra::{Vector2, Vector3};

use super::geo::wrap_pi;
use super::gimbal::GimbalTarget;
use super::gopro::GoProRefusal;
use super::guidance::Guidance;
use super::yaw::YawMode;
use super::{Event, FlightMode, SpeedOverride, Vehicle};

/// Farther than this from a position target (with no yaw given), the vehicle
/// turns to face it (ArduCopter WP_YAW_BEHAVIOR 2, "face next waypoint").
const FACE_TARGET_MIN_M: f64 = 2.0;

/// Below this horizontal speed a velocity setpoint does not turn the nose.
const FACE_VELOCITY_MIN_MPS: f64 = 0.5;

/// Why arming was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArmRefusal {
    /// No 3D GPS fix yet.
    NoGpsFix,
    /// The EKF has no position yet.
    EkfNotReady,
    /// Battery below the arming minimum.
    BatteryLow {
        /// Remaining, percent.
        percent: f64,
        /// Required, percent.
        min_percent: f64,
    },
    /// The mode does not allow arming (LAND, RTL, AUTO without mission, CIRCLE).
    ModeNotArmable(FlightMode),
    /// A ground motor test is running (even a forced arm waits for its end).
    MotorTesting,
}

impl ArmRefusal {
    /// The STATUSTEXT ArduCopter sends for this failure.
    pub fn text(&self) -> String {
        match self {
            ArmRefusal::NoGpsFix => "PreArm: GPS 1: Bad fix".to_owned(),
            ArmRefusal::EkfNotReady => "PreArm: EKF3 waiting for GPS position".to_owned(),
            ArmRefusal::BatteryLow { .. } => {
                "PreArm: Battery 1 below minimum arming capacity".to_owned()
            }
            ArmRefusal::ModeNotArmable(_) => "Arm: Mode not armable".to_owned(),
            ArmRefusal::MotorTesting => "PreArm: Motor Testing".to_owned(),
        }
    }

    /// A retry later may succeed without anyone doing anything.
    pub fn is_temporary(&self) -> bool {
        matches!(
            self,
            ArmRefusal::NoGpsFix | ArmRefusal::EkfNotReady | ArmRefusal::MotorTesting
        )
    }
}

/// Farther than this from the EKF origin, home is refused: the simulator's flat-earth
/// frame is only meant for the few kilometres a flight covers.
pub const HOME_MAX_FROM_ORIGIN_M: f64 = 50_000.0;

/// Why DO_SET_HOME was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HomeRefusal {
    /// The EKF has no position yet: nothing to place home against (retry later).
    NoPosition,
    /// Farther than [`HOME_MAX_FROM_ORIGIN_M`] from the EKF origin, metres.
    FarFromOrigin(f64),
}

impl HomeRefusal {
    /// A retry later may succeed without anyone doing anything.
    pub fn is_temporary(&self) -> bool {
        matches!(self, HomeRefusal::NoPosition)
    }
}

/// Why disarming was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DisarmRefusal {
    /// Still flying; only a forced disarm (21196) stops the motors in the air.
    Flying,
}

/// Why a mode change was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum ModeRefusal {
    /// Not an ArduCopter mode number.
    Unknown(u32),
    /// An ArduCopter mode the simulator does not fly.
    NotSimulated(&'static str),
    /// The mode needs a position estimate while armed.
    RequiresPosition(FlightMode),
}

impl ModeRefusal {
    /// The STATUSTEXT for this failure.
    pub fn text(&self) -> String {
        match self {
            ModeRefusal::Unknown(n) => format!("Mode change to {n} failed: no such mode"),
            ModeRefusal::NotSimulated(name) => {
                format!("Mode change to {name} failed: not simulated")
            }
            ModeRefusal::RequiresPosition(m) => {
                format!("Mode change to {m} failed: requires position")
            }
        }
    }
}

/// Why a takeoff was refused (ArduCopter answers all of these with FAILED).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TakeoffRefusal {
    /// Motors are not armed.
    NotArmed,
    /// Already in the air.
    AlreadyFlying,
    /// The mode has no user takeoff.
    Mode(FlightMode),
    /// Altitude not positive and finite.
    BadAltitude(f64),
}

/// A guided setpoint arrived outside GUIDED and was ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotGuided(pub FlightMode);

/// Which speed DO_CHANGE_SPEED changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpeedKind {
    /// Horizontal (air- or ground speed).
    Horizontal,
    /// Climb rate.
    Climb,
    /// Descent rate.
    Descent,
}

/// A decoded SET_POSITION_TARGET_* in local NED.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GuidedTarget {
    /// Position target, local NED.
    pub pos: Option<Vector3<f64>>,
    /// Velocity target, NED m/s.
    pub vel: Option<Vector3<f64>>,
    /// Heading target, radians (absolute unless `yaw_relative`).
    pub yaw: Option<f64>,
    /// Yaw rate, rad/s.
    pub yaw_rate: Option<f64>,
    /// `yaw` is relative to the current heading (body frames).
    pub yaw_relative: bool,
}

impl Vehicle {
    /// MAV_CMD_COMPONENT_ARM_DISARM(1). `force` (param2 = 21196) skips every check.
    pub fn arm(&mut self, force: bool) -> Result<(), ArmRefusal> {
        if self.armed {
            return Ok(());
        }
        if self.motor_testing() {
            let refusal = ArmRefusal::MotorTesting;
            self.say(MavSeverity::MAV_SEVERITY_CRITICAL, &refusal.text());
            return Err(refusal);
        }
        if !force {
            if let Err(refusal) = self.arming_checks() {
                self.say(MavSeverity::MAV_SEVERITY_CRITICAL, &refusal.text());
                return Err(refusal);
            }
        }
        self.armed = true;
        self.landed_armed_s = 0.0;
        // ArduCopter moves home to where it arms, unless DO_SET_HOME locked it.
        if !self.home_locked {
            self.set_home_here();
        }
        self.guidance = if self.landed {
            Guidance::Hold(self.pos)
        } else {
            self.guidance_for_mode()
        };
        self.say(MavSeverity::MAV_SEVERITY_INFO, "Arming motors");
        Ok(())
    }

    /// ArduCopter's order: pre-arm checks (sensors, battery), then the mode.
    fn arming_checks(&self) -> Result<(), ArmRefusal> {
        if !self.gps_fix() {
            return Err(ArmRefusal::NoGpsFix);
        }
        if !self.ekf_ready {
            return Err(ArmRefusal::EkfNotReady);
        }
        let remaining = self.battery.remaining();
        if remaining < self.params.battery_arm_min_fraction {
            return Err(ArmRefusal::BatteryLow {
                percent: remaining * 100.0,
                min_percent: self.params.battery_arm_min_fraction * 100.0,
            });
        }
        if !self.mode.allows_arming() {
            return Err(ArmRefusal::ModeNotArmable(self.mode));
        }
        Ok(())
    }

    /// MAV_CMD_COMPONENT_ARM_DISARM(0). In the air only a forced disarm works
    /// (and the vehicle then falls).
    pub fn disarm(&mut self, force: bool) -> Result<(), DisarmRefusal> {
        if !self.armed {
            return Ok(());
        }
        if !self.landed && !force {
            return Err(DisarmRefusal::Flying);
        }
        self.disarm_now();
        Ok(())
    }

    pub(super) fn disarm_now(&mut self) {
        self.armed = false;
        self.landed_armed_s = 0.0;
        self.guidance = Guidance::Hold(self.pos);
        self.yaw_mode = YawMode::Hold;
        self.say(MavSeverity::MAV_SEVERITY_INFO, "Disarming motors");
    }

    /// Change mode by ArduCopter number (DO_SET_MODE, SET_MODE).
    pub fn set_mode_number(&mut self, number: u32) -> Result<(), ModeRefusal> {
        match FlightMode::from_number(number) {
            Some(mode) => self.set_mode(mode),
            None => {
                let refusal = match FlightMode::name_of_number(number) {
                    Some(name) => ModeRefusal::NotSimulated(name),
                    None => ModeRefusal::Unknown(number),
                };
                self.say(MavSeverity::MAV_SEVERITY_WARNING, &refusal.text());
                Err(refusal)
            }
        }
    }

    /// Change mode. Re-selecting the current mode changes nothing (targets kept).
    pub fn set_mode(&mut self, mode: FlightMode) -> Result<(), ModeRefusal> {
        if mode == self.mode {
            return Ok(());
        }
        // Disarmed, ArduCopter enters any mode; armed, position modes need the EKF.
        if self.armed && mode.requires_position() && !self.ekf_ready {
            let refusal = ModeRefusal::RequiresPosition(mode);
            self.say(MavSeverity::MAV_SEVERITY_WARNING, &refusal.text());
            return Err(refusal);
        }
        self.mode = mode;
        self.speed_override = SpeedOverride::default();
        self.yaw_mode = YawMode::Hold;
        self.roi = None;
        self.guidance = self.guidance_for_mode();
        self.say(MavSeverity::MAV_SEVERITY_INFO, &format!("Mode {mode}"));
        if mode == FlightMode::Auto {
            self.say(
                MavSeverity::MAV_SEVERITY_WARNING,
                "AUTO: no mission, holding position",
            );
        }
        Ok(())
    }

    /// MAV_CMD_NAV_TAKEOFF to `alt_m` above home.
    pub fn takeoff(&mut self, alt_m: f64) -> Result<(), TakeoffRefusal> {
        if !self.mode.allows_user_takeoff() {
            return Err(TakeoffRefusal::Mode(self.mode));
        }
        if !self.armed {
            return Err(TakeoffRefusal::NotArmed);
        }
        if !self.landed {
            return Err(TakeoffRefusal::AlreadyFlying);
        }
        if !(alt_m.is_finite() && alt_m > 0.0) {
            return Err(TakeoffRefusal::BadAltitude(alt_m));
        }
        let home_z = self.home.map_or(0.0, |h| h.z);
        let target = Vector3::new(self.pos.x, self.pos.y, home_z - alt_m);
        self.guidance = Guidance::Takeoff(target);
        self.landed_armed_s = 0.0;
        Ok(())
    }

    /// SET_POSITION_TARGET_* (already converted to local NED). Only GUIDED
    /// listens; with neither position nor velocity the vehicle stops and holds.
    pub fn guided_target(&mut self, t: GuidedTarget) -> Result<(), NotGuided> {
        if self.mode != FlightMode::Guided {
            return Err(NotGuided(self.mode));
        }
        let until = self.time_s + self.params.velocity_timeout_s;
        // While landed only a takeoff leaves the ground; ArduCopter keeps
        // GUIDED setpoints from lifting off, so the target is kept but inert.
        self.guidance = match (t.pos, t.vel) {
            (Some(target), Some(ff)) => Guidance::Position {
                target,
                ff,
                ff_until: until,
            },
            (Some(target), None) => Guidance::Position {
                target,
                ff: Vector3::zeros(),
                ff_until: until,
            },
            (None, Some(vel)) => Guidance::Velocity { vel, until },
            (None, None) => {
                let limits = self.limits();
                Guidance::Hold(super::control::stopping_point(
                    &self.pos,
                    &self.vel,
                    limits.accel,
                ))
            }
        };
        self.yaw_mode = if let Some(yaw) = t.yaw {
            if t.yaw_relative {
                YawMode::Slew {
                    remaining: wrap_pi(yaw),
                    rate: self.params.max_yaw_rate,
                }
            } else {
                YawMode::to_heading(self.att.yaw, yaw, self.params.max_yaw_rate)
            }
        } else if let Some(rate) = t.yaw_rate {
            YawMode::Rate { rate, until }
        } else if let Some(roi) = self.roi {
            YawMode::Face(roi)
        } else {
            self.default_yaw(&t)
        };
        Ok(())
    }

    /// No yaw in the setpoint: face where the vehicle is going.
    fn default_yaw(&self, t: &GuidedTarget) -> YawMode {
        let rate = self.params.max_yaw_rate;
        if let Some(target) = t.pos {
            let d = Vector2::new(target.x - self.pos.x, target.y - self.pos.y);
            if d.norm() > FACE_TARGET_MIN_M {
                return YawMode::to_heading(self.att.yaw, d.y.atan2(d.x), rate);
            }
        } else if let Some(v) = t.vel {
            if Vector2::new(v.x, v.y).norm() > FACE_VELOCITY_MIN_MPS {
                return YawMode::to_heading(self.att.yaw, v.y.atan2(v.x), rate);
            }
        }
        YawMode::Hold
    }

    /// DO_CHANGE_SPEED: until the next mode change.
    pub fn set_speed(&mut self, kind: SpeedKind, speed: f64) {
        match kind {
            SpeedKind::Horizontal => self.speed_override.xy = Some(speed),
            SpeedKind::Climb => self.speed_override.up = Some(speed),
            SpeedKind::Descent => self.speed_override.down = Some(speed),
        }
    }

    /// CONDITION_YAW: `angle_deg` absolute (direction picks the way round, 0 =
    /// shortest) or relative (direction -1 = counter-clockwise).
    pub fn condition_yaw(&mut self, angle_deg: f64, rate_dps: f64, direction: i8, relative: bool) {
        let rate = if rate_dps > 0.0 {
            rate_dps.to_radians()
        } else {
            self.params.max_yaw_rate
        };
        let angle = angle_deg.to_radians();
        let remaining = if relative {
            if direction < 0 {
                -angle
            } else {
                angle
            }
        } else {
            let shortest = wrap_pi(angle - self.att.yaw);
            match direction {
                d if d > 0 && shortest < 0.0 => shortest + std::f64::consts::TAU,
                d if d < 0 && shortest > 0.0 => shortest - std::f64::consts::TAU,
                _ => shortest,
            }
        };
        self.yaw_mode = YawMode::Slew { remaining, rate };
    }

    /// DO_SET_ROI*: face `roi` (local NED) or, with `None`, hold heading.
    pub fn set_roi(&mut self, roi: Option<Vector3<f64>>) {
        self.roi = roi;
        self.yaw_mode = match roi {
            Some(p) => YawMode::Face(p),
            None => YawMode::Hold,
        };
    }

    /// Point the gimbal (DO_GIMBAL_MANAGER_PITCHYAW, DO_MOUNT_CONTROL). While an
    /// ROI is set the ROI wins: the target is dropped and `false` says so (the
    /// handler still records the request in [`super::Payload::mount`]). After the
    /// ROI is cleared the gimbal holds where it points until the next target.
    pub fn point_gimbal(&mut self, target: GimbalTarget) -> bool {
        if self.roi.is_some() {
            return false;
        }
        self.gimbal.set_target(target);
        true
    }

    /// GOPRO_SET_REQUEST; `None` when no GoPro is fitted. A change to what the
    /// GoPro heartbeat reports queues [`Event::GoProChanged`].
    pub fn gopro_set(
        &mut self,
        command: GoproCommand,
        value: [u8; 4],
    ) -> Option<Result<(), GoProRefusal>> {
        let gopro = self.gopro.as_mut()?;
        Some(gopro.set(command, value).map(|changed| {
            if changed {
                self.events.push(Event::GoProChanged);
            }
        }))
    }

    /// DO_SET_HOME: move home (RTL's destination, and what the relative altitude is
    /// measured from) to a local NED point, and lock it there: arming no longer moves
    /// it, as on ArduCopter. Needs an EKF position. Queues [`Event::HomeChanged`], so
    /// HOME_POSITION goes out at once.
    ///
    /// Home's altitude may differ from the ground's: the relative altitude then
    /// shifts by the difference (ArduPilot's is also relative to home), while the
    /// land detector still finds the flat ground.
    pub fn set_home(&mut self, ned: Vector3<f64>) -> Result<(), HomeRefusal> {
        if !self.ekf_ready {
            return Err(HomeRefusal::NoPosition);
        }
        let from_origin = ned.xy().norm();
        if !(from_origin <= HOME_MAX_FROM_ORIGIN_M && ned.z.is_finite()) {
            return Err(HomeRefusal::FarFromOrigin(from_origin));
        }
        self.home = Some(ned);
        self.home_locked = true;
        self.events.push(Event::HomeChanged);
        Ok(())
    }

    /// DO_REPOSITION: fly to `target` in GUIDED (caller switched mode if asked).
    pub fn reposition(&mut self, target: Vector3<f64>, yaw: Option<f64>) -> Result<(), NotGuided> {
        self.guided_target(GuidedTarget {
            pos: Some(target),
            yaw,
            ..GuidedTarget::default()
        })
    }
}
