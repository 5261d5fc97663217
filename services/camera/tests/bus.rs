//! The camera service in-process on the real bus (its own iceoryx2 domain): frames
//! reach a `FrameSubscriber` with a consistent header, and the truth matches them;
//! frames are made only on demand (a reader's word, a subscriber, or `always_on`).

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_camera::{run, RawConfig};
use skymesh_ipc_types::{
    topics, CameraDemand, FrameHeader, LensModel, PixelFormat, SceneTruth, ServiceId, VehicleState,
    CAMERA_DEMAND_LEASE_NS,
};
use skymesh_runtime::ipc::DomainGuard;
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, ServiceConfig, Stats};

/// Generous bound for anything that should take a moment.
const PATIENCE: Duration = Duration::from_secs(30);

fn unique_domain() -> DomainGuard {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "cam{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    DomainGuard(Domain::load(&name, None).expect("domain"))
}

fn settings(edits: &[(&str, &str)]) -> skymesh_camera::Settings {
    let mut text = RawConfig::DEFAULT_TOML.to_string();
    for (from, to) in [
        ("width = 1280", "width = 320"),
        ("height = 720", "height = 240"),
    ]
    .iter()
    .chain(edits)
    {
        assert!(text.contains(from), "the shipped config has no `{from}`");
        text = text.replace(from, to);
    }
    skymesh_runtime::config::parse::<RawConfig>(&text, "test").expect("config")
}

#[derive(Debug, Clone)]
struct Seen {
    header: FrameHeader,
    /// A copy of the pixels (the test's own; the service never copies them).
    pixels: Vec<u8>,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_and_truth_follow_the_vehicle() {
    let settings = settings(&[]);
    let domain = unique_domain();
    let stats = Stats::new();
    let bus = Bus::open(&domain, "camera", ServiceId::Camera, 0, stats.clone()).expect("bus");
    let tool = Bus::open(&domain, "viewer", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut frames = tool
        .frame_subscriber(&topics::camera_frames("main"))
        .expect("frame subscriber");
    let truth = tool
        .subscriber::<SceneTruth>(&topics::camera_truth("main"))
        .expect("truth subscriber");
    let mut vehicle = tool
        .publisher::<VehicleState>(&topics::vehicle_state(1))
        .expect("vehicle publisher");

    let shutdown = CancellationToken::new();
    let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "camera");
    let task = tokio::spawn(run(settings, ctx));

    // The vehicle hovers 50 m above home, heading east; the default mount looks down.
    let state = VehicleState {
        vehicle_id: 1,
        position_valid: 1,
        attitude_valid: 1,
        lat_deg: 47.397742,
        lon_deg: 8.545594,
        alt_msl_m: 538.0,
        alt_rel_m: 50.0,
        yaw_rad: std::f32::consts::FRAC_PI_2,
        ..VehicleState::default()
    };
    let mut seen: Vec<Seen> = Vec::new();
    let mut truths: Vec<SceneTruth> = Vec::new();
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let paired = |seen: &[Seen], truths: &[SceneTruth]| {
        truths.iter().find_map(|t| {
            seen.iter()
                .find(|f| f.header.frame_seq == t.frame_seq)
                .map(|f| (f.clone(), *t))
        })
    };
    while seen.len() < 3 || paired(&seen, &truths).is_none() {
        assert!(tokio::time::Instant::now() < deadline, "no frames");
        // Published until frames come: a subscriber that connects late gets the
        // history only when the publisher sends again.
        vehicle.publish(state).expect("publish vehicle state");
        let got = tokio::time::timeout(
            Duration::from_millis(100),
            frames.recv_with(|h, px| Seen {
                header: *h,
                pixels: px.to_vec(),
            }),
        )
        .await;
        if let Ok(frame) = got {
            seen.push(frame.expect("receive frame"));
        }
        while let Some(t) = truth.try_recv().expect("receive truth") {
            truths.push(t);
        }
    }
    shutdown.cancel();
    task.await.expect("join").expect("camera run");

    for w in seen.windows(2) {
        assert!(w[1].header.frame_seq > w[0].header.frame_seq);
        assert!(w[1].header.capture_mono_ns > w[0].header.capture_mono_ns);
    }
    let last = seen.last().unwrap();
    let h = &last.header;
    assert_eq!(h.validate(last.pixels.len()), Ok(PixelFormat::Rgb24));
    assert_eq!((h.width, h.height, h.stride), (320, 240, 960));
    assert_eq!(h.header.service, ServiceId::Camera.to_wire());
    assert_eq!(h.lens_model(), Ok(LensModel::Pinhole));
    assert_eq!(h.intrinsics.valid, 1);
    assert!((h.intrinsics.fx - 160.0).abs() < 1e-3);
    assert_eq!((h.intrinsics.cx, h.intrinsics.cy), (159.5, 119.5));
    assert!(h.capture_unix_ns > 0);
    assert_eq!(h.pose.valid, 1);
    assert_eq!(
        (h.pose.lat_deg, h.pose.lon_deg),
        (state.lat_deg, state.lon_deg)
    );
    assert_eq!(h.pose.alt_m, 538.0);
    // Mount → NED: looking down with the image top toward the east (yaw 90°, pitch −90°):
    // the optical axis is down.
    let [w, x, y, z] = h.pose.attitude_q.map(f64::from);
    let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let axis = q.transform_vector(&nalgebra::Vector3::x());
    assert!((axis.z - 1.0).abs() < 1e-5, "{axis:?}");
    let top = q.transform_vector(&-nalgebra::Vector3::z());
    assert!((top.y - 1.0).abs() < 1e-5, "{top:?}");
    // The vehicle's nose (yaw_rad π/2) travels separately from the camera.
    assert!(
        (h.vehicle_heading_deg - 90.0).abs() < 1e-3,
        "{}",
        h.vehicle_heading_deg
    );

    // The truth of a frame: three targets around home on the ground.
    let (frame, t) = paired(&seen, &truths).expect("a truth of a frame");
    assert_eq!(t.capture_mono_ns, frame.header.capture_mono_ns);
    let ids: Vec<u32> = t.targets().iter().map(|t| t.id).collect();
    assert_eq!(ids, [1, 2, 3]);
    for tg in t.targets() {
        assert_eq!(tg.alt_msl_m, 488.0);
        assert!((tg.lat_deg - state.lat_deg).abs() < 0.001);
        assert!((tg.lon_deg - state.lon_deg).abs() < 0.001);
        // Where the truth says the target is, the frame shows its colour.
        assert_eq!(tg.in_view, 1, "{tg:?}");
        let (u, v) = (tg.pixel_u.round() as u32, tg.pixel_v.round() as u32);
        let i = (v * frame.header.stride + u * 3) as usize;
        assert_eq!(frame.pixels[i..i + 3], tg.rgb, "{tg:?}");
    }
    assert!(
        stats
            .value("skymesh_camera_frames_published_total", "")
            .unwrap_or(0.0)
            >= 3.0
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_vehicle_the_camera_waits_unless_an_origin_is_set() {
    // With an origin: frames at once, from the standby pose.
    let s = settings(&[
        ("# origin = {", "origin = {"),
        ("format = \"rgb24\"", "format = \"nv12\""),
    ]);
    let domain = unique_domain();
    let stats = Stats::new();
    let bus = Bus::open(&domain, "camera", ServiceId::Camera, 0, stats.clone()).expect("bus");
    let tool = Bus::open(&domain, "viewer", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut frames = tool
        .frame_subscriber(&topics::camera_frames("main"))
        .expect("frame subscriber");
    let shutdown = CancellationToken::new();
    let task = tokio::spawn(run(
        s,
        Context::new(bus, shutdown.clone(), stats.clone(), "camera"),
    ));
    let (h, len) = tokio::time::timeout(PATIENCE, frames.recv_with(|h, px| (*h, px.len())))
        .await
        .expect("a frame")
        .expect("receive");
    shutdown.cancel();
    task.await.expect("join").expect("run");
    assert_eq!(h.validate(len), Ok(PixelFormat::Nv12));
    assert_eq!(len, 320 * 240 * 3 / 2);
    assert_eq!(h.pose.alt_m, 538.0);

    // Without: nothing is published, and the ticks are counted.
    let s = settings(&[]);
    let domain = unique_domain();
    let stats = Stats::new();
    let bus = Bus::open(&domain, "camera", ServiceId::Camera, 0, stats.clone()).expect("bus");
    let tool = Bus::open(&domain, "viewer", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let frames = tool
        .frame_subscriber(&topics::camera_frames("main"))
        .expect("frame subscriber");
    let shutdown = CancellationToken::new();
    let task = tokio::spawn(run(
        s,
        Context::new(bus, shutdown.clone(), stats.clone(), "camera"),
    ));
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while stats
        .value("skymesh_camera_frames_skipped_total", "reason=no_pose")
        .unwrap_or(0.0)
        < 3.0
    {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no skipped ticks counted"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    shutdown.cancel();
    task.await.expect("join").expect("run");
    assert!(frames.try_recv_with(|_, _| ()).expect("receive").is_none());
}

/// Waits (up to `PATIENCE`) until `f` holds.
async fn until(what: &str, mut f: impl FnMut() -> bool) {
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while !f() {
        assert!(tokio::time::Instant::now() < deadline, "never: {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Frames are made only on demand: none while nobody wants them; a reader's demand
/// word makes them without any subscriber, until it is withdrawn or lapses; a
/// subscriber that sends no word gets them too; `always_on` makes them regardless.
/// Each step waits for the event the contract names (the `skymesh_camera_active`
/// gauge, the frame counter, a frame), never for a time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_are_made_only_on_demand() {
    for always_on in [false, true] {
        // A configured origin: frames need no vehicle.
        let settings = settings(&[
            ("# origin = {", "origin = {"),
            ("always_on = false", &format!("always_on = {always_on}")),
        ]);
        let period = Duration::from_secs_f64(1.0 / f64::from(settings.fps));
        let domain = unique_domain();
        let stats = Stats::new();
        let bus = Bus::open(&domain, "camera", ServiceId::Camera, 0, stats.clone()).expect("bus");
        let tool =
            Bus::open(&domain, "viewer", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
        let mut words = tool
            .publisher::<CameraDemand>(&topics::camera_demand("main"))
            .expect("demand publisher");
        let word = |wanted| CameraDemand {
            wanted,
            ..CameraDemand::default()
        };
        let shutdown = CancellationToken::new();
        let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "camera");
        let task = tokio::spawn(run(settings, ctx));
        let published = || {
            stats
                .value("skymesh_camera_frames_published_total", "")
                .unwrap_or(0.0)
        };
        let active = || stats.value("skymesh_camera_active", "");

        if always_on {
            until("frames without a reader (always_on)", || published() >= 5.0).await;
            assert_eq!(active(), Some(1.0));
            shutdown.cancel();
            task.await.expect("join").expect("clean stop");
            continue;
        }

        // 1. Nobody wants frames: idle from the first look, and no frame is made
        // however long it stays so (ten frame periods here).
        until("idle", || active() == Some(0.0)).await;
        tokio::time::sleep(period * 10).await;
        assert_eq!(published(), 0.0, "frames without a reader");
        assert_eq!(active(), Some(0.0));

        // 2. A demand word: frames, with no subscriber at all.
        words.publish(word(1)).expect("demand word");
        until("frames after the demand word", || published() >= 3.0).await;
        assert_eq!(active(), Some(1.0));

        // 3. The word withdrawn: idle again, and no frame after that.
        words.publish(word(0)).expect("demand word");
        until("idle after the word was withdrawn", || {
            active() == Some(0.0)
        })
        .await;
        let stopped = published();
        tokio::time::sleep(period * 10).await;
        assert_eq!(published(), stopped, "frames after the word was withdrawn");

        // 4. A word never renewed (its reader died) lapses, not before its lease.
        let sent = std::time::Instant::now();
        words.publish(word(1)).expect("demand word");
        until("frames after the second word", || published() > stopped).await;
        until("the word lapsed", || active() == Some(0.0)).await;
        let lapsed = sent.elapsed();
        assert!(
            lapsed >= Duration::from_nanos(CAMERA_DEMAND_LEASE_NS),
            "lapsed after {lapsed:?}"
        );
        let stopped = published();

        // 5. A subscriber that sends no word is found by the idle look: it gets the
        // next frame; once it leaves, the camera idles.
        let mut frames = tool
            .frame_subscriber(&topics::camera_frames("main"))
            .expect("frame subscriber");
        let got = tokio::time::timeout(PATIENCE, async {
            loop {
                let seq = frames.recv_with(|h, _| h.frame_seq).await.expect("frame");
                // The topic's history may hold the last frame made for the word.
                if seq as f64 > stopped {
                    break seq;
                }
            }
        })
        .await
        .expect("no frame for the subscriber");
        assert_eq!(got as f64, stopped + 1.0, "the next frame");
        assert_eq!(active(), Some(1.0));
        drop(frames);
        until("idle after the subscriber left", || active() == Some(0.0)).await;
        let stopped = published();
        tokio::time::sleep(period * 10).await;
        assert_eq!(published(), stopped, "frames after the subscriber left");

        shutdown.cancel();
        task.await.expect("join").expect("clean stop");
    }
}
