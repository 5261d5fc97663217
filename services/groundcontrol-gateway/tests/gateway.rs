//! groundcontrol-gateway in-process: records → SwarmCommands, privilege, parameter
//! records, replies routed to the right client, CHECK_ALL_IDLE per drone.

mod common;

use std::time::Duration;

use common::{other_host, privileged_host, Gateway, PATIENCE};
use gc_proto::{NetCmdType, Params, Record};
use skymesh_groundcontrol_gateway::client::GcClient;
use skymesh_ipc_types::{swarm_flags, ServiceId, SwarmCommandKind, SwarmResult, ALL_DRONES};

fn waypoint(drone: i32, xyz: [f32; 3], speed: f32, yaw_cdeg: i32) -> Record {
    Record::floats(
        NetCmdType::CmdExtWaypoint,
        drone,
        yaw_cdeg,
        0,
        [xyz[0], xyz[1], xyz[2], speed],
    )
}

#[tokio::test]
async fn records_split_across_chunks_become_commands() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect(gw.tcp).await.expect("connect");
    let records = [
        waypoint(3, [1.5, -2.0, 10.0], 2.0, 9000),
        Record::new(NetCmdType::CmdExtGoExternal, 4),
        waypoint(4, [0.0, 0.0, 5.0], 0.0, -4500),
    ];
    let bytes: Vec<u8> = records.iter().flat_map(|r| r.encode()).collect();
    // Cut inside the first record's header, inside the second's floats, and one
    // byte before the end.
    for piece in [&bytes[..5], &bytes[5..53], &bytes[53..95], &bytes[95..]] {
        client.send_raw(piece).await.expect("send");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let a = gw.next_command().await;
    let b = gw.next_command().await;
    let c = gw.next_command().await;
    assert_eq!(a.kind(), Ok(SwarmCommandKind::ExtWaypoint));
    assert_eq!((a.drone, a.int1), (3, 9000));
    assert_eq!(&a.f[..4], &[1.5, -2.0, 10.0, 2.0]);
    assert_eq!(a.header.service_id(), Ok(ServiceId::GroundcontrolGateway));
    assert_eq!(a.flags, swarm_flags::PRIVILEGED, "127.0.0.1 is privileged");
    assert_eq!(b.kind(), Ok(SwarmCommandKind::ExtGoExternal));
    assert_eq!(b.drone, 4);
    assert_eq!((c.drone, c.int1), (4, -4500));
    // One connection, unique request ids.
    assert_eq!(a.client, b.client);
    assert_eq!(b.client, c.client);
    assert_ne!(a.request_id, 0);
    assert!(a.request_id < b.request_id && b.request_id < c.request_id);
    gw.wait_metric("skymesh_gc_commands_published_total", "", 3.0)
        .await;
    gw.wait_metric("skymesh_gc_records_in_total", "type=cmd_ext_waypoint", 2.0)
        .await;
    gw.wait_metric("skymesh_gc_clients", "", 1.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn ping_is_answered_with_the_sequence_and_doubles() {
    let gw = Gateway::start().await;
    let mut client = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect");
    for seq in [0, 1, 77] {
        client
            .send(&Record::ping_request(seq, 125.5, 900.25))
            .await
            .expect("send");
        let r = client.recv(PATIENCE).await.expect("open").expect("a reply");
        assert_eq!(r.net_type(), Some(NetCmdType::PingResponse));
        assert_eq!(r.int1, seq);
        assert_eq!(r.params, Params::Doubles([125.5, 900.25]));
    }
    gw.wait_metric("skymesh_gc_records_out_total", "type=ping_response", 3.0)
        .await;
    gw.stop().await;
}

#[tokio::test]
async fn a_non_privileged_client_is_limited_to_ext_commands() {
    let mut gw = Gateway::start().await;
    let mut guest = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect");
    let emergency = Record {
        int1: 1,
        ..Record::new(NetCmdType::CmdEmergencyMode, 2)
    };
    guest.send(&emergency).await.expect("send");
    guest
        .send(&Record::new(NetCmdType::CmdResetTrackingToSetup, 2))
        .await
        .expect("send");
    gw.wait_refused("not_privileged", 2.0).await;
    // A refused geofence command is answered ACK_CMD_TIMEOUT (issue 43): the client
    // must not believe a fence is in force.
    guest
        .send(&Record::floats(
            NetCmdType::CmdSetGeofence,
            2,
            0,
            0,
            [5.0, 5.0, 5.0, 0.0],
        ))
        .await
        .expect("send");
    let ack = guest.recv(PATIENCE).await.expect("open").expect("an ack");
    assert_eq!(ack.net_type(), Some(NetCmdType::AckCmdTimeout));
    assert_eq!(
        (ack.context, ack.int1),
        (2, NetCmdType::CmdSetGeofence.id())
    );
    gw.wait_refused("not_privileged", 3.0).await;
    // Still connected, and CMD_EXT_* goes through (without the privileged flag).
    guest
        .send(&waypoint(2, [1.0, 1.0, 1.0], 1.0, 0))
        .await
        .expect("send");
    let c = gw.next_command().await;
    assert_eq!(c.kind(), Ok(SwarmCommandKind::ExtWaypoint));
    assert_eq!(c.flags & swarm_flags::PRIVILEGED, 0);

    // The same command from a privileged address is published.
    let mut operator = GcClient::connect_from(privileged_host(), gw.tcp)
        .await
        .expect("connect");
    operator.send(&emergency).await.expect("send");
    let c = gw.next_command().await;
    assert_eq!(c.kind(), Ok(SwarmCommandKind::EmergencyMode));
    assert_eq!((c.drone, c.int1), (2, 1));
    assert!(c.has(swarm_flags::PRIVILEGED));
    assert_ne!(c.client, 0);
    assert_eq!(
        gw.metric("skymesh_gc_refused_total", "reason=not_privileged"),
        Some(3.0)
    );
    gw.stop().await;
}

#[tokio::test]
async fn parameter_records_merge_into_the_next_command_of_their_drone() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect");
    client
        .send_all(&[
            Record::floats(NetCmdType::ExtParam1, 5, 0, 0, [1.0, 0.0, 0.0, 0.0]),
            Record::floats(NetCmdType::ExtParam2, 5, 0, 0, [0.0, 0.0, 1.0, 0.0]),
            // Another drone's parameters in between stay with that drone.
            Record::floats(NetCmdType::ExtParam1, 6, 0, 0, [0.5, 0.5, 0.5, 0.0]),
            Record::floats(
                NetCmdType::CmdExtColorGradient,
                5,
                0,
                0,
                [4.0, 0.0, 0.0, 0.0],
            ),
            // Cleared after use: a second gradient lacks them.
            Record::floats(
                NetCmdType::CmdExtColorGradient,
                5,
                0,
                0,
                [4.0, 0.0, 0.0, 0.0],
            ),
            Record::floats(NetCmdType::CmdExtColor, 6, 0, 0, [1.0, 0.0, 0.0, 0.0]),
            Record::new(NetCmdType::ExtParamAck, 6),
        ])
        .await
        .expect("send");
    let grad = gw.next_command().await;
    assert_eq!(grad.kind(), Ok(SwarmCommandKind::ExtColorGradient));
    assert_eq!(grad.drone, 5);
    assert_eq!(
        grad.flags & 0x03,
        swarm_flags::HAS_EXT1 | swarm_flags::HAS_EXT2
    );
    assert_eq!(grad.rgb1(), [1.0, 0.0, 0.0]);
    assert_eq!(grad.rgb2(), [0.0, 0.0, 1.0]);
    assert_eq!(grad.f[0], 4.0);
    let color = gw.next_command().await;
    assert_eq!(color.kind(), Ok(SwarmCommandKind::ExtColor));
    assert_eq!(color.drone, 6);
    assert_eq!(color.rgb1(), [0.5, 0.5, 0.5]);
    gw.wait_refused("missing_ext_param", 1.0).await;
    gw.wait_metric("skymesh_gc_records_in_total", "type=ext_param_ack", 1.0)
        .await;
    gw.no_command_for(Duration::from_millis(200)).await;
    gw.stop().await;
}

#[tokio::test]
async fn invalid_records_are_refused_and_the_connection_keeps_working() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect(gw.tcp).await.expect("connect");
    client
        .send_all(&[
            waypoint(1, [f32::NAN, 0.0, 0.0], 1.0, 0),
            waypoint(1, [0.0, 0.0, 1e9], 1.0, 0),
            waypoint(1, [0.0, 0.0, 1.0], 1000.0, 0),
            Record {
                kind: 0x7777,
                ..Record::default()
            },
            waypoint(-1, [0.0, 0.0, 1.0], 1.0, 0),
            waypoint(70_000, [0.0, 0.0, 1.0], 1.0, 0),
            Record::ack(true, 1, 0xA6),
            Record::new(NetCmdType::DataBlob, 0),
        ])
        .await
        .expect("send");
    gw.wait_refused("invalid_value", 3.0).await;
    gw.wait_refused("unknown_type", 1.0).await;
    gw.wait_refused("bad_context", 2.0).await;
    gw.wait_refused("wrong_direction", 1.0).await;
    gw.wait_refused("unsupported", 1.0).await;
    // Nothing was published, and the connection still works.
    client
        .send(&Record::ping_request(9, 0.0, 0.0))
        .await
        .expect("send");
    let pong = client.recv(PATIENCE).await.expect("open").expect("reply");
    assert_eq!(
        (pong.net_type(), pong.int1),
        (Some(NetCmdType::PingResponse), 9)
    );
    client
        .send(&waypoint(1, [0.0, 0.0, 1.0], 1.0, 0))
        .await
        .expect("send");
    let c = gw.next_command().await;
    assert_eq!((c.kind(), c.drone), (Ok(SwarmCommandKind::ExtWaypoint), 1));
    assert_eq!(
        gw.metric("skymesh_gc_commands_published_total", ""),
        Some(1.0)
    );
    gw.stop().await;
}

#[tokio::test]
async fn a_client_leaving_mid_record_loses_nothing_else() {
    let mut gw = Gateway::start().await;
    let mut a = GcClient::connect(gw.tcp).await.expect("connect a");
    let mut b = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect b");
    // b starts a record, a sends one and a half and leaves.
    let b_rec = waypoint(8, [8.0, 8.0, 8.0], 1.0, 0).encode();
    b.send_raw(&b_rec[..10]).await.expect("send");
    let mut a_bytes = Record::new(NetCmdType::CmdExtHalt, 1).encode().to_vec();
    a_bytes.extend_from_slice(&waypoint(1, [1.0, 1.0, 1.0], 1.0, 0).encode()[..16]);
    a.send_raw(&a_bytes).await.expect("send");
    drop(a);
    let halt = gw.next_command().await;
    assert_eq!(
        (halt.kind(), halt.drone),
        (Ok(SwarmCommandKind::ExtHalt), 1)
    );
    gw.wait_metric("skymesh_gc_disconnects_total", "reason=truncated", 1.0)
        .await;
    gw.wait_metric("skymesh_gc_clients", "", 1.0).await;
    // b finishes its record and carries on.
    b.send_raw(&b_rec[10..]).await.expect("send");
    let c = gw.next_command().await;
    assert_eq!((c.drone, c.f[0]), (8, 8.0));
    assert_ne!(c.client, halt.client);
    gw.no_command_for(Duration::from_millis(200)).await;
    gw.stop().await;
}

#[tokio::test]
async fn acks_go_to_the_client_whose_command_they_answer() {
    let mut gw = Gateway::start().await;
    let mut a = GcClient::connect(gw.tcp).await.expect("connect a");
    let mut b = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect b");
    a.send(&waypoint(1, [1.0, 0.0, 5.0], 0.0, 0))
        .await
        .expect("send");
    let ca = gw.next_command().await;
    b.send(&Record::new(NetCmdType::CmdExtGoExternal, 2))
        .await
        .expect("send");
    let cb = gw.next_command().await;
    assert_ne!(ca.client, cb.client);

    gw.reply(&cb, 2, SwarmResult::Success, 0);
    gw.reply(&ca, 1, SwarmResult::Timeout, 0);
    gw.reply(&ca, 1, SwarmResult::Accepted, 0);
    gw.reply(&ca, 1, SwarmResult::Refused, 0);
    gw.reply(&ca, 1, SwarmResult::Success, 0);

    let rb = b.recv(PATIENCE).await.expect("open").expect("ack for b");
    assert_eq!(rb.net_type(), Some(NetCmdType::AckCmdSuccess));
    assert_eq!((rb.context, rb.int1), (2, 0xA0));
    let ra1 = a
        .recv(PATIENCE)
        .await
        .expect("open")
        .expect("timeout for a");
    assert_eq!(ra1.net_type(), Some(NetCmdType::AckCmdTimeout));
    assert_eq!((ra1.context, ra1.int1), (1, 0xA6));
    let ra2 = a
        .recv(PATIENCE)
        .await
        .expect("open")
        .expect("success for a");
    assert_eq!(ra2.net_type(), Some(NetCmdType::AckCmdSuccess));
    // Accepted and Refused have no record; nothing else arrives.
    assert!(a.collect_for(Duration::from_millis(200)).await.is_empty());
    assert!(b.collect_for(Duration::from_millis(200)).await.is_empty());
    gw.wait_metric("skymesh_gc_queue_replies_total", "result=refused", 1.0)
        .await;
    gw.wait_metric("skymesh_gc_queue_replies_total", "result=accepted", 1.0)
        .await;

    // A reply for a client that has left is dropped and counted.
    drop(b);
    gw.wait_metric("skymesh_gc_clients", "", 1.0).await;
    gw.reply(&cb, 2, SwarmResult::Success, 0);
    gw.wait_metric(
        "skymesh_gc_replies_dropped_total",
        "reason=client_gone",
        1.0,
    )
    .await;
    gw.stop().await;
}

#[tokio::test]
async fn check_all_idle_is_answered_per_drone() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect");
    // The reference client sends context 0 and expects every drone.
    client
        .send(&Record::new(NetCmdType::CmdExtCheckAllIdle, 0))
        .await
        .expect("send");
    let c = gw.next_command().await;
    assert_eq!(c.kind(), Ok(SwarmCommandKind::ExtCheckAllIdle));
    assert_eq!(c.drone, ALL_DRONES);
    let idle = [1, 0, 1, 1, 0];
    for (drone, value) in idle.iter().enumerate() {
        gw.reply(&c, drone as u16, SwarmResult::IdleState, *value);
    }
    let mut got = Vec::new();
    while got.len() < idle.len() {
        let r = client.recv(PATIENCE).await.expect("open").expect("answer");
        assert_eq!(r.net_type(), Some(NetCmdType::CmdExtCheckAllIdle));
        got.push((r.context, r.int1));
    }
    assert_eq!(got, vec![(0, 1), (1, 0), (2, 1), (3, 1), (4, 0)]);
    gw.stop().await;
}

#[tokio::test]
async fn clients_beyond_max_clients_are_closed() {
    let gw = Gateway::start_with(|s| s.max_clients = 2).await;
    let mut a = GcClient::connect(gw.tcp).await.expect("a");
    let mut b = GcClient::connect(gw.tcp).await.expect("b");
    for c in [&mut a, &mut b] {
        c.send(&Record::ping_request(1, 0.0, 0.0))
            .await
            .expect("send");
        assert!(c.recv(PATIENCE).await.expect("open").is_some());
    }
    let mut third = GcClient::connect(gw.tcp).await.expect("tcp accepts");
    assert!(
        third.wait_closed(PATIENCE).await,
        "the third client is closed"
    );
    gw.wait_metric(
        "skymesh_gc_connections_total",
        "result=refused_max_clients",
        1.0,
    )
    .await;
    // The first two are unaffected; when one leaves, a new one fits.
    drop(a);
    gw.wait_metric("skymesh_gc_clients", "", 1.0).await;
    let mut d = GcClient::connect(gw.tcp).await.expect("d");
    d.send(&Record::ping_request(2, 0.0, 0.0))
        .await
        .expect("send");
    assert!(d.recv(PATIENCE).await.expect("open").is_some());
    b.send(&Record::ping_request(3, 0.0, 0.0))
        .await
        .expect("send");
    assert!(b.recv(PATIENCE).await.expect("open").is_some());
    gw.stop().await;
}

#[tokio::test]
async fn a_client_that_stops_reading_is_closed_and_blocks_nobody() {
    let gw = Gateway::start_with(|s| {
        s.outgoing_queue = 16;
        // Only the queue is under test here: no rate limit in the way.
        s.max_records_per_s = 100_000;
        s.record_burst = 100_000;
    })
    .await;
    let mut reader = GcClient::connect(gw.tcp).await.expect("reader");
    let mut stalled = GcClient::connect(gw.tcp).await.expect("stalled");
    // Pings without ever reading the answers: the socket buffers fill, then the
    // 16-record queue, then the gateway closes the connection.
    let burst: Vec<u8> = (0..4096)
        .flat_map(|i| Record::ping_request(i, 0.0, 0.0).encode())
        .collect();
    let flood = tokio::spawn(async move {
        for _ in 0..400 {
            if stalled.send_raw(&burst).await.is_err() {
                return true;
            }
        }
        false
    });
    gw.wait_metric("skymesh_gc_disconnects_total", "reason=overflow", 1.0)
        .await;
    // Meanwhile, and after, the other client is served.
    reader
        .send(&Record::ping_request(5, 0.0, 0.0))
        .await
        .expect("send");
    let r = reader.recv(PATIENCE).await.expect("open").expect("pong");
    assert_eq!(r.int1, 5);
    let _ = flood.await;
    gw.stop().await;
}

#[tokio::test]
async fn a_client_beyond_its_record_rate_is_throttled_and_others_are_not() {
    let mut gw = Gateway::start_with(|s| {
        s.max_records_per_s = 1;
        s.record_burst = 10;
    })
    .await;
    let mut flooder = GcClient::connect(gw.tcp).await.expect("flooder");
    let mut polite = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("polite");
    let flood: Vec<Record> = (0..100)
        .map(|_| Record::new(NetCmdType::CmdExtHalt, 1))
        .collect();
    flooder.send_all(&flood).await.expect("send");
    gw.wait_metric("skymesh_gc_records_in_total", "type=cmd_ext_halt", 100.0)
        .await;
    // Every record of the flood was either published or dropped as rate_limited,
    // and the burst (at least) got through.
    let limited = gw
        .metric("skymesh_gc_refused_total", "reason=rate_limited")
        .expect("rate_limited counted");
    let mut published = 0;
    while let Some(c) = gw
        .commands
        .recv_timeout(Duration::from_millis(300))
        .await
        .expect("swarm_command")
    {
        assert_eq!(c.kind(), Ok(SwarmCommandKind::ExtHalt));
        published += 1;
    }
    assert_eq!(published as f64 + limited, 100.0, "{published} published");
    assert!(published >= 10, "the burst passes: {published}");
    assert!(limited >= 50.0, "the flood is throttled: {limited}");
    // The flooder is still connected, and the other client has its own budget.
    assert!(!flooder.is_closed());
    let before = gw.metric("skymesh_gc_refused_total", "reason=rate_limited");
    let polite_records: Vec<Record> = (0..5)
        .map(|i| waypoint(2, [0.0, 0.0, 1.0 + i as f32], 1.0, 0))
        .collect();
    polite.send_all(&polite_records).await.expect("send");
    for i in 0..5 {
        let c = gw.next_command().await;
        assert_eq!((c.drone, c.f[2]), (2, 1.0 + i as f32));
    }
    assert_eq!(
        gw.metric("skymesh_gc_refused_total", "reason=rate_limited"),
        before
    );
    gw.stop().await;
}

#[tokio::test]
async fn a_record_left_incomplete_closes_only_that_client() {
    let mut gw =
        Gateway::start_with(|s| s.partial_record_timeout = Duration::from_millis(300)).await;
    let mut loris = GcClient::connect(gw.tcp).await.expect("loris");
    let mut other = GcClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("other");
    // One whole record, then 10 bytes of the next and silence.
    let mut bytes = Record::new(NetCmdType::CmdExtHalt, 1).encode().to_vec();
    bytes.extend_from_slice(&Record::new(NetCmdType::CmdExtHalt, 2).encode()[..10]);
    loris.send_raw(&bytes).await.expect("send");
    let c = gw.next_command().await;
    assert_eq!(c.drone, 1);
    assert!(
        loris.wait_closed(PATIENCE).await,
        "the stalled client is closed"
    );
    gw.wait_metric(
        "skymesh_gc_disconnects_total",
        "reason=partial_record_timeout",
        1.0,
    )
    .await;
    gw.no_command_for(Duration::from_millis(100)).await;
    // The other client, idle meanwhile (no partial record), is still served.
    other
        .send(&waypoint(3, [0.0, 0.0, 1.0], 1.0, 0))
        .await
        .expect("send");
    assert_eq!(gw.next_command().await.drone, 3);
    gw.wait_metric("skymesh_gc_clients", "", 1.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn non_finite_numbers_never_reach_the_bus() {
    let mut gw = Gateway::start().await;
    let mut client = GcClient::connect(gw.tcp).await.expect("connect");
    let mut records = Vec::new();
    for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        // A kind whose floats mean nothing, and one whose floats are positions.
        records.push(Record::floats(
            NetCmdType::CmdExtHalt,
            1,
            0,
            0,
            [0.0, v, 0.0, 0.0],
        ));
        records.push(waypoint(1, [0.0, 0.0, v], 1.0, 0));
        records.push(waypoint(1, [0.0, 0.0, 1.0], v, 0));
        // Through a parameter record into the colour of the next command.
        records.push(Record::floats(
            NetCmdType::ExtParam1,
            1,
            0,
            0,
            [v, 0.0, 0.0, 0.0],
        ));
        records.push(Record::floats(
            NetCmdType::CmdExtColor,
            1,
            0,
            0,
            [1.0, 0.0, 0.0, 0.0],
        ));
    }
    // Absurd magnitudes where the value has a meaning.
    records.push(waypoint(1, [f32::MAX, 0.0, 1.0], 1.0, 0));
    records.push(waypoint(1, [0.0, 0.0, 1.0], 1e30, 0));
    let refused = records.len() - 3; // the three ExtParam1 records are stored
    client.send_all(&records).await.expect("send");
    gw.wait_refused("invalid_value", refused as f64).await;
    gw.no_command_for(Duration::from_millis(200)).await;
    assert_eq!(
        gw.metric("skymesh_gc_commands_published_total", ""),
        Some(0.0)
    );
    gw.stop().await;
}
