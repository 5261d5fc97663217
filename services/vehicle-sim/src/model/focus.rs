//! The simulated MAVLink camera's focus (MAV_CMD_SET_CAMERA_FOCUS), part of
//! [`super::Payload`]: a lens with a 1/distance scale from [`MIN_FOCUS_M`] (0 %)
//! to infinity (100 %), moved by steps, continuously, to a level or a distance, or
//! handed to the camera's automatic modes.

/// One focus step (SET_FOCUS_TYPE step), percent of the focus range.
pub const FOCUS_STEP_PCT: f64 = 1.0;

/// Continuous focus at full rate (value ±1), percent of the range per second.
pub const FOCUS_RATE_PCT_S: f64 = 20.0;

/// The closest distance the simulated lens focuses at, metres (0 % of the range).
pub const MIN_FOCUS_M: f64 = 0.5;

/// How the focus is driven (the SET_FOCUS_TYPE of the last accepted command).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum FocusControl {
    /// Set by steps, a continuous move, a level or a distance.
    #[default]
    Manual,
    /// FOCUS_TYPE_AUTO.
    Auto,
    /// FOCUS_TYPE_AUTO_SINGLE (AF-S).
    AutoSingle,
    /// FOCUS_TYPE_AUTO_CONTINUOUS (AF-C).
    AutoContinuous,
}

/// The simulated camera's focus, 0 % (closest, [`MIN_FOCUS_M`]) ..= 100 %
/// (infinity), as MAV_CMD_SET_CAMERA_FOCUS sets it: a step of [`FOCUS_STEP_PCT`]
/// in (−) or out (+), a continuous move at up to [`FOCUS_RATE_PCT_S`] until
/// stopped or at an end, a level, a distance, or one of the automatic modes
/// (which keep the level: the simulator has no scene to focus on). Every command
/// replaces a continuous move in progress. Starts at infinity, manual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Focus {
    level_pct: f64,
    /// −1..=1 of [`FOCUS_RATE_PCT_S`]; 0 = not moving.
    rate: f64,
    control: FocusControl,
}

impl Default for Focus {
    fn default() -> Self {
        Self {
            level_pct: 100.0,
            rate: 0.0,
            control: FocusControl::Manual,
        }
    }
}

/// Why a focus command was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FocusRefusal {
    /// A step that is not a number in −1..=1.
    Step(f64),
    /// A continuous rate that is not a number.
    Rate(f64),
    /// A level outside 0..=100 %.
    Level(f64),
    /// A distance that is negative or not a finite number.
    Distance(f64),
}

impl Focus {
    /// Focus level, percent of the range (100 = infinity).
    pub fn level_pct(&self) -> f64 {
        self.level_pct
    }

    /// Continuous focus rate, −1..=1 (0 = not moving).
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Manual or one of the automatic modes.
    pub fn control(&self) -> FocusControl {
        self.control
    }

    /// The distance in focus, metres (`f64::INFINITY` at 100 %): the inverse of
    /// [`Focus::set_distance`].
    pub fn distance_m(&self) -> f64 {
        if self.level_pct >= 100.0 {
            f64::INFINITY
        } else {
            MIN_FOCUS_M / (1.0 - self.level_pct / 100.0)
        }
    }

    fn manual(&mut self) {
        self.rate = 0.0;
        self.control = FocusControl::Manual;
    }

    /// One step in (−1) or out (+1); fractions move part of a step. Stops at the ends.
    pub fn step_by(&mut self, step: f64) -> Result<(), FocusRefusal> {
        if !(-1.0..=1.0).contains(&step) {
            return Err(FocusRefusal::Step(step));
        }
        self.manual();
        self.level_pct = (self.level_pct + step * FOCUS_STEP_PCT).clamp(0.0, 100.0);
        Ok(())
    }

    /// Keep focusing in (−), out (+) or stop (0); beyond ±1 is clipped, as MAVLink's
    /// FOCUS_TYPE_CONTINUOUS says.
    pub fn continuous(&mut self, rate: f64) -> Result<(), FocusRefusal> {
        if !rate.is_finite() {
            return Err(FocusRefusal::Rate(rate));
        }
        self.manual();
        self.rate = rate.clamp(-1.0, 1.0);
        Ok(())
    }

    /// Go to `pct` percent of the range.
    pub fn set_level(&mut self, pct: f64) -> Result<(), FocusRefusal> {
        if !(0.0..=100.0).contains(&pct) {
            return Err(FocusRefusal::Level(pct));
        }
        self.manual();
        self.level_pct = pct;
        Ok(())
    }

    /// Focus at `m` metres: 100 × (1 − [`MIN_FOCUS_M`] / m) percent of the range
    /// (the lens's 1/distance scale), closer than the lens can is its closest.
    pub fn set_distance(&mut self, m: f64) -> Result<(), FocusRefusal> {
        if !(m.is_finite() && m >= 0.0) {
            return Err(FocusRefusal::Distance(m));
        }
        self.manual();
        self.level_pct = if m <= MIN_FOCUS_M {
            0.0
        } else {
            100.0 * (1.0 - MIN_FOCUS_M / m)
        };
        Ok(())
    }

    /// Hand the focus to the camera (an automatic mode); the level stays.
    pub fn auto(&mut self, control: FocusControl) {
        self.rate = 0.0;
        self.control = control;
    }

    /// Advance a continuous move by `dt` seconds; it stops at either end.
    pub fn step(&mut self, dt: f64) {
        if self.rate == 0.0 {
            return;
        }
        self.level_pct += self.rate * FOCUS_RATE_PCT_S * dt;
        if !(0.0..=100.0).contains(&self.level_pct) {
            self.level_pct = self.level_pct.clamp(0.0, 100.0);
            self.rate = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn focus_moves_by_steps_continuously_to_a_level_and_to_a_distance() {
        let mut f = Focus::default();
        assert_eq!((f.level_pct(), f.distance_m()), (100.0, f64::INFINITY));
        f.step_by(-1.0).unwrap();
        assert_eq!(f.level_pct(), 99.0);
        f.step_by(1.0).unwrap();
        f.step_by(1.0).unwrap();
        assert_eq!(f.level_pct(), 100.0, "stops at infinity");
        f.continuous(-3.0).unwrap();
        assert_eq!(f.rate(), -1.0, "clipped");
        for _ in 0..100 {
            f.step(0.01);
        }
        assert!((f.level_pct() - 80.0).abs() < 1e-9, "{}", f.level_pct());
        f.continuous(0.0).unwrap();
        f.step(1.0);
        assert!((f.level_pct() - 80.0).abs() < 1e-9);
        f.set_level(50.0).unwrap();
        assert_eq!(f.distance_m(), 2.0 * MIN_FOCUS_M);
        f.set_distance(10.0).unwrap();
        assert!((f.distance_m() - 10.0).abs() < 1e-9);
        f.set_distance(0.0).unwrap();
        assert_eq!(f.level_pct(), 0.0, "closer than the lens: its closest");
        f.auto(FocusControl::AutoContinuous);
        assert_eq!(f.control(), FocusControl::AutoContinuous);
        f.set_level(30.0).unwrap();
        assert_eq!(f.control(), FocusControl::Manual);
        for bad in [
            f.step_by(1.5),
            f.step_by(f64::NAN),
            f.continuous(f64::INFINITY),
            f.set_level(100.5),
            f.set_distance(-1.0),
            f.set_distance(f64::INFINITY),
        ] {
            assert!(bad.is_err());
        }
        assert_eq!(f.level_pct(), 30.0, "refusals change nothing");
    }
}
