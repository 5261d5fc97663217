//! Vehicle state → MAVLink messages, filled in the way ArduCopter fills them
//! (units, sentinels for unknown values, positions zero before the EKF has
//! one).

use mavlink::dialects::ardupilotmega::{
    EkfStatusFlags, GimbalDeviceErrorFlags, GimbalDeviceFlags, GoproHeartbeatFlags,
    GoproHeartbeatStatus, GpsFixType, MavAutopilot, MavBatteryFunction, MavBatteryType, MavCmd,
    MavMessage, MavModeFlag, MavProtocolCapability, MavResult, MavSeverity, MavState,
    MavSysStatusSensor, MavType, ATTITUDE_DATA, AUTOPILOT_VERSION_DATA, BATTERY_STATUS_DATA,
    COMMAND_ACK_DATA, EKF_STATUS_REPORT_DATA, GIMBAL_DEVICE_ATTITUDE_STATUS_DATA,
    GLOBAL_POSITION_INT_DATA, GOPRO_HEARTBEAT_DATA, GPS_RAW_INT_DATA, HEARTBEAT_DATA,
    HOME_POSITION_DATA, LOCAL_POSITION_NED_DATA, SERVO_OUTPUT_RAW_DATA, STATUSTEXT_DATA,
    SYS_STATUS_DATA, VFR_HUD_DATA,
};
use mavlink::MessageData;

use crate::handler::Outgoing;
use crate::model::Vehicle;

/// GIMBAL_DEVICE_ATTITUDE_STATUS.gimbal_device_id: the autopilot drives the
/// mount, so device and manager share component 1 and the device is numbered
/// (ArduPilot: mount instance + 1).
pub const GIMBAL_DEVICE_ID: u8 = 1;

/// Message ids [`build`] can produce: the only ones SET_MESSAGE_INTERVAL and
/// REQUEST_MESSAGE accept. (GOPRO_HEARTBEAT is the gimbal's, not the
/// autopilot's: it is always sent at 1 Hz and cannot be asked for.)
pub const PRODUCIBLE: [u32; 13] = [
    HEARTBEAT_DATA::ID,
    SYS_STATUS_DATA::ID,
    GPS_RAW_INT_DATA::ID,
    ATTITUDE_DATA::ID,
    SERVO_OUTPUT_RAW_DATA::ID,
    LOCAL_POSITION_NED_DATA::ID,
    GLOBAL_POSITION_INT_DATA::ID,
    VFR_HUD_DATA::ID,
    BATTERY_STATUS_DATA::ID,
    AUTOPILOT_VERSION_DATA::ID,
    EKF_STATUS_REPORT_DATA::ID,
    HOME_POSITION_DATA::ID,
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID,
];

/// ArduCopter 4.5.7, FIRMWARE_VERSION_TYPE_OFFICIAL.
const FLIGHT_SW_VERSION: u32 = (4 << 24) | (5 << 16) | (7 << 8) | 255;

/// Satellites a healthy simulated GPS sees.
const SATELLITES: u8 = 10;

/// Build message `id` from the vehicle's state; `None` if the simulator does
/// not produce it or has nothing to say yet (no home, no position).
pub fn build(id: u32, v: &Vehicle, system_id: u8) -> Option<MavMessage> {
    match id {
        HEARTBEAT_DATA::ID => Some(heartbeat(v)),
        SYS_STATUS_DATA::ID => Some(sys_status(v)),
        GPS_RAW_INT_DATA::ID => Some(gps_raw_int(v)),
        ATTITUDE_DATA::ID => Some(attitude(v)),
        LOCAL_POSITION_NED_DATA::ID => local_position_ned(v),
        GLOBAL_POSITION_INT_DATA::ID => Some(global_position_int(v)),
        VFR_HUD_DATA::ID => Some(vfr_hud(v)),
        BATTERY_STATUS_DATA::ID => Some(battery_status(v)),
        AUTOPILOT_VERSION_DATA::ID => Some(autopilot_version(system_id)),
        EKF_STATUS_REPORT_DATA::ID => Some(ekf_status_report(v)),
        HOME_POSITION_DATA::ID => home_position(v),
        GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID => Some(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(
            gimbal_device_attitude_status(v),
        )),
        SERVO_OUTPUT_RAW_DATA::ID => Some(MavMessage::SERVO_OUTPUT_RAW(servo_output_raw(v))),
        _ => None,
    }
}

/// Message `id` as it goes on the wire: GOPRO_HEARTBEAT from the gimbal (`None`
/// without a GoPro), the rest as [`build`] makes them, from the autopilot.
pub fn build_outgoing(id: u32, v: &Vehicle, system_id: u8) -> Option<Outgoing> {
    match id {
        GOPRO_HEARTBEAT_DATA::ID => gopro_heartbeat(v).map(Outgoing::from_gimbal),
        _ => build(id, v, system_id).map(Outgoing::Message),
    }
}

fn time_boot_ms(v: &Vehicle) -> u32 {
    (v.time_s() * 1000.0) as u32
}

/// Centidegrees in 0..36000 (the heading convention of GLOBAL_POSITION_INT).
fn centidegrees(rad: f64) -> u16 {
    ((rad.to_degrees().rem_euclid(360.0) * 100.0).round() as u32 % 36_000) as u16
}

/// m/s → cm/s, saturating at the i16 range.
fn cm_per_s(v: f64) -> i16 {
    (v * 100.0)
        .round()
        .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// HEARTBEAT with ArduCopter's base_mode flags.
pub fn heartbeat(v: &Vehicle) -> MavMessage {
    let mode = v.mode();
    let mut base = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED
        | MavModeFlag::MAV_MODE_FLAG_MANUAL_INPUT_ENABLED;
    if mode.is_guided_flag() {
        base |= MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED;
    }
    if v.armed() {
        base |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: mode.number(),
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: base,
        system_status: if v.armed() {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        },
        mavlink_version: 3,
    })
}

fn sys_status(v: &Vehicle) -> MavMessage {
    type S = MavSysStatusSensor;
    let present = S::MAV_SYS_STATUS_SENSOR_3D_GYRO
        | S::MAV_SYS_STATUS_SENSOR_3D_ACCEL
        | S::MAV_SYS_STATUS_SENSOR_3D_MAG
        | S::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
        | S::MAV_SYS_STATUS_SENSOR_GPS
        | S::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
        | S::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
        | S::MAV_SYS_STATUS_SENSOR_YAW_POSITION
        | S::MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
        | S::MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        | S::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        | S::MAV_SYS_STATUS_AHRS
        | S::MAV_SYS_STATUS_SENSOR_BATTERY;
    let mut health = present;
    if !v.gps_fix() {
        health.remove(S::MAV_SYS_STATUS_SENSOR_GPS);
    }
    if !v.ekf_ready() {
        health.remove(S::MAV_SYS_STATUS_AHRS);
    }
    let b = v.battery();
    MavMessage::SYS_STATUS(SYS_STATUS_DATA {
        onboard_control_sensors_present: present,
        onboard_control_sensors_enabled: present,
        onboard_control_sensors_health: health,
        load: 150,
        voltage_battery: (b.voltage() * 1000.0).round() as u16,
        current_battery: (b.current() * 100.0).round() as i16,
        battery_remaining: (b.remaining() * 100.0).round() as i8,
        ..SYS_STATUS_DATA::DEFAULT
    })
}

fn gps_raw_int(v: &Vehicle) -> MavMessage {
    let fix = v.gps_fix();
    let p = v.position_geo();
    let vel = v.velocity_ned();
    let speed = (vel.x * vel.x + vel.y * vel.y).sqrt();
    MavMessage::GPS_RAW_INT(GPS_RAW_INT_DATA {
        time_usec: (v.time_s() * 1e6) as u64,
        lat: if fix { p.lat_e7() } else { 0 },
        lon: if fix { p.lon_e7() } else { 0 },
        alt: if fix {
            (p.alt_msl_m * 1000.0).round() as i32
        } else {
            0
        },
        eph: if fix { 121 } else { u16::MAX },
        epv: if fix { 200 } else { u16::MAX },
        vel: (speed * 100.0).round() as u16,
        // Course over ground is meaningless when (nearly) stationary.
        cog: if speed > 0.2 {
            centidegrees(vel.y.atan2(vel.x))
        } else {
            u16::MAX
        },
        fix_type: if fix {
            GpsFixType::GPS_FIX_TYPE_3D_FIX
        } else {
            GpsFixType::GPS_FIX_TYPE_NO_FIX
        },
        satellites_visible: if fix { SATELLITES } else { 0 },
        // Height above the WGS-84 ellipsoid: MSL plus the geoid undulation at home.
        alt_ellipsoid: if fix {
            ((p.alt_msl_m + v.params().geoid_undulation_m) * 1000.0).round() as i32
        } else {
            0
        },
        ..GPS_RAW_INT_DATA::DEFAULT
    })
}

fn attitude(v: &Vehicle) -> MavMessage {
    let a = v.attitude();
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms: time_boot_ms(v),
        roll: a.roll as f32,
        pitch: a.pitch as f32,
        yaw: a.yaw as f32,
        rollspeed: a.rates.x as f32,
        pitchspeed: a.rates.y as f32,
        yawspeed: a.rates.z as f32,
    })
}

/// ArduPilot has no local position until the EKF has an origin.
fn local_position_ned(v: &Vehicle) -> Option<MavMessage> {
    if !v.ekf_ready() {
        return None;
    }
    let p = v.position_ned();
    let vel = v.velocity_ned();
    Some(MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
        time_boot_ms: time_boot_ms(v),
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        vx: vel.x as f32,
        vy: vel.y as f32,
        vz: vel.z as f32,
    }))
}

/// Before the EKF has a position ArduPilot reports zeros, as SITL does.
fn global_position_int(v: &Vehicle) -> MavMessage {
    let vel = v.velocity_ned();
    let (lat, lon, alt, rel) = if v.ekf_ready() {
        let p = v.position_geo();
        (
            p.lat_e7(),
            p.lon_e7(),
            (p.alt_msl_m * 1000.0).round() as i32,
            (v.relative_alt() * 1000.0).round() as i32,
        )
    } else {
        (0, 0, 0, 0)
    };
    MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
        time_boot_ms: time_boot_ms(v),
        lat,
        lon,
        alt,
        relative_alt: rel,
        vx: cm_per_s(vel.x),
        vy: cm_per_s(vel.y),
        vz: cm_per_s(vel.z),
        hdg: centidegrees(v.heading()),
    })
}

fn vfr_hud(v: &Vehicle) -> MavMessage {
    let vel = v.velocity_ned();
    let speed = (vel.x * vel.x + vel.y * vel.y).sqrt() as f32;
    MavMessage::VFR_HUD(VFR_HUD_DATA {
        // No wind in the simulation: airspeed equals groundspeed.
        airspeed: speed,
        groundspeed: speed,
        alt: v.position_geo().alt_msl_m as f32,
        climb: -vel.z as f32,
        heading: (centidegrees(v.heading()) / 100) as i16,
        throttle: (v.throttle() * 100.0).round() as u16,
    })
}

fn battery_status(v: &Vehicle) -> MavMessage {
    let b = v.battery();
    // No per-cell monitoring: the pack voltage goes in cell 0, the rest unknown.
    let mut voltages = [u16::MAX; 10];
    voltages[0] = (b.voltage() * 1000.0).round().min(f64::from(u16::MAX - 1)) as u16;
    MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
        current_consumed: b.consumed_mah().round() as i32,
        // Wh → hJ (hecto-joules): ×3600/100.
        energy_consumed: (b.consumed_wh() * 36.0).round() as i32,
        temperature: i16::MAX,
        voltages,
        current_battery: (b.current() * 100.0).round() as i16,
        id: 0,
        battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
        mavtype: MavBatteryType::MAV_BATTERY_TYPE_LIPO,
        battery_remaining: (b.remaining() * 100.0).round() as i8,
        ..BATTERY_STATUS_DATA::DEFAULT
    })
}

fn autopilot_version(system_id: u8) -> MavMessage {
    type C = MavProtocolCapability;
    MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
        capabilities: C::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | C::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | C::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | C::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
        uid: u64::from(system_id),
        flight_sw_version: FLIGHT_SW_VERSION,
        flight_custom_version: *b"skymesh\0",
        ..AUTOPILOT_VERSION_DATA::DEFAULT
    })
}

fn ekf_status_report(v: &Vehicle) -> MavMessage {
    let flags = if v.ekf_ready() {
        EkfStatusFlags::EKF_ATTITUDE
            | EkfStatusFlags::EKF_VELOCITY_HORIZ
            | EkfStatusFlags::EKF_VELOCITY_VERT
            | EkfStatusFlags::EKF_POS_HORIZ_REL
            | EkfStatusFlags::EKF_POS_HORIZ_ABS
            | EkfStatusFlags::EKF_POS_VERT_ABS
            | EkfStatusFlags::EKF_PRED_POS_HORIZ_REL
            | EkfStatusFlags::EKF_PRED_POS_HORIZ_ABS
    } else {
        EkfStatusFlags::EKF_ATTITUDE | EkfStatusFlags::EKF_CONST_POS_MODE
    };
    MavMessage::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
        velocity_variance: 0.02,
        pos_horiz_variance: 0.01,
        pos_vert_variance: 0.02,
        compass_variance: 0.01,
        terrain_alt_variance: 0.0,
        flags,
        airspeed_variance: 0.0,
    })
}

fn home_position(v: &Vehicle) -> Option<MavMessage> {
    let geo = v.home_geo()?;
    let ned = v.home_ned()?;
    Some(MavMessage::HOME_POSITION(HOME_POSITION_DATA {
        latitude: geo.lat_e7(),
        longitude: geo.lon_e7(),
        altitude: (geo.alt_msl_m * 1000.0).round() as i32,
        x: ned.x as f32,
        y: ned.y as f32,
        z: ned.z as f32,
        q: [1.0, 0.0, 0.0, 0.0],
        ..HOME_POSITION_DATA::DEFAULT
    }))
}

/// The gimbal attitude, as ArduPilot reports the mount it drives: yaw in the
/// vehicle frame (relative to the nose), delta_yaw = the vehicle's heading.
pub fn gimbal_device_attitude_status(v: &Vehicle) -> GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
    let g = v.gimbal().attitude();
    let w = g.angular_velocity();
    let a = v.attitude();
    // Euler yaw rate from the body rates.
    let (sr, cr) = a.roll.sin_cos();
    let heading_rate = (a.rates.y * sr + a.rates.z * cr) / a.pitch.cos();
    GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
        time_boot_ms: time_boot_ms(v),
        q: g.quaternion(),
        angular_velocity_x: w.x as f32,
        angular_velocity_y: w.y as f32,
        angular_velocity_z: w.z as f32,
        failure_flags: GimbalDeviceErrorFlags::empty(),
        flags: GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
        target_system: 0,
        target_component: 0,
        delta_yaw: a.yaw as f32,
        delta_yaw_velocity: if heading_rate.is_finite() {
            heading_rate as f32
        } else {
            f32::NAN
        },
        gimbal_device_id: GIMBAL_DEVICE_ID,
    }
}

/// SERVO_OUTPUT_RAW, port 0 (outputs 1..=16), as ArduCopter fills it: outputs
/// 1..=4 are the motors ([`Vehicle::motor_outputs`]: idle, flight throttle or a
/// motor test), 5..=16 what MAV_CMD_DO_SET_SERVO last set on that channel (0 if
/// never set).
pub fn servo_output_raw(v: &Vehicle) -> SERVO_OUTPUT_RAW_DATA {
    let servos = &v.payload().servos;
    let mut out = [0u16; 16];
    for (i, pwm) in out.iter_mut().enumerate() {
        let channel = i as u8 + 1;
        *pwm = servos.get(&channel).copied().unwrap_or(0);
    }
    for (pwm, motor) in out.iter_mut().zip(v.motor_outputs()) {
        *pwm = motor;
    }
    let [s1, s2, s3, s4, s5, s6, s7, s8, s9, s10, s11, s12, s13, s14, s15, s16] = out;
    SERVO_OUTPUT_RAW_DATA {
        // ArduPilot sends its boot time in µs, wrapping at 32 bits.
        time_usec: (v.time_s() * 1e6) as u64 as u32,
        servo1_raw: s1,
        servo2_raw: s2,
        servo3_raw: s3,
        servo4_raw: s4,
        servo5_raw: s5,
        servo6_raw: s6,
        servo7_raw: s7,
        servo8_raw: s8,
        port: 0,
        servo9_raw: s9,
        servo10_raw: s10,
        servo11_raw: s11,
        servo12_raw: s12,
        servo13_raw: s13,
        servo14_raw: s14,
        servo15_raw: s15,
        servo16_raw: s16,
    }
}

/// GOPRO_HEARTBEAT (sent by the gimbal); `None` when no GoPro is fitted.
pub fn gopro_heartbeat(v: &Vehicle) -> Option<MavMessage> {
    let hb = v.gopro()?.heartbeat();
    Some(MavMessage::GOPRO_HEARTBEAT(GOPRO_HEARTBEAT_DATA {
        status: if hb.powered {
            GoproHeartbeatStatus::GOPRO_HEARTBEAT_STATUS_CONNECTED
        } else {
            GoproHeartbeatStatus::GOPRO_HEARTBEAT_STATUS_DISCONNECTED
        },
        capture_mode: hb.capture_mode,
        flags: if hb.recording {
            GoproHeartbeatFlags::GOPRO_FLAG_RECORDING
        } else {
            GoproHeartbeatFlags::empty()
        },
    }))
}

/// A STATUSTEXT (truncated to the 50 bytes MAVLink carries).
pub fn statustext(severity: MavSeverity, text: &str) -> MavMessage {
    let mut end = text.len().min(50);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    MavMessage::STATUSTEXT(STATUSTEXT_DATA {
        severity,
        text: text[..end].into(),
        ..STATUSTEXT_DATA::DEFAULT
    })
}

/// A COMMAND_ACK for a command the dialect knows, to every component (target
/// 0/0, as autopilots without the extension fields answer).
pub fn command_ack(command: MavCmd, result: MavResult) -> MavMessage {
    MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        ..COMMAND_ACK_DATA::DEFAULT
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{FlightMode, VehicleParams};

    #[test]
    fn heartbeat_flags_follow_mode_and_arming() {
        let mut v = Vehicle::new(VehicleParams::default());
        let MavMessage::HEARTBEAT(hb) = heartbeat(&v) else {
            panic!("not a heartbeat")
        };
        assert_eq!(hb.custom_mode, 0);
        assert!(!hb
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED));
        assert_eq!(hb.system_status, MavState::MAV_STATE_STANDBY);
        v.set_mode(FlightMode::Guided).expect("guided");
        v.arm(false).expect("arm");
        let MavMessage::HEARTBEAT(hb) = heartbeat(&v) else {
            panic!("not a heartbeat")
        };
        assert_eq!(
            FlightMode::from_number(hb.custom_mode),
            Some(FlightMode::Guided)
        );
        assert!(hb.base_mode.contains(
            MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED
                | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        ));
        assert_eq!(hb.system_status, MavState::MAV_STATE_ACTIVE);
    }

    #[test]
    fn positions_are_zero_before_the_ekf() {
        let v = Vehicle::new(VehicleParams {
            ekf_ready_after_s: 30.0,
            ..VehicleParams::default()
        });
        let Some(MavMessage::GLOBAL_POSITION_INT(g)) = build(GLOBAL_POSITION_INT_DATA::ID, &v, 1)
        else {
            panic!("no GLOBAL_POSITION_INT")
        };
        assert_eq!((g.lat, g.lon), (0, 0));
        assert!(build(LOCAL_POSITION_NED_DATA::ID, &v, 1).is_none());
        assert!(build(HOME_POSITION_DATA::ID, &v, 1).is_none());
    }

    #[test]
    fn units() {
        let v = Vehicle::new(VehicleParams::default());
        let Some(MavMessage::GLOBAL_POSITION_INT(g)) = build(GLOBAL_POSITION_INT_DATA::ID, &v, 1)
        else {
            panic!("no GLOBAL_POSITION_INT")
        };
        assert_eq!(g.lat, -353_632_610);
        assert_eq!(g.alt, 584_000);
        assert_eq!(g.relative_alt, 0);
        assert_eq!(g.hdg, 35_300);
        let Some(MavMessage::SYS_STATUS(s)) = build(SYS_STATUS_DATA::ID, &v, 1) else {
            panic!("no SYS_STATUS")
        };
        assert_eq!(s.voltage_battery, 16_800);
        assert_eq!(s.battery_remaining, 100);
        assert_eq!(centidegrees(-0.0001), 35_999);
    }

    #[test]
    fn statustext_truncates_on_a_char_boundary() {
        let long = "é".repeat(40);
        let MavMessage::STATUSTEXT(t) = statustext(MavSeverity::MAV_SEVERITY_INFO, &long) else {
            panic!("not statustext")
        };
        assert_eq!(t.text.to_str().map(str::len), Ok(50));
    }

    #[test]
    fn everything_producible_builds_once_ready() {
        let v = Vehicle::new(VehicleParams::default());
        for id in PRODUCIBLE {
            assert!(build(id, &v, 1).is_some(), "message {id}");
        }
    }
}
