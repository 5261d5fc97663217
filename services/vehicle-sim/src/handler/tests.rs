//! Handler tests: messages in, vehicle changes and replies out, no I/O.

#![allow(deprecated)]

use super::*;
use mavlink::dialects::ardupilotmega::{
    MavCmd, MavFrame, PositionTargetTypemask as Mask, COMMAND_INT_DATA, COMMAND_LONG_DATA,
    REQUEST_DATA_STREAM_DATA, SET_MODE_DATA, SET_POSITION_TARGET_GLOBAL_INT_DATA,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use mavlink::{MavHeader, MavlinkVersion};
use nalgebra::Vector3;

use crate::model::{FlightMode, VehicleParams};

mod actuators;
mod camera;
mod home;
mod payload;

const GCS: MavHeader = MavHeader {
    system_id: 255,
    component_id: 190,
    sequence: 0,
};

fn setup() -> (Handler, Vehicle) {
    (Handler::new(1), Vehicle::new(VehicleParams::default()))
}

fn msg(m: MavMessage) -> Inbound {
    Inbound::Message {
        header: GCS,
        version: MavlinkVersion::V2,
        msg: m,
    }
}

fn long(command: MavCmd, p: [f32; 7]) -> Inbound {
    msg(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        command,
        target_system: 1,
        target_component: 1,
        confirmation: 0,
    }))
}

/// Send a COMMAND_LONG and return its ACK result.
fn cmd(h: &Handler, v: &mut Vehicle, command: MavCmd, p: [f32; 7]) -> MavResult {
    let r = h.handle(v, &long(command, p));
    match r.replies.first() {
        Some(Outgoing::Message(MavMessage::COMMAND_ACK(a))) => {
            assert_eq!(a.command, command);
            assert_eq!(r.ack, Some(a.result));
            a.result
        }
        other => panic!("expected COMMAND_ACK, got {other:?}"),
    }
}

fn airborne(h: &Handler, v: &mut Vehicle, alt: f32) {
    let ok = MavResult::MAV_RESULT_ACCEPTED;
    assert_eq!(
        cmd(
            h,
            v,
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1., 4., 0., 0., 0., 0., 0.]
        ),
        ok
    );
    assert_eq!(
        cmd(
            h,
            v,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1., 0., 0., 0., 0., 0., 0.]
        ),
        ok
    );
    assert_eq!(
        cmd(
            h,
            v,
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [0., 0., 0., 0., 0., 0., alt]
        ),
        ok
    );
    for _ in 0..(100.0 * (8.0 + alt / 2.5)) as usize {
        v.step(0.01);
    }
}

#[test]
fn set_mode_command_and_message() {
    let (h, mut v) = setup();
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1., 4., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(v.mode(), FlightMode::Guided);
    // Without MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: DENIED.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_MODE,
            [0., 5., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_DENIED
    );
    // Not simulated: FAILED.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1., 21., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_FAILED
    );
    let r = h.handle(
        &mut v,
        &msg(MavMessage::SET_MODE(SET_MODE_DATA {
            custom_mode: 9,
            target_system: 1,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        })),
    );
    assert_eq!(
        r.replies,
        vec![Outgoing::CommandAckRaw {
            command: 11,
            result: MavResult::MAV_RESULT_ACCEPTED
        }]
    );
    assert_eq!(v.mode(), FlightMode::Land);
}

#[test]
fn arming_results_distinguish_temporary_refusals() {
    let mut v = Vehicle::new(VehicleParams {
        ekf_ready_after_s: 30.0,
        ..VehicleParams::default()
    });
    let h = Handler::new(1);
    let arm = [1., 0., 0., 0., 0., 0., 0.];
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    let (h, mut v) = setup();
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1., 9., 0., 0., 0., 0., 0.],
    );
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, arm),
        MavResult::MAV_RESULT_DENIED
    );
    // Force arm (21196) works anywhere.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1., 21196., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(v.armed());
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [3., 0., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
}

#[test]
fn disarm_in_flight_fails_unless_forced() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.; 7]),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [0., 21196., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert!(!v.armed());
}

#[test]
fn takeoff_land_rtl() {
    let (h, mut v) = setup();
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            [0., 0., 0., 0., 0., 0., 10.]
        ),
        MavResult::MAV_RESULT_FAILED,
        "not armed, not GUIDED"
    );
    airborne(&h, &mut v, 10.0);
    assert!((v.relative_alt() - 10.0).abs() < 0.1);
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH, [0.; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(v.mode(), FlightMode::Rtl);
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_NAV_LAND, [0.; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(v.mode(), FlightMode::Land);
}

#[test]
fn unknown_and_unsimulated_commands_are_unsupported() {
    let (h, mut v) = setup();
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_DO_FLIGHTTERMINATION, [1.; 7]),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    let r = h.handle(
        &mut v,
        &Inbound::UnknownCommand {
            header: GCS,
            command: 65000,
            target_system: 1,
            target_component: 0,
        },
    );
    assert_eq!(
        r.replies,
        vec![Outgoing::CommandAckRaw {
            command: 65000,
            result: MavResult::MAV_RESULT_UNSUPPORTED
        }]
    );
}

#[test]
fn messages_for_other_systems_are_ignored() {
    let (h, mut v) = setup();
    let mut m = long(MavCmd::MAV_CMD_DO_SET_MODE, [1., 4., 0., 0., 0., 0., 0.]);
    if let Inbound::Message {
        msg: MavMessage::COMMAND_LONG(d),
        ..
    } = &mut m
    {
        d.target_system = 2;
    }
    assert_eq!(h.handle(&mut v, &m), Response::default());
    assert_eq!(v.mode(), FlightMode::Stabilize);
}

#[test]
fn message_interval_and_request_message() {
    let (h, mut v) = setup();
    let r = h.handle(
        &mut v,
        &long(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [30., 10_000., 0., 0., 0., 0., 0.],
        ),
    );
    assert_eq!(r.ack, Some(MavResult::MAV_RESULT_ACCEPTED));
    assert!(matches!(
        r.streams[..],
        [StreamRequest::Interval { id: 30, request: IntervalRequest::Every(d) }]
            if d == std::time::Duration::from_millis(10)
    ));
    // A message the simulator never produces.
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [65., 1e6, 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_DENIED
    );
    let r = h.handle(
        &mut v,
        &long(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [242., 0., 0., 0., 0., 0., 0.],
        ),
    );
    assert!(matches!(
        &r.replies[..],
        [
            Outgoing::Message(MavMessage::COMMAND_ACK(_)),
            Outgoing::Message(MavMessage::HOME_POSITION(_))
        ]
    ));
    let r = h.handle(
        &mut v,
        &msg(MavMessage::REQUEST_DATA_STREAM(REQUEST_DATA_STREAM_DATA {
            req_message_rate: 4,
            target_system: 1,
            target_component: 1,
            req_stream_id: MavDataStream::MAV_DATA_STREAM_POSITION,
            start_stop: 1,
        })),
    );
    assert_eq!(r.replies, vec![]);
    assert_eq!(r.streams.len(), 1);
}

#[test]
fn request_home_before_ekf_fails() {
    let mut v = Vehicle::new(VehicleParams {
        ekf_ready_after_s: 30.0,
        ..VehicleParams::default()
    });
    let h = Handler::new(1);
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [242., 0., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_FAILED
    );
}

fn local_target(frame: MavFrame, mask: Mask, xyz: [f32; 3], vel: [f32; 3], yaw: f32) -> Inbound {
    msg(MavMessage::SET_POSITION_TARGET_LOCAL_NED(
        SET_POSITION_TARGET_LOCAL_NED_DATA {
            x: xyz[0],
            y: xyz[1],
            z: xyz[2],
            vx: vel[0],
            vy: vel[1],
            vz: vel[2],
            yaw,
            type_mask: mask,
            target_system: 1,
            target_component: 1,
            coordinate_frame: frame,
            ..SET_POSITION_TARGET_LOCAL_NED_DATA::DEFAULT
        },
    ))
}

const VEL_ONLY: Mask = Mask::POSITION_TARGET_TYPEMASK_X_IGNORE
    .union(Mask::POSITION_TARGET_TYPEMASK_Y_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_Z_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AX_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AY_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AZ_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE);

const POS_ONLY: Mask = Mask::POSITION_TARGET_TYPEMASK_VX_IGNORE
    .union(Mask::POSITION_TARGET_TYPEMASK_VY_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_VZ_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AX_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AY_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_AZ_IGNORE)
    .union(Mask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE);

fn run(v: &mut Vehicle, secs: f64) {
    for _ in 0..(secs * 100.0) as usize {
        v.step(0.01);
    }
}

#[test]
fn body_frame_velocity_is_rotated_by_heading() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    // Face east first.
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_CONDITION_YAW,
        [90., 0., 0., 0., 0., 0., 0.],
    );
    run(&mut v, 3.0);
    h.handle(
        &mut v,
        &local_target(
            MavFrame::MAV_FRAME_BODY_OFFSET_NED,
            VEL_ONLY,
            [0.; 3],
            [1., 0., 0.],
            0.,
        ),
    );
    run(&mut v, 2.0);
    let vel = v.velocity_ned();
    assert!((vel.y - 1.0).abs() < 1e-3 && vel.x.abs() < 1e-3, "{vel:?}");
}

#[test]
fn local_offset_position_and_absolute_yaw() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    let start = v.position_ned();
    h.handle(
        &mut v,
        &local_target(
            MavFrame::MAV_FRAME_LOCAL_OFFSET_NED,
            POS_ONLY,
            [10., 0., -2.],
            [0.; 3],
            3.0,
        ),
    );
    run(&mut v, 15.0);
    assert!((v.position_ned() - (start + Vector3::new(10.0, 0.0, -2.0))).norm() < 0.05);
    assert!((v.heading() - 3.0).abs() < 1e-3);
    // A frame ArduCopter refuses for this message changes nothing.
    h.handle(
        &mut v,
        &local_target(MavFrame::MAV_FRAME_GLOBAL, POS_ONLY, [0.; 3], [0.; 3], 0.),
    );
    run(&mut v, 2.0);
    assert!((v.position_ned() - (start + Vector3::new(10.0, 0.0, -2.0))).norm() < 0.05);
}

#[test]
fn global_relative_alt_target() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    let home = v.home_geo().expect("home");
    h.handle(
        &mut v,
        &msg(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(
            SET_POSITION_TARGET_GLOBAL_INT_DATA {
                lat_int: home.lat_e7() + 1000, // ≈ 11 m north
                lon_int: home.lon_e7(),
                alt: 12.0,
                type_mask: POS_ONLY | Mask::POSITION_TARGET_TYPEMASK_YAW_IGNORE,
                target_system: 1,
                target_component: 1,
                coordinate_frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                ..SET_POSITION_TARGET_GLOBAL_INT_DATA::DEFAULT
            },
        )),
    );
    run(&mut v, 20.0);
    assert!(
        (v.relative_alt() - 12.0).abs() < 0.05,
        "{}",
        v.relative_alt()
    );
    assert!(
        (v.position_ned().x - 11.13).abs() < 0.05,
        "{:?}",
        v.position_ned()
    );
}

#[test]
fn setpoints_ignored_outside_guided() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1., 5., 0., 0., 0., 0., 0.],
    );
    let before = v.position_ned();
    let r = h.handle(
        &mut v,
        &local_target(
            MavFrame::MAV_FRAME_LOCAL_NED,
            VEL_ONLY,
            [0.; 3],
            [3., 0., 0.],
            0.,
        ),
    );
    assert_eq!(r, Response::default(), "no ack for setpoints");
    run(&mut v, 2.0);
    assert!((v.position_ned() - before).norm() < 0.5);
}

#[test]
fn reposition_needs_guided_or_the_change_mode_flag() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    cmd(
        &h,
        &mut v,
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1., 5., 0., 0., 0., 0., 0.],
    );
    let home = v.home_geo().expect("home");
    let int = |flags: f32| {
        msg(MavMessage::COMMAND_INT(COMMAND_INT_DATA {
            param1: -1.0,
            param2: flags,
            param4: f32::NAN,
            x: home.lat_e7() + 1000,
            y: home.lon_e7(),
            z: 8.0,
            command: MavCmd::MAV_CMD_DO_REPOSITION,
            target_system: 1,
            target_component: 1,
            frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            ..COMMAND_INT_DATA::DEFAULT
        }))
    };
    assert_eq!(
        h.handle(&mut v, &int(0.0)).ack,
        Some(MavResult::MAV_RESULT_DENIED)
    );
    assert_eq!(
        h.handle(&mut v, &int(1.0)).ack,
        Some(MavResult::MAV_RESULT_ACCEPTED)
    );
    assert_eq!(v.mode(), FlightMode::Guided);
    run(&mut v, 20.0);
    assert!((v.relative_alt() - 8.0).abs() < 0.05);
    assert!((v.position_ned().x - 11.13).abs() < 0.05);
}

#[test]
fn roi_speed_yaw_and_payload_commands() {
    let (h, mut v) = setup();
    airborne(&h, &mut v, 5.0);
    let ok = MavResult::MAV_RESULT_ACCEPTED;
    let home = v.home_geo().expect("home");
    // ROI 100 m east (param5/6 in degrees for COMMAND_LONG).
    let east = home.lon_deg + 100.0 / (111_318.845 * home.lat_deg.to_radians().cos());
    let roi = [0., 0., 0., 0., home.lat_deg as f32, east as f32, 0.];
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_DO_SET_ROI_LOCATION, roi),
        ok
    );
    run(&mut v, 5.0);
    assert!(
        (v.heading() - std::f64::consts::FRAC_PI_2).abs() < 0.05,
        "{}",
        v.heading()
    );
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_DO_SET_ROI_NONE, [0.; 7]),
        ok
    );
    assert!(v.roi().is_none());

    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_CHANGE_SPEED,
            [1., -1., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_CONDITION_YAW,
            [400., 0., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_SERVO,
            [9., 1900., 0., 0., 0., 0., 0.]
        ),
        ok
    );
    assert_eq!(v.payload().servos.get(&9), Some(&1900));
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_SET_SERVO,
            [0., 1900., 0., 0., 0., 0., 0.]
        ),
        MavResult::MAV_RESULT_FAILED
    );
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            [-45., 10., f32::NAN, f32::NAN, 0., 0., 0.]
        ),
        ok
    );
    assert_eq!(v.payload().mount.map(|m| m.pitch_deg), Some(-45.0));
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_DO_MOUNT_CONTROL,
            [-90., 0., 0., 0., 0., 0., 2.]
        ),
        ok
    );
    assert_eq!(
        cmd(
            &h,
            &mut v,
            MavCmd::MAV_CMD_IMAGE_START_CAPTURE,
            [0., 0., 3., 0., 0., 0., 0.]
        ),
        ok
    );
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_VIDEO_START_CAPTURE, [0.; 7]),
        ok
    );
    assert_eq!(v.payload().images_captured, 3);
    assert!(v.payload().video_recording);
    assert_eq!(
        cmd(&h, &mut v, MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE, [0.; 7]),
        ok
    );
    assert!(!v.payload().video_recording);
    assert_eq!(v.payload().video_starts, 1);
}
