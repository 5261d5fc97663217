//! IMC actuator messages → skymesh commands (pure).
//!
//! The mapping tables come from the config (`[[servo]]`, `[[surface]]`, `[[pwm]]`,
//! `[[thruster]]` in `deploy/imc-gateway.toml`); an id that is not listed is
//! [`Refusal::Unmapped`]. Every number is checked here, before a command is built,
//! so what the arbiter sees is always in range; `Command::validate` checks again.

use std::f32::consts::FRAC_PI_2;

use imc_proto::ZoomAction;
use skymesh_ipc_types::command::limits;
use skymesh_ipc_types::{Command, ZoomMode};

/// A `SetServoPosition` id and the autopilot output it drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoMap {
    pub id: u8,
    /// Autopilot servo output, 1..=32.
    pub channel: u8,
    /// Pulse width at −π/2 rad, µs.
    pub pwm_min: u16,
    /// Pulse width at +π/2 rad, µs.
    pub pwm_max: u16,
}

/// A `SetControlSurfaceDeflection` id and the autopilot output it drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceMap {
    pub id: u8,
    pub channel: u8,
    /// Largest deflection either way, rad; maps onto `pwm_min` / `pwm_max`.
    pub max_angle_rad: f32,
    pub pwm_min: u16,
    pub pwm_max: u16,
}

/// A `SetPWM` id and the autopilot output it drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PwmMap {
    pub id: u8,
    pub channel: u8,
    /// The output's period as the autopilot is configured (MAVLink cannot set it).
    pub period_us: u32,
}

/// A `SetThrusterActuation` id and the motor it tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrusterMap {
    pub id: u8,
    /// ArduPilot motor number, 1..=12.
    pub motor: u8,
    /// Throttle at actuation 1.0, percent.
    pub max_throttle_pct: f32,
    /// How long each motor test runs, seconds.
    pub duration_s: f32,
}

/// Every actuator mapping of the gateway.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Actuators {
    pub servos: Vec<ServoMap>,
    pub surfaces: Vec<SurfaceMap>,
    pub pwms: Vec<PwmMap>,
    pub thrusters: Vec<ThrusterMap>,
}

/// Why an actuator message becomes no command.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refusal {
    #[error("{message} id {id} is not in the gateway's configuration")]
    Unmapped { message: &'static str, id: u8 },
    #[error("{message} id {id}: {detail}")]
    OutOfRange {
        message: &'static str,
        id: u8,
        detail: String,
    },
    #[error("{message} id {id}: {detail}")]
    Unsupported {
        message: &'static str,
        id: u8,
        detail: String,
    },
    #[error("{message} id {id}: value is not a finite number")]
    NotFinite { message: &'static str, id: u8 },
}

impl Refusal {
    /// The `skymesh_imc_dropped_total` reason.
    pub fn reason(&self) -> &'static str {
        match self {
            Refusal::Unmapped { .. } => "unmapped",
            Refusal::OutOfRange { .. } => "out_of_range",
            Refusal::Unsupported { .. } => "unsupported",
            Refusal::NotFinite { .. } => "invalid_value",
        }
    }
}

/// Small slack for angles that arrive as f32 renderings of ±π/2 or ±max.
const ANGLE_SLACK: f32 = 1e-5;

/// `value` in `-max..=max` mapped linearly onto `pwm_min..=pwm_max`, rounded.
fn linear_pwm(value: f32, max: f32, pwm_min: u16, pwm_max: u16) -> u16 {
    let t = ((value.clamp(-max, max) + max) / (2.0 * max)).clamp(0.0, 1.0);
    let span = f32::from(pwm_max) - f32::from(pwm_min);
    (f32::from(pwm_min) + t * span).round() as u16
}

impl Actuators {
    /// `SetServoPosition`: −π/2..π/2 rad → `Servo` on the mapped channel.
    pub fn servo(&self, id: u8, value: f32) -> Result<Command, Refusal> {
        const M: &str = "SetServoPosition";
        let map = self
            .servos
            .iter()
            .find(|s| s.id == id)
            .ok_or(Refusal::Unmapped { message: M, id })?;
        if !value.is_finite() {
            return Err(Refusal::NotFinite { message: M, id });
        }
        if value.abs() > FRAC_PI_2 + ANGLE_SLACK {
            return Err(Refusal::OutOfRange {
                message: M,
                id,
                detail: format!("position {value} rad is outside ±π/2"),
            });
        }
        Ok(Command::Servo {
            channel: map.channel,
            pwm_us: linear_pwm(value, FRAC_PI_2, map.pwm_min, map.pwm_max),
        })
    }

    /// `SetControlSurfaceDeflection`: −max..max rad → `Servo` on the mapped channel.
    pub fn surface(&self, id: u8, angle: f32) -> Result<Command, Refusal> {
        const M: &str = "SetControlSurfaceDeflection";
        let map = self
            .surfaces
            .iter()
            .find(|s| s.id == id)
            .ok_or(Refusal::Unmapped { message: M, id })?;
        if !angle.is_finite() {
            return Err(Refusal::NotFinite { message: M, id });
        }
        if angle.abs() > map.max_angle_rad + ANGLE_SLACK {
            return Err(Refusal::OutOfRange {
                message: M,
                id,
                detail: format!(
                    "angle {angle} rad is beyond the configured ±{} rad",
                    map.max_angle_rad
                ),
            });
        }
        Ok(Command::Servo {
            channel: map.channel,
            pwm_us: linear_pwm(angle, map.max_angle_rad, map.pwm_min, map.pwm_max),
        })
    }

    /// `SetPWM`: the duty cycle is the pulse width; the period must be the
    /// configured one. Returns the command and the mapping (for the `PWM` reply).
    pub fn pwm(&self, id: u8, period: u32, duty: u32) -> Result<(Command, PwmMap), Refusal> {
        const M: &str = "SetPWM";
        let map = *self
            .pwms
            .iter()
            .find(|p| p.id == id)
            .ok_or(Refusal::Unmapped { message: M, id })?;
        if period != map.period_us {
            return Err(Refusal::Unsupported {
                message: M,
                id,
                detail: format!(
                    "period {period} µs: the autopilot's output period is fixed by its own \
                     configuration (e.g. SERVO_RATE), not by MAVLink; this output runs at {} µs",
                    map.period_us
                ),
            });
        }
        let range = limits::PWM_US;
        let pwm_us = u16::try_from(duty)
            .ok()
            .filter(|d| range.contains(d))
            .ok_or_else(|| Refusal::OutOfRange {
                message: M,
                id,
                detail: format!(
                    "duty cycle {duty} µs is outside {}..={} µs",
                    range.start(),
                    range.end()
                ),
            })?;
        Ok((
            Command::Servo {
                channel: map.channel,
                pwm_us,
            },
            map,
        ))
    }

    /// `SetThrusterActuation`: 0..1 → a motor test at that share of the configured
    /// throttle.
    pub fn thruster(&self, id: u8, value: f32) -> Result<Command, Refusal> {
        const M: &str = "SetThrusterActuation";
        let map = self
            .thrusters
            .iter()
            .find(|t| t.id == id)
            .ok_or(Refusal::Unmapped { message: M, id })?;
        if !value.is_finite() {
            return Err(Refusal::NotFinite { message: M, id });
        }
        if !(0.0..=1.0).contains(&value) {
            return Err(Refusal::OutOfRange {
                message: M,
                id,
                detail: format!(
                    "actuation {value} is outside 0..1 (multicopter motors do not reverse)"
                ),
            });
        }
        Ok(Command::MotorTest {
            motor: map.motor,
            throttle_pct: value * map.max_throttle_pct,
            duration_s: map.duration_s,
        })
    }
}

/// `CameraZoom` → `Command::CameraZoom` for camera `id` (0 = every camera).
///
/// RESET → range 0 % (widest); IN → continuous +1; OUT → continuous −1; STOP →
/// continuous 0, or, with `zoom` > 0, "go to this absolute level": range
/// zoom / 255 × 100 %.
pub fn zoom(id: u8, zoom: u8, action: ZoomAction) -> Command {
    let (mode, value) = match action {
        ZoomAction::Reset => (ZoomMode::Range, 0.0),
        ZoomAction::In => (ZoomMode::Continuous, 1.0),
        ZoomAction::Out => (ZoomMode::Continuous, -1.0),
        ZoomAction::Stop if zoom > 0 => (ZoomMode::Range, f32::from(zoom) / 255.0 * 100.0),
        ZoomAction::Stop => (ZoomMode::Continuous, 0.0),
    };
    Command::CameraZoom {
        camera: id,
        mode,
        value,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Actuators {
        Actuators {
            servos: vec![ServoMap {
                id: 0,
                channel: 9,
                pwm_min: 1000,
                pwm_max: 2000,
            }],
            surfaces: vec![SurfaceMap {
                id: 2,
                channel: 11,
                max_angle_rad: 0.5,
                pwm_min: 1100,
                pwm_max: 1900,
            }],
            pwms: vec![PwmMap {
                id: 0,
                channel: 10,
                period_us: 20_000,
            }],
            thrusters: vec![ThrusterMap {
                id: 3,
                motor: 4,
                max_throttle_pct: 15.0,
                duration_s: 2.0,
            }],
        }
    }

    fn servo_pwm(c: Command) -> (u8, u16) {
        match c {
            Command::Servo { channel, pwm_us } => (channel, pwm_us),
            other => panic!("not a servo command: {other:?}"),
        }
    }

    #[test]
    fn servo_position_maps_linearly_onto_the_pulse_range() {
        let a = table();
        assert_eq!(servo_pwm(a.servo(0, -FRAC_PI_2).unwrap()), (9, 1000));
        assert_eq!(servo_pwm(a.servo(0, 0.0).unwrap()), (9, 1500));
        assert_eq!(servo_pwm(a.servo(0, FRAC_PI_2).unwrap()), (9, 2000));
        assert_eq!(servo_pwm(a.servo(0, FRAC_PI_2 / 2.0).unwrap()), (9, 1750));
        assert_eq!(a.servo(0, 1.6).unwrap_err().reason(), "out_of_range");
        assert_eq!(a.servo(0, f32::NAN).unwrap_err().reason(), "invalid_value");
        assert_eq!(a.servo(1, 0.0).unwrap_err().reason(), "unmapped");
    }

    #[test]
    fn surface_deflection_is_limited_to_its_configured_angle() {
        let a = table();
        assert_eq!(servo_pwm(a.surface(2, -0.5).unwrap()), (11, 1100));
        assert_eq!(servo_pwm(a.surface(2, 0.25).unwrap()), (11, 1700));
        assert_eq!(a.surface(2, 0.6).unwrap_err().reason(), "out_of_range");
        assert_eq!(a.surface(0, 0.1).unwrap_err().reason(), "unmapped");
    }

    #[test]
    fn pwm_takes_the_duty_as_pulse_width_at_the_configured_period_only() {
        let a = table();
        let (cmd, map) = a.pwm(0, 20_000, 1234).unwrap();
        assert_eq!(servo_pwm(cmd), (10, 1234));
        assert_eq!(map.period_us, 20_000);
        let e = a.pwm(0, 2_500, 1234).unwrap_err();
        assert_eq!(e.reason(), "unsupported");
        assert!(e.to_string().contains("20000"), "{e}");
        assert_eq!(a.pwm(0, 20_000, 499).unwrap_err().reason(), "out_of_range");
        assert_eq!(
            a.pwm(0, 20_000, 70_000).unwrap_err().reason(),
            "out_of_range"
        );
        assert_eq!(a.pwm(5, 20_000, 1500).unwrap_err().reason(), "unmapped");
    }

    #[test]
    fn thrusters_become_bounded_forward_only_motor_tests() {
        let a = table();
        assert_eq!(
            a.thruster(3, 0.5).unwrap(),
            Command::MotorTest {
                motor: 4,
                throttle_pct: 7.5,
                duration_s: 2.0
            }
        );
        assert_eq!(a.thruster(3, -0.1).unwrap_err().reason(), "out_of_range");
        assert_eq!(a.thruster(3, 1.1).unwrap_err().reason(), "out_of_range");
        assert_eq!(a.thruster(0, 0.1).unwrap_err().reason(), "unmapped");
        for v in [0.0, 0.3, 1.0] {
            assert!(a.thruster(3, v).unwrap().validate().is_ok());
        }
    }

    #[test]
    fn zoom_actions_map_to_the_documented_modes() {
        let z = |zoom_level, action| match zoom(1, zoom_level, action) {
            Command::CameraZoom {
                camera: 1,
                mode,
                value,
            } => (mode, value),
            other => panic!("{other:?}"),
        };
        assert_eq!(z(0, ZoomAction::Reset), (ZoomMode::Range, 0.0));
        assert_eq!(z(0, ZoomAction::In), (ZoomMode::Continuous, 1.0));
        assert_eq!(z(9, ZoomAction::Out), (ZoomMode::Continuous, -1.0));
        assert_eq!(z(0, ZoomAction::Stop), (ZoomMode::Continuous, 0.0));
        assert_eq!(z(255, ZoomAction::Stop), (ZoomMode::Range, 100.0));
        let (mode, v) = z(51, ZoomAction::Stop);
        assert_eq!(mode, ZoomMode::Range);
        assert!((v - 20.0).abs() < 1e-4);
        for a in ZoomAction::ALL {
            for level in [0, 1, 128, 255] {
                assert!(zoom(0, level, *a).validate().is_ok());
            }
        }
    }
}
