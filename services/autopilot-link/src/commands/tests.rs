//! Tests of the mapping: each `Command` and the MAVLink it becomes.

use mavlink::dialects::ardupilotmega::{MavCmd, MavFrame};
use skymesh_ipc_types::{CameraModeKind, Command, FlightMode, FocusMode, ZoomMode};

use super::*;

const T: Target = Target {
    system: 1,
    component: 1,
};

fn ctx(mode: FlightMode) -> PlanContext {
    PlanContext {
        target: T,
        mode,
        capture_seq: 7,
    }
}

fn long_of(p: &Plan) -> &COMMAND_LONG_DATA {
    match &p.command {
        Some(MavCommand::Long(c)) => c,
        other => panic!("expected COMMAND_LONG, got {other:?}"),
    }
}

fn plan_of(c: Command) -> Plan {
    plan(&c, &ctx(FlightMode::Loiter)).unwrap()
}

#[test]
fn arming_commands_map_to_component_arm_disarm() {
    for (cmd, p1, p2) in [
        (Command::Arm { force: false }, 1.0, 0.0),
        (Command::Arm { force: true }, 1.0, FORCE_MAGIC),
        (Command::Disarm { force: false }, 0.0, 0.0),
        (Command::Disarm { force: true }, 0.0, FORCE_MAGIC),
        (Command::MotorKill { emergency: true }, 0.0, FORCE_MAGIC),
        (Command::MotorKill { emergency: false }, 0.0, 0.0),
    ] {
        let p = plan_of(cmd);
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, "{cmd:?}");
        assert_eq!((c.param1, c.param2), (p1, p2), "{cmd:?}");
        assert_eq!((c.target_system, c.target_component), (1, 1));
        assert_eq!(c.confirmation, 0);
        assert!(p.setpoint.is_none());
    }
}

#[test]
fn modes_takeoff_and_navigation_commands() {
    let p = plan_of(Command::SetMode(FlightMode::Guided));
    let c = long_of(&p);
    assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
    assert_eq!((c.param1, c.param2), (1.0, 4.0));
    let p = plan_of(Command::Takeoff { alt_rel_m: 10.0 });
    assert_eq!(long_of(&p).command, MavCmd::MAV_CMD_NAV_TAKEOFF);
    assert_eq!(long_of(&p).param7, 10.0);
    assert_eq!(
        long_of(&plan_of(Command::Land)).command,
        MavCmd::MAV_CMD_NAV_LAND
    );
    assert_eq!(
        long_of(&plan_of(Command::ReturnToLaunch)).command,
        MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH
    );
    assert!(plan(
        &Command::SetMode(FlightMode::Unknown),
        &ctx(FlightMode::Loiter)
    )
    .is_err());
}

#[test]
fn go_to_is_a_global_position_setpoint_with_optional_yaw_and_speed() {
    let p = plan_of(Command::GoTo {
        lat_deg: -35.363261,
        lon_deg: 149.16523,
        alt_rel_m: 20.0,
        yaw_deg: None,
        speed_mps: None,
    });
    assert!(p.command.is_none());
    let Some(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(s)) = &p.setpoint else {
        panic!("{p:?}")
    };
    assert_eq!(
        (s.lat_int, s.lon_int, s.alt),
        (-353_632_610, 1_491_652_300, 20.0)
    );
    #[allow(deprecated)]
    let frame = MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT;
    assert_eq!(s.coordinate_frame, frame);
    assert_eq!(s.type_mask.bits(), 0b1101_1111_1000, "position only");
    assert_eq!((s.target_system, s.target_component), (1, 1));

    let p = plan_of(Command::GoTo {
        lat_deg: 1.0,
        lon_deg: 2.0,
        alt_rel_m: 5.0,
        yaw_deg: Some(90.0),
        speed_mps: Some(3.0),
    });
    let Some(MavMessage::SET_POSITION_TARGET_GLOBAL_INT(s)) = &p.setpoint else {
        panic!("{p:?}")
    };
    assert_eq!(s.type_mask.bits(), 0b1001_1111_1000, "position and yaw");
    assert!((s.yaw - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    let c = long_of(&p);
    assert_eq!(c.command, MavCmd::MAV_CMD_DO_CHANGE_SPEED);
    assert_eq!((c.param1, c.param2), (1.0, 3.0));
}

#[test]
fn velocity_is_a_local_ned_setpoint_with_optional_yaw_rate() {
    let p = plan_of(Command::VelocityNed {
        vel_ned_mps: [1.0, -2.0, 0.5],
        yaw_rate_dps: None,
    });
    assert!(p.command.is_none());
    let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(s)) = &p.setpoint else {
        panic!("{p:?}")
    };
    assert_eq!((s.vx, s.vy, s.vz), (1.0, -2.0, 0.5));
    assert_eq!(s.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
    assert_eq!(s.type_mask.bits(), 0b1101_1100_0111, "velocity only");
    let p = plan_of(Command::VelocityNed {
        vel_ned_mps: [0.0; 3],
        yaw_rate_dps: Some(-90.0),
    });
    let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(s)) = &p.setpoint else {
        panic!("{p:?}")
    };
    assert_eq!(
        s.type_mask.bits(),
        0b0101_1100_0111,
        "velocity and yaw rate"
    );
    assert!((s.yaw_rate + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
}

#[test]
fn yaw_roi_gimbal_camera_and_servo() {
    let c = plan_of(Command::SetYaw {
        yaw_deg: -30.0,
        rate_dps: 20.0,
        relative: true,
    });
    let c = long_of(&c);
    assert_eq!(c.command, MavCmd::MAV_CMD_CONDITION_YAW);
    assert_eq!(
        [c.param1, c.param2, c.param3, c.param4],
        [30.0, 20.0, -1.0, 1.0]
    );
    let c = plan_of(Command::SetYaw {
        yaw_deg: -30.0,
        rate_dps: 0.0,
        relative: false,
    });
    let c = long_of(&c);
    assert_eq!(
        [c.param1, c.param2, c.param3, c.param4],
        [330.0, 0.0, 0.0, 0.0]
    );

    let p = plan_of(Command::SetRoi {
        lat_deg: 1.5,
        lon_deg: -2.5,
        alt_rel_m: 3.0,
    });
    let Some(MavCommand::Int(c)) = &p.command else {
        panic!("{p:?}")
    };
    assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_ROI_LOCATION);
    assert_eq!((c.x, c.y, c.z), (15_000_000, -25_000_000, 3.0));
    assert_eq!(c.frame, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT);
    assert_eq!(
        long_of(&plan_of(Command::ClearRoi)).command,
        MavCmd::MAV_CMD_DO_SET_ROI_NONE
    );

    let g = plan_of(Command::Gimbal {
        pitch_deg: -45.0,
        yaw_deg: 10.0,
    });
    let g = long_of(&g);
    assert_eq!(g.command, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW);
    assert_eq!((g.param1, g.param2, g.param5), (-45.0, 10.0, 32.0));
    assert!(g.param3.is_nan() && g.param4.is_nan());

    let cam = plan_of(Command::CameraCapture);
    let cam = long_of(&cam);
    assert_eq!(cam.command, MavCmd::MAV_CMD_IMAGE_START_CAPTURE);
    assert_eq!((cam.param3, cam.param4), (1.0, 7.0));
    assert_eq!(
        long_of(&plan_of(Command::RecordStart)).command,
        MavCmd::MAV_CMD_VIDEO_START_CAPTURE
    );
    assert_eq!(
        long_of(&plan_of(Command::RecordStop)).command,
        MavCmd::MAV_CMD_VIDEO_STOP_CAPTURE
    );
    let s = plan_of(Command::Servo {
        channel: 9,
        pwm_us: 1900,
    });
    let s = long_of(&s);
    assert_eq!(s.command, MavCmd::MAV_CMD_DO_SET_SERVO);
    assert_eq!((s.param1, s.param2), (9.0, 1900.0));
}

#[test]
fn set_home_is_a_command_int_in_the_global_frame_with_msl_altitude() {
    let p = plan_of(Command::SetHome {
        lat_deg: -35.363261,
        lon_deg: 149.16523,
        alt_msl_m: 584.5,
    });
    assert!(p.setpoint.is_none());
    let Some(MavCommand::Int(c)) = &p.command else {
        panic!("{p:?}")
    };
    assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_HOME);
    assert_eq!(c.frame, MavFrame::MAV_FRAME_GLOBAL);
    assert_eq!(c.param1, 0.0, "the given location, not the current one");
    assert_eq!((c.x, c.y, c.z), (-353_632_610, 1_491_652_300, 584.5));
    assert_eq!((c.target_system, c.target_component), (1, 1));
    let cmd = p.command.unwrap();
    assert_eq!(
        cmd.key(),
        AnswerKey::CommandAck(MavCmd::MAV_CMD_DO_SET_HOME as u32)
    );
    assert!(cmd.retransmits());
    assert!(matches!(cmd.message(), MavMessage::COMMAND_INT(_)));
    // (0, 0) would set home to wherever the vehicle is.
    let err = plan(
        &Command::SetHome {
            lat_deg: 0.0,
            lon_deg: 0.0,
            alt_msl_m: 10.0,
        },
        &ctx(FlightMode::Loiter),
    )
    .unwrap_err();
    assert!(err.contains("'here'"), "{err}");
}

#[test]
fn brake_holds_guided_with_zero_velocity_and_switches_to_brake_otherwise() {
    let p = plan(&Command::Brake, &ctx(FlightMode::Guided)).unwrap();
    assert!(p.command.is_none());
    let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(s)) = &p.setpoint else {
        panic!("{p:?}")
    };
    assert_eq!((s.vx, s.vy, s.vz), (0.0, 0.0, 0.0));
    for mode in [FlightMode::Auto, FlightMode::Rtl, FlightMode::Unknown] {
        let p = plan(&Command::Brake, &ctx(mode)).unwrap();
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
        assert_eq!(c.param2, 17.0);
    }
    // The stop tracker's frames: BRAKE counting its repeats, and the zero setpoint.
    let MavCommand::Long(c) = brake_mode(T, 2).unwrap() else {
        panic!("COMMAND_LONG")
    };
    assert_eq!(
        (c.command, c.param2, c.confirmation),
        (MavCmd::MAV_CMD_DO_SET_MODE, 17.0, 2)
    );
    assert_eq!(
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(match zero_velocity(T) {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) => s,
            other => panic!("{other:?}"),
        }),
        plan(&Command::Brake, &ctx(FlightMode::Guided))
            .unwrap()
            .setpoint
            .unwrap()
    );
    assert!(plan(&Command::EmergencyStop, &ctx(FlightMode::Guided)).is_err());
}

#[test]
fn gopro_set_is_a_gopro_set_request_to_the_gimbal() {
    let p = plan_of(Command::GoProSet {
        command: 1,
        value: [1, 0, 0, 0],
    });
    assert!(p.setpoint.is_none());
    let Some(MavCommand::GoPro(r)) = &p.command else {
        panic!("{p:?}")
    };
    assert_eq!((r.target_system, r.target_component), (1, GIMBAL_COMPONENT));
    assert_eq!(r.cmd_id, GoproCommand::GOPRO_COMMAND_CAPTURE_MODE);
    assert_eq!(r.value, [1, 0, 0, 0]);
    let cmd = p.command.unwrap();
    assert_eq!(cmd.key(), AnswerKey::GoPro(1));
    assert!(!cmd.retransmits());
    assert!(matches!(cmd.message(), MavMessage::GOPRO_SET_REQUEST(_)));
    // Every id the dialect knows maps to itself.
    for id in 0..=16 {
        assert_eq!(gopro_command(id).map(|c| c as u8), Some(id));
    }
    // ipc-types refuses ids above the dialect's last GOPRO_COMMAND; the mapping
    // still refuses them should a wire struct carry one.
    assert_eq!(skymesh_ipc_types::command::limits::MAX_GOPRO_COMMAND, 16);
    assert!(gopro_command(17).is_none());
    let arm = plan_of(Command::Arm { force: false }).command.unwrap();
    assert_eq!(arm.key(), AnswerKey::CommandAck(400));
    assert!(arm.retransmits());
}

#[test]
fn motor_test_and_camera_zoom_map_to_do_motor_test_and_set_camera_zoom() {
    let p = plan_of(Command::MotorTest {
        motor: 3,
        throttle_pct: 12.5,
        duration_s: 2.0,
    });
    assert!(p.setpoint.is_none());
    let c = long_of(&p);
    assert_eq!((c.target_system, c.target_component), (1, 1));
    assert_eq!(c.command, MavCmd::MAV_CMD_DO_MOTOR_TEST);
    // Motor 3, MOTOR_TEST_THROTTLE_PERCENT, 12.5 %, 2 s, one motor.
    assert_eq!(
        [c.param1, c.param2, c.param3, c.param4, c.param5],
        [3.0, 0.0, 12.5, 2.0, 1.0]
    );
    assert_eq!(
        p.command.unwrap().key(),
        AnswerKey::CommandAck(MavCmd::MAV_CMD_DO_MOTOR_TEST as u32)
    );

    for (mode, value, p1) in [
        (ZoomMode::Step, -3.0, 0.0),
        (ZoomMode::Continuous, 1.0, 1.0),
        (ZoomMode::Range, 55.5, 2.0),
    ] {
        let p = plan_of(Command::CameraZoom {
            camera: 2,
            mode,
            value,
        });
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_SET_CAMERA_ZOOM);
        // param1 CAMERA_ZOOM_TYPE, param2 the value, param3 the camera id.
        assert_eq!([c.param1, c.param2, c.param3], [p1, value, 2.0], "{mode}");
        assert_eq!([c.param4, c.param5, c.param6, c.param7], [0.0; 4]);
    }
}

#[test]
fn camera_mode_and_capture_stop_carry_the_camera_id_in_param1() {
    for (mode, p2) in [
        (CameraModeKind::Image, 0.0),
        (CameraModeKind::Video, 1.0),
        (CameraModeKind::ImageSurvey, 2.0),
    ] {
        let p = plan_of(Command::CameraMode { camera: 3, mode });
        assert!(p.setpoint.is_none());
        let c = long_of(&p);
        assert_eq!((c.target_system, c.target_component), (1, 1));
        assert_eq!(c.command, MavCmd::MAV_CMD_SET_CAMERA_MODE);
        assert_eq!((c.param1, c.param2), (3.0, p2), "{mode}");
        assert!(c.param3.is_nan() && c.param4.is_nan() && c.param7.is_nan());
        assert_eq!((c.param5, c.param6), (0.0, 0.0));
    }
    let p = plan_of(Command::CameraCaptureStop { camera: 0 });
    let c = long_of(&p);
    assert_eq!(c.command, MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE);
    assert_eq!(c.param1, 0.0, "every camera");
    assert!(c.param2.is_nan() && c.param3.is_nan() && c.param4.is_nan());
    assert_eq!(
        p.command.unwrap().key(),
        AnswerKey::CommandAck(MavCmd::MAV_CMD_IMAGE_STOP_CAPTURE as u32)
    );
    let c = plan_of(Command::CameraCaptureStop { camera: 200 });
    assert_eq!(long_of(&c).param1, 200.0);
}

#[test]
fn gimbal_rate_is_pitchyaw_with_unset_angles_and_the_rates() {
    let p = plan_of(Command::GimbalRate {
        pitch_rate_dps: -15.0,
        yaw_rate_dps: 30.0,
    });
    let g = long_of(&p);
    assert_eq!(g.command, MavCmd::MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW);
    assert!(g.param1.is_nan() && g.param2.is_nan(), "no angle");
    assert_eq!(
        [g.param3, g.param4, g.param5, g.param6, g.param7],
        [-15.0, 30.0, 32.0, 0.0, 0.0]
    );
    // Same MAV_CMD as an angle command: a rate supersedes a pending angle.
    let angle = plan_of(Command::Gimbal {
        pitch_deg: 0.0,
        yaw_deg: 0.0,
    });
    assert_eq!(p.command.unwrap().key(), angle.command.unwrap().key());
}

#[test]
fn camera_focus_maps_type_value_and_camera() {
    for (mode, value, p1, p2) in [
        (FocusMode::Step, 1.0, 0.0, 1.0),
        (FocusMode::Continuous, -1.0, 1.0, -1.0),
        (FocusMode::Range, 42.5, 2.0, 42.5),
        (FocusMode::Meters, 12.0, 3.0, 12.0),
        (FocusMode::Auto, 99.0, 4.0, 0.0),
        (FocusMode::AutoSingle, 0.0, 5.0, 0.0),
        (FocusMode::AutoContinuous, -3.0, 6.0, 0.0),
    ] {
        let p = plan_of(Command::CameraFocus {
            camera: 2,
            mode,
            value,
        });
        let c = long_of(&p);
        assert_eq!(c.command, MavCmd::MAV_CMD_SET_CAMERA_FOCUS);
        // param1 SET_FOCUS_TYPE, param2 the value (0 when ignored), param3 camera.
        assert_eq!([c.param1, c.param2, c.param3], [p1, p2, 2.0], "{mode}");
        assert!(c.param4.is_nan());
    }
}
