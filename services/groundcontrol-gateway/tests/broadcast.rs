//! The pose broadcast in-process: nothing before the first SwarmState, then one
//! datagram of 84-byte records per tick with the right ids and poses; a pause when
//! the swarm queue falls silent; 250 drones in one datagram.

mod common;

use std::f32::consts::FRAC_1_SQRT_2;
use std::time::Duration;

use common::{swarm_state, Gateway, PATIENCE};
use gc_proto::{PoseRecord, POSE_RECORD_LEN};
use skymesh_ipc_types::SwarmState;

/// Publishes `state` as the queue does (every 50 ms: a sample published before the
/// gateway subscribed reaches it only with the publisher's next send) until a
/// datagram with `n` records arrives.
async fn publish_until_broadcast(gw: &mut Gateway, state: SwarmState) -> Vec<PoseRecord> {
    let n = usize::from(state.count);
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no datagram of {n} drones"
        );
        gw.publish_state(state);
        if let Some((_, poses)) = gw.poses.recv(Duration::from_millis(50)).await.expect("udp") {
            let poses = poses.expect("a whole number of 84-byte records");
            if poses.len() == n {
                return poses;
            }
        }
    }
}

async fn next_poses(gw: &mut Gateway) -> Vec<PoseRecord> {
    let (_, poses) = gw
        .poses
        .recv(PATIENCE)
        .await
        .expect("udp")
        .unwrap_or_else(|| panic!("no pose datagram within {PATIENCE:?}"));
    poses.expect("a whole number of 84-byte records")
}

#[tokio::test]
async fn poses_of_every_drone_once_the_queue_publishes() {
    let mut gw = Gateway::start_with(|s| s.broadcast_period = Duration::from_millis(20)).await;
    // No SwarmState yet: no datagram.
    assert!(gw
        .poses
        .recv(Duration::from_millis(300))
        .await
        .expect("udp")
        .is_none());
    gw.wait_metric("skymesh_gc_broadcast_datagrams_total", "", 0.0)
        .await;
    assert!(gw
        .metric("skymesh_gc_broadcast_skipped_total", "reason=no_state")
        .is_some_and(|n| n >= 1.0));

    let first = publish_until_broadcast(&mut gw, swarm_state(5, 42.5)).await;
    assert_eq!(first.len(), 5);
    for (i, p) in first.iter().enumerate() {
        let f = i as f32;
        assert_eq!(p.id, 100 + i as u16);
        assert_eq!((p.object_type, p.liveness), (0, 2), "UAV, simulated");
        assert_eq!(p.tracking, [f, 2.0 * f, 10.0]);
        assert_eq!(p.tracking_yaw_deg, 90.0);
        assert_eq!(p.target, [f + 5.0, 2.0 * f, 10.0]);
        assert_eq!(p.target_yaw_deg, 180.0);
        assert_eq!(p.color, [0.0, 1.0, 0.0]);
        assert_eq!(p.timestamp, 42.5);
        assert_eq!(p.quaternion, [0.0, 0.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2]);
        assert_eq!(p.drone_state, 5);
        assert_eq!(p.flags, 0x03, "idle | active; skymesh's bits masked");
        assert_eq!(p.frame_count, first[0].frame_count);
    }
    let second = next_poses(&mut gw).await;
    assert!(second[0].frame_count > first[0].frame_count);

    // A newer state replaces the old one.
    let poses = publish_until_broadcast(&mut gw, swarm_state(2, 43.0)).await;
    assert_eq!(poses[1].timestamp, 43.0);
    assert!(gw
        .metric("skymesh_gc_broadcast_bytes_total", "")
        .is_some_and(|b| b >= (5 * POSE_RECORD_LEN) as f64));
    gw.wait_metric("skymesh_gc_broadcast_drones", "", 2.0).await;
    gw.stop().await;
}

#[tokio::test]
async fn the_broadcast_pauses_when_the_queue_falls_silent() {
    let mut gw = Gateway::start_with(|s| {
        s.broadcast_period = Duration::from_millis(20);
        s.state_timeout = Duration::from_millis(300);
    })
    .await;
    publish_until_broadcast(&mut gw, swarm_state(3, 1.0)).await;
    // Within ~300 ms the datagrams stop.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while gw
        .metric("skymesh_gc_broadcast_skipped_total", "reason=stale")
        .is_none()
    {
        assert!(tokio::time::Instant::now() < deadline, "never went stale");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    while gw
        .poses
        .recv(Duration::from_millis(100))
        .await
        .expect("udp")
        .is_some()
    {}
    // A new state resumes it.
    publish_until_broadcast(&mut gw, swarm_state(4, 2.0)).await;
    gw.stop().await;
}

#[tokio::test]
async fn two_hundred_fifty_drones_fit_one_datagram() {
    let mut gw = Gateway::start_with(|s| s.broadcast_period = Duration::from_millis(20)).await;
    let poses = publish_until_broadcast(&mut gw, swarm_state(250, 7.0)).await;
    assert_eq!(poses.len(), 250);
    assert_eq!(poses[249].id, 349);
    assert_eq!(poses[249].tracking, [249.0, 498.0, 10.0]);
    gw.stop().await;
}

/// A loopback address nothing listens at: a port bound and closed again.
fn closed_port() -> std::net::SocketAddr {
    let s = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
    s.local_addr().expect("addr")
}

/// Starts listening at `closed` and publishes state until 25 datagrams of two
/// drones arrived there (a probe a second would take 25 s: more than
/// [`PATIENCE`]); returns how long that took.
async fn listen_until_every_tick(gw: &mut Gateway, closed: std::net::SocketAddr) -> Duration {
    let mut late = skymesh_groundcontrol_gateway::client::PoseListener::bind(closed)
        .await
        .expect("bind the closed port");
    let t1 = tokio::time::Instant::now();
    let mut got = 0;
    while got < 25 {
        assert!(
            t1.elapsed() < PATIENCE,
            "{got} datagrams within {PATIENCE:?} of listening"
        );
        gw.publish_state(swarm_state(2, 1.0));
        while let Some((_, poses)) = late.recv(Duration::from_millis(40)).await.expect("udp") {
            assert_eq!(poses.expect("records").len(), 2);
            got += 1;
        }
        while gw.poses.recv(Duration::ZERO).await.expect("udp").is_some() {}
    }
    t1.elapsed()
}

/// A destination nothing listens at (ICMP port unreachable) gets one datagram a
/// second, the rest counted `not_listening`, while a listening one beside it gets
/// every tick; once something listens there it gets every tick too.
#[tokio::test]
async fn a_destination_nobody_listens_at_gets_a_datagram_a_second_until_it_listens() {
    let closed = closed_port();
    let mut gw = Gateway::start_with(|s| {
        s.broadcast_period = Duration::from_millis(20);
        s.broadcast_destinations.insert(0, closed);
    })
    .await;
    publish_until_broadcast(&mut gw, swarm_state(2, 1.0)).await;
    let datagrams = |gw: &Gateway| {
        gw.metric("skymesh_gc_broadcast_datagrams_total", "")
            .unwrap_or(0.0)
    };
    let skipped = |gw: &Gateway| {
        gw.metric("skymesh_gc_broadcast_skipped_total", "reason=not_listening")
            .unwrap_or(0.0)
    };
    let (sent0, skipped0) = (datagrams(&gw), skipped(&gw));
    // 1.5 s at 50 Hz: the listening destination gets every tick.
    let mut heard = 0;
    let t0 = tokio::time::Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        gw.publish_state(swarm_state(2, 1.0));
        while gw
            .poses
            .recv(Duration::from_millis(40))
            .await
            .expect("udp")
            .is_some()
        {
            heard += 1;
        }
    }
    let (sent, skip) = (datagrams(&gw) - sent0, skipped(&gw) - skipped0);
    assert!(
        heard >= 40,
        "the listening destination got {heard} datagrams in 1.5 s"
    );
    // Sent = the listener's + the closed port's probes (one a second, and one whose
    // refusal a send found; a few more on a machine that processes the ICMP error
    // late).
    assert!(
        sent <= f64::from(heard) + 10.0 && skip >= f64::from(heard) - 15.0,
        "listener heard {heard}; sent {sent}, skipped not_listening {skip}"
    );
    // Now something listens at the closed port: every tick reaches it again.
    let after = listen_until_every_tick(&mut gw, closed).await;
    assert!(
        after < Duration::from_secs(6),
        "every tick again only after {after:?}"
    );
    gw.stop().await;
}

/// With every destination refusing, the broadcast sleeps until a probe is due
/// instead of ticking: it reads the swarm queue's state a few times a second, not
/// every tick, and counts none of what it did not read as lost.
#[tokio::test]
async fn with_nobody_listening_anywhere_the_broadcast_sleeps_between_probes() {
    let closed = closed_port();
    let mut gw = Gateway::start_with(|s| {
        s.broadcast_period = Duration::from_millis(20);
        s.broadcast_destinations = vec![closed];
    })
    .await;
    let topic = "topic=skymesh/swarm/state";
    let received = |gw: &Gateway| {
        gw.metric("skymesh_topic_samples_received_total", topic)
            .unwrap_or(0.0)
    };
    // Until the first refusal is known the broadcast ticks.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while gw
        .metric("skymesh_gc_broadcast_skipped_total", "reason=not_listening")
        .is_none()
    {
        assert!(tokio::time::Instant::now() < deadline, "never refused");
        gw.publish_state(swarm_state(2, 1.0));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // 2 s of state at 50 Hz, 100 samples: ticking every 20 ms would read ~100.
    let before = received(&gw);
    for _ in 0..100 {
        gw.publish_state(swarm_state(2, 1.0));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let read = received(&gw) - before;
    assert!(
        read <= 20.0,
        "read {read} of 100 states while nobody listened"
    );
    assert_eq!(
        gw.metric("skymesh_topic_samples_lost_total", topic)
            .unwrap_or(0.0),
        0.0,
        "states the broadcast slept through are not lost"
    );
    // Something listens now: every tick again.
    listen_until_every_tick(&mut gw, closed).await;
    gw.stop().await;
}

/// The next word on the watch topic.
async fn next_word(gw: &mut Gateway) -> bool {
    let w = tokio::time::timeout(PATIENCE, gw.watch.recv())
        .await
        .unwrap_or_else(|_| panic!("no word on the watch topic within {PATIENCE:?}"))
        .expect("bus");
    w.watching == 1
}

/// The broadcast says it watches the swarm state while some destination may listen
/// (renewed every second), stops while every destination refuses (so the queue can
/// rest), and for a probe watches again first and sends a state published after
/// that.
#[tokio::test]
async fn the_broadcast_watches_the_state_only_while_somebody_may_listen() {
    let closed = closed_port();
    let mut gw = Gateway::start_with(|s| {
        s.broadcast_period = Duration::from_millis(20);
        s.broadcast_destinations = vec![closed];
    })
    .await;
    assert!(next_word(&mut gw).await, "watching from the start");
    // Until the refusal is known: then a word that it stopped.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    loop {
        assert!(tokio::time::Instant::now() < deadline, "never stopped");
        gw.publish_state(swarm_state(2, 1.0));
        if gw
            .watch
            .try_recv()
            .expect("bus")
            .is_some_and(|w| w.watching == 0)
        {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // Something listens now. The next probe watches again, and what it sends is
    // the state published after the word.
    let mut late = skymesh_groundcontrol_gateway::client::PoseListener::bind(closed)
        .await
        .expect("bind the closed port");
    assert!(next_word(&mut gw).await, "a probe watches again");
    let (_, poses) = loop {
        gw.publish_state(swarm_state(3, 9.0));
        if let Some(d) = late.recv(Duration::from_millis(50)).await.expect("udp") {
            break d;
        }
        assert!(tokio::time::Instant::now() < deadline, "no probe");
    };
    let poses = poses.expect("records");
    assert_eq!(poses.len(), 3);
    assert_eq!(poses[0].timestamp, 9.0, "the probe carries the new state");
    // Once every tick reaches the listener, the word is renewed every second and
    // never withdrawn.
    let mut got = 0;
    while got < 25 {
        assert!(tokio::time::Instant::now() < deadline, "{got} datagrams");
        gw.publish_state(swarm_state(3, 9.0));
        tokio::time::sleep(Duration::from_millis(20)).await;
        while late.recv(Duration::ZERO).await.expect("udp").is_some() {
            got += 1;
        }
    }
    while gw.watch.try_recv().expect("bus").is_some() {}
    let mut renewed = 0;
    let t0 = tokio::time::Instant::now();
    while t0.elapsed() < Duration::from_millis(2500) {
        gw.publish_state(swarm_state(3, 9.0));
        tokio::time::sleep(Duration::from_millis(20)).await;
        while late.recv(Duration::ZERO).await.expect("udp").is_some() {}
        while let Some(w) = gw.watch.try_recv().expect("bus") {
            assert_eq!(w.watching, 1, "withdrawn while listened to");
            renewed += 1;
        }
    }
    assert!(renewed >= 2, "{renewed} words in 2.5 s");
    gw.stop().await;
}
