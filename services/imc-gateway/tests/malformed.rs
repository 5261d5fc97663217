//! Bad input never crashes the gateway and never changes state: each kind is
//! counted, nothing is answered or published for it, and the next good message
//! works. Both byte orders are accepted; replies are little-endian.

mod common;

use common::{barrier, Gateway, GATEWAY_ID, PATIENCE};
use imc_proto::{crc16_arc, ByteOrder, Message};
use skymesh_ipc_types::{AckResult, Command, HardwareOp, HardwareResult, RefusalReason};

/// Recomputes the little-endian CRC after editing a datagram.
fn reseal_le(d: &mut [u8]) {
    let n = d.len() - 2;
    let crc = crc16_arc(&d[..n]);
    d[n..].copy_from_slice(&crc.to_le_bytes());
}

fn swap(d: &mut [u8], at: usize, len: usize) {
    d[at..at + len].reverse();
}

/// The same datagram written by a big-endian sender: every header field, the
/// payload's u16 fields at `payload_u16` (offsets within the payload) and the CRC.
fn to_big_endian(le: &[u8], payload_u16: &[usize]) -> Vec<u8> {
    let mut be = le.to_vec();
    for (at, len) in [(0, 2), (2, 2), (4, 2), (6, 8), (14, 2), (17, 2)] {
        swap(&mut be, at, len);
    }
    for off in payload_u16 {
        swap(&mut be, 20 + off, 2);
    }
    let n = be.len() - 2;
    let crc = crc16_arc(&be[..n]);
    be[n..].copy_from_slice(&crc.to_be_bytes());
    be
}

#[tokio::test]
async fn every_kind_of_bad_datagram_is_counted_and_changes_nothing() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;
    let servo = peer
        .datagram(&Message::SetServoPosition { id: 0, value: 0.0 })
        .unwrap();

    let mut bad_sync = servo.clone();
    bad_sync[0..2].copy_from_slice(&[0x12, 0x34]);
    let mut bad_crc = servo.clone();
    let last = bad_crc.len() - 1;
    bad_crc[last] ^= 0x5a;
    let mut size_mismatch = servo.clone();
    size_mismatch.push(0);
    let mut unknown_id = servo.clone();
    unknown_id[2..4].copy_from_slice(&9999u16.to_le_bytes());
    reseal_le(&mut unknown_id);
    // SetServoPosition is id u8 + value f32: cut the payload to 3 bytes.
    let mut truncated = servo[..20 + 3].to_vec();
    truncated[4..6].copy_from_slice(&3u16.to_le_bytes());
    truncated.extend([0, 0]);
    reseal_le(&mut truncated);
    // ...or give it two bytes too many.
    let mut trailing = servo[..20 + 5].to_vec();
    trailing.extend([7, 7]);
    trailing[4..6].copy_from_slice(&7u16.to_le_bytes());
    trailing.extend([0, 0]);
    reseal_le(&mut trailing);
    let mut not_for_us = servo.clone();
    not_for_us[17..19].copy_from_slice(&0x1234u16.to_le_bytes());
    reseal_le(&mut not_for_us);
    let unmapped = peer
        .datagram(&Message::SetServoPosition { id: 7, value: 0.0 })
        .unwrap();
    let out_of_range = peer
        .datagram(&Message::SetThrusterActuation { id: 0, value: -0.5 })
        .unwrap();
    let pwm_out_of_range = peer
        .datagram(&Message::SetPwm {
            id: 0,
            period: 20_000,
            duty_cycle: 3000,
        })
        .unwrap();

    for bytes in [
        &servo[..5],
        &bad_sync[..],
        &bad_crc[..],
        &size_mismatch[..],
        &unknown_id[..],
        &truncated[..],
        &trailing[..],
        &not_for_us[..],
        &unmapped[..],
        &out_of_range[..],
        &pwm_out_of_range[..],
    ] {
        peer.send_raw(bytes).await.unwrap();
    }
    // Nothing was answered: the first reply is the marker's.
    barrier(&peer).await;
    for (reason, n) in [
        ("too_short", 1.0),
        ("bad_sync", 1.0),
        ("bad_crc", 1.0),
        ("size_mismatch", 1.0),
        ("unknown_id", 1.0),
        ("truncated", 1.0),
        ("trailing_bytes", 1.0),
        ("not_for_us", 1.0),
        ("unmapped", 1.0),
        ("out_of_range", 2.0),
    ] {
        gw.wait_dropped(reason, n).await;
    }
    assert!(
        gw.commands.try_recv().unwrap().is_none(),
        "nothing published"
    );

    // The good datagram still works.
    peer.send_raw(&servo).await.unwrap();
    let cmd = gw.next_command().await;
    assert_eq!(
        cmd.command().unwrap(),
        Command::Servo {
            channel: 9,
            pwm_us: 1500
        }
    );
    gw.ack(&cmd, AckResult::Accepted, RefusalReason::None);
    gw.wait_metric(
        "skymesh_imc_messages_total",
        "direction=in,message=SetServoPosition",
        1.0,
    )
    .await;
    gw.stop().await;
}

#[tokio::test]
async fn a_flood_of_garbage_is_counted_and_the_gateway_keeps_answering() {
    let gw = Gateway::start().await;
    let peer = gw.peer().await;
    let mut bad = peer.datagram(&Message::Heartbeat).unwrap();
    let last = bad.len() - 1;
    bad[last] ^= 1;
    // In bursts a UDP receive buffer holds; each burst fully handled before the next.
    for _ in 0..10 {
        for _ in 0..50 {
            peer.send_raw(&bad).await.unwrap();
        }
        barrier(&peer).await;
    }
    gw.wait_dropped("bad_crc", 500.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn both_byte_orders_are_accepted_and_replies_are_little_endian() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;

    let le = peer
        .datagram(&Message::QueryLedBrightness {
            name: "status".into(),
        })
        .unwrap();
    let be = to_big_endian(&le, &[0]);
    assert_eq!(
        &be[0..2],
        &[0xFE, 0x54],
        "sync as a big-endian sender writes it"
    );
    peer.send_raw(&be).await.unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::LedQuery));
    assert_eq!(req.name.as_str(), "status");
    gw.hw_reply(&req, HardwareResult::Ok, 42);
    let reply = peer
        .recv_until(PATIENCE, |p| {
            matches!(p.message, Message::LedBrightness { .. })
        })
        .await
        .expect("LedBrightness");
    assert_eq!(
        reply.message,
        Message::LedBrightness {
            name: "status".into(),
            value: 42
        }
    );
    assert_eq!(reply.byte_order, ByteOrder::Little);
    assert_eq!(reply.header.src, GATEWAY_ID);
    assert_eq!(
        reply.header.dst, peer.identity.src,
        "addressed to the sender"
    );
    assert_eq!(reply.header.dst_ent, peer.identity.src_ent);

    // A big-endian datagram with a bad CRC is still refused.
    let mut be_bad = be.clone();
    be_bad[20 + 2] ^= 0x20;
    peer.send_raw(&be_bad).await.unwrap();
    // And a big-endian heartbeat counts as a message.
    let hb = to_big_endian(&peer.datagram(&Message::Heartbeat).unwrap(), &[]);
    peer.send_raw(&hb).await.unwrap();
    gw.wait_dropped("bad_crc", 1.0).await;
    gw.wait_metric(
        "skymesh_imc_messages_total",
        "direction=in,message=Heartbeat",
        1.0,
    )
    .await;
    gw.stop().await;
}
