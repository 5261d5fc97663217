//! Fixtures shared by the gimbal v2 tests.

pub(super) use super::*;
pub(super) use mavlink::dialects::ardupilotmega::{
    COMMAND_INT_DATA, COMMAND_LONG_DATA, GIMBAL_MANAGER_SET_ATTITUDE_DATA,
    GIMBAL_MANAGER_SET_PITCHYAW_DATA,
};
pub(super) use mavlink::Message as _;
pub(super) use skymesh_ipc_types::{FixedStr, ZoomMode};

pub(super) const SYS: u8 = 1;
pub(super) const GCS: (u8, u8) = (255, 190);
pub(super) const OTHER: (u8, u8) = (254, 190);
pub(super) const T0: u64 = 10_000_000_000;

pub(super) fn gimbals() -> GimbalV2 {
    GimbalV2::new(
        SYS,
        &VisionSettings {
            components: vec![154, 171, 172, 173],
            ..VisionSettings::default()
        },
        1000,
        T0,
    )
}

pub(super) fn state(active: &[usize], stamp_ns: u64) -> VisionState {
    let mut s = VisionState::default();
    s.header.stamp_ns = stamp_ns;
    s.stream_count = 1;
    s.streams[0].configured = 1;
    for &i in active {
        s.streams[0].cams[i].active = 1;
        s.streams[0].cams[i].lock_flags = LOCK_YAW | LOCK_PITCH;
        s.streams[0].cams[i].ned_from_cam_q = [0.9, 0.1, -0.3, 0.3];
    }
    s
}

pub(super) fn handle(
    g: &mut GimbalV2,
    from: (u8, u8),
    msg: MavMessage,
    home: Option<f32>,
) -> Output {
    let mut out = Output::default();
    g.handle(Incoming { from, msg: &msg }, home, T0, &mut out);
    out
}

pub(super) fn long(target: u8, command: MavCmd, p: [f32; 7]) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: SYS,
        target_component: target,
        command,
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
        ..COMMAND_LONG_DATA::DEFAULT
    })
}

pub(super) fn roi_int(frame: MavFrame, z: f32) -> MavMessage {
    MavMessage::COMMAND_INT(COMMAND_INT_DATA {
        target_system: SYS,
        target_component: 154,
        frame,
        command: MavCmd::MAV_CMD_DO_SET_ROI_LOCATION,
        x: 473_977_420,
        y: 85_455_940,
        z,
        ..COMMAND_INT_DATA::DEFAULT
    })
}

pub(super) fn pitchyaw_msg(target: u8, device: u8, pitch: f32, yaw: f32) -> MavMessage {
    MavMessage::GIMBAL_MANAGER_SET_PITCHYAW(GIMBAL_MANAGER_SET_PITCHYAW_DATA {
        target_system: SYS,
        target_component: target,
        flags: GimbalManagerFlags::from_bits_truncate(FLAG_YAW_LOCK),
        gimbal_device_id: device,
        pitch,
        yaw,
        pitch_rate: f32::NAN,
        yaw_rate: f32::NAN,
    })
}

pub(super) fn acks(out: &Output) -> Vec<(u8, MavCmd, MavResult)> {
    out.sends
        .iter()
        .filter_map(|(c, m)| match m {
            MavMessage::COMMAND_ACK(a) => Some((*c, a.command, a.result)),
            _ => None,
        })
        .collect()
}

pub(super) fn reply(id: u64, result: VisionResult) -> VisionReply {
    VisionReply {
        request_id: id,
        result: result.to_wire(),
        message: FixedStr::new("why"),
        ..VisionReply::default()
    }
}
