//! COMMAND_LONG / COMMAND_INT: one normalised [`Cmd`], executed against the
//! vehicle, answered with the MAV_RESULT ArduCopter gives.

// DO_SET_ROI, DO_MOUNT_CONTROL, GET_HOME_POSITION, REQUEST_AUTOPILOT_CAPABILITIES
// and the *_INT frames are deprecated in MAVLink; ArduPilot still honours them.
#![allow(deprecated)]

use mavlink::dialects::ardupilotmega::{
    MavCmd, MavFrame, MavModeFlag, MavResult, MavSeverity, AUTOPILOT_VERSION_DATA,
    COMMAND_INT_DATA, COMMAND_LONG_DATA, HOME_POSITION_DATA,
};
use mavlink::MessageData;
use nalgebra::Vector3;
use tracing::{debug, info, warn};

use super::setpoint::global_to_ned;
use super::{actuators, camera, gimbal};
use super::{set_mode, Outgoing, Response, StreamRequest};
use crate::model::{FlightMode, SpeedKind, Vehicle};
use crate::streams::IntervalRequest;
use crate::telemetry;

/// COMPONENT_ARM_DISARM param2 that skips the checks (ArduPilot's magic value).
const FORCE_MAGIC: f32 = 21196.0;

/// MAV_DO_REPOSITION_FLAGS_CHANGE_MODE.
const REPOSITION_CHANGE_MODE: i32 = 1;

/// A command from either COMMAND_LONG or COMMAND_INT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cmd {
    /// The command.
    pub command: MavCmd,
    /// param1..param4.
    pub p: [f32; 4],
    /// param5 (COMMAND_INT: `x` as sent, degrees × 1e7 for locations).
    pub p5: f64,
    /// param6 (COMMAND_INT: `y` as sent).
    pub p6: f64,
    /// param7 (COMMAND_INT: `z`).
    pub p7: f32,
    /// COMMAND_INT's frame; `None` for COMMAND_LONG.
    pub frame: Option<MavFrame>,
}

impl Cmd {
    /// From COMMAND_LONG.
    pub fn from_long(d: &COMMAND_LONG_DATA) -> Self {
        Self {
            command: d.command,
            p: [d.param1, d.param2, d.param3, d.param4],
            p5: f64::from(d.param5),
            p6: f64::from(d.param6),
            p7: d.param7,
            frame: None,
        }
    }

    /// From COMMAND_INT.
    pub fn from_int(d: &COMMAND_INT_DATA) -> Self {
        Self {
            command: d.command,
            p: [d.param1, d.param2, d.param3, d.param4],
            p5: f64::from(d.x),
            p6: f64::from(d.y),
            p7: d.z,
            frame: Some(d.frame),
        }
    }

    /// A location argument: latitude and longitude in degrees, altitude, and its
    /// frame. COMMAND_LONG has no frame field; ArduPilot reads it in `long_frame`.
    fn location(&self, long_frame: MavFrame) -> (f64, f64, f64, MavFrame) {
        match self.frame {
            Some(frame) => (self.p5 / 1e7, self.p6 / 1e7, f64::from(self.p7), frame),
            None => (self.p5, self.p6, f64::from(self.p7), long_frame),
        }
    }

    /// The location as local NED; zero latitude and longitude mean "here"
    /// (ArduPilot's `Location::sanitize`), as does a non-finite altitude.
    fn target_ned(&self, v: &Vehicle, long_frame: MavFrame) -> Option<Vector3<f64>> {
        let (lat, lon, alt, frame) = self.location(long_frame);
        let here = v.position_geo();
        let (lat, lon) = if lat == 0.0 && lon == 0.0 {
            (here.lat_deg, here.lon_deg)
        } else {
            (lat, lon)
        };
        let mut ned = global_to_ned(v, lat, lon, alt, frame)?;
        if !alt.is_finite() {
            ned.z = v.position_ned().z;
        }
        Some(ned)
    }
}

/// Execute `cmd`, pushing the COMMAND_ACK (and any requested message) onto `resp`.
pub(super) fn execute(v: &mut Vehicle, system_id: u8, cmd: &Cmd, resp: &mut Response) {
    let mut extra = None;
    let result = run(v, system_id, cmd, resp, &mut extra);
    match result {
        MavResult::MAV_RESULT_ACCEPTED => debug!(command = ?cmd.command, "command accepted"),
        MavResult::MAV_RESULT_UNSUPPORTED => {
            info!(command = ?cmd.command, "command not simulated; unsupported")
        }
        other => info!(command = ?cmd.command, result = ?other, "command refused"),
    }
    resp.replies.push(Outgoing::Message(telemetry::command_ack(
        cmd.command,
        result,
    )));
    resp.ack = Some(result);
    // ArduPilot sends the ACK first, then the requested message.
    if let Some(out) = extra {
        resp.replies.push(out);
    }
}

fn run(
    v: &mut Vehicle,
    system_id: u8,
    cmd: &Cmd,
    resp: &mut Response,
    extra: &mut Option<Outgoing>,
) -> MavResult {
    use MavResult::*;
    let [p1, p2, p3, p4] = cmd.p;
    match cmd.command {
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => arm_disarm(v, p1, p2),
        MavCmd::MAV_CMD_DO_SET_MODE => {
            set_mode(v, MavModeFlag::from_bits_truncate(p1 as u8), p2 as u32)
        }
        MavCmd::MAV_CMD_NAV_TAKEOFF => match v.takeoff(f64::from(cmd.p7)) {
            Ok(()) => MAV_RESULT_ACCEPTED,
            Err(why) => {
                info!(?why, "takeoff refused");
                MAV_RESULT_FAILED
            }
        },
        MavCmd::MAV_CMD_NAV_LAND => mode_result(v.set_mode(FlightMode::Land)),
        MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH => mode_result(v.set_mode(FlightMode::Rtl)),
        MavCmd::MAV_CMD_DO_CHANGE_SPEED => {
            if p2 > 0.0 && p2.is_finite() {
                let kind = match p1 as i32 {
                    2 => SpeedKind::Climb,
                    3 => SpeedKind::Descent,
                    _ => SpeedKind::Horizontal,
                };
                v.set_speed(kind, f64::from(p2));
                MAV_RESULT_ACCEPTED
            } else {
                MAV_RESULT_FAILED
            }
        }
        MavCmd::MAV_CMD_CONDITION_YAW => {
            if (0.0..=360.0).contains(&p1) && (p4 == 0.0 || p4 == 1.0) {
                let direction = if p3 < 0.0 {
                    -1
                } else if p3 > 0.0 {
                    1
                } else {
                    0
                };
                v.condition_yaw(f64::from(p1), f64::from(p2), direction, p4 == 1.0);
                MAV_RESULT_ACCEPTED
            } else {
                MAV_RESULT_FAILED
            }
        }
        MavCmd::MAV_CMD_DO_SET_ROI_LOCATION | MavCmd::MAV_CMD_DO_SET_ROI => {
            let (lat, lon, _, _) = cmd.location(MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT);
            if lat == 0.0 && lon == 0.0 {
                // A zero location clears the ROI (ArduPilot).
                v.set_roi(None);
                return MAV_RESULT_ACCEPTED;
            }
            match cmd.target_ned(v, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT) {
                Some(roi) => {
                    v.set_roi(Some(roi));
                    MAV_RESULT_ACCEPTED
                }
                None => MAV_RESULT_DENIED,
            }
        }
        MavCmd::MAV_CMD_DO_SET_ROI_NONE => {
            v.set_roi(None);
            MAV_RESULT_ACCEPTED
        }
        MavCmd::MAV_CMD_DO_SET_SERVO => actuators::set_servo(v, p1, p2),
        MavCmd::MAV_CMD_DO_MOTOR_TEST => actuators::motor_test(v, cmd),
        MavCmd::MAV_CMD_SET_CAMERA_ZOOM => actuators::camera_zoom(v, cmd),
        MavCmd::MAV_CMD_DO_REPOSITION => reposition(v, cmd),
        MavCmd::MAV_CMD_DO_SET_HOME => set_home(v, cmd),
        MavCmd::MAV_CMD_DO_MOUNT_CONTROL => gimbal::mount_control(v, cmd),
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW => gimbal::manager_pitchyaw(v, cmd),
        MavCmd::MAV_CMD_IMAGE_START_CAPTURE => camera::start_capture(v, cmd),
        MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE => camera::stop_capture(v, cmd),
        MavCmd::MAV_CMD_SET_CAMERA_MODE => camera::set_mode(v, cmd),
        MavCmd::MAV_CMD_SET_CAMERA_FOCUS => camera::focus(v, cmd),
        MavCmd::MAV_CMD_VIDEO_START_CAPTURE => {
            let payload = v.payload_mut();
            payload.video_recording = true;
            payload.video_starts += 1;
            MAV_RESULT_ACCEPTED
        }
        MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE => {
            v.payload_mut().video_recording = false;
            MAV_RESULT_ACCEPTED
        }
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
            let id = p1 as u32;
            if !(p1 >= 0.0 && telemetry::PRODUCIBLE.contains(&id)) {
                v.say(
                    MavSeverity::MAV_SEVERITY_INFO,
                    &format!("No ap_message for mavlink id ({id})"),
                );
                return MAV_RESULT_DENIED;
            }
            match IntervalRequest::from_param(p2) {
                Some(request) => {
                    resp.streams.push(StreamRequest::Interval { id, request });
                    MAV_RESULT_ACCEPTED
                }
                None => MAV_RESULT_DENIED,
            }
        }
        MavCmd::MAV_CMD_REQUEST_MESSAGE => request_message(v, system_id, p1, extra),
        MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
            let id = AUTOPILOT_VERSION_DATA::ID as f32;
            request_message(v, system_id, id, extra)
        }
        MavCmd::MAV_CMD_GET_HOME_POSITION => {
            let id = HOME_POSITION_DATA::ID as f32;
            request_message(v, system_id, id, extra)
        }
        other => {
            warn!(command = ?other, "command not simulated");
            MAV_RESULT_UNSUPPORTED
        }
    }
}

fn arm_disarm(v: &mut Vehicle, p1: f32, p2: f32) -> MavResult {
    use MavResult::*;
    let force = p2 == FORCE_MAGIC;
    if p1 == 1.0 {
        match v.arm(force) {
            Ok(()) => MAV_RESULT_ACCEPTED,
            // ArduCopter itself answers FAILED for every refusal; the simulator
            // separates "retry later" from "not in this state" so clients can
            // tell them apart without parsing STATUSTEXT.
            Err(why) if why.is_temporary() => MAV_RESULT_TEMPORARILY_REJECTED,
            Err(_) => MAV_RESULT_DENIED,
        }
    } else if p1 == 0.0 {
        match v.disarm(force) {
            Ok(()) => MAV_RESULT_ACCEPTED,
            Err(_) => MAV_RESULT_FAILED,
        }
    } else {
        MAV_RESULT_UNSUPPORTED
    }
}

fn mode_result<E>(r: Result<(), E>) -> MavResult {
    match r {
        Ok(()) => MavResult::MAV_RESULT_ACCEPTED,
        Err(_) => MavResult::MAV_RESULT_FAILED,
    }
}

/// MAV_CMD_DO_SET_HOME (COMMAND_INT or COMMAND_LONG), as ArduPilot's
/// `handle_command_do_set_home`: param1 = 1, or latitude and longitude both 0, is
/// "here" (the current position, altitude included); otherwise the location, in
/// COMMAND_INT's frame (COMMAND_LONG: `GLOBAL`, altitude above MSL). An impossible
/// location or a non-global frame is DENIED; far from the EKF origin FAILED. Without
/// an EKF position the simulator answers TEMPORARILY_REJECTED (ArduCopter says
/// FAILED; the simulator tells "retry later" apart, as for arming). Accepted: home
/// moves and is locked, and HOME_POSITION goes to every link at once (the engine
/// broadcasts the model's `HomeChanged`).
fn set_home(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    use MavResult::*;
    let (lat, lon, _, _) = cmd.location(MavFrame::MAV_FRAME_GLOBAL);
    let home = if cmd.p[0] == 1.0 || (lat == 0.0 && lon == 0.0) {
        v.position_ned()
    } else {
        match cmd.target_ned(v, MavFrame::MAV_FRAME_GLOBAL) {
            Some(ned) => ned,
            None => return MAV_RESULT_DENIED,
        }
    };
    match v.set_home(home) {
        Ok(()) => {
            if let Some(h) = v.home_geo() {
                info!(
                    lat = h.lat_deg,
                    lon = h.lon_deg,
                    alt_msl = h.alt_msl_m,
                    "home set"
                );
            }
            MAV_RESULT_ACCEPTED
        }
        Err(why) if why.is_temporary() => MAV_RESULT_TEMPORARILY_REJECTED,
        Err(why) => {
            info!(?why, "home refused");
            MAV_RESULT_FAILED
        }
    }
}

/// ArduCopter `handle_command_int_do_reposition`.
fn reposition(v: &mut Vehicle, cmd: &Cmd) -> MavResult {
    use MavResult::*;
    let [speed, flags, _, yaw_deg] = cmd.p;
    let change_mode = (flags as i32) & REPOSITION_CHANGE_MODE != 0;
    if v.mode() != FlightMode::Guided && !change_mode {
        return MAV_RESULT_DENIED;
    }
    let Some(target) = cmd.target_ned(v, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT) else {
        return MAV_RESULT_DENIED;
    };
    if v.set_mode(FlightMode::Guided).is_err() {
        return MAV_RESULT_FAILED;
    }
    if speed > 0.0 && speed.is_finite() {
        v.set_speed(SpeedKind::Horizontal, f64::from(speed));
    }
    let yaw = yaw_deg.is_finite().then(|| f64::from(yaw_deg).to_radians());
    match v.reposition(target, yaw) {
        Ok(()) => MAV_RESULT_ACCEPTED,
        Err(_) => MAV_RESULT_FAILED,
    }
}

/// MAV_CMD_REQUEST_MESSAGE: DENIED for messages the simulator never sends,
/// FAILED when it has nothing to send yet (e.g. no home).
fn request_message(
    v: &Vehicle,
    system_id: u8,
    id_param: f32,
    extra: &mut Option<Outgoing>,
) -> MavResult {
    let id = id_param as u32;
    if !(id_param >= 0.0 && telemetry::PRODUCIBLE.contains(&id)) {
        return MavResult::MAV_RESULT_DENIED;
    }
    match telemetry::build_outgoing(id, v, system_id) {
        Some(msg) => {
            *extra = Some(msg);
            MavResult::MAV_RESULT_ACCEPTED
        }
        None => MavResult::MAV_RESULT_FAILED,
    }
}
