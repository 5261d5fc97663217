//! MAVLink telemetry → [`VehicleState`] and [`VehicleStatus`]: pure fusion, no I/O.
//!
//! [`Telemetry`] identifies the autopilot (the first HEARTBEAT from component 1 of
//! system `vehicle_id` whose `autopilot` is not `MAV_AUTOPILOT_INVALID`; ground
//! stations and companion computers send INVALID), keeps the latest value of every
//! message it fuses, and builds a `VehicleState` for each ATTITUDE:
//!
//! | field | from |
//! |---|---|
//! | lat, lon, alt msl, alt rel, NED velocity, heading | latest GLOBAL_POSITION_INT |
//! | roll, pitch, yaw, body rates, `time_boot_ms` | the ATTITUDE itself |
//! | quaternion | ATTITUDE_QUATERNION of the same instant (±100 ms) if it arrives, else from the Euler angles |
//! | alt ellipsoid, geoid undulation | latest GPS_RAW_INT with a 3D fix and `alt_ellipsoid` set |
//!
//! `VehicleStatus` comes from HEARTBEAT (mode, armed, system status), EKF_STATUS_REPORT,
//! GPS_RAW_INT, SYS_STATUS/BATTERY_STATUS, HOME_POSITION and STATUSTEXT. Link state
//! ([`LinkMonitor`]) is decided from heartbeat times only; every instant is passed in.

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::{
    EkfStatusFlags, GpsFixType, MavAutopilot, MavMessage, MavModeFlag, ATTITUDE_DATA,
    GLOBAL_POSITION_INT_DATA, GPS_RAW_INT_DATA, HEARTBEAT_DATA,
};
use mavlink::MavHeader;
use nalgebra::UnitQuaternion;
use skymesh_ipc_types::{FixedStr, FlightMode, GpsFix, VehicleState, VehicleStatus};

/// MAVLink component id of the autopilot.
pub const AUTOPILOT_COMPONENT: u8 = 1;

/// EKF_STATUS_REPORT flags that must all be set for `ekf_healthy`.
const EKF_REQUIRED: EkfStatusFlags = EkfStatusFlags::EKF_ATTITUDE
    .union(EkfStatusFlags::EKF_VELOCITY_HORIZ)
    .union(EkfStatusFlags::EKF_VELOCITY_VERT)
    .union(EkfStatusFlags::EKF_POS_HORIZ_ABS)
    .union(EkfStatusFlags::EKF_POS_VERT_ABS);
/// EKF_STATUS_REPORT flags of which none may be set for `ekf_healthy`.
const EKF_FORBIDDEN: EkfStatusFlags =
    EkfStatusFlags::EKF_UNINITIALIZED.union(EkfStatusFlags::EKF_CONST_POS_MODE);

/// The identified flight controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Autopilot {
    pub system_id: u8,
    /// `MAV_AUTOPILOT` as on the wire.
    pub autopilot: u8,
    /// `MAV_TYPE` as on the wire.
    pub vehicle_type: u8,
}

/// What one message changed, for the caller to act on.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Update {
    /// A HEARTBEAT of the identified autopilot.
    pub heartbeat: bool,
    /// This message identified the autopilot (first heartbeat ever).
    pub identified: Option<Autopilot>,
    /// A heartbeat from a system other than `vehicle_id`, seen for the first time.
    pub foreign_autopilot: Option<u8>,
    /// The armed flag changed with this heartbeat.
    pub armed_changed: bool,
    /// An ATTITUDE: the state to publish.
    pub state: Option<VehicleState>,
    /// A STATUSTEXT: severity and text.
    pub status_text: Option<(u8, String)>,
    /// A COMMAND_ACK: MAV_CMD and MAV_RESULT as on the wire.
    pub command_ack: Option<(u32, u8)>,
}

#[derive(Debug, Clone, Copy)]
struct Position {
    lat_deg: f64,
    lon_deg: f64,
    alt_msl_m: f32,
    alt_rel_m: f32,
    vel_ned_mps: [f32; 3],
    /// `None` when the autopilot reports UINT16_MAX (unknown).
    heading_deg: Option<f32>,
    stamp_ns: u64,
}

#[derive(Debug, Clone, Copy)]
struct Ellipsoid {
    alt_m: f32,
    undulation_m: f32,
}

/// The ellipsoid height of a GPS_RAW_INT, if it carries one.
fn ellipsoid(g: &GPS_RAW_INT_DATA) -> Option<Ellipsoid> {
    let fix = g.fix_type as u8 >= GpsFixType::GPS_FIX_TYPE_3D_FIX as u8;
    (fix && g.alt_ellipsoid != 0).then(|| Ellipsoid {
        alt_m: (f64::from(g.alt_ellipsoid) / 1000.0) as f32,
        undulation_m: ((i64::from(g.alt_ellipsoid) - i64::from(g.alt)) as f64 / 1000.0) as f32,
    })
}

/// Latest LOCAL_POSITION_NED: position and velocity in the EKF origin frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalPosition {
    pub time_boot_ms: u32,
    pub pos_ned_m: [f32; 3],
    pub vel_ned_mps: [f32; 3],
}

/// The fusion state of one vehicle.
#[derive(Debug)]
pub struct Telemetry {
    vehicle_id: u8,
    autopilot: Option<Autopilot>,
    /// Systems already warned about (so the log says it once per system).
    foreign: BTreeSet<u32>,
    position: Option<Position>,
    /// Latest ATTITUDE_QUATERNION: `time_boot_ms` and w, x, y, z.
    quaternion: Option<(u32, [f32; 4])>,
    /// From the latest GPS_RAW_INT: its height above the WGS-84 ellipsoid and the
    /// geoid undulation (`alt_ellipsoid - alt`), m; `None` without a 3D fix or
    /// when the autopilot does not send `alt_ellipsoid` (0, or MAVLink 1).
    ellipsoid: Option<Ellipsoid>,
    local: Option<LocalPosition>,
    /// Every status field except link state, header and heartbeat age.
    status: VehicleStatus,
    battery_from_sys_status: bool,
}

/// `MAV_AUTOPILOT_ARDUPILOTMEGA`: custom modes are ArduCopter's.
const ARDUPILOT: u8 = MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA as u8;

impl Telemetry {
    pub fn new(vehicle_id: u8) -> Self {
        Telemetry {
            vehicle_id,
            autopilot: None,
            foreign: BTreeSet::new(),
            position: None,
            quaternion: None,
            ellipsoid: None,
            local: None,
            status: VehicleStatus {
                vehicle_id,
                battery_remaining_pct: -1,
                ..VehicleStatus::default()
            },
            battery_from_sys_status: false,
        }
    }

    pub fn autopilot(&self) -> Option<Autopilot> {
        self.autopilot
    }

    /// The current flight mode (Unknown before the first heartbeat).
    pub fn flight_mode(&self) -> FlightMode {
        self.status.flight_mode()
    }

    pub fn is_armed(&self) -> bool {
        self.status.is_armed()
    }

    /// Latest LOCAL_POSITION_NED, if one arrived.
    pub fn local_position(&self) -> Option<LocalPosition> {
        self.local
    }

    /// Fuses one message. `now_ns` is `CLOCK_MONOTONIC` (for `position_stamp_ns`).
    pub fn handle(&mut self, header: &MavHeader, msg: &MavMessage, now_ns: u64) -> Update {
        let mut update = Update::default();
        if let MavMessage::HEARTBEAT(hb) = msg {
            self.heartbeat(header, hb, &mut update);
            return update;
        }
        if header.system_id != u32::from(self.vehicle_id) {
            return update;
        }
        // STATUSTEXT may come from any component of the vehicle (camera, gimbal, ...).
        if let MavMessage::STATUSTEXT(t) = msg {
            let text = t.text.to_str().unwrap_or("<invalid utf-8>").trim_end();
            self.status.status_text = FixedStr::new(text);
            self.status.status_severity = t.severity as u8;
            update.status_text = Some((t.severity as u8, text.to_string()));
            return update;
        }
        if header.component_id != AUTOPILOT_COMPONENT {
            return update;
        }
        match msg {
            MavMessage::ATTITUDE(a) => update.state = Some(self.state(a)),
            MavMessage::ATTITUDE_QUATERNION(q) => {
                self.quaternion = Some((q.time_boot_ms, [q.q1, q.q2, q.q3, q.q4]));
            }
            MavMessage::GLOBAL_POSITION_INT(p) => self.position = Some(position(p, now_ns)),
            MavMessage::LOCAL_POSITION_NED(l) => {
                self.local = Some(LocalPosition {
                    time_boot_ms: l.time_boot_ms,
                    pos_ned_m: [l.x, l.y, l.z],
                    vel_ned_mps: [l.vx, l.vy, l.vz],
                });
            }
            MavMessage::EKF_STATUS_REPORT(e) => {
                self.status.ekf_flags = e.flags.bits();
                self.status.ekf_healthy =
                    u8::from(e.flags.contains(EKF_REQUIRED) && !e.flags.intersects(EKF_FORBIDDEN));
            }
            MavMessage::GPS_RAW_INT(g) => {
                self.ellipsoid = ellipsoid(g);
                self.status.gps_fix = GpsFix::try_from(g.fix_type as u8)
                    .unwrap_or(GpsFix::NoGps)
                    .to_wire();
                self.status.satellites = if g.satellites_visible == u8::MAX {
                    0
                } else {
                    g.satellites_visible
                };
            }
            MavMessage::SYS_STATUS(s) => {
                if s.voltage_battery != u16::MAX {
                    self.status.battery_voltage_v = f32::from(s.voltage_battery) / 1000.0;
                    self.battery_from_sys_status = true;
                }
                self.status.battery_remaining_pct = s.battery_remaining.max(-1);
            }
            MavMessage::BATTERY_STATUS(b) if b.id == 0 => {
                if !self.battery_from_sys_status {
                    let cells: u32 = b
                        .voltages
                        .iter()
                        .filter(|&&mv| mv != u16::MAX)
                        .map(|&mv| u32::from(mv))
                        .sum();
                    if cells > 0 {
                        self.status.battery_voltage_v = cells as f32 / 1000.0;
                    }
                }
                self.status.battery_remaining_pct = b.battery_remaining.max(-1);
            }
            MavMessage::HOME_POSITION(h) => {
                self.status.home_valid = 1;
                self.status.home_lat_deg = f64::from(h.latitude) / 1e7;
                self.status.home_lon_deg = f64::from(h.longitude) / 1e7;
                self.status.home_alt_msl_m = h.altitude as f32 / 1000.0;
            }
            MavMessage::COMMAND_ACK(a) => {
                update.command_ack = Some((a.command as u32, a.result as u8));
            }
            _ => {}
        }
        update
    }

    fn heartbeat(&mut self, header: &MavHeader, hb: &HEARTBEAT_DATA, update: &mut Update) {
        if header.component_id != AUTOPILOT_COMPONENT
            || hb.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID
        {
            return; // a ground station, companion computer, gimbal, ...
        }
        if header.system_id != u32::from(self.vehicle_id) {
            if self.foreign.insert(header.system_id) {
                update.foreign_autopilot = Some(header.system_id.min(255) as u8);
            }
            return;
        }
        let ap = Autopilot {
            system_id: self.vehicle_id,
            autopilot: hb.autopilot as u8,
            vehicle_type: hb.mavtype as u8,
        };
        if self.autopilot.is_none() {
            update.identified = Some(ap);
        }
        self.autopilot = Some(ap);
        update.heartbeat = true;
        let armed = u8::from(
            hb.base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
        );
        update.armed_changed = armed != self.status.armed;
        let s = &mut self.status;
        s.armed = armed;
        s.custom_mode = hb.custom_mode;
        s.mode = if ap.autopilot == ARDUPILOT {
            FlightMode::from_copter_custom_mode(hb.custom_mode)
        } else {
            FlightMode::Other
        }
        .to_wire();
        s.system_status = hb.system_status as u8;
        s.autopilot = ap.autopilot;
        s.vehicle_type = ap.vehicle_type;
    }

    fn state(&self, a: &ATTITUDE_DATA) -> VehicleState {
        let q = match self.quaternion {
            Some((t, q)) if t.abs_diff(a.time_boot_ms) <= 100 => q,
            _ => {
                let q = UnitQuaternion::from_euler_angles(a.roll, a.pitch, a.yaw);
                [q.w, q.i, q.j, q.k]
            }
        };
        let yaw_heading = a.yaw.to_degrees().rem_euclid(360.0);
        let mut s = VehicleState {
            vehicle_id: self.vehicle_id,
            attitude_valid: 1,
            time_boot_ms: a.time_boot_ms,
            attitude_q: q,
            roll_rad: a.roll,
            pitch_rad: a.pitch,
            yaw_rad: a.yaw,
            body_rates_radps: [a.rollspeed, a.pitchspeed, a.yawspeed],
            heading_deg: yaw_heading,
            alt_ellipsoid_m: f32::NAN,
            geoid_undulation_m: f32::NAN,
            ..VehicleState::default()
        };
        if let Some(e) = self.ellipsoid {
            s.alt_ellipsoid_valid = 1;
            s.alt_ellipsoid_m = e.alt_m;
            s.geoid_undulation_m = e.undulation_m;
        }
        if let Some(p) = self.position {
            // Before the EKF has a position, ArduPilot reports 0/0: not a position.
            s.position_valid = u8::from(p.lat_deg != 0.0 || p.lon_deg != 0.0);
            s.lat_deg = p.lat_deg;
            s.lon_deg = p.lon_deg;
            s.alt_msl_m = p.alt_msl_m;
            s.alt_rel_m = p.alt_rel_m;
            s.vel_ned_mps = p.vel_ned_mps;
            s.heading_deg = p.heading_deg.unwrap_or(yaw_heading);
            s.position_stamp_ns = p.stamp_ns;
        }
        s
    }

    /// The status to publish: the fused fields plus link state and heartbeat age.
    pub fn status(&self, link_up: bool, heartbeat_age: Option<Duration>) -> VehicleStatus {
        VehicleStatus {
            link_up: u8::from(link_up),
            heartbeat_age_ms: heartbeat_age.map_or(u32::MAX, |a| {
                u32::try_from(a.as_millis()).unwrap_or(u32::MAX - 1)
            }),
            ..self.status
        }
    }
}

fn position(p: &GLOBAL_POSITION_INT_DATA, now_ns: u64) -> Position {
    Position {
        lat_deg: f64::from(p.lat) / 1e7,
        lon_deg: f64::from(p.lon) / 1e7,
        alt_msl_m: p.alt as f32 / 1000.0,
        alt_rel_m: p.relative_alt as f32 / 1000.0,
        vel_ned_mps: [
            f32::from(p.vx) / 100.0,
            f32::from(p.vy) / 100.0,
            f32::from(p.vz) / 100.0,
        ],
        heading_deg: (p.hdg != u16::MAX).then(|| f32::from(p.hdg) / 100.0),
        stamp_ns: now_ns,
    }
}

/// A link-state transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkChange {
    Up,
    Down,
}

/// Decides link up/down from autopilot heartbeats and the transport.
///
/// Up: a heartbeat of the identified autopilot arrived less than `timeout` ago on
/// the current connection. Down: none for `timeout`, or the transport closed.
#[derive(Debug, Clone)]
pub struct LinkMonitor {
    timeout: Duration,
    last_heartbeat: Option<Instant>,
    up: bool,
}

impl LinkMonitor {
    pub fn new(timeout: Duration) -> Self {
        LinkMonitor {
            timeout,
            last_heartbeat: None,
            up: false,
        }
    }

    pub fn is_up(&self) -> bool {
        self.up
    }

    pub fn last_heartbeat(&self) -> Option<Instant> {
        self.last_heartbeat
    }

    /// Age of the last heartbeat at `now`, `None` if there never was one.
    pub fn heartbeat_age(&self, now: Instant) -> Option<Duration> {
        self.last_heartbeat
            .map(|t| now.saturating_duration_since(t))
    }

    pub fn heartbeat(&mut self, now: Instant) -> Option<LinkChange> {
        self.last_heartbeat = Some(now);
        (!std::mem::replace(&mut self.up, true)).then_some(LinkChange::Up)
    }

    /// The transport closed: down at once, without waiting for the timeout.
    pub fn transport_lost(&mut self) -> Option<LinkChange> {
        std::mem::replace(&mut self.up, false).then_some(LinkChange::Down)
    }

    /// Down if the last heartbeat is `timeout` old at `now`.
    pub fn poll(&mut self, now: Instant) -> Option<LinkChange> {
        match self.deadline() {
            Some(d) if now >= d => self.transport_lost(),
            _ => None,
        }
    }

    /// When [`LinkMonitor::poll`] would next change something.
    pub fn deadline(&self) -> Option<Instant> {
        if !self.up {
            return None;
        }
        self.last_heartbeat.map(|t| t + self.timeout)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::*;

    fn from(sys: u32, comp: u8) -> MavHeader {
        MavHeader {
            system_id: sys,
            component_id: comp,
            sequence: 0,
        }
    }

    fn heartbeat(custom_mode: u32, armed: bool, autopilot: MavAutopilot) -> MavMessage {
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot,
            base_mode,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    fn attitude(t: u32, roll: f32, pitch: f32, yaw: f32) -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: t,
            roll,
            pitch,
            yaw,
            rollspeed: 0.1,
            pitchspeed: 0.2,
            yawspeed: 0.3,
        })
    }

    const AP: MavAutopilot = MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA;

    #[test]
    fn the_autopilot_is_the_first_component_1_heartbeat_of_our_system() {
        let mut t = Telemetry::new(1);
        // A ground station heartbeat (autopilot INVALID) and a gimbal are ignored.
        let gcs = heartbeat(0, false, MavAutopilot::MAV_AUTOPILOT_INVALID);
        assert_eq!(t.handle(&from(255, 190), &gcs, 0), Update::default());
        assert_eq!(t.handle(&from(1, 1), &gcs, 0), Update::default());
        assert_eq!(
            t.handle(&from(1, 154), &heartbeat(0, false, AP), 0),
            Update::default()
        );
        // Another vehicle: reported once, then ignored.
        let u = t.handle(&from(7, 1), &heartbeat(4, true, AP), 0);
        assert_eq!(u.foreign_autopilot, Some(7));
        assert!(!u.heartbeat);
        assert_eq!(
            t.handle(&from(7, 1), &heartbeat(4, true, AP), 0),
            Update::default()
        );
        assert_eq!(t.autopilot(), None);
        // Ours.
        let u = t.handle(&from(1, 1), &heartbeat(4, false, AP), 0);
        assert!(u.heartbeat);
        assert_eq!(
            u.identified,
            Some(Autopilot {
                system_id: 1,
                autopilot: AP as u8,
                vehicle_type: MavType::MAV_TYPE_QUADROTOR as u8
            })
        );
        assert!(!u.armed_changed);
        assert_eq!(t.flight_mode(), FlightMode::Guided);
        let u = t.handle(&from(1, 1), &heartbeat(4, true, AP), 0);
        assert_eq!(u.identified, None);
        assert!(u.armed_changed && t.is_armed());
        // Telemetry of other systems does not leak into ours.
        t.handle(&from(7, 1), &attitude(5, 1.0, 0.0, 0.0), 0);
        let s = t.status(true, Some(Duration::from_millis(250)));
        assert_eq!(s.custom_mode, 4);
        assert_eq!(s.flight_mode(), FlightMode::Guided);
        assert_eq!(s.armed, 1);
        assert_eq!(s.link_up, 1);
        assert_eq!(s.heartbeat_age_ms, 250);
        assert_eq!(s.system_status, MavState::MAV_STATE_STANDBY as u8);
        assert_eq!(t.status(false, None).heartbeat_age_ms, u32::MAX);
    }

    #[test]
    fn non_ardupilot_modes_are_not_normalised_as_copter_modes() {
        let mut t = Telemetry::new(1);
        t.handle(
            &from(1, 1),
            &heartbeat(4, false, MavAutopilot::MAV_AUTOPILOT_PX4),
            0,
        );
        let s = t.status(true, None);
        assert_eq!(s.custom_mode, 4);
        assert_eq!(s.flight_mode(), FlightMode::Other);
    }

    #[test]
    fn state_fuses_attitude_with_the_latest_global_position() {
        let mut t = Telemetry::new(1);
        let ap = from(1, 1);
        // Attitude before any position: attitude only, heading from yaw.
        let s = t
            .handle(
                &ap,
                &attitude(10, 0.0, 0.0, -std::f32::consts::FRAC_PI_2),
                0,
            )
            .state
            .unwrap();
        assert_eq!(s.attitude_valid, 1);
        assert_eq!(s.position_valid, 0);
        assert!((s.heading_deg - 270.0).abs() < 1e-3);
        // A zero position (EKF not ready) is not valid.
        let zero = MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA::default());
        t.handle(&ap, &zero, 5);
        let s = t
            .handle(&ap, &attitude(11, 0.0, 0.0, 0.0), 0)
            .state
            .unwrap();
        assert_eq!(s.position_valid, 0);
        let gpi = MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms: 20,
            lat: -353_632_610,
            lon: 1_491_652_300,
            alt: 594_000,
            relative_alt: 10_000,
            vx: 150,
            vy: -250,
            vz: -50,
            hdg: 35_300,
        });
        assert_eq!(t.handle(&ap, &gpi, 123_456), Update::default());
        let s = t
            .handle(&ap, &attitude(30, 0.1, -0.2, 0.3), 0)
            .state
            .unwrap();
        assert_eq!(s.vehicle_id, 1);
        assert_eq!(s.position_valid, 1);
        assert_eq!(s.time_boot_ms, 30);
        assert!((s.lat_deg + 35.363261).abs() < 1e-9);
        assert!((s.lon_deg - 149.16523).abs() < 1e-9);
        assert_eq!(s.alt_msl_m, 594.0);
        assert_eq!(s.alt_rel_m, 10.0);
        assert_eq!(s.vel_ned_mps, [1.5, -2.5, -0.5]);
        assert_eq!(s.heading_deg, 353.0);
        assert_eq!(s.position_stamp_ns, 123_456);
        assert_eq!((s.roll_rad, s.pitch_rad, s.yaw_rad), (0.1, -0.2, 0.3));
        assert_eq!(s.body_rates_radps, [0.1, 0.2, 0.3]);
        // The quaternion from Euler (ZYX, body → NED) turns body x into the heading.
        let [w, x, y, z] = s.attitude_q;
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let (r, p, yw) = q.euler_angles();
        assert!((r - 0.1).abs() < 1e-5 && (p + 0.2).abs() < 1e-5 && (yw - 0.3).abs() < 1e-5);
        let nose = q * nalgebra::Vector3::x();
        assert!(nose.y > 0.0, "positive yaw turns the nose east");
    }

    #[test]
    fn state_carries_the_ellipsoid_height_of_the_latest_gps_fix() {
        let mut t = Telemetry::new(1);
        let ap = from(1, 1);
        let gps = |fix_type, alt_ellipsoid| {
            MavMessage::GPS_RAW_INT(GPS_RAW_INT_DATA {
                fix_type,
                alt: 594_000,
                alt_ellipsoid,
                ..Default::default()
            })
        };
        let s = t.handle(&ap, &attitude(1, 0.0, 0.0, 0.0), 0).state.unwrap();
        assert_eq!(s.alt_ellipsoid_valid, 0);
        assert!(s.alt_ellipsoid_m.is_nan() && s.geoid_undulation_m.is_nan());
        t.handle(&ap, &gps(GpsFixType::GPS_FIX_TYPE_3D_FIX, 613_600), 0);
        let s = t.handle(&ap, &attitude(2, 0.0, 0.0, 0.0), 0).state.unwrap();
        assert_eq!(s.alt_ellipsoid_valid, 1);
        assert_eq!(s.alt_ellipsoid_m, 613.6);
        assert!((s.geoid_undulation_m - 19.6).abs() < 1e-4);
        // Not sent (0, as ArduPilot without an undulation and MAVLink 1 give) or
        // no 3D fix: unknown again.
        for (fix, alt) in [
            (GpsFixType::GPS_FIX_TYPE_RTK_FIXED, 0),
            (GpsFixType::GPS_FIX_TYPE_2D_FIX, 613_600),
        ] {
            t.handle(&ap, &gps(GpsFixType::GPS_FIX_TYPE_3D_FIX, 613_600), 0);
            t.handle(&ap, &gps(fix, alt), 0);
            let s = t.handle(&ap, &attitude(3, 0.0, 0.0, 0.0), 0).state.unwrap();
            assert_eq!(s.alt_ellipsoid_valid, 0, "{fix:?} {alt}");
            assert!(s.alt_ellipsoid_m.is_nan());
        }
    }

    #[test]
    fn an_attitude_quaternion_of_the_same_instant_is_used_as_is() {
        let mut t = Telemetry::new(1);
        let ap = from(1, 1);
        let q = MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
            time_boot_ms: 1000,
            q1: 0.5,
            q2: 0.5,
            q3: 0.5,
            q4: 0.5,
            ..Default::default()
        });
        t.handle(&ap, &q, 0);
        let s = t
            .handle(&ap, &attitude(1050, 0.0, 0.0, 0.0), 0)
            .state
            .unwrap();
        assert_eq!(s.attitude_q, [0.5; 4]);
        // A stale one is not.
        let s = t
            .handle(&ap, &attitude(5000, 0.0, 0.0, 0.0), 0)
            .state
            .unwrap();
        assert_eq!(s.attitude_q, [1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn status_collects_ekf_gps_battery_home_and_status_text() {
        let mut t = Telemetry::new(3);
        let ap = from(3, 1);
        let healthy = EKF_REQUIRED | EkfStatusFlags::EKF_POS_HORIZ_REL;
        t.handle(
            &ap,
            &MavMessage::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
                flags: healthy,
                ..Default::default()
            }),
            0,
        );
        assert_eq!(t.status(true, None).ekf_healthy, 1);
        assert_eq!(t.status(true, None).ekf_flags, healthy.bits());
        for bad in [
            healthy | EkfStatusFlags::EKF_CONST_POS_MODE,
            healthy | EkfStatusFlags::EKF_UNINITIALIZED,
            healthy - EkfStatusFlags::EKF_POS_VERT_ABS,
        ] {
            t.handle(
                &ap,
                &MavMessage::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
                    flags: bad,
                    ..Default::default()
                }),
                0,
            );
            assert_eq!(t.status(true, None).ekf_healthy, 0, "{bad:?}");
        }
        t.handle(
            &ap,
            &MavMessage::GPS_RAW_INT(GPS_RAW_INT_DATA {
                fix_type: GpsFixType::GPS_FIX_TYPE_RTK_FIXED,
                satellites_visible: 17,
                ..Default::default()
            }),
            0,
        );
        // BATTERY_STATUS cells until SYS_STATUS gives a pack voltage.
        let mut voltages = [u16::MAX; 10];
        voltages[..4].copy_from_slice(&[4000, 4000, 4000, 4000]);
        t.handle(
            &ap,
            &MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
                voltages,
                battery_remaining: 80,
                ..Default::default()
            }),
            0,
        );
        assert_eq!(t.status(true, None).battery_voltage_v, 16.0);
        t.handle(
            &ap,
            &MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                voltage_battery: 15_800,
                battery_remaining: 79,
                ..Default::default()
            }),
            0,
        );
        t.handle(
            &ap,
            &MavMessage::HOME_POSITION(HOME_POSITION_DATA {
                latitude: -353_632_610,
                longitude: 1_491_652_300,
                altitude: 584_000,
                ..Default::default()
            }),
            0,
        );
        let u = t.handle(
            &from(3, 1),
            &MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                severity: MavSeverity::MAV_SEVERITY_CRITICAL,
                text: "PreArm: EKF attitude is bad".into(),
                ..Default::default()
            }),
            0,
        );
        assert_eq!(
            u.status_text,
            Some((2, "PreArm: EKF attitude is bad".to_string()))
        );
        let s = t.status(true, None);
        assert_eq!(s.vehicle_id, 3);
        assert_eq!(s.gps_fix_type(), GpsFix::RtkFixed);
        assert_eq!(s.satellites, 17);
        assert_eq!(s.battery_voltage_v, 15.8);
        assert_eq!(s.battery_remaining_pct, 79);
        assert_eq!(s.home_valid, 1);
        assert!((s.home_lat_deg + 35.363261).abs() < 1e-9);
        assert_eq!(s.home_alt_msl_m, 584.0);
        assert_eq!(s.status_text.as_str(), "PreArm: EKF attitude is bad");
        assert_eq!(s.status_severity, 2);
        // Before any battery message the remaining charge is unknown.
        assert_eq!(
            Telemetry::new(1).status(true, None).battery_remaining_pct,
            -1
        );
    }

    #[test]
    fn command_acks_of_the_autopilot_are_reported() {
        let mut t = Telemetry::new(1);
        let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result: MavResult::MAV_RESULT_DENIED,
            ..Default::default()
        });
        assert_eq!(t.handle(&from(1, 1), &ack, 0).command_ack, Some((400, 2)));
        assert_eq!(t.handle(&from(2, 1), &ack, 0).command_ack, None);
        assert_eq!(t.handle(&from(1, 100), &ack, 0).command_ack, None);
    }

    #[test]
    fn the_link_goes_down_after_the_timeout_or_with_the_transport() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut l = LinkMonitor::new(Duration::from_secs(2));
        assert!(!l.is_up());
        assert_eq!(l.deadline(), None);
        assert_eq!(l.poll(ms(10_000)), None);
        assert_eq!(l.heartbeat(ms(0)), Some(LinkChange::Up));
        assert_eq!(l.heartbeat(ms(1000)), None);
        assert_eq!(l.deadline(), Some(ms(3000)));
        assert_eq!(l.poll(ms(2999)), None);
        assert_eq!(l.heartbeat_age(ms(2999)), Some(Duration::from_millis(1999)));
        assert_eq!(l.poll(ms(3000)), Some(LinkChange::Down));
        assert_eq!(l.poll(ms(4000)), None);
        assert_eq!(l.heartbeat(ms(5000)), Some(LinkChange::Up));
        assert_eq!(l.transport_lost(), Some(LinkChange::Down));
        assert_eq!(l.transport_lost(), None);
    }
}
