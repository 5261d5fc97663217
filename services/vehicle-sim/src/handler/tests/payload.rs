//! Gimbal and GoPro handler tests: commands and requests in, gimbal motion,
//! GoPro state and replies out.

use mavlink::dialects::ardupilotmega::{
    GimbalDeviceFlags, GoproCaptureMode, GoproCommand, GoproHeartbeatFlags, GoproHeartbeatStatus,
    GoproRequestStatus, GIMBAL_DEVICE_ATTITUDE_STATUS_DATA, GOPRO_GET_REQUEST_DATA,
    GOPRO_HEARTBEAT_DATA, GOPRO_SET_REQUEST_DATA,
};
use mavlink::MessageData;

use super::*;
use crate::config::GIMBAL_COMPONENT_ID;
use crate::model::Event;
use crate::telemetry;

const OK: MavResult = MavResult::MAV_RESULT_ACCEPTED;
const SUCCESS: GoproRequestStatus = GoproRequestStatus::GOPRO_REQUEST_SUCCESS;
const FAILED: GoproRequestStatus = GoproRequestStatus::GOPRO_REQUEST_FAILED;

fn pitch_yaw_deg(v: &Vehicle) -> (f64, f64) {
    let a = v.gimbal().attitude();
    (a.pitch.to_degrees(), a.yaw.to_degrees())
}

fn pitchyaw(h: &Handler, v: &mut Vehicle, pitch: f32, yaw: f32, flags: f32) -> MavResult {
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        [pitch, yaw, f32::NAN, f32::NAN, flags, 0., 0.],
    )
}

#[test]
fn gimbal_slews_at_its_rate_to_the_commanded_angles() {
    let (h, mut v) = setup();
    // autopilot-link's form: yaw in the vehicle frame (flags 32), rates NaN.
    assert_eq!(pitchyaw(&h, &mut v, -45., 30., 32.), OK);
    run(&mut v, 0.25);
    let (p, y) = pitch_yaw_deg(&v);
    assert!((p + 22.5).abs() < 0.5, "90 deg/s: {p}");
    assert!((y - 22.5).abs() < 0.5, "{y}");
    run(&mut v, 1.0);
    let (p, y) = pitch_yaw_deg(&v);
    assert!(
        (p + 45.0).abs() < 1e-6 && (y - 30.0).abs() < 1e-6,
        "{p} {y}"
    );
    // Beyond the travel: pitch stops at +30.
    assert_eq!(pitchyaw(&h, &mut v, 80., 0., 0.), OK);
    run(&mut v, 3.0);
    assert!((pitch_yaw_deg(&v).0 - 30.0).abs() < 1e-6);
    // DO_MOUNT_CONTROL in MAVLink targeting mode.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_MOUNT_CONTROL,
            [-90., 0., -20., 0., 0., 0., 2.]
        ),
        OK
    );
    run(&mut v, 3.0);
    let (p, y) = pitch_yaw_deg(&v);
    assert!(
        (p + 90.0).abs() < 1e-6 && (y + 20.0).abs() < 1e-6,
        "{p} {y}"
    );
    assert_eq!(v.payload().mount.map(|m| m.yaw_deg), Some(-20.0));
}

#[test]
fn gimbal_commands_refused_like_ardupilot() {
    let (h, mut v) = setup();
    let mount = |v: &mut Vehicle, p: [f32; 7]| cmd(&h, v, MavCmd::MAV_CMD_DO_MOUNT_CONTROL, p);
    // Centidegrees, NaN, an unknown mode, a location mode it does not simulate.
    assert_eq!(
        mount(&mut v, [-4500., 0., 0., 0., 0., 0., 2.]),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        mount(&mut v, [f32::NAN, 0., 0., 0., 0., 0., 2.]),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        mount(&mut v, [0., 0., 0., 0., 0., 0., 9.]),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        mount(&mut v, [0., 0., 0., 0., 0., 0., 4.]),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    let manager =
        |v: &mut Vehicle, p: [f32; 7]| cmd(&h, v, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, p);
    // Neither angles nor rates; a gimbal device that does not exist.
    assert_eq!(
        manager(&mut v, [f32::NAN, 0., f32::NAN, 0., 0., 0., 0.]),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        manager(&mut v, [-10., 0., f32::NAN, f32::NAN, 0., 0., 2.]),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(v.payload().mount, None, "refusals are not recorded");
    // Rates when the angles are NaN: −30 deg/s pitch for 1 s.
    assert_eq!(
        manager(&mut v, [f32::NAN, f32::NAN, -30., 0., 0., 0., 1.]),
        OK
    );
    run(&mut v, 1.0);
    assert!((pitch_yaw_deg(&v).0 + 30.0).abs() < 0.5);
}

#[test]
fn earth_frame_yaw_holds_a_heading() {
    let (h, mut v) = setup();
    let heading = v.heading().to_degrees();
    // YAW_LOCK: 10° east of north, whatever the nose does.
    assert_eq!(pitchyaw(&h, &mut v, 0., 10., 16.), OK);
    run(&mut v, 3.0);
    let expected = skymesh_runtime::angle::wrap_180(10.0 - heading);
    assert!((pitch_yaw_deg(&v).1 - expected).abs() < 1e-6);
}

/// ROI location `north_m` north of home on the ground (COMMAND_LONG, degrees).
fn roi_north(h: &Handler, v: &mut Vehicle, north_m: f64) -> MavResult {
    let home = v.home_geo().expect("home");
    let lat = home.lat_deg + north_m / 111_318.845;
    cmd(
        h,
        v,
        MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
        [0., 0., 0., 0., lat as f32, home.lon_deg as f32, 0.],
    )
}

#[test]
fn gimbal_tracks_an_roi_below_and_the_roi_wins() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 20.0);
    assert_eq!(roi_north(&h, &mut v, 40.0), OK);
    run(&mut v, 8.0);
    let pos = v.position_ned();
    let roi = v.roi().expect("roi");
    let horizontal = (roi.x - pos.x).hypot(roi.y - pos.y);
    // NED: the ROI's height above the vehicle is −(roi.z − pos.z).
    let expected = (-(roi.z - pos.z)).atan2(horizontal).to_degrees();
    let (p, y) = pitch_yaw_deg(&v);
    assert!(expected < -20.0, "ROI below: {expected}");
    assert!((p - expected).abs() < 2.0, "pitch {p}, expected {expected}");
    assert!(y.abs() < 2.0, "nose faces the ROI, camera ahead: {y}");

    // An explicit command is accepted and recorded, but the ROI keeps the camera.
    assert_eq!(pitchyaw(&h, &mut v, 0., 90., 0.), OK);
    run(&mut v, 3.0);
    assert!((pitch_yaw_deg(&v).0 - expected).abs() < 2.0);
    assert_eq!(v.payload().mount.map(|m| m.yaw_deg), Some(90.0));

    // Cleared: the camera stays where the ROI left it, then obeys again.
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.; 7]),
        OK
    );
    run(&mut v, 2.0);
    assert!((pitch_yaw_deg(&v).0 - expected).abs() < 2.0);
    assert_eq!(pitchyaw(&h, &mut v, -10., 0., 0.), OK);
    run(&mut v, 2.0);
    assert!((pitch_yaw_deg(&v).0 + 10.0).abs() < 1e-6);
}

#[test]
fn gimbal_attitude_status_is_in_the_vehicle_frame() {
    let (h, mut v) = setup();
    assert_eq!(pitchyaw(&h, &mut v, -30., 20., 32.), OK);
    run(&mut v, 2.0);
    let Some(Outgoing::Message(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(s))) =
        telemetry::build_outgoing(GIMBAL_DEVICE_ATTITUDE_STATUS_DATA::ID, &v, 1)
    else {
        panic!("no gimbal status")
    };
    assert_eq!(
        s.flags,
        GimbalDeviceFlags::GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME
    );
    assert_eq!(s.failure_flags.bits(), 0);
    assert_eq!(s.gimbal_device_id, 1);
    assert!((f64::from(s.delta_yaw) - v.attitude().yaw).abs() < 1e-6);
    // Roll 0, pitch −30°, yaw 20°: w, x, y, z (Hamilton, pitch then yaw).
    let (p, y) = ((-30f64).to_radians() / 2.0, 20f64.to_radians() / 2.0);
    let expected = [
        p.cos() * y.cos(),
        -p.sin() * y.sin(),
        p.sin() * y.cos(),
        p.cos() * y.sin(),
    ];
    for (got, want) in s.q.iter().zip(expected) {
        assert!((f64::from(*got) - want).abs() < 1e-6, "{:?}", s.q);
    }
    let w = [
        s.angular_velocity_x,
        s.angular_velocity_y,
        s.angular_velocity_z,
    ];
    assert!(w.iter().all(|x| x.is_finite()), "{w:?}");

    // Asked for by rate; GOPRO_HEARTBEAT is the gimbal's, not the autopilot's.
    let r = h.handle(
        &mut v,
        &long(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [285., 50_000., 0., 0., 0., 0., 0.],
        ),
    );
    assert_eq!(r.ack, Some(OK));
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [215., 1e6, 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_DENIED
    );
    let r = h.handle(
        &mut v,
        &long(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [285., 0., 0., 0., 0., 0., 0.],
        ),
    );
    assert!(matches!(
        &r.replies[..],
        [
            Outgoing::Message(MavMessage::COMMAND_ACK(_)),
            Outgoing::Message(MavMessage::GIMBAL_DEVICE_ATTITUDE_STATUS(_))
        ]
    ));
}

fn gopro_set(target_component: u8, cmd_id: GoproCommand, value: [u8; 4]) -> Inbound {
    msg(MavMessage::GOPRO_SET_REQUEST(GOPRO_SET_REQUEST_DATA {
        target_system: 1,
        target_component,
        cmd_id,
        value,
    }))
}

/// GOPRO_SET_REQUEST to the gimbal; the status of its GOPRO_SET_RESPONSE.
fn set(h: &Handler, v: &mut Vehicle, cmd_id: GoproCommand, value: [u8; 4]) -> GoproRequestStatus {
    let r = h.handle(v, &gopro_set(GIMBAL_COMPONENT_ID, cmd_id, value));
    match &r.replies[..] {
        [Outgoing::FromComponent {
            component: GIMBAL_COMPONENT_ID,
            msg: MavMessage::GOPRO_SET_RESPONSE(s),
        }] => {
            assert_eq!(s.cmd_id, cmd_id);
            assert_eq!(r.gopro, Some((GoProRequest::Set, s.status)));
            s.status
        }
        other => panic!("expected one GOPRO_SET_RESPONSE from the gimbal, got {other:?}"),
    }
}

fn get(h: &Handler, v: &mut Vehicle, cmd_id: GoproCommand) -> (GoproRequestStatus, [u8; 4]) {
    let r = h.handle(
        v,
        &msg(MavMessage::GOPRO_GET_REQUEST(GOPRO_GET_REQUEST_DATA {
            target_system: 1,
            target_component: GIMBAL_COMPONENT_ID,
            cmd_id,
        })),
    );
    match &r.replies[..] {
        [Outgoing::FromComponent {
            component: GIMBAL_COMPONENT_ID,
            msg: MavMessage::GOPRO_GET_RESPONSE(g),
        }] => {
            assert_eq!(g.cmd_id, cmd_id);
            (g.status, g.value)
        }
        other => panic!("expected one GOPRO_GET_RESPONSE from the gimbal, got {other:?}"),
    }
}

fn gopro_heartbeat(v: &Vehicle) -> GOPRO_HEARTBEAT_DATA {
    match telemetry::build_outgoing(GOPRO_HEARTBEAT_DATA::ID, v, 1) {
        Some(Outgoing::FromComponent {
            component: GIMBAL_COMPONENT_ID,
            msg: MavMessage::GOPRO_HEARTBEAT(hb),
        }) => hb,
        other => panic!("expected GOPRO_HEARTBEAT from the gimbal, got {other:?}"),
    }
}

fn gopro_changed(v: &mut Vehicle) -> bool {
    v.take_events().contains(&Event::GoProChanged)
}

#[test]
fn gopro_set_and_get_round_trip() {
    use GoproCommand::*;
    let (h, mut v) = setup();
    let hb = gopro_heartbeat(&v);
    assert_eq!(
        hb.status,
        GoproHeartbeatStatus::GOPRO_HEARTBEAT_STATUS_CONNECTED
    );
    assert_eq!(hb.capture_mode, GoproCaptureMode::GOPRO_CAPTURE_MODE_VIDEO);
    assert_eq!(hb.flags, GoproHeartbeatFlags::empty());
    assert_eq!(
        get(&h, &mut v, GOPRO_COMMAND_MODEL),
        (SUCCESS, [4, 0, 0, 0])
    );
    assert_eq!(
        get(&h, &mut v, GOPRO_COMMAND_BATTERY),
        (SUCCESS, [100, 0, 0, 0])
    );
    for (cmd_id, value) in [
        (GOPRO_COMMAND_VIDEO_SETTINGS, [6, 5, 1, 1]),
        (GOPRO_COMMAND_LOW_LIGHT, [1, 0, 0, 0]),
        (GOPRO_COMMAND_PHOTO_RESOLUTION, [2, 0, 0, 0]),
        (GOPRO_COMMAND_PHOTO_BURST_RATE, [8, 0, 0, 0]),
        (GOPRO_COMMAND_PROTUNE, [1, 0, 0, 0]),
        (GOPRO_COMMAND_PROTUNE_WHITE_BALANCE, [4, 0, 0, 0]),
        (GOPRO_COMMAND_PROTUNE_COLOUR, [1, 0, 0, 0]),
        (GOPRO_COMMAND_PROTUNE_GAIN, [3, 0, 0, 0]),
        (GOPRO_COMMAND_PROTUNE_SHARPNESS, [0, 0, 0, 0]),
        (GOPRO_COMMAND_PROTUNE_EXPOSURE, [7, 0, 0, 0]),
        (GOPRO_COMMAND_CHARGING, [1, 0, 0, 0]),
        (GOPRO_COMMAND_CAPTURE_MODE, [3, 0, 0, 0]),
    ] {
        assert_eq!(set(&h, &mut v, cmd_id, value), SUCCESS, "{cmd_id:?}");
        assert_eq!(get(&h, &mut v, cmd_id), (SUCCESS, value), "{cmd_id:?}");
    }
    assert!(gopro_changed(&mut v), "capture mode changed");
    assert_eq!(
        gopro_heartbeat(&v).capture_mode,
        GoproCaptureMode::GOPRO_CAPTURE_MODE_TIME_LAPSE
    );
}

#[test]
fn gopro_invalid_values_fail_and_change_nothing() {
    use GoproCommand::*;
    let (h, mut v) = setup();
    for (cmd_id, value) in [
        (GOPRO_COMMAND_CAPTURE_MODE, [7, 0, 0, 0]),
        (GOPRO_COMMAND_SHUTTER, [2, 0, 0, 0]),
        (GOPRO_COMMAND_BATTERY, [50, 0, 0, 0]),
        (GOPRO_COMMAND_MODEL, [1, 0, 0, 0]),
        (GOPRO_COMMAND_VIDEO_SETTINGS, [3, 4, 0, 0x80]),
        (GOPRO_COMMAND_PROTUNE_EXPOSURE, [21, 0, 0, 0]),
    ] {
        assert_eq!(set(&h, &mut v, cmd_id, value), FAILED, "{cmd_id:?}");
    }
    assert!(!gopro_changed(&mut v));
    assert_eq!(
        get(&h, &mut v, GOPRO_COMMAND_CAPTURE_MODE),
        (SUCCESS, [0, 0, 0, 0])
    );
}

#[test]
fn gopro_shutter_records_in_video_and_shoots_in_photo_mode() {
    use GoproCommand::*;
    let (h, mut v) = setup();
    v.take_events();
    assert_eq!(
        set(&h, &mut v, GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]),
        SUCCESS
    );
    assert!(gopro_changed(&mut v), "recording starts: heartbeat at once");
    assert_eq!(
        gopro_heartbeat(&v).flags,
        GoproHeartbeatFlags::GOPRO_FLAG_RECORDING
    );
    // No mode change while recording.
    assert_eq!(
        set(&h, &mut v, GOPRO_COMMAND_CAPTURE_MODE, [1, 0, 0, 0]),
        FAILED
    );
    assert_eq!(
        set(&h, &mut v, GOPRO_COMMAND_SHUTTER, [0, 0, 0, 0]),
        SUCCESS
    );
    assert!(gopro_changed(&mut v));
    assert_eq!(gopro_heartbeat(&v).flags, GoproHeartbeatFlags::empty());

    assert_eq!(
        set(&h, &mut v, GOPRO_COMMAND_CAPTURE_MODE, [1, 0, 0, 0]),
        SUCCESS
    );
    assert!(gopro_changed(&mut v));
    for _ in 0..3 {
        assert_eq!(
            set(&h, &mut v, GOPRO_COMMAND_SHUTTER, [1, 0, 0, 0]),
            SUCCESS
        );
    }
    assert!(!gopro_changed(&mut v), "a photo is not a recording");
    assert_eq!(gopro_heartbeat(&v).flags, GoproHeartbeatFlags::empty());
    assert_eq!(v.gopro().map(|g| g.photos_taken()), Some(3));
}

#[test]
fn gopro_requests_for_others_or_without_a_gopro_go_unanswered() {
    let (h, mut v) = setup();
    let shutter = GoproCommand::GOPRO_COMMAND_SHUTTER;
    // Addressed to the autopilot, or to another system.
    assert_eq!(
        h.handle(&mut v, &gopro_set(1, shutter, [1, 0, 0, 0])),
        Response::default()
    );
    let other = msg(MavMessage::GOPRO_SET_REQUEST(GOPRO_SET_REQUEST_DATA {
        target_system: 7,
        target_component: GIMBAL_COMPONENT_ID,
        cmd_id: shutter,
        value: [1, 0, 0, 0],
    }));
    assert_eq!(h.handle(&mut v, &other), Response::default());
    // Component 0 (every component) reaches the gimbal.
    let r = h.handle(&mut v, &gopro_set(0, shutter, [1, 0, 0, 0]));
    assert_eq!(r.gopro, Some((GoProRequest::Set, SUCCESS)));

    let mut bare = Vehicle::new(VehicleParams {
        gopro: false,
        ..VehicleParams::default()
    });
    let r = h.handle(
        &mut bare,
        &gopro_set(GIMBAL_COMPONENT_ID, shutter, [1, 0, 0, 0]),
    );
    assert_eq!(r, Response::default());
    assert!(telemetry::build_outgoing(GOPRO_HEARTBEAT_DATA::ID, &bare, 1).is_none());
}
