//! Tests of the endpoints: UDP sending from the routing thread, peers, refusals.

use std::time::Instant;

use super::udp::Peers;
use super::*;
use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use mavlink::MavHeader;
use mavlink_frame::signing::{signature_is_valid, signed_parts, SigningKey};

const PATIENCE: Duration = Duration::from_secs(10);

/// An ATTITUDE from the autopilot (system 1) or, with `from`, someone else.
fn attitude(i: u32) -> RawFrame {
    attitude_from((1, 1), i)
}

fn attitude_from(from: (u8, u8), i: u32) -> RawFrame {
    let header = MavHeader {
        system_id: u32::from(from.0),
        component_id: from.1,
        sequence: i as u8,
    };
    let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms: i,
        ..ATTITUDE_DATA::DEFAULT
    });
    RawFrame::encode(header, &msg)
}

fn ground_station() -> std::net::UdpSocket {
    let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    s.set_read_timeout(Some(PATIENCE)).unwrap();
    s
}

/// The next datagram on `socket` (within [`PATIENCE`]) as a frame.
fn next_frame(socket: &std::net::UdpSocket, who: &str) -> RawFrame {
    let mut buf = [0u8; 512];
    let n = socket
        .recv(&mut buf)
        .unwrap_or_else(|e| panic!("{who}: no frame within {PATIENCE:?}: {e}"));
    let mut parser = FrameParser::new();
    parser.push(&buf[..n]);
    parser
        .next_frame()
        .unwrap_or_else(|| panic!("{who}: not a frame: {:?}", &buf[..n]))
}

/// Frames for `udpout` and `udpin` endpoints are sent by the thread that routes
/// them: they arrive (signed on a signing endpoint) while the endpoints' only
/// runtime thread is blocked, so no tokio wake-up is needed per frame.
#[test]
fn udp_endpoints_are_sent_to_by_the_routing_thread() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (plain, signed) = (ground_station(), ground_station());
    let out = |s: &std::net::UdpSocket| Endpoint::UdpOut {
        host: "127.0.0.1".into(),
        port: s.local_addr().unwrap().port(),
    };
    let endpoints = vec![
        out(&plain),
        out(&signed),
        Endpoint::UdpIn("127.0.0.1:0".parse().unwrap()),
    ];
    let key = SigningKey::new([7; 32]);
    let signing = SigningSettings {
        key: key.clone(),
        endpoints: vec![1],
    };
    let stats = Stats::new();
    let shutdown = CancellationToken::new();
    let peer = ground_station();
    let (hub, task) = rt.block_on(async {
        let bound = Bound::bind(&endpoints).await.unwrap();
        let udpin = bound.local_addrs()[2].unwrap();
        let (hub, task) = start(
            bound,
            (1, 191),
            Some(&signing),
            None,
            &stats,
            shutdown.clone(),
        );
        // The udpin endpoint learns its peer from what it sends; the udpout
        // ones open their sockets: wait (driving the runtime) until all three
        // receive what the hub routes.
        let mut ready = [false; 3];
        let deadline = Instant::now() + PATIENCE;
        while ready.contains(&false) {
            assert!(Instant::now() < deadline, "endpoints not up: {ready:?}");
            peer.send_to(attitude_from((255, 190), 0).as_bytes(), udpin)
                .unwrap();
            hub.from_autopilot(&attitude(0));
            tokio::time::sleep(Duration::from_millis(20)).await;
            for (i, s) in [&plain, &signed, &peer].into_iter().enumerate() {
                s.set_nonblocking(true).unwrap();
                while s.recv(&mut [0u8; 512]).is_ok() {
                    ready[i] = true;
                }
                s.set_nonblocking(false).unwrap();
            }
        }
        (hub, task)
    });

    // The runtime is not running now: nothing but the routing thread can send.
    let n = 20u32;
    let router = {
        let hub = hub.clone();
        std::thread::spawn(move || {
            for i in 1..=n {
                hub.from_autopilot(&attitude(i));
            }
        })
    };
    for i in 1..=n {
        let sent = attitude(i);
        let got = next_frame(&plain, "udpout");
        assert_eq!(got.as_bytes(), sent.as_bytes(), "udpout frame {i}");
        let got = next_frame(&peer, "udpin peer");
        assert_eq!(got.as_bytes(), sent.as_bytes(), "udpin frame {i}");
        let got = next_frame(&signed, "signing udpout");
        assert!(
            got.is_signed(),
            "frame {i} to the signing endpoint is unsigned"
        );
        assert!(
            signature_is_valid(&key, got.as_bytes()),
            "frame {i}: bad signature"
        );
        assert_eq!(signed_parts(got.as_bytes()).unwrap().link_id, 1);
        // Header (but the incompatibility flags) and payload unchanged.
        let payload_end = 10 + usize::from(sent.as_bytes()[1]);
        let (g, w) = (got.as_bytes(), sent.as_bytes());
        assert_eq!(g[..2], w[..2], "frame {i}");
        assert_eq!(g[3..payload_end], w[3..payload_end], "frame {i}");
    }
    router.join().unwrap();

    let mut snapshot = Box::<skymesh_ipc_types::ServiceStats>::default();
    stats.snapshot_into(&mut snapshot);
    let sent_to = |label: String| {
        snapshot
            .entries()
            .iter()
            .find(|e| {
                e.name.as_str() == "skymesh_router_frames_total"
                    && e.labels.as_str() == format!("endpoint={label},direction=out")
            })
            .map_or(0.0, |e| e.value)
    };
    assert!(sent_to(endpoints[0].to_string()) >= f64::from(n + 1));
    assert!(sent_to(endpoints[1].to_string()) >= f64::from(n + 1));

    shutdown.cancel();
    rt.block_on(task).unwrap();
}

#[test]
fn udp_peers_are_remembered_bounded_and_expire() {
    let t = Instant::now();
    let mut p = Peers::default();
    let a: SocketAddr = "127.0.0.1:1000".parse().unwrap();
    assert!(p.heard(a, t));
    assert!(!p.heard(a, t + Duration::from_secs(10)));
    for port in 0..MAX_PEERS as u16 {
        p.heard(SocketAddr::from(([127, 0, 0, 2], port)), t);
    }
    assert_eq!(p.heard.len(), MAX_PEERS);
    assert!(
        p.heard.iter().all(|(x, _)| *x != a),
        "the oldest was forgotten"
    );
    assert_eq!(p.expire(t + PEER_TIMEOUT), MAX_PEERS);
}

/// A `udpout` ground station that is not listening (ICMP port unreachable) gets
/// one frame a second, the rest counted `not_listening`; once something listens
/// there it gets the whole stream again within two seconds.
#[test]
fn a_udpout_destination_nobody_listens_at_gets_a_frame_a_second_until_it_listens() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let port = ground_station().local_addr().unwrap().port(); // closed again
    let endpoint = Endpoint::UdpOut {
        host: "127.0.0.1".into(),
        port,
    };
    let name = label(0, &endpoint);
    let stats = Stats::new();
    let shutdown = CancellationToken::new();
    let (hub, _task) = rt.block_on(async {
        let bound = Bound::bind(&[endpoint]).await.unwrap();
        let started = start(bound, (1, 191), None, None, &stats, shutdown.clone());
        // Let the endpoint task open its socket and install its sink.
        tokio::time::sleep(Duration::from_millis(200)).await;
        started
    });
    let count = |what: &str| {
        stats
            .value(
                "skymesh_router_frames_total",
                &format!("endpoint={name},direction={what}"),
            )
            .unwrap_or(0.0)
    };
    let not_listening = || {
        stats
            .value(
                "skymesh_router_frames_dropped_total",
                &format!("endpoint={name},reason=not_listening"),
            )
            .unwrap_or(0.0)
    };
    // 1.5 s of 200 Hz telemetry to nobody.
    let t0 = Instant::now();
    let mut i = 0;
    while t0.elapsed() < Duration::from_millis(1500) {
        hub.from_autopilot(&attitude(i));
        i += 1;
        std::thread::sleep(Duration::from_millis(5));
    }
    let (out, skipped) = (count("out"), not_listening());
    assert!(
        // (A loaded machine may process an ICMP error a few frames late.)
        skipped >= f64::from(i) - 20.0 && out <= 15.0,
        "{i} frames to a closed port: {out} sent, {skipped} counted not_listening"
    );
    // Now a ground station listens there: the stream comes back.
    let gs = std::net::UdpSocket::bind(("127.0.0.1", port)).unwrap();
    gs.set_nonblocking(true).unwrap();
    let t1 = Instant::now();
    let mut got = 0;
    while got < 50 {
        assert!(
            t1.elapsed() < PATIENCE,
            "{got} frames within {PATIENCE:?} of listening"
        );
        hub.from_autopilot(&attitude(i));
        i += 1;
        std::thread::sleep(Duration::from_millis(5));
        while gs.recv(&mut [0u8; 512]).is_ok() {
            got += 1;
        }
    }
    // Within two probe periods (plus slack for a loaded machine), not 50 probes.
    assert!(
        t1.elapsed() < Duration::from_secs(5),
        "stream back after {:?}",
        t1.elapsed()
    );
    shutdown.cancel();
}
