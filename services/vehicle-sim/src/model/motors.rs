//! The four motors' outputs (servo outputs 1..=4 of SERVO_OUTPUT_RAW) and the
//! ground motor test (MAV_CMD_DO_MOTOR_TEST), as ArduCopter's `motor_test.cpp`
//! runs it: one motor (or several in turn) at a fixed throttle for a timeout, then
//! "finished motor test".
//!
//! Differences from ArduCopter, all on the safe side: a test needs disarmed motors
//! (ArduCopter also accepts a landed, armed copter and disarms it at the end), a bad
//! motor number, throttle or timeout is refused up front (ArduCopter starts and
//! stops at once), and the vehicle never reports armed during a test (ArduCopter
//! arms its motor outputs). Arming waits until the test is over.

use std::ops::RangeInclusive;

use mavlink::dialects::ardupilotmega::MavSeverity;

use super::Vehicle;

/// Motors of the quad, numbered 1..=4 (outputs 1..=4).
pub const MOTORS: u8 = 4;

/// Motor output range, µs (MOT_PWM_MIN, MOT_PWM_MAX).
pub const PWM_MIN: u16 = 1000;
pub const PWM_MAX: u16 = 2000;

/// Armed on the ground the motors idle at this fraction of the range (MOT_SPIN_ARM).
const SPIN_ARM: f64 = 0.10;

/// In flight no motor goes below this fraction of the range (MOT_SPIN_MIN).
const SPIN_MIN: f64 = 0.15;

/// ArduCopter's longest motor test (MOTOR_TEST_TIMEOUT_SEC); longer requests are cut
/// to it.
pub const MOTOR_TEST_MAX_S: f64 = 600.0;

/// PWM a motor test may output, µs (MOTOR_TEST_PWM_MIN..=MOTOR_TEST_PWM_MAX).
pub const MOTOR_TEST_PWM: RangeInclusive<u16> = 800..=2200;

/// A motor test's throttle (DO_MOTOR_TEST param2/param3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TestThrottle {
    /// MOTOR_TEST_THROTTLE_PERCENT: 0..=100 % of the output range.
    Percent(f64),
    /// MOTOR_TEST_THROTTLE_PWM: the output itself, µs.
    Pwm(f64),
}

/// A DO_MOTOR_TEST request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorTestRequest {
    /// First motor, 1..=[`MOTORS`] (param1).
    pub motor: f64,
    /// Throttle (param2, param3).
    pub throttle: TestThrottle,
    /// Seconds each motor spins (param4), cut to [`MOTOR_TEST_MAX_S`].
    pub timeout_s: f64,
    /// Motors tested in turn from `motor` (param5; 0 means 1).
    pub count: f64,
}

/// Why a motor test was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotorTestRefusal {
    /// In the air (the land detector has not seen it landed).
    NotLanded,
    /// Motors armed: disarm first.
    Armed,
    /// Not a motor of this frame (or the sequence runs past the last one).
    NoSuchMotor { motor: f64, count: f64 },
    /// Percent outside 0..=100 or PWM outside [`MOTOR_TEST_PWM`].
    Throttle(TestThrottle),
    /// Not a positive, finite number of seconds.
    Timeout(f64),
}

impl MotorTestRefusal {
    /// The STATUSTEXT sent with the refusal (ArduCopter's words where it has them).
    pub fn text(&self) -> String {
        match self {
            MotorTestRefusal::NotLanded => "Motor Test: vehicle not landed".to_owned(),
            MotorTestRefusal::Armed => "Motor Test: vehicle armed, disarm first".to_owned(),
            MotorTestRefusal::NoSuchMotor { motor, count } => {
                if whole(*motor, 1..=MOTORS).is_none() {
                    format!("Motor Test: invalid motor {motor}")
                } else {
                    format!("Motor Test: invalid motor count {count}")
                }
            }
            MotorTestRefusal::Throttle(TestThrottle::Percent(p)) => {
                format!("Motor Test: throttle {p}% out of range")
            }
            MotorTestRefusal::Throttle(TestThrottle::Pwm(p)) => {
                format!("Motor Test: PWM {p} out of range")
            }
            MotorTestRefusal::Timeout(t) => format!("Motor Test: timeout {t} s invalid"),
        }
    }
}

/// A running motor test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct MotorTest {
    /// First motor, 1-based.
    first: u8,
    count: u8,
    pwm: u16,
    timeout_s: f64,
    started_s: f64,
}

impl MotorTest {
    /// What the test outputs `elapsed_s` after its start: `Some((motor, pwm))` while
    /// a motor spins, `None` in the pause between two motors (half a timeout, as
    /// ArduCopter) and after the end.
    fn output(&self, elapsed_s: f64) -> Option<(u8, u16)> {
        let slot = self.timeout_s * 1.5;
        let index = (elapsed_s / slot).floor();
        if !(0.0..f64::from(self.count)).contains(&index) {
            return None;
        }
        let spinning = elapsed_s - index * slot < self.timeout_s;
        spinning.then_some((self.first + index as u8, self.pwm))
    }

    /// The last motor stopped.
    fn finished(&self, elapsed_s: f64) -> bool {
        elapsed_s >= self.timeout_s * (1.5 * f64::from(self.count) - 0.5)
    }
}

/// `value` as a whole number in `range`.
fn whole(value: f64, range: RangeInclusive<u8>) -> Option<u8> {
    (value.fract() == 0.0 && (f64::from(*range.start())..=f64::from(*range.end())).contains(&value))
        .then_some(value as u8)
}

impl Vehicle {
    /// MAV_CMD_DO_MOTOR_TEST: spin motor `motor` (then the next `count - 1` in turn)
    /// at the throttle for the timeout. Only landed and disarmed; a new test replaces
    /// the running one and restarts the clock. A refusal is also said as STATUSTEXT.
    pub fn motor_test(&mut self, req: MotorTestRequest) -> Result<(), MotorTestRefusal> {
        let checked = self.check_motor_test(&req);
        let test = match checked {
            Ok(test) => test,
            Err(refusal) => {
                self.say(MavSeverity::MAV_SEVERITY_CRITICAL, &refusal.text());
                return Err(refusal);
            }
        };
        if self.motor_test.is_none() {
            self.say(MavSeverity::MAV_SEVERITY_INFO, "starting motor test");
        }
        self.motor_test = Some(test);
        Ok(())
    }

    fn check_motor_test(&self, req: &MotorTestRequest) -> Result<MotorTest, MotorTestRefusal> {
        if !self.landed {
            return Err(MotorTestRefusal::NotLanded);
        }
        if self.armed {
            return Err(MotorTestRefusal::Armed);
        }
        let count = if req.count == 0.0 { 1.0 } else { req.count };
        let no_such = MotorTestRefusal::NoSuchMotor {
            motor: req.motor,
            count: req.count,
        };
        let first = whole(req.motor, 1..=MOTORS).ok_or(no_such)?;
        let count = whole(count, 1..=MOTORS - first + 1).ok_or(no_such)?;
        let pwm = match req.throttle {
            TestThrottle::Percent(p) if (0.0..=100.0).contains(&p) => {
                f64::from(PWM_MIN) + f64::from(PWM_MAX - PWM_MIN) * p / 100.0
            }
            TestThrottle::Pwm(p)
                if (f64::from(*MOTOR_TEST_PWM.start())..=f64::from(*MOTOR_TEST_PWM.end()))
                    .contains(&p) =>
            {
                p
            }
            other => return Err(MotorTestRefusal::Throttle(other)),
        };
        if !(req.timeout_s > 0.0 && req.timeout_s.is_finite()) {
            return Err(MotorTestRefusal::Timeout(req.timeout_s));
        }
        Ok(MotorTest {
            first,
            count,
            pwm: pwm.round() as u16,
            timeout_s: req.timeout_s.min(MOTOR_TEST_MAX_S),
            started_s: self.time_s,
        })
    }

    /// Ends a motor test whose time is up (called every step).
    pub(super) fn step_motor_test(&mut self) {
        if let Some(test) = self.motor_test {
            if test.finished(self.time_s - test.started_s) {
                self.motor_test = None;
                self.say(MavSeverity::MAV_SEVERITY_INFO, "finished motor test");
            }
        }
    }

    /// A motor test is running.
    pub fn motor_testing(&self) -> bool {
        self.motor_test.is_some()
    }

    /// The four motor outputs, µs: [`PWM_MIN`] disarmed, MOT_SPIN_ARM armed on the
    /// ground, the throttle (at least MOT_SPIN_MIN) in flight, all four alike (a
    /// point mass has no attitude control); a motor under test at its test PWM.
    pub fn motor_outputs(&self) -> [u16; MOTORS as usize] {
        let range = f64::from(PWM_MAX - PWM_MIN);
        let level = match (self.armed, self.landed) {
            (false, _) => PWM_MIN,
            (true, true) => PWM_MIN + (range * SPIN_ARM).round() as u16,
            (true, false) => PWM_MIN + (range * self.throttle().max(SPIN_MIN)).round() as u16,
        };
        let mut out = [level; MOTORS as usize];
        if let Some((motor, pwm)) = self
            .motor_test
            .and_then(|t| t.output(self.time_s - t.started_s))
        {
            out[usize::from(motor - 1)] = pwm;
        }
        out
    }
}
