//! Unit tests of [`super::Inbound`]: one record at a time, no I/O.

use super::*;
use gc_proto::{pack_text, Params};

fn wp(t: NetCmdType, ctx: i32, xyz_speed: [f32; 4], yaw_cdeg: i32) -> Record {
    Record::floats(t, ctx, yaw_cdeg, 0, xyz_speed)
}

fn published(v: Verdict) -> SwarmCommand {
    match v {
        Verdict::Publish(c) => *c,
        other => panic!("expected a command, got {other:?}"),
    }
}

fn reason(v: Verdict) -> RefuseReason {
    match v {
        Verdict::Refused(r) => r.reason,
        other => panic!("expected a refusal, got {other:?}"),
    }
}

#[test]
fn a_waypoint_becomes_a_command() {
    let mut ib = Inbound::new(7, false);
    let c = published(ib.on_record(&wp(
        NetCmdType::CmdExtWaypoint,
        3,
        [1.0, -2.0, 5.0, 1.5],
        9000,
    )));
    assert_eq!((c.client, c.drone), (7, 3));
    assert_eq!(c.kind(), Ok(SwarmCommandKind::ExtWaypoint));
    assert_eq!(&c.f[..4], &[1.0, -2.0, 5.0, 1.5]);
    assert_eq!(c.int1, 9000);
    assert_eq!(c.flags, 0);
    assert_eq!(c.request_id, 0);
}

#[test]
fn ping_is_answered_for_everyone() {
    let mut ib = Inbound::new(1, false);
    let req = Record::ping_request(5, 10.0, 20.0);
    match ib.on_record(&req) {
        Verdict::Reply(r) => {
            assert_eq!(r.net_type(), Some(NetCmdType::PingResponse));
            assert_eq!(r.int1, 5);
            assert_eq!(r.params, Params::Doubles([10.0, 20.0]));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn privilege() {
    let emergency = Record::floats(NetCmdType::CmdEmergencyMode, 2, 1, 0, [0.0; 4]);
    let mut ib = Inbound::new(1, false);
    assert_eq!(
        reason(ib.on_record(&emergency)),
        RefuseReason::NotPrivileged
    );
    let reset = Record::new(NetCmdType::CmdResetTrackingToSetup, 2);
    assert_eq!(reason(ib.on_record(&reset)), RefuseReason::NotPrivileged);
    let blob = Record::new(NetCmdType::DataBlob, 0);
    assert_eq!(reason(ib.on_record(&blob)), RefuseReason::NotPrivileged);
    let mut ib = Inbound::new(1, true);
    let c = published(ib.on_record(&emergency));
    assert_eq!(c.kind(), Ok(SwarmCommandKind::EmergencyMode));
    assert_eq!(c.flags, swarm_flags::PRIVILEGED);
    assert_eq!(reason(ib.on_record(&blob)), RefuseReason::Unsupported);
}

#[test]
fn parameters_merge_into_the_next_command_of_their_drone_then_clear() {
    let mut ib = Inbound::new(1, false);
    let p1 = Record::floats(NetCmdType::ExtParam1, 4, 0, 0, [1.0, 0.5, 0.0, 0.0]);
    let p2 = Record::floats(NetCmdType::ExtParam2, 4, 0, 0, [0.0, 0.0, 1.0, 0.0]);
    let other = Record::floats(NetCmdType::ExtParam1, 5, 0, 0, [0.2, 0.2, 0.2, 0.0]);
    assert_eq!(ib.on_record(&p1), Verdict::Stored);
    assert_eq!(ib.on_record(&p2), Verdict::Stored);
    assert_eq!(ib.on_record(&other), Verdict::Stored);
    let grad = Record::floats(
        NetCmdType::CmdExtColorGradient,
        4,
        0,
        0,
        [2.0, 0.0, 0.0, 0.0],
    );
    let c = published(ib.on_record(&grad));
    assert_eq!(c.flags, swarm_flags::HAS_EXT1 | swarm_flags::HAS_EXT2);
    assert_eq!(c.rgb1(), [1.0, 0.5, 0.0]);
    assert_eq!(c.rgb2(), [0.0, 0.0, 1.0]);
    assert_eq!(c.f[0], 2.0);
    // Cleared: the same command again lacks its parameters.
    assert_eq!(reason(ib.on_record(&grad)), RefuseReason::MissingExtParam);
    // Drone 5's are still there.
    let color = Record::floats(NetCmdType::CmdExtColor, 5, 0, 0, [0.0; 4]);
    assert_eq!(published(ib.on_record(&color)).rgb1(), [0.2, 0.2, 0.2]);
    assert_eq!(ib.pending_contexts(), 0);
}

#[test]
fn bitmask_contexts_of_the_reference_client_still_apply() {
    // CmdExtColor({0, 1}): EXT_PARAM_1 context 0b11, CMD_EXT_COLOR context 0, twice.
    let mut ib = Inbound::new(1, false);
    for drone in [0, 1] {
        let p = Record::floats(NetCmdType::ExtParam1, 0b11, 0, 0, [0.0, 1.0, 0.0, 0.0]);
        assert_eq!(ib.on_record(&p), Verdict::Stored);
        let c = Record::floats(NetCmdType::CmdExtColor, drone, 0, 0, [1.0, 0.0, 0.0, 0.0]);
        let cmd = published(ib.on_record(&c));
        assert_eq!(cmd.drone, drone as u16);
        assert_eq!(cmd.rgb1(), [0.0, 1.0, 0.0]);
    }
    assert_eq!(ib.pending_contexts(), 0);
    // Not adjacent: a waypoint in between breaks the link.
    let p = Record::floats(NetCmdType::ExtParam1, 9, 0, 0, [0.0, 1.0, 0.0, 0.0]);
    ib.on_record(&p);
    published(ib.on_record(&wp(NetCmdType::CmdExtWaypoint, 2, [0.0; 4], 0)));
    let c = Record::floats(NetCmdType::CmdExtColor, 0, 0, 0, [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(reason(ib.on_record(&c)), RefuseReason::MissingExtParam);
}

#[test]
fn global_commands_go_to_every_drone() {
    let mut ib = Inbound::new(1, false);
    let idle = Record::new(NetCmdType::CmdExtCheckAllIdle, 0);
    assert_eq!(published(ib.on_record(&idle)).drone, ALL_DRONES);
    let min = Record::floats(NetCmdType::ExtParam1, 0, 0, 0, [-10.0, -10.0, 0.0, 0.0]);
    ib.on_record(&min);
    let bbox = Record::floats(
        NetCmdType::CmdExtSetBoundingBox,
        0,
        0,
        0,
        [10.0, 10.0, 5.0, 0.0],
    );
    let c = published(ib.on_record(&bbox));
    assert_eq!(c.drone, ALL_DRONES);
    assert!(c.has(swarm_flags::HAS_EXT1));
}

#[test]
fn bad_contexts_types_and_values() {
    let mut ib = Inbound::new(1, true);
    for ctx in [-1, 65535, 70_000, i32::MIN] {
        let r = wp(NetCmdType::CmdExtWaypoint, ctx, [0.0; 4], 0);
        assert_eq!(reason(ib.on_record(&r)), RefuseReason::BadContext, "{ctx}");
    }
    let unknown = Record {
        kind: 0x7777,
        ..Record::default()
    };
    assert_eq!(reason(ib.on_record(&unknown)), RefuseReason::UnknownType);
    let ack = Record::ack(true, 1, 0xA6);
    assert_eq!(reason(ib.on_record(&ack)), RefuseReason::WrongDirection);
    let nan = wp(NetCmdType::CmdExtWaypoint, 1, [f32::NAN, 0.0, 0.0, 0.0], 0);
    assert_eq!(reason(ib.on_record(&nan)), RefuseReason::InvalidValue);
    let far = wp(NetCmdType::CmdExtWaypoint, 1, [1e6, 0.0, 0.0, 0.0], 0);
    assert_eq!(reason(ib.on_record(&far)), RefuseReason::InvalidValue);
    let yaw = wp(NetCmdType::CmdExtWaypoint, 1, [0.0; 4], 99_999);
    assert_eq!(reason(ib.on_record(&yaw)), RefuseReason::InvalidValue);
    assert_eq!(
        ib.on_record(&Record::new(NetCmdType::ExtParamAck, 1)),
        Verdict::Ignored
    );
}

#[test]
fn non_finite_numbers_are_refused_even_where_the_kind_ignores_them() {
    let mut ib = Inbound::new(1, true);
    // CMD_EXT_HALT gives its floats no meaning (validate does not look at them).
    for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let halt = wp(NetCmdType::CmdExtHalt, 1, [0.0, v, 0.0, 0.0], 0);
        assert_eq!(
            reason(ib.on_record(&halt)),
            RefuseReason::InvalidValue,
            "{v}"
        );
    }
    // A NaN in a parameter record reaches the command's ext slots: refused there.
    let p1 = wp(NetCmdType::ExtParam1, 2, [0.5, f32::NAN, 0.5, 0.0], 0);
    assert_eq!(ib.on_record(&p1), Verdict::Stored);
    let halt = wp(NetCmdType::CmdExtHalt, 2, [0.0; 4], 0);
    assert_eq!(reason(ib.on_record(&halt)), RefuseReason::InvalidValue);
    // Finite values in the same places pass.
    let halt = wp(NetCmdType::CmdExtHalt, 2, [0.0, 1e30, 0.0, 0.0], 0);
    assert_eq!(published(ib.on_record(&halt)).drone, 2);
}

#[test]
fn text() {
    let mut ib = Inbound::new(1, false);
    let (int2, longs) = pack_text("GO TEAM").unwrap();
    let r = Record {
        int2,
        params: Params::Longs(longs),
        ..Record::new(NetCmdType::CmdExtText, 2)
    };
    let c = published(ib.on_record(&r));
    assert_eq!(c.text.as_str(), "GO TEAM");
    assert_eq!(c.d, [longs[0] as u64, longs[1] as u64]);
    assert_eq!(&c.f[..4], &[0.0; 4]);
    let bad = Record {
        int2: i32::from_le_bytes([0xFF, 0xFE, 0, 0]),
        ..r
    };
    assert_eq!(reason(ib.on_record(&bad)), RefuseReason::InvalidValue);
}

#[test]
fn pending_parameters_are_bounded() {
    let mut ib = Inbound::new(1, false);
    for ctx in 0..MAX_PENDING_CONTEXTS as i32 {
        let p = Record::floats(NetCmdType::ExtParam1, ctx, 0, 0, [0.0; 4]);
        assert_eq!(ib.on_record(&p), Verdict::Stored);
    }
    let p = Record::floats(NetCmdType::ExtParam1, -5, 0, 0, [0.0; 4]);
    assert_eq!(reason(ib.on_record(&p)), RefuseReason::TooManyPending);
    // An existing context can still be updated.
    let p = Record::floats(NetCmdType::ExtParam2, 3, 0, 0, [0.0; 4]);
    assert_eq!(ib.on_record(&p), Verdict::Stored);
}

#[test]
fn a_refused_geofence_command_is_answered_ack_cmd_timeout() {
    let fence = |t| Record::floats(t, 4, 0, 0, [10.0, 10.0, 5.0, 0.0]);
    let timeout = |t: NetCmdType| Some(Record::ack(false, 4, t.id()));
    // Not privileged.
    let mut ib = Inbound::new(1, false);
    for t in [
        NetCmdType::CmdSetGeofence,
        NetCmdType::CmdSetGeofencePosition,
        NetCmdType::CmdReconfigureGeofence,
    ] {
        match ib.on_record(&fence(t)) {
            Verdict::Refused(r) => {
                assert_eq!(r.reason, RefuseReason::NotPrivileged);
                assert_eq!(r.reply, timeout(t), "{t}");
            }
            other => panic!("{t}: {other:?}"),
        }
    }
    // Privileged, but NaN: refused as invalid, still answered.
    let mut ib = Inbound::new(1, true);
    let nan = Record::floats(NetCmdType::CmdSetGeofence, 4, 0, 0, [f32::NAN; 4]);
    match ib.on_record(&nan) {
        Verdict::Refused(r) => {
            assert_eq!(r.reason, RefuseReason::InvalidValue);
            assert_eq!(r.reply, timeout(NetCmdType::CmdSetGeofence));
        }
        other => panic!("{other:?}"),
    }
    // Other refusals have no record.
    let mut ib = Inbound::new(1, false);
    let emergency = Record::floats(NetCmdType::CmdEmergencyMode, 2, 1, 0, [0.0; 4]);
    match ib.on_record(&emergency) {
        Verdict::Refused(r) => assert_eq!(r.reply, None),
        other => panic!("{other:?}"),
    }
    assert_eq!(refusal_reply(&emergency), None);
    assert_eq!(
        refusal_reply(&fence(NetCmdType::CmdSetGeofence)),
        timeout(NetCmdType::CmdSetGeofence)
    );
}
