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
    // After every node is gone, only iceoryx2's global management file and the
    // topic's event count (owned by nobody, so a service restarted alone finds the
    // one the others use) may remain; the supervisor removes them with the domain.
    let left = d1.leftover_files();
    let count_file = |p: &std::path::PathBuf| {
        let name = p
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        name.starts_with(&d1.wake_prefix()) && name.ends_with(".dyn")
    };
    assert!(
        left.len() <= 2
            && left
                .iter()
                .all(|p| p.to_string_lossy().ends_with(".global_mgmt") || count_file(p)),
        "{left:?}"
    );
    assert!(left.iter().any(count_file), "no event count: {left:?}");
    d1.remove_leftover_files();
    assert!(d1.leftover_files().is_empty(), "{:?}", d1.leftover_files());
    d2.remove_leftover_files();
    assert!(d1.leftover_files().is_empty());
}

#[test]
fn the_blocking_wait_loop_wakes_on_samples_and_ticks_and_stops() {
    use skymesh_ipc_types::VehicleStatus;
    use skymesh_runtime::{wait_loop, CancellationToken, Wake};
    use std::ops::ControlFlow;

    // No tokio runtime here: the blocking loop needs none.
    let d = domain("w");
    let bus = Bus::open(&d, "waiter", ServiceId::Tool, 0, Stats::new()).unwrap();
    let state_sub = bus
        .subscriber::<VehicleState>(&topics::vehicle_state(2))
        .unwrap();
    let status_sub = bus
        .subscriber::<VehicleStatus>(&topics::vehicle_status(2))
        .unwrap();
    let mut state_pub = bus
        .publisher::<VehicleState>(&topics::vehicle_state(2))
        .unwrap();
    let mut status_pub = bus
        .publisher::<VehicleStatus>(&topics::vehicle_status(2))
        .unwrap();

    let stop = CancellationToken::new();
    let stopper = stop.clone();
    let publisher = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(50));
        state_pub
            .publish(VehicleState {
                lat_deg: 9.0,
                ..Default::default()
            })
            .unwrap();
        std::thread::sleep(Duration::from_millis(50));
        status_pub
            .publish(VehicleStatus {
                armed: 1,
                ..Default::default()
            })
            .unwrap();
        std::thread::sleep(Duration::from_millis(300));
        stopper.cancel();
    });
    let (mut states, mut statuses, mut ticks) = (Vec::new(), Vec::new(), 0);
    wait_loop(
        &[&state_sub, &status_sub],
        Some(Duration::from_millis(20)),
        &stop,
        |wake| {
            match wake {
                Wake::Topic(0) => {
                    states.extend(std::iter::from_fn(|| state_sub.try_recv().unwrap()))
                }
                Wake::Topic(_) => {
                    statuses.extend(std::iter::from_fn(|| status_sub.try_recv().unwrap()))
                }
                Wake::Tick => ticks += 1,
            }
            ControlFlow::Continue(())
        },
    )
    .unwrap();
    publisher.join().unwrap();
    assert_eq!(states.len(), 1);
    assert_eq!(states[0].lat_deg, 9.0);
    assert_eq!(statuses.len(), 1);
    assert!(statuses[0].is_armed());
    assert!(ticks >= 5, "interval ticks: {ticks}");
}

/// `recv_blocking` (with and without a spin before blocking): times out with
/// nothing pending, is woken by a publisher on another thread, returns samples in
/// order, and a spin that took a sample leaves no stale notification behind (the
/// next receive must wait for the next sample, not return early with nothing).
#[test]
fn recv_blocking_waits_wakes_and_times_out_with_and_without_spin() {
    for (tag, spin) in [("rb0", Duration::ZERO), ("rb1", Duration::from_micros(300))] {
        let d = domain(tag);
        let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
        let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
        let topic = topics::vehicle_state(3);
        let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
        sub.set_spin(spin);
        let mut publ = a.publisher::<VehicleState>(&topic).unwrap();

        let t0 = std::time::Instant::now();
        assert!(sub
            .recv_blocking(Some(Duration::from_millis(30)))
            .unwrap()
            .is_none());
        assert!(t0.elapsed() >= Duration::from_millis(30), "{spin:?}");

        std::thread::scope(|s| {
            let publisher = s.spawn(move || {
                for i in 1..=3 {
                    std::thread::sleep(Duration::from_millis(10));
                    publ.publish(VehicleState {
                        lat_deg: f64::from(i),
                        ..Default::default()
                    })
                    .unwrap();
                }
                publ
            });
            for i in 1..=3 {
                let v = sub
                    .recv_blocking(Some(Duration::from_secs(5)))
                    .unwrap()
                    .expect("woken by the publisher");
                assert_eq!(v.lat_deg, f64::from(i), "{spin:?}");
            }
            let _publ = publisher.join().unwrap();
            // Everything was taken: the next receive waits for its whole timeout.
            let t0 = std::time::Instant::now();
            assert!(sub
                .recv_blocking(Some(Duration::from_millis(20)))
                .unwrap()
                .is_none());
            assert!(t0.elapsed() >= Duration::from_millis(20), "{spin:?}");
        });
    }
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

/// The receive paths take a sample before they consume its notification and drain
/// before they wait again: a stream of samples each published while the receiver is
/// blocked is received whole (a notification consumed but not looked after would
/// lose a wake-up and time out), and after the last one the receiver blocks — it
/// does not poll on an unread notification (measured as the thread's CPU time over
/// the wait, which a poll would spend whole).
#[test]
fn receivers_take_the_sample_first_and_block_again_after_draining() {
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

    // Blocking receive.
    std::thread::scope(|s| {
        let p = s.spawn(|| publish_stream(&mut publ));
        for i in 1..=50 {
            let v = sub
                .recv_blocking(Some(Duration::from_secs(5)))
                .unwrap()
                .expect("every sample wakes the receiver");
            assert_eq!(v.lat_deg, f64::from(i));
        }
        p.join().unwrap();
    });
    assert_blocks(idle, "blocking wait", || {
        assert!(sub.recv_blocking(Some(idle)).unwrap().is_none())
    });

    // Async receive, on a current-thread runtime (the receiving thread is this one).
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    std::thread::scope(|s| {
        let p = s.spawn(|| publish_stream(&mut publ));
        rt.block_on(async {
            for i in 51..=100 {
                let v = sub
                    .recv_timeout(Duration::from_secs(5))
                    .await
                    .unwrap()
                    .expect("every sample wakes the receiver");
                assert_eq!(v.lat_deg, f64::from(i - 50));
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

/// `set_anticipate`: a periodic stream is received whole and in order, some samples
/// are taken by polling in the window around their expected time (no wake-up), the
/// period is learnt from the send stamps, a receive still times out when the stream
/// stops, and a sample taken while polling leaves no stale notification behind.
#[test]
fn anticipating_receive_takes_a_periodic_stream_in_order_and_times_out() {
    let d = domain("ant");
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::vehicle_state(4);
    let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
    sub.set_anticipate(Duration::from_millis(2));
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();
    const N: u32 = 150;
    const PERIOD: Duration = Duration::from_millis(5);

    let sent = std::thread::scope(|s| {
        let publisher = s.spawn(move || {
            let t0 = std::time::Instant::now();
            let mut sent = Vec::with_capacity(N as usize);
            for i in 1..=N {
                // Absolute pacing, as a camera or a fixed-rate telemetry loop does.
                let due = t0 + PERIOD * i;
                std::thread::sleep(due.saturating_duration_since(std::time::Instant::now()));
                sent.push(std::time::Instant::now());
                publ.publish(VehicleState {
                    lat_deg: f64::from(i),
                    ..Default::default()
                })
                .unwrap();
            }
            (publ, sent)
        });
        for i in 1..=N {
            let v = sub
                .recv_blocking(Some(Duration::from_secs(5)))
                .unwrap()
                .expect("every sample arrives");
            assert_eq!(v.lat_deg, f64::from(i));
        }
        let (_publ, sent) = publisher.join().unwrap();
        let t0 = std::time::Instant::now();
        assert!(sub
            .recv_blocking(Some(Duration::from_millis(30)))
            .unwrap()
            .is_none());
        assert!(t0.elapsed() >= Duration::from_millis(30));
        sent
    });
    let stats = sub.anticipation().expect("on");
    let period = stats.period.expect("period learnt");
    // Learnt from the send stamps: within the span of the intervals the publisher
    // really had (a stall on a loaded machine stretches some and bunches others; the
    // filter itself is checked with exact stamps in anticipate.rs). Off by the
    // factors a wrong unit or a receive-side clock would give, it fails.
    let intervals: Vec<Duration> = sent.windows(2).map(|w| w[1] - w[0]).collect();
    let (shortest, longest) = (
        *intervals.iter().min().unwrap(),
        *intervals.iter().max().unwrap(),
    );
    assert!(
        period >= shortest / 2 && period <= longest * 2,
        "{stats:?}, send intervals {shortest:?}..{longest:?}"
    );
    assert!(stats.windows > 0 && stats.hits > 0, "{stats:?}");
    assert!(stats.hits <= stats.windows, "{stats:?}");

    sub.set_anticipate(Duration::ZERO);
    assert!(sub.anticipation().is_none());
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

/// Publishes one sample on `topic` after `after` unless `cancel` is set first: a
/// receive that should time out but instead hangs (a timeout that never fires)
/// gets this sample and fails its assertion instead of hanging the test.
fn rescue(
    bus: &Bus,
    topic: &skymesh_ipc_types::Topic,
    after: Duration,
) -> (
    Arc<std::sync::atomic::AtomicBool>,
    std::thread::JoinHandle<()>,
) {
    let cancel = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut publ = bus.publisher::<VehicleState>(topic).unwrap();
    let c = Arc::clone(&cancel);
    let t = std::thread::spawn(move || {
        let t0 = std::time::Instant::now();
        while t0.elapsed() < after {
            if c.load(Ordering::SeqCst) {
                return;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        publ.publish(VehicleState {
            lat_deg: -1.0,
            ..Default::default()
        })
        .unwrap();
    });
    (cancel, t)
}

/// A receiver that blocks on the topic's event count: a [`skymesh_runtime::Subscriber`]
/// after `set_futex_wake`, or a [`skymesh_runtime::BlockingSubscriber`].
trait FutexReceiver {
    fn recv_for(&self, timeout: Duration) -> Option<VehicleState>;
    fn set_spin(&mut self, spin: Duration);
}

impl FutexReceiver for skymesh_runtime::Subscriber<VehicleState> {
    fn recv_for(&self, timeout: Duration) -> Option<VehicleState> {
        self.recv_blocking(Some(timeout)).unwrap()
    }
    fn set_spin(&mut self, spin: Duration) {
        skymesh_runtime::Subscriber::set_spin(self, spin);
    }
}

impl FutexReceiver for skymesh_runtime::BlockingSubscriber<VehicleState> {
    fn recv_for(&self, timeout: Duration) -> Option<VehicleState> {
        self.recv_blocking(Some(timeout)).unwrap()
    }
    fn set_spin(&mut self, spin: Duration) {
        skymesh_runtime::BlockingSubscriber::set_spin(self, spin);
    }
}

/// `set_futex_wake`: blocking receives sleep on the topic's event count. With and
/// without a spin: a receive with nothing pending times out (the futex wait's own
/// timeout), a stream published while the receiver blocks arrives whole and in
/// order (a publisher that did not wake the count would leave every receive to time
/// out), after it the receiver blocks rather than polls (thread CPU over the wait),
/// and no receive leaves its announcement behind (publishers would make the wake-up
/// call on every publish).
#[test]
fn futex_wake_receives_a_stream_whole_and_times_out() {
    for (tag, spin) in [("fx0", Duration::ZERO), ("fx1", Duration::from_micros(300))] {
        futex_receiver_takes_a_stream(tag, spin, |bus, topic| {
            let mut sub = bus.subscriber::<VehicleState>(topic).unwrap();
            sub.set_futex_wake().unwrap();
            sub
        });
    }
}

/// The same for a [`skymesh_runtime::BlockingSubscriber`] (iceoryx2's single-thread
/// flavour on a node of its own, beside thread-safe publishers), which also counts
/// what it received in the bus's series.
#[test]
fn a_blocking_subscriber_receives_a_stream_whole_and_times_out() {
    for (tag, spin) in [("bs0", Duration::ZERO), ("bs1", Duration::from_micros(300))] {
        futex_receiver_takes_a_stream(tag, spin, |bus, topic| {
            bus.blocking_subscriber::<VehicleState>(topic).unwrap()
        });
    }
}

fn futex_receiver_takes_a_stream<R: FutexReceiver>(
    tag: &str,
    spin: Duration,
    make: impl FnOnce(&Bus, &skymesh_ipc_types::Topic) -> R,
) {
    let d = domain(tag);
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
    // Room for the whole stream: a receiver stalled by a loaded machine must not
    // lose samples to overwriting (that is not what this test is about).
    let topic = skymesh_ipc_types::Topic {
        qos: skymesh_ipc_types::TopicQos {
            buffer: 64,
            ..skymesh_ipc_types::TopicQos::STATE
        },
        ..topics::vehicle_state(5)
    };
    let mut sub = make(&b, &topic);
    sub.set_spin(spin);
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();

    let (cancel, rescuer) = rescue(&a, &topic, Duration::from_secs(10));
    let t0 = std::time::Instant::now();
    let got = sub.recv_for(Duration::from_millis(30));
    let waited = t0.elapsed();
    cancel.store(true, Ordering::SeqCst);
    rescuer.join().unwrap();
    assert!(got.is_none(), "{tag}: the timeout never ended the wait");
    assert!(waited >= Duration::from_millis(30), "{tag}: {waited:?}");

    let t0 = std::time::Instant::now();
    std::thread::scope(|s| {
        let p = s.spawn(|| {
            for i in 1..=50 {
                std::thread::sleep(Duration::from_micros(if i % 2 == 0 { 200 } else { 1500 }));
                publ.publish(VehicleState {
                    lat_deg: f64::from(i),
                    ..Default::default()
                })
                .unwrap();
            }
        });
        for i in 1..=50 {
            let v = sub
                .recv_for(Duration::from_secs(5))
                .expect("every sample wakes the receiver");
            assert_eq!(v.lat_deg, f64::from(i), "{tag}");
        }
        p.join().unwrap();
    });
    // Woken by each sample, not by the 5 s timeout: the stream takes ~45 ms.
    let took = t0.elapsed();
    assert!(took < Duration::from_secs(4), "{tag}: stream took {took:?}");
    let idle = Duration::from_millis(300);
    assert_blocks(idle, &format!("{tag}: blocking wait"), || {
        assert!(sub.recv_for(idle).is_none())
    });
    let count = skymesh_runtime::TopicWord::open(&d.wake_prefix(), &topic.name).unwrap();
    assert_eq!(count.waiters(), 0, "{tag}: an announcement left behind");
    let series = [("topic", topic.name.as_str())];
    let stats = b.stats();
    assert_eq!(
        stats
            .counter("skymesh_topic_samples_received_total", &series)
            .get(),
        50,
        "{tag}"
    );
    assert_eq!(
        stats
            .counter("skymesh_topic_samples_lost_total", &series)
            .get(),
        0,
        "{tag}"
    );
}

/// One publish wakes every futex receiver asleep on its topic — two subscribers
/// with `set_futex_wake` and two `BlockingSubscriber`s here, each on its own
/// thread. Until 2026-11-29 the wake-up call woke exactly one of them (a count of
/// `u32::MAX` is -1 to the kernel); the others slept through the sample until the
/// next publish or, on a quiet topic, their timeout (20 s here; a receive ended
/// by its timeout still takes the sample, so the test tells the two apart by when
/// each returned: within half the timeout of the publish, against milliseconds
/// when woken — not a measurement).
#[test]
fn one_publish_wakes_every_futex_receiver_of_the_topic() {
    let d = domain("fxall");
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::vehicle_state(8);
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();
    let count = skymesh_runtime::TopicWord::open(&d.wake_prefix(), &topic.name).unwrap();
    let guard = Duration::from_secs(20);
    std::thread::scope(|s| {
        let receivers: Vec<_> = (0..4)
            .map(|i| {
                let (b, topic) = (&b, &topic);
                s.spawn(move || {
                    // A `BlockingSubscriber` is made on the thread that uses it.
                    let got = if i % 2 == 0 {
                        let mut sub = b.subscriber::<VehicleState>(topic).unwrap();
                        sub.set_futex_wake().unwrap();
                        sub.recv_for(guard)
                    } else {
                        b.blocking_subscriber::<VehicleState>(topic)
                            .unwrap()
                            .recv_for(guard)
                    };
                    (got.map(|v| v.lat_deg), std::time::Instant::now())
                })
            })
            .collect();
        // All four asleep (or about to be: a wait announced before the publish
        // returns at once once the count has moved) before the one publish.
        let t0 = std::time::Instant::now();
        while count.waiters() < 4 {
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "receivers did not wait"
            );
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(20));
        let published = std::time::Instant::now();
        publ.publish(VehicleState {
            lat_deg: 1.0,
            ..Default::default()
        })
        .unwrap();
        for (i, r) in receivers.into_iter().enumerate() {
            let (got, at) = r.join().unwrap();
            assert_eq!(got, Some(1.0), "receiver {i}'s sample");
            let after = at.duration_since(published);
            assert!(
                after < guard / 2,
                "receiver {i} slept through the publish: it returned {after:?} later, at its timeout"
            );
        }
    });
    assert_eq!(count.waiters(), 0);
}

/// Timeouts of two futex receivers on one topic are their own: after a long timeout
/// ended by a sample, a shorter one ends on time (not at the old deadline), and one
/// receiver's timeout neither ends nor shortens the other's wait. (Until 2026-11-28
/// a watchdog thread per subscriber ended timed waits by waking the whole topic;
/// this test kept its early wake-up honest and stays for the same properties.)
#[test]
fn futex_wake_a_shorter_timeout_than_the_last_still_ends_on_time() {
    let d = domain("fxt");
    let a = Bus::open(&d, "pub-node", ServiceId::AutopilotLink, 1, Stats::new()).unwrap();
    let b = Bus::open(&d, "sub-node", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::vehicle_state(6);
    let mut sub = b.subscriber::<VehicleState>(&topic).unwrap();
    sub.set_futex_wake().unwrap();
    let mut other = b.subscriber::<VehicleState>(&topic).unwrap();
    other.set_futex_wake().unwrap();
    let mut publ = a.publisher::<VehicleState>(&topic).unwrap();

    // A long timeout, ended by a sample.
    std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(Duration::from_millis(20));
            publ.publish(VehicleState::default()).unwrap();
        });
        assert!(sub
            .recv_blocking(Some(Duration::from_secs(8)))
            .unwrap()
            .is_some());
    });
    assert!(other.try_recv().unwrap().is_some());

    // The rescue sample at 4 s comes before the old deadline: without the early
    // wake-up the short receive below gets it instead of timing out.
    let (cancel, rescuer) = rescue(&a, &topic, Duration::from_secs(4));
    let t0 = std::time::Instant::now();
    let got = sub.recv_blocking(Some(Duration::from_millis(40))).unwrap();
    let waited = t0.elapsed();
    assert!(
        got.is_none(),
        "the short timeout waited for the old deadline"
    );
    assert!(waited >= Duration::from_millis(40), "{waited:?}");

    // The other receiver waits on through this one's timeout.
    let other_wait = Duration::from_millis(600);
    std::thread::scope(|s| {
        let o = s.spawn(|| {
            let t0 = std::time::Instant::now();
            let got = other.recv_blocking(Some(other_wait)).unwrap();
            (got, t0.elapsed())
        });
        assert!(sub
            .recv_blocking(Some(Duration::from_millis(40)))
            .unwrap()
            .is_none());
        let (got, waited) = o.join().unwrap();
        assert!(got.is_none());
        assert!(
            waited >= other_wait,
            "ended by the other receiver's timeout, returned after {waited:?}"
        );
    });
    cancel.store(true, Ordering::SeqCst);
    rescuer.join().unwrap();
}
