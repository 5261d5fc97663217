//! ArduCopter flight modes: their custom-mode numbers and the properties the
//! simulator needs (armable, needs a position estimate, user takeoff, …).

/// The ArduCopter flight modes the simulator flies. Numbers are ArduCopter's
/// `custom_mode` values (`Mode::Number`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FlightMode {
    /// 0: manual attitude; without a pilot the sim holds altitude and brakes.
    Stabilize,
    /// 1: manual rates; simulated like STABILIZE.
    Acro,
    /// 2: altitude hold; without a pilot the sim brakes and holds altitude.
    AltHold,
    /// 3: mission; the simulator has no mission, so AUTO holds position.
    Auto,
    /// 4: offboard control (setpoints, takeoff, reposition).
    Guided,
    /// 5: position hold.
    Loiter,
    /// 6: climb to RTL_ALT, return home, land.
    Rtl,
    /// 7: orbit a point ahead of the vehicle.
    Circle,
    /// 9: descend and disarm.
    Land,
    /// 16: position hold.
    PosHold,
    /// 17: stop and hold.
    Brake,
}

/// ArduCopter mode numbers the simulator knows by name but does not fly.
const UNSIMULATED: &[(u32, &str)] = &[
    (11, "DRIFT"),
    (13, "SPORT"),
    (14, "FLIP"),
    (15, "AUTOTUNE"),
    (18, "THROW"),
    (19, "AVOID_ADSB"),
    (20, "GUIDED_NOGPS"),
    (21, "SMART_RTL"),
    (22, "FLOWHOLD"),
    (23, "FOLLOW"),
    (24, "ZIGZAG"),
    (25, "SYSTEMID"),
    (26, "AUTOROTATE"),
    (27, "AUTO_RTL"),
    (28, "TURTLE"),
];

impl FlightMode {
    /// Every simulated mode.
    pub const ALL: [FlightMode; 11] = [
        FlightMode::Stabilize,
        FlightMode::Acro,
        FlightMode::AltHold,
        FlightMode::Auto,
        FlightMode::Guided,
        FlightMode::Loiter,
        FlightMode::Rtl,
        FlightMode::Circle,
        FlightMode::Land,
        FlightMode::PosHold,
        FlightMode::Brake,
    ];

    /// ArduCopter `custom_mode` number.
    pub fn number(self) -> u32 {
        match self {
            FlightMode::Stabilize => 0,
            FlightMode::Acro => 1,
            FlightMode::AltHold => 2,
            FlightMode::Auto => 3,
            FlightMode::Guided => 4,
            FlightMode::Loiter => 5,
            FlightMode::Rtl => 6,
            FlightMode::Circle => 7,
            FlightMode::Land => 9,
            FlightMode::PosHold => 16,
            FlightMode::Brake => 17,
        }
    }

    /// The mode with ArduCopter number `n`, if the simulator flies it.
    pub fn from_number(n: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.number() == n)
    }

    /// ArduCopter's name for mode number `n` (for messages about modes the sim
    /// does not fly), if it has one.
    pub fn name_of_number(n: u32) -> Option<&'static str> {
        Self::from_number(n)
            .map(Self::name)
            .or_else(|| UNSIMULATED.iter().find(|(k, _)| *k == n).map(|(_, s)| *s))
    }

    /// ArduCopter's name, as it appears in STATUSTEXT.
    pub fn name(self) -> &'static str {
        match self {
            FlightMode::Stabilize => "STABILIZE",
            FlightMode::Acro => "ACRO",
            FlightMode::AltHold => "ALT_HOLD",
            FlightMode::Auto => "AUTO",
            FlightMode::Guided => "GUIDED",
            FlightMode::Loiter => "LOITER",
            FlightMode::Rtl => "RTL",
            FlightMode::Circle => "CIRCLE",
            FlightMode::Land => "LAND",
            FlightMode::PosHold => "POSHOLD",
            FlightMode::Brake => "BRAKE",
        }
    }

    /// Arming is allowed in this mode (ArduCopter `allows_arming`). AUTO is
    /// refused because the simulator never has a mission.
    pub fn allows_arming(self) -> bool {
        !matches!(
            self,
            FlightMode::Auto | FlightMode::Rtl | FlightMode::Land | FlightMode::Circle
        )
    }

    /// The mode needs a position estimate to be entered while armed
    /// (ArduCopter `requires_GPS`).
    pub fn requires_position(self) -> bool {
        matches!(
            self,
            FlightMode::Auto
                | FlightMode::Guided
                | FlightMode::Loiter
                | FlightMode::Rtl
                | FlightMode::Circle
                | FlightMode::PosHold
                | FlightMode::Brake
        )
    }

    /// MAV_CMD_NAV_TAKEOFF is accepted in this mode (ArduCopter `has_user_takeoff`
    /// with `must_navigate`).
    pub fn allows_user_takeoff(self) -> bool {
        matches!(
            self,
            FlightMode::Guided | FlightMode::Loiter | FlightMode::PosHold
        )
    }

    /// ArduCopter reports MAV_MODE_FLAG_GUIDED_ENABLED in these modes.
    pub fn is_guided_flag(self) -> bool {
        matches!(
            self,
            FlightMode::Auto
                | FlightMode::Rtl
                | FlightMode::Loiter
                | FlightMode::Guided
                | FlightMode::Circle
                | FlightMode::PosHold
                | FlightMode::Brake
        )
    }

    /// Touching down in this mode disarms at once (the others wait DISARM_DELAY).
    pub fn disarms_on_landing(self) -> bool {
        matches!(self, FlightMode::Land | FlightMode::Rtl)
    }
}

impl std::fmt::Display for FlightMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_round_trip_and_match_arducopter() {
        for m in FlightMode::ALL {
            assert_eq!(FlightMode::from_number(m.number()), Some(m));
        }
        assert_eq!(FlightMode::Guided.number(), 4);
        assert_eq!(FlightMode::Land.number(), 9);
        assert_eq!(FlightMode::Brake.number(), 17);
        assert_eq!(FlightMode::from_number(8), None);
        assert_eq!(FlightMode::name_of_number(21), Some("SMART_RTL"));
        assert_eq!(FlightMode::name_of_number(99), None);
    }
}
