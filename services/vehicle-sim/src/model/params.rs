//! Parameters of the simulated vehicle (the subset of ArduCopter's that the
//! model uses), validated and converted by `config`.

use super::GeoPoint;

/// Model parameters (validated by `config`).
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleParams {
    /// EKF origin and initial home; the ground is flat at its altitude.
    pub home: GeoPoint,
    /// Height of the geoid (mean sea level) above the WGS-84 ellipsoid around
    /// home, m: GPS_RAW_INT's `alt_ellipsoid` is the MSL altitude plus this.
    pub geoid_undulation_m: f64,
    /// Initial heading, radians.
    pub initial_heading_rad: f64,
    /// Sim time until the EKF has a position, seconds (GPS fix comes at half of it).
    pub ekf_ready_after_s: f64,
    /// Battery capacity, mAh.
    pub battery_capacity_mah: f64,
    /// LiPo cells in series.
    pub battery_cells: u32,
    /// State of charge at start, 0..=1.
    pub battery_initial_fraction: f64,
    /// Minimum state of charge to arm, 0..=1.
    pub battery_arm_min_fraction: f64,
    /// Current in a hover, A.
    pub hover_current_a: f64,
    /// Horizontal speed limit, m/s.
    pub max_speed_xy: f64,
    /// Climb rate limit, m/s.
    pub max_speed_up: f64,
    /// Descent rate limit, m/s.
    pub max_speed_down: f64,
    /// Acceleration limit, m/s².
    pub max_accel: f64,
    /// Yaw rate limit, rad/s.
    pub max_yaw_rate: f64,
    /// LAND final descent speed, m/s.
    pub land_speed: f64,
    /// RTL minimum return altitude above home, m.
    pub rtl_alt_m: f64,
    /// Landed-and-armed time before auto-disarm, s.
    pub disarm_delay_s: f64,
    /// Guided velocity / yaw-rate setpoint lifetime, s.
    pub velocity_timeout_s: f64,
    /// Gimbal slew rate, rad/s.
    pub gimbal_slew_rate: f64,
    /// A GoPro sits on the gimbal (behind its MAVLink GoPro bridge).
    pub gopro: bool,
}

/// The geoid's height above the WGS-84 ellipsoid at SITL's CMAC field near
/// Canberra (EGM96, about +20 m; a GNSS receiver reports the same kind of value).
pub const CMAC_GEOID_UNDULATION_M: f64 = 19.6;

impl Default for VehicleParams {
    /// ArduCopter defaults at SITL's CMAC field.
    fn default() -> Self {
        Self {
            home: GeoPoint {
                lat_deg: -35.363_261,
                lon_deg: 149.165_230,
                alt_msl_m: 584.0,
            },
            geoid_undulation_m: CMAC_GEOID_UNDULATION_M,
            initial_heading_rad: 353.0_f64.to_radians(),
            ekf_ready_after_s: 0.0,
            battery_capacity_mah: 5200.0,
            battery_cells: 4,
            battery_initial_fraction: 1.0,
            battery_arm_min_fraction: 0.2,
            hover_current_a: 15.0,
            max_speed_xy: 5.0,
            max_speed_up: 2.5,
            max_speed_down: 1.5,
            max_accel: 2.5,
            max_yaw_rate: 90.0_f64.to_radians(),
            land_speed: 0.5,
            rtl_alt_m: 15.0,
            disarm_delay_s: 10.0,
            velocity_timeout_s: 3.0,
            gimbal_slew_rate: 90.0_f64.to_radians(),
            gopro: true,
        }
    }
}
