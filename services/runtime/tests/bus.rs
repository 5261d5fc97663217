//! The bus through real iceoryx2 shared memory, inside one process.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use skymesh_ipc_types::{topics, ServiceId, VehicleState};
use skymesh_runtime::ipc::DomainGuard;
use skymesh_runtime::{Bus, Domain, Stats};

/// A fresh domain per test, its files removed at the end of the test.
fn domain(tag: &str) -> DomainGuard {
    DomainGuard(Domain::load(&format!("rt{}{tag}", std::process::id()), None).unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_published_sample_wakes_an_awaiting_subscriber() {
    let d = domain("a");
    let sub_stats = Stats::new();
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 3, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, sub_stats.clone()).unwrap();
    let topic = topics::vehicle_state(7);
    let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();

    // Nothing pending: recv must wait, not return garbage.
    assert!(sub
        .recv_timeout(Duration::from_millis(50))
        .await
        .unwrap()
        .is_none());

    let waiter = tokio::spawn(async move {
        let first = sub.recv().await.unwrap();
        let second = sub.recv().await.unwrap();
        (first, second, sub)
    });
    tokio::time::sleep(Duration::from_millis(20)).await;
    publ.publish(VehicleState {
        vehicle_id: 7,
        lat_deg: 1.5,
        ..Default::default()
    })
    .unwrap();
    publ.publish(VehicleState {
        vehicle_id: 7,
        lat_deg: 2.5,
        ..Default::default()
    })
    .unwrap();
    let (first, second, sub) = tokio::time::timeout(Duration::from_secs(5), waiter)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(first.lat_deg, 1.5);
    assert_eq!(second.lat_deg, 2.5);
    assert_eq!(first.header.seq, 1);
    assert_eq!(second.header.seq, 2);
    assert_eq!(first.header.service, ServiceId::AutopilotLink.to_wire());
    assert_eq!(first.header.instance, 3);
    assert!(first.header.stamp_ns > 0);

    // A gap in sequence numbers is counted as lost.
    for i in 0..3 {
        publ.publish(VehicleState {
            lat_deg: i as f64,
            ..Default::default()
        })
        .unwrap();
    }
    let newest = sub.latest().unwrap().unwrap();
    assert_eq!(newest.lat_deg, 2.0);
    let c = sub_stats.counter(
        "skymesh_topic_samples_received_total",
        &[("topic", &topic.name)],
    );
    assert_eq!(c.get(), 5);
    let lost = sub_stats.counter(
        "skymesh_topic_samples_lost_total",
        &[("topic", &topic.name)],
    );
    assert_eq!(lost.get(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn domains_are_isolated_and_leave_no_files_behind() {
    let d1 = domain("x");
    let d2 = domain("y");
    {
        let a = Bus::open(&d1, "n1", ServiceId::Tool, 0, Stats::new()).unwrap();
        let b = Bus::open(&d2, "n2", ServiceId::Tool, 0, Stats::new()).unwrap();
        let topic = topics::vehicle_state(1);
        let mut p = a.publisher::<VehicleState>(&topic).unwrap();
        let mut s = b.subscriber::<VehicleState>(&topic).unwrap();
        p.publish(VehicleState::default()).unwrap();
        assert!(
            s.recv_timeout(Duration::from_millis(100))
                .await
                .unwrap()
                .is_none(),
            "crossed domains"
        );
        assert!(!d1.leftover_files().is_empty());
        assert_eq!(d1.live_nodes().len(), 1);
    }
    // After every node is gone, only iceoryx2's global management file may remain;
    // the supervisor removes it with the domain.
    let left = d1.leftover_files();
    assert!(
        left.len() <= 1
            && left
                .iter()
                .all(|p| p.to_string_lossy().ends_with(".global_mgmt")),
        "{left:?}"
    );
    d1.remove_leftover_files();
    assert!(d1.leftover_files().is_empty(), "{:?}", d1.leftover_files());
    d2.remove_leftover_files();
    assert!(d1.leftover_files().is_empty());
}

/// CPU time of the calling thread.
fn thread_cpu() -> Duration {
    let ts = nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID).unwrap();
    Duration::new(ts.tv_sec() as u64, ts.tv_nsec() as u32)
}

/// Runs `wait` (a receive that finds nothing for `idle`) and checks the thread slept
/// through it: a wait that polls would spend the whole of `idle` on the CPU.
fn assert_blocks(idle: Duration, what: &str, wait: impl FnOnce()) {
    let cpu0 = thread_cpu();
    wait();
    let spent = thread_cpu() - cpu0;
    assert!(
        spent < idle / 3,
        "{what} spent {spent:?} of CPU in {idle:?}"
    );
}

/// The receive takes a sample before it consumes its notification and drains
/// before it waits again: a stream of samples each published while the receiver is
/// waiting is received whole (a notification consumed but not looked after would
/// lose a wake-up and time out), and after the last one the receiver blocks — it
/// does not poll on an unread notification (measured as the thread's CPU time over
/// the wait, which a poll would spend whole).
#[test]
fn the_receive_takes_the_sample_first_and_blocks_again_after_draining() {
    let d = domain("dr");
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::vehicle_state(4);
    let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();
    let idle = Duration::from_millis(300);
    let publish_stream = |publ: &mut skymesh_runtime::Publisher<VehicleState>| {
        for i in 1..=50 {
            std::thread::sleep(Duration::from_micros(if i % 2 == 0 { 200 } else { 1500 }));
            publ.publish(VehicleState {
                lat_deg: f64::from(i),
                ..Default::default()
            })
            .unwrap();
        }
    };

    // Async receive, on a current-thread runtime (the receiving thread is this one).
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    std::thread::scope(|s| {
        let p = s.spawn(|| publish_stream(&mut publ));
        rt.block_on(async {
            for i in 1..=50 {
                let v = sub
                    .recv_timeout(Duration::from_secs(5))
                    .await
                    .unwrap()
                    .expect("every sample wakes the receiver");
                assert_eq!(v.lat_deg, f64::from(i));
            }
        });
        p.join().unwrap();
    });
    assert_blocks(idle, "async wait", || {
        rt.block_on(async { assert!(sub.recv_timeout(idle).await.unwrap().is_none()) })
    });
}

/// Samples overwritten before a slow reader looked are counted as lost, unless the
/// subscriber declared it reads only the newest value.
#[test]
fn overwritten_samples_count_as_lost_unless_the_subscriber_wants_only_the_newest() {
    for newest_only in [false, true] {
        let d = domain(if newest_only { "nw1" } else { "nw0" });
        let stats = Stats::new();
        let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
        let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, stats.clone()).unwrap();
        let topic = topics::vehicle_state(4);
        let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
        if newest_only {
            sub.set_newest_only();
        }
        let mut publ = a.publisher::<VehicleState>(&topic).unwrap();
        publ.publish(VehicleState::default()).unwrap();
        assert!(sub.latest().unwrap().is_some());
        // Far more than the topic's buffer holds, then read only the newest.
        for i in 0..100 {
            publ.publish(VehicleState {
                lat_deg: f64::from(i),
                ..Default::default()
            })
            .unwrap();
        }
        assert_eq!(sub.latest().unwrap().unwrap().lat_deg, 99.0);
        let lost = stats
            .counter(
                "skymesh_topic_samples_lost_total",
                &[("topic", &topic.name)],
            )
            .get();
        if newest_only {
            assert_eq!(lost, 0);
        } else {
            assert!(lost > 0, "overwritten samples not counted");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_state_change_is_heartbeated_at_once_not_a_period_later() {
    use skymesh_ipc_types::{ServiceHealth, ServiceState};
    use skymesh_runtime::health::{run_heartbeat, HealthState};
    use tokio_util::sync::CancellationToken;

    let d = domain("h");
    let service = Bus::open(&d, "hb-svc", ServiceId::Tool, 0, Stats::new()).unwrap();
    let watcher = Bus::open(&d, "hb-watch", ServiceId::Tool, 1, Stats::new()).unwrap();
    let mut health = watcher
        .subscriber::<ServiceHealth>(&topics::service_health(service.name()))
        .unwrap();
    let state = HealthState::default();
    let stop = CancellationToken::new();
    // A period far longer than the test may take.
    let task = tokio::spawn(run_heartbeat(
        service.clone(),
        state.clone(),
        Duration::from_secs(60),
        true,
        stop.clone(),
    ));
    let first = tokio::time::timeout(Duration::from_secs(5), health.recv())
        .await
        .expect("first heartbeat at once")
        .unwrap();
    assert_eq!(
        ServiceState::try_from(first.state),
        Ok(ServiceState::Starting)
    );
    state.set(ServiceState::Running);
    let next = tokio::time::timeout(Duration::from_secs(5), health.recv())
        .await
        .expect("the change is published without waiting for the 60 s tick")
        .unwrap();
    assert_eq!(
        ServiceState::try_from(next.state),
        Ok(ServiceState::Running)
    );
    // Setting the same state again publishes nothing extra.
    state.set(ServiceState::Running);
    assert!(health
        .recv_timeout(Duration::from_millis(200))
        .await
        .unwrap()
        .is_none());
    stop.cancel();
    task.await.unwrap().unwrap();
}

/// A `select!` loop re-creates every branch's `recv` future whenever any branch
/// fires. After a receive found the queue empty, those re-created receives wait
/// for a notification without looking at shared memory again — seen from outside
/// as a quietly published sample (which notifies nobody) staying unreceived
/// however often the loop turns, until a notified sample comes: then both, in
/// order. And through such a loop, under a busy other branch, a stream arrives
/// whole and in order.
#[tokio::test(flavor = "current_thread")]
async fn a_receive_that_found_nothing_waits_for_a_notification_without_looking_again() {
    let d = domain("ke");
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::vehicle_state(5);
    let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();
    let sample = |lat: f64| VehicleState {
        lat_deg: lat,
        ..Default::default()
    };

    // Nothing there: the first receive looks, finds nothing, waits.
    assert!(sub
        .recv_timeout(Duration::from_millis(20))
        .await
        .unwrap()
        .is_none());
    publ.publish_quiet(sample(1.0)).unwrap();
    let mut tick = tokio::time::interval(Duration::from_millis(1));
    for _ in 0..50 {
        tokio::select! {
            biased;
            v = sub.recv() => panic!("a quiet sample woke nobody, yet was received: {v:?}"),
            _ = tick.tick() => {}
        }
    }
    // Still there for a direct look, which takes it.
    assert_eq!(sub.try_recv().unwrap().map(|v| v.lat_deg), Some(1.0));

    // Quiet then notified: the notification brings both, in order.
    publ.publish_quiet(sample(2.0)).unwrap();
    for _ in 0..5 {
        tokio::select! {
            biased;
            v = sub.recv() => panic!("received before any notification: {v:?}"),
            _ = tick.tick() => {}
        }
    }
    publ.publish(sample(3.0)).unwrap();
    for want in [2.0, 3.0] {
        let v = tokio::time::timeout(Duration::from_secs(5), sub.recv())
            .await
            .expect("the notified sample wakes the receiver")
            .unwrap();
        assert_eq!(v.lat_deg, want);
    }

    // A stream through a select! loop whose other branch fires all the time. The
    // producer stays at most 4 samples ahead of the receiver (the topic buffers 8
    // and overwrites the oldest), so a loaded machine cannot lose samples to
    // overflow: a stall can only be a missed wake-up, and says what a direct look
    // finds. (Without the bound, a receiver starved for a millisecond by a busy CI
    // machine lost samples and the loop waited for ever: its stall timer was
    // re-created on every tick.)
    let taken = Arc::new(AtomicUsize::new(0));
    let seen = taken.clone();
    let producer = std::thread::spawn(move || {
        let give_up = std::time::Instant::now() + Duration::from_secs(60);
        for i in 1..=300usize {
            while i > seen.load(Ordering::Acquire) + 4 {
                if std::time::Instant::now() > give_up {
                    return publ;
                }
                std::thread::sleep(Duration::from_micros(50));
            }
            if i % 3 == 0 {
                std::thread::sleep(Duration::from_micros(300));
            }
            publ.publish(sample(i as f64)).unwrap();
        }
        publ
    });
    let mut got = Vec::new();
    let stall = tokio::time::sleep(Duration::from_secs(10));
    tokio::pin!(stall);
    while got.len() < 300 {
        tokio::select! {
            v = sub.recv() => {
                got.push(v.unwrap().lat_deg);
                taken.store(got.len(), Ordering::Release);
                stall.as_mut().reset(tokio::time::Instant::now() + Duration::from_secs(10));
            }
            _ = tick.tick() => {}
            () = &mut stall => {
                let waiting = sub.try_recv().unwrap().map(|v| v.lat_deg);
                panic!(
                    "stalled 10 s after {} samples (last {:?}); a direct look finds {waiting:?}",
                    got.len(),
                    got.last()
                );
            }
        }
    }
    let want: Vec<f64> = (1..=300u32).map(f64::from).collect();
    assert_eq!(got, want);
    let _publ = producer.join().unwrap();
}
