//! What the vehicle is doing: published by `autopilot-link`, read by everyone.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

wire_enum! {
    /// The normalised flight mode. `VehicleStatus::custom_mode` keeps the autopilot's own number.
    pub enum FlightMode: u8 {
        Unknown = 0 => "unknown",
        Stabilize = 1 => "stabilize",
        AltHold = 2 => "alt_hold",
        Loiter = 3 => "loiter",
        PosHold = 4 => "poshold",
        Guided = 5 => "guided",
        Auto = 6 => "auto",
        Rtl = 7 => "rtl",
        SmartRtl = 8 => "smart_rtl",
        Land = 9 => "land",
        Brake = 10 => "brake",
        Circle = 11 => "circle",
        Acro = 12 => "acro",
        /// A mode the autopilot knows that skymesh does not normalise (see `custom_mode`).
        Other = 13 => "other",
    }
}

impl FlightMode {
    /// Normalises an ArduCopter custom mode number.
    pub fn from_copter_custom_mode(custom_mode: u32) -> Self {
        match custom_mode {
            0 => Self::Stabilize,
            1 => Self::Acro,
            2 => Self::AltHold,
            3 => Self::Auto,
            4 => Self::Guided,
            5 => Self::Loiter,
            6 => Self::Rtl,
            7 => Self::Circle,
            9 => Self::Land,
            16 => Self::PosHold,
            17 => Self::Brake,
            21 => Self::SmartRtl,
            _ => Self::Other,
        }
    }

    /// The ArduCopter custom mode number, `None` for modes that have none.
    pub fn to_copter_custom_mode(self) -> Option<u32> {
        Some(match self {
            Self::Stabilize => 0,
            Self::Acro => 1,
            Self::AltHold => 2,
            Self::Auto => 3,
            Self::Guided => 4,
            Self::Loiter => 5,
            Self::Rtl => 6,
            Self::Circle => 7,
            Self::Land => 9,
            Self::PosHold => 16,
            Self::Brake => 17,
            Self::SmartRtl => 21,
            Self::Unknown | Self::Other => return None,
        })
    }
}

wire_enum! {
    /// GPS fix type, numbered as MAVLink's `GPS_FIX_TYPE`.
    pub enum GpsFix: u8 {
        NoGps = 0 => "no_gps",
        NoFix = 1 => "no_fix",
        Fix2d = 2 => "2d",
        Fix3d = 3 => "3d",
        Dgps = 4 => "dgps",
        RtkFloat = 5 => "rtk_float",
        RtkFixed = 6 => "rtk_fixed",
        Static = 7 => "static",
        Ppp = 8 => "ppp",
    }
}

/// Kinematic state, published at the rate ATTITUDE arrives from the autopilot.
///
/// Topic: [`crate::topics::vehicle_state`]. Position fields come from the latest
/// GLOBAL_POSITION_INT (their own stamp in `position_stamp_ns`); attitude from ATTITUDE;
/// the ellipsoid height from the latest GPS_RAW_INT.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.VehicleState.v2")]
#[repr(C)]
pub struct VehicleState {
    pub header: SampleHeader,
    /// MAVLink system id of the vehicle.
    pub vehicle_id: u8,
    /// 1 once a global position has been received.
    pub position_valid: u8,
    /// 1 once an attitude has been received.
    pub attitude_valid: u8,
    /// 1 while the latest GPS_RAW_INT with a 3D fix carried `alt_ellipsoid` (a
    /// MAVLink 2 extension field; autopilots send 0 when they do not know it):
    /// `alt_ellipsoid_m` and `geoid_undulation_m` hold values. 0: ignore both
    /// (autopilot-link sets them NaN).
    pub alt_ellipsoid_valid: u8,
    /// Autopilot time since boot of the attitude, ms.
    pub time_boot_ms: u32,
    /// WGS84 latitude, degrees.
    pub lat_deg: f64,
    /// WGS84 longitude, degrees.
    pub lon_deg: f64,
    /// Altitude above mean sea level, m.
    pub alt_msl_m: f32,
    /// Altitude above home, m.
    pub alt_rel_m: f32,
    /// The GPS receiver's height above the WGS-84 ellipsoid, m (GPS_RAW_INT
    /// `alt_ellipsoid`); NaN unless `alt_ellipsoid_valid`.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::nan_as_null"),
        schemars(with = "Option<f32>")
    )]
    pub alt_ellipsoid_m: f32,
    /// Height of the geoid (mean sea level) above the WGS-84 ellipsoid where the
    /// vehicle is, m: GPS_RAW_INT `alt_ellipsoid - alt` of the same fix. Add it to an
    /// MSL altitude (`alt_msl_m`, home's) for a height above the ellipsoid. NaN
    /// unless `alt_ellipsoid_valid`.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::nan_as_null"),
        schemars(with = "Option<f32>")
    )]
    pub geoid_undulation_m: f32,
    /// Velocity north, east, down, m/s.
    pub vel_ned_mps: [f32; 3],
    /// Heading over ground, degrees 0..360.
    pub heading_deg: f32,
    /// Attitude quaternion w, x, y, z (body → NED).
    pub attitude_q: [f32; 4],
    pub roll_rad: f32,
    pub pitch_rad: f32,
    pub yaw_rad: f32,
    /// Body rates p, q, r in rad/s.
    pub body_rates_radps: [f32; 3],
    /// `CLOCK_MONOTONIC` ns when the position fields were last updated.
    pub position_stamp_ns: u64,
}
crate::assert_layout!(VehicleState, size = 128, align = 8);

/// Mode, health and link state, published on change and at 1 Hz.
///
/// Topic: [`crate::topics::vehicle_status`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
#[type_name("skymesh.VehicleStatus.v1")]
#[repr(C)]
pub struct VehicleStatus {
    pub header: SampleHeader,
    pub vehicle_id: u8,
    /// [`FlightMode`] as stored on the wire.
    #[cfg_attr(
        feature = "serde",
        serde(with = "crate::json::Wire::<crate::FlightMode>")
    )]
    pub mode: u8,
    /// 1 when the motors are armed.
    pub armed: u8,
    /// MAVLink `MAV_STATE` of the autopilot (0 uninit … 8 flight termination).
    pub system_status: u8,
    /// 1 when the EKF reports a usable attitude, velocity and position solution.
    pub ekf_healthy: u8,
    /// [`GpsFix`] as stored on the wire.
    #[cfg_attr(feature = "serde", serde(with = "crate::json::Wire::<crate::GpsFix>"))]
    pub gps_fix: u8,
    pub satellites: u8,
    /// 1 while autopilot heartbeats arrive (none for the link timeout → 0).
    pub link_up: u8,
    /// The autopilot's own mode number (ArduCopter custom mode).
    pub custom_mode: u32,
    /// Raw `EKF_STATUS_FLAGS` bits.
    pub ekf_flags: u16,
    /// Battery remaining, percent; -1 unknown.
    pub battery_remaining_pct: i8,
    /// 1 once a home position is known.
    pub home_valid: u8,
    pub battery_voltage_v: f32,
    /// Milliseconds since the last autopilot heartbeat (u32::MAX if never).
    pub heartbeat_age_ms: u32,
    pub home_lat_deg: f64,
    pub home_lon_deg: f64,
    pub home_alt_msl_m: f32,
    /// MAVLink `MAV_AUTOPILOT` of the flight controller.
    pub autopilot: u8,
    /// MAVLink `MAV_TYPE` of the vehicle.
    pub vehicle_type: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved: u16,
    /// The last STATUSTEXT from the autopilot (e.g. why arming was refused).
    pub status_text: FixedStr<56>,
    /// MAVLink severity of `status_text` (0 emergency … 7 debug).
    pub status_severity: u8,
    #[cfg_attr(feature = "serde", serde(skip))]
    pub reserved2: [u8; 7],
}
crate::assert_layout!(VehicleStatus, size = 136, align = 8);

impl VehicleStatus {
    pub fn flight_mode(&self) -> FlightMode {
        FlightMode::try_from(self.mode).unwrap_or(FlightMode::Unknown)
    }

    pub fn gps_fix_type(&self) -> GpsFix {
        GpsFix::try_from(self.gps_fix).unwrap_or(GpsFix::NoGps)
    }

    pub fn is_armed(&self) -> bool {
        self.armed != 0
    }

    pub fn is_link_up(&self) -> bool {
        self.link_up != 0
    }

    /// `CLOCK_MONOTONIC` nanoseconds when the autopilot heartbeat this status
    /// describes arrived (its mode, armed state and system status come from that
    /// heartbeat), or `None` before the first. Publishers republish the last
    /// heartbeat's fields between heartbeats (autopilot-link once a second), so a
    /// status stamped after an event may still describe the vehicle before it; this
    /// says when the description is from. It errs late, by the millisecond
    /// `heartbeat_age_ms` is counted in plus the publisher's own delay.
    pub fn heartbeat_ns(&self) -> Option<u64> {
        (self.heartbeat_age_ms != u32::MAX).then(|| {
            self.header
                .stamp_ns
                .saturating_sub(u64::from(self.heartbeat_age_ms) * 1_000_000)
        })
    }
}

crate::impl_sample!(VehicleState, VehicleStatus);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copter_modes_round_trip() {
        for mode in FlightMode::ALL {
            if let Some(n) = mode.to_copter_custom_mode() {
                assert_eq!(FlightMode::from_copter_custom_mode(n), *mode);
            }
        }
        assert_eq!(FlightMode::from_copter_custom_mode(999), FlightMode::Other);
    }

    #[test]
    fn enums_refuse_unknown_values() {
        assert!(FlightMode::try_from(200u8).is_err());
        assert_eq!(GpsFix::try_from(3u8), Ok(GpsFix::Fix3d));
        let mut s = VehicleStatus {
            mode: 250,
            ..Default::default()
        };
        assert_eq!(s.flight_mode(), FlightMode::Unknown);
        s.mode = FlightMode::Guided.to_wire();
        assert_eq!(s.flight_mode(), FlightMode::Guided);
    }

    #[test]
    fn heartbeat_time_is_the_stamp_less_the_age() {
        let mut s = VehicleStatus {
            heartbeat_age_ms: 250,
            ..Default::default()
        };
        s.header.stamp_ns = 2_000_000_000;
        assert_eq!(s.heartbeat_ns(), Some(1_750_000_000));
        s.heartbeat_age_ms = u32::MAX;
        assert_eq!(s.heartbeat_ns(), None);
    }
}
