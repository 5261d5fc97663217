//! Tests of the link: both directions, reconnects, silence, tcpin and udpin.

use super::*;
use mavlink::dialects::ardupilotmega::{
    MavAutopilot, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
};
use mavlink::{Connectable, MavConnection, TcpConfig};
use skymesh_runtime::Stats;
use std::net::TcpStream;

use mavlink_frame::{FrameParser, RawFrame};

fn hub() -> Arc<Hub> {
    Hub::detached((1, 191))
}

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 4,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

fn config(endpoint: Endpoint) -> LinkConfig {
    LinkConfig {
        endpoint,
        system_id: 1,
        component_id: 191,
        reconnect_min: Duration::from_millis(50),
        reconnect_max: Duration::from_millis(200),
        silence_reconnect: None,
    }
}

async fn next(rx: &mut mpsc::Receiver<LinkEvent>) -> LinkEvent {
    tokio::time::timeout(Duration::from_secs(20), rx.recv())
        .await
        .expect("a link event within 20 s")
        .expect("link task alive")
}

/// A fake autopilot on a TCP port: the link connects, messages flow both ways,
/// the peer closes, the link reports it and connects again to a new peer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_messages_flow_both_ways_and_the_link_reconnects() {
    let server = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = server.local_addr().unwrap().port();
    let stats = Stats::new();
    let metrics = Metrics::new(&stats);
    let shutdown = CancellationToken::new();
    let endpoint = Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    };
    let (mut rx, task) = spawn(config(endpoint), metrics.clone(), hub(), shutdown.clone());

    for round in 0..2 {
        let peer = tokio::task::spawn_blocking({
            let server = server.try_clone().unwrap();
            move || {
                let (stream, _) = server.accept().unwrap();
                stream
                    .set_read_timeout(Some(Duration::from_secs(20)))
                    .unwrap();
                let conn = TcpConfig::from_stream(stream)
                    .unwrap()
                    .connect::<MavMessage>()
                    .unwrap();
                let hdr = MavHeader {
                    system_id: 1,
                    component_id: 1,
                    sequence: 0,
                };
                conn.send(&hdr, &heartbeat()).unwrap();
                let (h, m) = conn.recv().unwrap();
                (h, m)
            }
        });
        let LinkEvent::Connected(writer) = next(&mut rx).await else {
            panic!("expected Connected in round {round}")
        };
        let LinkEvent::Message(h, m) = next(&mut rx).await else {
            panic!("expected a message")
        };
        assert_eq!((h.system_id, h.component_id), (1, 1));
        assert_eq!(m, heartbeat());
        writer.send(heartbeat()).unwrap();
        let (h, m) = peer.await.unwrap();
        assert_eq!((h.system_id, h.component_id), (1, 191));
        assert_eq!(m, heartbeat());
        // The peer is gone now.
        let LinkEvent::Disconnected { reason } = next(&mut rx).await else {
            panic!("expected Disconnected")
        };
        assert!(!reason.is_empty());
    }
    // At least the second round's connection; the link may already have connected
    // a third time (the kernel accepts into the listener's backlog before `accept`).
    assert!(
        metrics.reconnects.get() >= 1,
        "{}",
        metrics.reconnects.get()
    );
    shutdown.cancel();
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

/// Nobody listening: attempts repeat with backoff and shutdown ends the task quickly.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_autopilot_is_retried_until_shutdown() {
    let port = {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let shutdown = CancellationToken::new();
    let (mut rx, task) = spawn(
        config(Endpoint::TcpOut {
            host: "127.0.0.1".into(),
            port,
        }),
        Metrics::new(&Stats::new()),
        hub(),
        shutdown.clone(),
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(rx.try_recv().is_err(), "no event without a connection");
    shutdown.cancel();
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

/// `tcpin`: we listen, a peer connects, and the listener survives the peer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcpin_accepts_one_client_after_another() {
    let port = {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let addr = format!("127.0.0.1:{port}").parse().unwrap();
    let shutdown = CancellationToken::new();
    let (mut rx, task) = spawn(
        config(Endpoint::TcpIn(addr)),
        Metrics::new(&Stats::new()),
        hub(),
        shutdown.clone(),
    );
    for _ in 0..2 {
        let client = tokio::task::spawn_blocking(move || {
            let deadline = Instant::now() + Duration::from_secs(20);
            loop {
                match TcpStream::connect(addr) {
                    Ok(s) => break s,
                    Err(_) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(50))
                    }
                    Err(e) => panic!("{e}"),
                }
            }
        })
        .await
        .unwrap();
        assert!(matches!(next(&mut rx).await, LinkEvent::Connected(_)));
        drop(client);
        assert!(matches!(
            next(&mut rx).await,
            LinkEvent::Disconnected { .. }
        ));
    }
    shutdown.cancel();
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

fn frame_from_autopilot(sequence: u8) -> RawFrame {
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence,
    };
    RawFrame::encode(header, &heartbeat())
}

/// A TCP autopilot that stops talking but keeps the socket open is dropped after
/// `silence_reconnect`, and not while it talks (the check is re-armed by every
/// message, not once from the connect).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_tcp_autopilot_is_dropped_after_the_silence_and_not_before() {
    use std::io::Write;
    let server = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = server.local_addr().unwrap().port();
    let shutdown = CancellationToken::new();
    let mut cfg = config(Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    });
    let silence = Duration::from_millis(800);
    cfg.silence_reconnect = Some(silence);
    let (mut rx, task) = spawn(cfg, Metrics::new(&Stats::new()), hub(), shutdown.clone());
    let talking = 20u8; // × 100 ms: well past the silence
    let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
    let peer = std::thread::spawn(move || {
        let (mut stream, _) = server.accept().unwrap();
        for seq in 0..talking {
            stream
                .write_all(frame_from_autopilot(seq).as_bytes())
                .unwrap();
            std::thread::sleep(Duration::from_millis(100));
        }
        // Silent from here, with the socket open until the test is done.
        let _ = done_rx.recv_timeout(Duration::from_secs(30));
        drop(stream);
    });
    assert!(matches!(next(&mut rx).await, LinkEvent::Connected(_)));
    for seq in 0..talking {
        match next(&mut rx).await {
            LinkEvent::Message(h, _) => assert_eq!(h.sequence, seq),
            other => panic!("message {seq} expected while the peer talks, got {other:?}"),
        }
    }
    let quiet_since = Instant::now();
    let LinkEvent::Disconnected { reason } = next(&mut rx).await else {
        panic!("expected Disconnected")
    };
    assert!(reason.contains("no MAVLink received"), "{reason}");
    // From the last message (sent ~100 ms before we noted the time).
    assert!(quiet_since.elapsed() + Duration::from_millis(150) >= silence);
    done_tx.send(()).unwrap();
    peer.join().unwrap();
    shutdown.cancel();
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

/// `udpin`: we bind, the autopilot speaks first, and what we send goes to the
/// last address the autopilot spoke from.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn udpin_replies_go_to_the_last_sender() {
    let addr = {
        let probe = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        probe.local_addr().unwrap()
    };
    let shutdown = CancellationToken::new();
    let (mut rx, task) = spawn(
        config(Endpoint::UdpIn(addr)),
        Metrics::new(&Stats::new()),
        hub(),
        shutdown.clone(),
    );
    let LinkEvent::Connected(writer) = next(&mut rx).await else {
        panic!("expected Connected")
    };
    for (round, seq) in [(0, 7u8), (1, 9u8)] {
        let autopilot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        autopilot
            .set_read_timeout(Some(Duration::from_secs(10)))
            .unwrap();
        autopilot
            .send_to(frame_from_autopilot(seq).as_bytes(), addr)
            .unwrap();
        let LinkEvent::Message(h, m) = next(&mut rx).await else {
            panic!("expected a message in round {round}")
        };
        assert_eq!((h.system_id, h.sequence), (1, seq));
        assert_eq!(m, heartbeat());
        writer.send(heartbeat()).unwrap();
        let mut buf = [0u8; 512];
        let n = autopilot.recv(&mut buf).expect("our reply at the sender");
        let mut parser = FrameParser::new();
        parser.push(&buf[..n]);
        let frame = parser.next_frame().expect("a whole frame");
        assert_eq!(
            (frame.header().system_id, frame.header().component_id),
            (1, 191)
        );
    }
    shutdown.cancel();
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

/// A peer that stops reading: our messages fill the socket (direct writes), then the
/// writer thread's queue, until a send is refused as congested. Once the peer reads
/// again, every accepted message arrives whole, in order, with consecutive sequence
/// numbers: a direct write never overtakes or splits a queued one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_socket_keeps_our_frames_whole_and_in_order() {
    let server = TcpListener::bind("127.0.0.1:0").unwrap();
    // A small receive window (inherited by the accepted socket): the socket fills
    // after a few thousand frames rather than megabytes.
    nix::sys::socket::setsockopt(&server, nix::sys::socket::sockopt::RcvBuf, &4096).unwrap();
    let port = server.local_addr().unwrap().port();
    let stats = Stats::new();
    let shutdown = CancellationToken::new();
    let endpoint = Endpoint::TcpOut {
        host: "127.0.0.1".into(),
        port,
    };
    let (mut rx, task) = spawn(
        config(endpoint),
        Metrics::new(&stats),
        hub(),
        shutdown.clone(),
    );
    let (peer, _) = tokio::task::spawn_blocking(move || server.accept().unwrap())
        .await
        .unwrap();
    let LinkEvent::Connected(writer) = next(&mut rx).await else {
        panic!("expected Connected")
    };
    let mut accepted = 0usize;
    loop {
        match writer.send(heartbeat()) {
            Ok(()) => accepted += 1,
            Err(WriteError::Congested) => break,
            Err(e) => panic!("send failed: {e}"),
        }
        assert!(accepted < 10_000_000, "the socket never filled");
    }
    assert!(accepted > WRITE_QUEUE, "{accepted}");
    let sequences = tokio::task::spawn_blocking(move || {
        let mut peer = peer;
        peer.set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        let mut parser = FrameParser::new();
        let mut buf = vec![0u8; 65536];
        let mut sequences = Vec::with_capacity(accepted);
        while sequences.len() < accepted {
            let n = std::io::Read::read(&mut peer, &mut buf).expect("the rest within 20 s");
            assert!(n > 0, "closed after {} frames", sequences.len());
            parser.push(&buf[..n]);
            while let Some(frame) = parser.next_frame() {
                assert_eq!(frame.decode().unwrap(), heartbeat());
                sequences.push(frame.header().sequence);
            }
        }
        assert_eq!(parser.take_malformed(), 0);
        sequences
    })
    .await
    .unwrap();
    assert_eq!(sequences.len(), accepted);
    for (i, s) in sequences.iter().enumerate() {
        assert_eq!(usize::from(*s), i % 256, "frame {i}");
    }
    shutdown.cancel();
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}
