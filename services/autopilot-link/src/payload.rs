//! MAVLink gimbal and GoPro telemetry → [`PayloadState`]: pure fusion, no I/O, every
//! instant (`CLOCK_MONOTONIC` ns) passed in.
//!
//! | field | from |
//! |---|---|
//! | `gimbal_pitch/roll/yaw_deg`, `gimbal_valid`, `gimbal_stamp_ns` | GIMBAL_DEVICE_ATTITUDE_STATUS (gimbal protocol v2) |
//! | `gopro_status`, `gopro_capture_mode`, `gopro_recording`, `gopro_stamp_ns` | GOPRO_HEARTBEAT (the Solo gimbal's GoPro bridge) |
//!
//! Only messages of the vehicle's own system count. The gimbal attitude is taken
//! from the autopilot (component 1, ArduPilot's mount driver) or from a gimbal
//! component (154, 171..=175); once one is heard, another is ignored while the first
//! is valid, except that the autopilot always takes over (it reports the mount it
//! drives, a gimbal may be one it only routes). GOPRO_HEARTBEAT and
//! GOPRO_SET_RESPONSE are taken from any component of the system (the Solo gimbal
//! sends them as 154).
//!
//! The quaternion is converted to Euler angles in MAVLink's convention (yaw, then
//! pitch, then roll; pitch positive up, so the camera looking down is negative).
//! Pitch and roll are always relative to the horizon; yaw is relative to the nose
//! when the flags say vehicle frame and is turned into that by subtracting the
//! vehicle's heading when they say earth frame. With neither frame flag set MAVLink's
//! compatibility rule applies: `YAW_LOCK` means earth frame, else vehicle frame.
//!
//! [`Payload::due`] says when to publish: when something changed (validity, GoPro
//! fields, pitch or yaw by more than [`ANGLE_CHANGE_DEG`]), at least every
//! [`PERIOD_NS`], and when a source goes quiet ([`GIMBAL_VALID_NS`],
//! [`GOPRO_VALID_NS`]).

use mavlink::dialects::ardupilotmega::{
    GimbalDeviceFlags, GoproHeartbeatFlags, GoproRequestStatus, MavMessage,
};
use mavlink::MavHeader;
use nalgebra::{Quaternion, UnitQuaternion};
use skymesh_ipc_types::{GoProStatus, PayloadState};
use skymesh_runtime::angle::wrap_180_upper;

use crate::telemetry::AUTOPILOT_COMPONENT;

/// Publish at least this often, ns.
pub const PERIOD_NS: u64 = 1_000_000_000;
/// A gimbal attitude older than this is not valid, ns.
pub const GIMBAL_VALID_NS: u64 = 2_000_000_000;
/// No GOPRO_HEARTBEAT for this long → the GoPro is disconnected, ns.
pub const GOPRO_VALID_NS: u64 = 3_000_000_000;
/// A pitch or yaw change larger than this is published at once, degrees.
pub const ANGLE_CHANGE_DEG: f32 = 0.5;
/// `GOPRO_CAPTURE_MODE_UNKNOWN`: what `gopro_capture_mode` holds while no GoPro is heard.
pub const CAPTURE_MODE_UNKNOWN: u8 = 255;

/// Camera attitude, degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraAngles {
    /// Up positive, relative to the horizon.
    pub pitch_deg: f32,
    /// Right positive, relative to the horizon.
    pub roll_deg: f32,
    /// Relative to the vehicle's nose, clockwise positive, in (−180, 180].
    pub yaw_deg: f32,
}

/// Why a gimbal attitude could not be turned into [`CameraAngles`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AttitudeError {
    #[error("the gimbal quaternion is not a finite, non-zero quaternion")]
    BadQuaternion,
    #[error("the gimbal yaw is in the earth frame and the vehicle heading is unknown")]
    NoHeading,
}

/// Whether GIMBAL_DEVICE_ATTITUDE_STATUS `flags` put the yaw in the earth frame.
fn yaw_in_earth_frame(flags: GimbalDeviceFlags) -> bool {
    if flags.contains(GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME) {
        true
    } else if flags.contains(GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME) {
        false
    } else {
        // Neither frame flag: the pre-2022 meaning of YAW_LOCK (yaw relative to North).
        flags.contains(GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_LOCK)
    }
}

/// Converts a GIMBAL_DEVICE_ATTITUDE_STATUS quaternion (w, x, y, z) into camera
/// angles. `vehicle_yaw_deg` (the vehicle's heading, clockwise from North) is needed
/// only when the flags put the yaw in the earth frame.
pub fn camera_angles(
    q: [f32; 4],
    flags: GimbalDeviceFlags,
    vehicle_yaw_deg: Option<f32>,
) -> Result<CameraAngles, AttitudeError> {
    let [w, x, y, z] = q.map(f64::from);
    let quaternion = Quaternion::new(w, x, y, z);
    let norm = quaternion.norm();
    if !norm.is_finite() || norm < 1e-6 {
        return Err(AttitudeError::BadQuaternion);
    }
    // nalgebra's Euler angles are the ZYX (yaw, pitch, roll) sequence of the aerospace
    // convention: the same MAVLink's ATTITUDE uses.
    let (roll, pitch, yaw) = UnitQuaternion::from_quaternion(quaternion).euler_angles();
    let mut yaw_deg = yaw.to_degrees();
    if yaw_in_earth_frame(flags) {
        let heading = vehicle_yaw_deg
            .filter(|h| h.is_finite())
            .ok_or(AttitudeError::NoHeading)?;
        yaw_deg -= f64::from(heading);
    }
    Ok(CameraAngles {
        pitch_deg: pitch.to_degrees() as f32,
        roll_deg: roll.to_degrees() as f32,
        yaw_deg: wrap_180_upper(yaw_deg) as f32,
    })
}

/// A GOPRO_SET_RESPONSE from the vehicle's system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GoProResponse {
    /// The GOPRO_COMMAND answered.
    pub cmd_id: u8,
    /// `GOPRO_REQUEST_SUCCESS` (else `GOPRO_REQUEST_FAILED`).
    pub success: bool,
}

/// What one message meant for the payload, for the caller to act on.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct PayloadUpdate {
    /// A GOPRO_SET_RESPONSE: answers a GoPro request.
    pub gopro_response: Option<GoProResponse>,
    /// A gimbal attitude that could not be used.
    pub attitude_error: Option<AttitudeError>,
}

fn is_gimbal_component(component: u8) -> bool {
    component == 154 || (171..=175).contains(&component)
}

/// The payload fusion state of one vehicle.
#[derive(Debug)]
pub struct Payload {
    vehicle_id: u8,
    /// The fused state (header unset).
    current: PayloadState,
    /// Component whose gimbal attitude is used.
    gimbal_source: Option<u8>,
    /// A GoPro heartbeat was heard and has not expired yet.
    gopro_live: bool,
    last_published: Option<PayloadState>,
    last_published_ns: Option<u64>,
}

impl Payload {
    pub fn new(vehicle_id: u8) -> Self {
        Payload {
            vehicle_id,
            current: PayloadState {
                vehicle_id,
                gopro_status: GoProStatus::Disconnected.to_wire(),
                gopro_capture_mode: CAPTURE_MODE_UNKNOWN,
                ..PayloadState::default()
            },
            gimbal_source: None,
            gopro_live: false,
            last_published: None,
            last_published_ns: None,
        }
    }

    /// The fused state as it stands (validity as of the last [`Payload::due`]).
    pub fn current(&self) -> PayloadState {
        self.current
    }

    /// Fuses one message. `vehicle_yaw_deg` is the vehicle's latest heading (for a
    /// gimbal yaw in the earth frame); `now_ns` is `CLOCK_MONOTONIC`.
    pub fn handle(
        &mut self,
        header: &MavHeader,
        msg: &MavMessage,
        vehicle_yaw_deg: Option<f32>,
        now_ns: u64,
    ) -> PayloadUpdate {
        let mut update = PayloadUpdate::default();
        if header.system_id != u32::from(self.vehicle_id) {
            return update;
        }
        match msg {
            MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(g) => {
                if !self.accepts_gimbal(header.component_id, now_ns) {
                    return update;
                }
                match camera_angles(g.q, g.flags, vehicle_yaw_deg) {
                    Ok(a) => {
                        let s = &mut self.current;
                        s.gimbal_valid = 1;
                        s.gimbal_pitch_deg = a.pitch_deg;
                        s.gimbal_roll_deg = a.roll_deg;
                        s.gimbal_yaw_deg = a.yaw_deg;
                        s.gimbal_stamp_ns = now_ns;
                        self.gimbal_source = Some(header.component_id);
                    }
                    Err(e) => update.attitude_error = Some(e),
                }
            }
            MavMessage::GOPRO_HEARTBEAT(h) => {
                let s = &mut self.current;
                // GOPRO_HEARTBEAT_STATUS and GoProStatus share their numbering.
                s.gopro_status = GoProStatus::try_from(h.status as u8)
                    .unwrap_or(GoProStatus::Fault)
                    .to_wire();
                s.gopro_capture_mode = h.capture_mode as u8;
                s.gopro_recording =
                    u8::from(h.flags.contains(GoproHeartbeatFlags::GOPRO_FLAG_RECORDING));
                s.gopro_stamp_ns = now_ns;
                self.gopro_live = true;
            }
            MavMessage::GOPRO_SET_RESPONSE(r) => {
                update.gopro_response = Some(GoProResponse {
                    cmd_id: r.cmd_id as u8,
                    success: r.status == GoproRequestStatus::GOPRO_REQUEST_SUCCESS,
                });
            }
            _ => {}
        }
        update
    }

    fn accepts_gimbal(&self, component: u8, now_ns: u64) -> bool {
        if component != AUTOPILOT_COMPONENT && !is_gimbal_component(component) {
            return false;
        }
        let source_valid = self.current.gimbal_valid == 1
            && now_ns.saturating_sub(self.current.gimbal_stamp_ns) < GIMBAL_VALID_NS;
        match self.gimbal_source {
            Some(source) if source_valid => component == source || component == AUTOPILOT_COMPONENT,
            _ => true,
        }
    }

    /// Applies the validity timeouts at `now_ns`.
    fn expire(&mut self, now_ns: u64) {
        let s = &mut self.current;
        if s.gimbal_valid == 1 && now_ns.saturating_sub(s.gimbal_stamp_ns) >= GIMBAL_VALID_NS {
            s.gimbal_valid = 0;
        }
        if self.gopro_live && now_ns.saturating_sub(s.gopro_stamp_ns) >= GOPRO_VALID_NS {
            self.gopro_live = false;
            s.gopro_status = GoProStatus::Disconnected.to_wire();
            s.gopro_capture_mode = CAPTURE_MODE_UNKNOWN;
            s.gopro_recording = 0;
        }
    }

    /// The sample to publish at `now_ns`, if one is due (changed, periodic, or a
    /// source went quiet). Records it as published.
    pub fn due(&mut self, now_ns: u64) -> Option<PayloadState> {
        self.expire(now_ns);
        let periodic = self
            .last_published_ns
            .is_none_or(|t| now_ns.saturating_sub(t) >= PERIOD_NS);
        let changed = self
            .last_published
            .is_none_or(|last| differs(&last, &self.current));
        if !(periodic || changed) {
            return None;
        }
        self.last_published = Some(self.current);
        self.last_published_ns = Some(now_ns);
        Some(self.current)
    }

    /// When [`Payload::due`] next has something to do without a message, ns.
    pub fn next_deadline_ns(&self) -> u64 {
        let s = &self.current;
        [
            Some(self.last_published_ns.map_or(0, |t| t + PERIOD_NS)),
            (s.gimbal_valid == 1).then(|| s.gimbal_stamp_ns + GIMBAL_VALID_NS),
            self.gopro_live.then(|| s.gopro_stamp_ns + GOPRO_VALID_NS),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(0)
    }
}

/// A change worth publishing at once.
fn differs(last: &PayloadState, now: &PayloadState) -> bool {
    let moved =
        |a: f32, b: f32| wrap_180_upper(f64::from(a - b)).abs() > f64::from(ANGLE_CHANGE_DEG);
    last.gimbal_valid != now.gimbal_valid
        || last.gopro_status != now.gopro_status
        || last.gopro_capture_mode != now.gopro_capture_mode
        || last.gopro_recording != now.gopro_recording
        || (now.gimbal_valid == 1
            && (moved(last.gimbal_pitch_deg, now.gimbal_pitch_deg)
                || moved(last.gimbal_yaw_deg, now.gimbal_yaw_deg)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega::{
        GimbalDeviceErrorFlags, GoproCaptureMode, GoproCommand, GoproHeartbeatStatus,
        GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, GOPRO_HEARTBEAT_DATA, GOPRO_SET_RESPONSE_DATA,
    };

    const MS: u64 = 1_000_000;
    const S: u64 = 1000 * MS;
    const VEHICLE_FRAME: GimbalDeviceFlags =
        GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME;
    const EARTH_FRAME: GimbalDeviceFlags =
        GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME;

    /// The quaternion of yaw, then pitch, then roll (degrees), written out by hand
    /// (not through nalgebra, which the conversion uses).
    fn q_of(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> [f32; 4] {
        let (r, p, y) = (
            roll_deg.to_radians() / 2.0,
            pitch_deg.to_radians() / 2.0,
            yaw_deg.to_radians() / 2.0,
        );
        let (cr, sr, cp, sp, cy, sy) = (r.cos(), r.sin(), p.cos(), p.sin(), y.cos(), y.sin());
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
        .map(|v| v as f32)
    }

    fn close(a: CameraAngles, pitch: f32, roll: f32, yaw: f32) -> bool {
        (a.pitch_deg - pitch).abs() < 0.01
            && (a.roll_deg - roll).abs() < 0.01
            && (a.yaw_deg - yaw).abs() < 0.01
    }

    #[test]
    fn quaternions_convert_to_camera_angles_at_known_attitudes() {
        let level = camera_angles([1.0, 0.0, 0.0, 0.0], VEHICLE_FRAME, None).unwrap();
        assert!(close(level, 0.0, 0.0, 0.0), "{level:?}");
        // 30° down: a rotation of −30° about the pitch (y) axis: w = cos 15°, y = −sin 15°.
        let h = 15f32.to_radians();
        let down = camera_angles([h.cos(), 0.0, -h.sin(), 0.0], VEHICLE_FRAME, None).unwrap();
        assert!(close(down, -30.0, 0.0, 0.0), "{down:?}");
        for (roll, pitch, yaw) in [
            (0.0, -45.0, 0.0),
            (0.0, -89.0, 0.0),
            (0.0, 20.0, 0.0),
            (0.0, 0.0, 90.0),
            (0.0, 0.0, -135.0),
            (10.0, -30.0, 45.0),
            (-5.0, -60.0, 170.0),
        ] {
            let a = camera_angles(q_of(roll, pitch, yaw), VEHICLE_FRAME, None).unwrap();
            assert!(
                close(a, pitch as f32, roll as f32, yaw as f32),
                "roll {roll} pitch {pitch} yaw {yaw}: {a:?}"
            );
        }
        // A camera looking down points its optical axis (x) below the horizon (NED z > 0).
        let q = q_of(0.0, -30.0, 0.0);
        let axis = UnitQuaternion::from_quaternion(Quaternion::new(
            f64::from(q[0]),
            f64::from(q[1]),
            f64::from(q[2]),
            f64::from(q[3]),
        )) * nalgebra::Vector3::x();
        assert!(axis.z > 0.0, "pitch negative = down: {axis:?}");
        // Non-unit quaternions are normalised; zero and NaN are refused.
        let scaled = q_of(0.0, -30.0, 20.0).map(|v| v * 2.0);
        assert!(close(
            camera_angles(scaled, VEHICLE_FRAME, None).unwrap(),
            -30.0,
            0.0,
            20.0
        ));
        for bad in [
            [0.0; 4],
            [f32::NAN, 0.0, 0.0, 0.0],
            [f32::INFINITY, 0.0, 0.0, 1.0],
        ] {
            assert_eq!(
                camera_angles(bad, VEHICLE_FRAME, None),
                Err(AttitudeError::BadQuaternion)
            );
        }
    }

    #[test]
    fn an_earth_frame_yaw_is_made_relative_to_the_nose() {
        // Camera looks at 100° (east-south-east), vehicle heads 30°: 70° right of the nose.
        let q = q_of(0.0, -20.0, 100.0);
        let a = camera_angles(q, EARTH_FRAME, Some(30.0)).unwrap();
        assert!(close(a, -20.0, 0.0, 70.0), "{a:?}");
        // Wrapped into (−180, 180]: camera at 10°, vehicle at 350° → 20°; and the reverse.
        let a = camera_angles(q_of(0.0, 0.0, 10.0), EARTH_FRAME, Some(350.0)).unwrap();
        assert!((a.yaw_deg - 20.0).abs() < 0.01, "{a:?}");
        let a = camera_angles(q_of(0.0, 0.0, 350.0), EARTH_FRAME, Some(10.0)).unwrap();
        assert!((a.yaw_deg + 20.0).abs() < 0.01, "{a:?}");
        assert_eq!(
            camera_angles(q, EARTH_FRAME, None),
            Err(AttitudeError::NoHeading)
        );
        // Without frame flags, YAW_LOCK means earth frame (MAVLink's compatibility rule).
        let lock = GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_LOCK;
        let a = camera_angles(q, lock, Some(30.0)).unwrap();
        assert!((a.yaw_deg - 70.0).abs() < 0.01, "{a:?}");
        let a = camera_angles(q, GimbalDeviceFlags::empty(), Some(30.0)).unwrap();
        assert!((a.yaw_deg - 100.0).abs() < 0.01, "vehicle frame: {a:?}");
        // The vehicle frame flag wins over YAW_LOCK.
        let a = camera_angles(q, lock | VEHICLE_FRAME, Some(30.0)).unwrap();
        assert!((a.yaw_deg - 100.0).abs() < 0.01, "{a:?}");
    }

    fn from(sys: u32, comp: u8) -> MavHeader {
        MavHeader {
            system_id: sys,
            component_id: comp,
            sequence: 0,
        }
    }

    fn attitude(pitch_deg: f64, yaw_deg: f64) -> MavMessage {
        MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
            q: q_of(0.0, pitch_deg, yaw_deg),
            flags: VEHICLE_FRAME,
            failure_flags: GimbalDeviceErrorFlags::empty(),
            ..Default::default()
        })
    }

    fn gopro(mode: GoproCaptureMode, recording: bool) -> MavMessage {
        MavMessage::GOPRO_HEARTBEAT(GOPRO_HEARTBEAT_DATA {
            status: GoproHeartbeatStatus::GOPRO_HEARTBEAT_STATUS_CONNECTED,
            capture_mode: mode,
            flags: if recording {
                GoproHeartbeatFlags::GOPRO_FLAG_RECORDING
            } else {
                GoproHeartbeatFlags::empty()
            },
        })
    }

    #[test]
    fn nothing_heard_is_published_as_invalid_at_1_hz() {
        let mut p = Payload::new(3);
        assert_eq!(p.next_deadline_ns(), 0, "the first sample is due at once");
        let s = p.due(10 * S).unwrap();
        assert_eq!(s.vehicle_id, 3);
        assert!(!s.is_gimbal_valid());
        assert_eq!(s.gopro_status(), GoProStatus::Disconnected);
        assert_eq!(s.gopro_capture_mode, CAPTURE_MODE_UNKNOWN);
        assert_eq!((s.gimbal_stamp_ns, s.gopro_stamp_ns), (0, 0));
        assert_eq!(p.due(10 * S + 999 * MS), None);
        assert_eq!(p.next_deadline_ns(), 11 * S);
        assert!(p.due(11 * S).is_some());
    }

    #[test]
    fn gimbal_attitude_is_published_on_change_and_expires() {
        let mut p = Payload::new(1);
        p.due(0);
        let gimbal = from(1, AUTOPILOT_COMPONENT);
        assert_eq!(
            p.handle(&gimbal, &attitude(-30.0, 10.0), None, S),
            PayloadUpdate::default()
        );
        let s = p.due(S).expect("valid now: a change");
        assert!(s.is_gimbal_valid());
        assert!((s.gimbal_pitch_deg + 30.0).abs() < 0.01);
        assert!((s.gimbal_yaw_deg - 10.0).abs() < 0.01);
        assert_eq!(s.gimbal_stamp_ns, S);
        // Small moves wait for the period; a pitch or yaw change above 0.5° does not.
        p.handle(&gimbal, &attitude(-30.3, 10.3), None, S + 100 * MS);
        assert_eq!(p.due(S + 100 * MS), None);
        p.handle(&gimbal, &attitude(-30.6, 10.3), None, S + 200 * MS);
        let s = p.due(S + 200 * MS).expect("pitch moved 0.6°");
        assert!((s.gimbal_pitch_deg + 30.6).abs() < 0.01);
        p.handle(&gimbal, &attitude(-30.6, 11.0), None, S + 300 * MS);
        assert!(p.due(S + 300 * MS).is_some(), "yaw moved 0.7°");
        // Yaw across ±180 is a small move.
        p.handle(&gimbal, &attitude(-30.6, 179.9), None, S + 400 * MS);
        assert!(p.due(S + 400 * MS).is_some());
        p.handle(&gimbal, &attitude(-30.6, -179.9), None, S + 500 * MS);
        assert_eq!(p.due(S + 500 * MS), None, "0.2° across the seam");
        // Quiet: valid until 2 s after the last attitude, then published invalid once.
        assert_eq!(p.next_deadline_ns(), S + 1400 * MS, "the period first");
        assert!(p.due(S + 1400 * MS).is_some(), "periodic");
        assert!(p.due(S + 2400 * MS).is_some(), "periodic");
        assert_eq!(
            p.next_deadline_ns(),
            S + 500 * MS + GIMBAL_VALID_NS,
            "then the expiry"
        );
        assert_eq!(p.due(S + 2499 * MS), None);
        let s = p.due(S + 2500 * MS).expect("validity dropped");
        assert!(!s.is_gimbal_valid());
        assert_eq!(s.gimbal_stamp_ns, S + 500 * MS, "the last attitude's time");
        assert_eq!(p.due(S + 2600 * MS), None);
        assert_eq!(
            p.next_deadline_ns(),
            S + 3500 * MS,
            "only the period is left"
        );
        assert!(!p.current().is_gimbal_valid());
    }

    #[test]
    fn gimbal_sources_other_systems_and_unusable_attitudes() {
        let mut p = Payload::new(1);
        // Another vehicle's gimbal, or a component that is no gimbal: ignored.
        p.handle(&from(2, 1), &attitude(-10.0, 0.0), None, S);
        p.handle(&from(1, 191), &attitude(-10.0, 0.0), None, S);
        assert!(!p.current().is_gimbal_valid());
        // A gimbal component is used until the autopilot reports.
        p.handle(&from(1, 154), &attitude(-10.0, 0.0), None, S);
        assert!((p.current().gimbal_pitch_deg + 10.0).abs() < 0.01);
        p.handle(&from(1, 171), &attitude(-20.0, 0.0), None, S);
        assert!(
            (p.current().gimbal_pitch_deg + 10.0).abs() < 0.01,
            "second gimbal ignored"
        );
        p.handle(&from(1, 1), &attitude(-40.0, 0.0), None, S);
        assert!((p.current().gimbal_pitch_deg + 40.0).abs() < 0.01);
        p.handle(&from(1, 154), &attitude(-10.0, 0.0), None, S + MS);
        assert!(
            (p.current().gimbal_pitch_deg + 40.0).abs() < 0.01,
            "autopilot wins"
        );
        // ... until the autopilot's attitude is no longer valid.
        p.handle(&from(1, 154), &attitude(-10.0, 0.0), None, 3 * S + MS);
        assert!((p.current().gimbal_pitch_deg + 10.0).abs() < 0.01);
        // Earth frame without a heading: reported, state unchanged.
        let earth = MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(GIMBAL_DEVICE_ATTITUDE_STATUS_DATA {
            q: q_of(0.0, -50.0, 0.0),
            flags: EARTH_FRAME,
            ..Default::default()
        });
        let u = p.handle(&from(1, 154), &earth, None, 3 * S + 2 * MS);
        assert_eq!(u.attitude_error, Some(AttitudeError::NoHeading));
        assert!((p.current().gimbal_pitch_deg + 10.0).abs() < 0.01);
        p.handle(&from(1, 154), &earth, Some(0.0), 3 * S + 3 * MS);
        assert!((p.current().gimbal_pitch_deg + 50.0).abs() < 0.01);
    }

    #[test]
    fn gopro_heartbeats_set_status_mode_and_recording_and_expire() {
        let mut p = Payload::new(1);
        p.due(0);
        let gimbal = from(1, 154);
        p.handle(
            &gimbal,
            &gopro(GoproCaptureMode::GOPRO_CAPTURE_MODE_VIDEO, false),
            None,
            S,
        );
        let s = p.due(S).expect("connected");
        assert_eq!(s.gopro_status(), GoProStatus::Connected);
        assert_eq!((s.gopro_capture_mode, s.gopro_recording), (0, 0));
        assert_eq!(s.gopro_stamp_ns, S);
        p.handle(
            &gimbal,
            &gopro(GoproCaptureMode::GOPRO_CAPTURE_MODE_VIDEO, true),
            None,
            2 * S,
        );
        assert_eq!(p.due(2 * S).expect("recording").gopro_recording, 1);
        p.handle(
            &gimbal,
            &gopro(GoproCaptureMode::GOPRO_CAPTURE_MODE_PHOTO, false),
            None,
            3 * S,
        );
        let s = p.due(3 * S).expect("photo mode");
        assert_eq!((s.gopro_capture_mode, s.gopro_recording), (1, 0));
        // Same again: only the period publishes.
        p.handle(
            &gimbal,
            &gopro(GoproCaptureMode::GOPRO_CAPTURE_MODE_PHOTO, false),
            None,
            3 * S + 500 * MS,
        );
        assert_eq!(p.due(3 * S + 500 * MS), None);
        assert_eq!(p.next_deadline_ns(), 4 * S);
        for t in [4, 5, 6] {
            assert!(p.due(t * S).is_some(), "periodic at {t} s");
        }
        assert_eq!(p.next_deadline_ns(), 3 * S + 500 * MS + GOPRO_VALID_NS);
        assert_eq!(p.due(6 * S + 499 * MS), None);
        let s = p.due(6 * S + 500 * MS).expect("no heartbeat for 3 s");
        assert_eq!(s.gopro_status(), GoProStatus::Disconnected);
        assert_eq!(
            (s.gopro_capture_mode, s.gopro_recording),
            (CAPTURE_MODE_UNKNOWN, 0)
        );
        assert_eq!(s.gopro_stamp_ns, 3 * S + 500 * MS);
    }

    #[test]
    fn gopro_responses_of_our_system_are_reported() {
        let mut p = Payload::new(1);
        let response = |status| {
            MavMessage::GOPRO_SET_RESPONSE(GOPRO_SET_RESPONSE_DATA {
                cmd_id: GoproCommand::GOPRO_COMMAND_CAPTURE_MODE,
                status,
            })
        };
        let ok = response(GoproRequestStatus::GOPRO_REQUEST_SUCCESS);
        assert_eq!(
            p.handle(&from(1, 154), &ok, None, S).gopro_response,
            Some(GoProResponse {
                cmd_id: 1,
                success: true
            })
        );
        let failed = response(GoproRequestStatus::GOPRO_REQUEST_FAILED);
        assert_eq!(
            p.handle(&from(1, 1), &failed, None, S).gopro_response,
            Some(GoProResponse {
                cmd_id: 1,
                success: false
            })
        );
        assert_eq!(p.handle(&from(9, 154), &ok, None, S).gopro_response, None);
    }
}
