//! The pipeline in-process on the real bus (its own iceoryx2 domain), fed synthetic
//! frames rendered by the camera's renderer at 50 m looking down with known targets:
//! detections match the truth, an `Output` control resizes the output, `Targeting`
//! aims a view at a target, `DirectionAt` its centre is the view's direction, every
//! control is answered and garbage is Invalid; the pipeline
//! reads frames only while its output is used, and publishes the state that contains
//! a control's change before the control's reply.

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_camera::synthetic::{FrameStamp, Synthetic};
use skymesh_ipc_types::{
    topics, view, CameraDemand, FixedStr, SceneTruth, ServiceId, VehicleState, ViewControl,
    ViewControlKind, ViewReply, VisionControl, VisionDemand, VisionOrigin, VisionReply,
    VisionResult, VisionState, MAX_FRAME_LEN, VISION_DEMAND_LEASE_NS,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::ipc::DomainGuard;
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, ServiceConfig, Stats, Subscriber};
use skymesh_vision_pipeline::geometry::{GeoPosition, YawPitch};

/// Generous bound for anything that should take a moment.
const PATIENCE: Duration = Duration::from_secs(60);

/// A fresh domain whose shared-memory files go when the test ends (declared
/// before the buses, so their nodes are gone first).
fn unique_domain() -> DomainGuard {
    static N: AtomicU32 = AtomicU32::new(0);
    let name = format!(
        "vis{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    DomainGuard(Domain::load(&name, None).expect("domain"))
}

fn edit<C: ServiceConfig>(edits: &[(&str, &str)]) -> C::Settings {
    let mut text = C::DEFAULT_TOML.to_string();
    for (from, to) in edits {
        assert!(text.contains(from), "the shipped config has no `{from}`");
        text = text.replace(from, to);
    }
    skymesh_runtime::config::parse::<C>(&text, "test").expect("config")
}

/// The camera's scene, targets standing still.
fn camera() -> Synthetic {
    Synthetic::new(edit::<skymesh_camera::RawConfig>(&[
        ("width = 1280", "width = 640"),
        ("height = 720", "height = 480"),
        ("# origin = {", "origin = {"),
        ("speed_mps = 1.4", "speed_mps = 0.0"),
        ("speed_mps = 1.2", "speed_mps = 0.0"),
        ("speed_mps = 1.0", "speed_mps = 0.0"),
    ]))
}

fn vehicle() -> VehicleState {
    // 50 m above the origin's ground, heading east, level.
    let yaw = std::f32::consts::FRAC_PI_2;
    let q = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, f64::from(yaw));
    VehicleState {
        vehicle_id: 1,
        position_valid: 1,
        attitude_valid: 1,
        lat_deg: 47.397742,
        lon_deg: 8.545594,
        alt_msl_m: 538.0,
        alt_rel_m: 50.0,
        heading_deg: 90.0,
        yaw_rad: yaw,
        attitude_q: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
        ..VehicleState::default()
    }
}

/// A view control of `kind` for stream `main`.
fn ctl(request_id: u64, kind: ViewControlKind) -> ViewControl {
    ViewControl {
        request_id,
        kind: kind.to_wire(),
        origin: VisionOrigin::DigiView.to_wire(),
        stream: FixedStr::new("main"),
        ..ViewControl::default()
    }
}

fn deg(rad: f64) -> f64 {
    rad.to_degrees()
}

fn angle_diff_deg(a: f64, b: f64) -> f64 {
    deg(skymesh_vision_pipeline::geometry::wrap_pi(a - b)).abs()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn detections_views_and_controls_on_the_bus() {
    let domain = unique_domain();
    let stats = Stats::new();
    let bus = Bus::open(
        &domain,
        "vision",
        ServiceId::VisionPipeline,
        0,
        stats.clone(),
    )
    .expect("bus");
    let tool = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut frames = tool
        .frame_publisher(&topics::camera_frames("main"), MAX_FRAME_LEN)
        .expect("frame publisher");
    let mut vehicle_pub = tool
        .publisher::<VehicleState>(&topics::vehicle_state(1))
        .expect("vehicle publisher");
    let mut control = tool
        .publisher::<VisionControl>(&topics::vision_control())
        .expect("control publisher");
    let replies = tool
        .subscriber::<VisionReply>(&topics::vision_reply())
        .expect("reply subscriber");
    let mut view_pub = tool
        .publisher::<ViewControl>(&view::view_control())
        .expect("view control publisher");
    let mut view_replies = tool
        .subscriber::<ViewReply>(&view::view_reply())
        .expect("view reply subscriber");
    let state_sub = tool
        .subscriber::<VisionState>(&topics::vision_state())
        .expect("state subscriber");
    let output = tool
        .frame_subscriber(&topics::vision_output("main"))
        .expect("output subscriber");

    let settings = edit::<skymesh_vision_pipeline::RawConfig>(&[
        ("thermal_zone = \"auto\"", "thermal_zone = \"none\""),
        ("width = 1280", "width = 640"),
        ("height = 720", "height = 480"),
    ]);
    let shutdown = CancellationToken::new();
    let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "vision");
    let task = tokio::spawn(skymesh_vision_pipeline::run(settings, ctx));

    let mut cam = camera();
    let v = vehicle();
    cam.update_vehicle(&v);
    let me = GeoPosition {
        lat_deg: v.lat_deg,
        lon_deg: v.lon_deg,
        alt_msl_m: f64::from(v.alt_msl_m),
    };

    // Feeds one frame and the vehicle state; returns the truth.
    let mut seq = 0u64;
    let mut feed = |frames: &mut skymesh_runtime::FramePublisher| -> SceneTruth {
        seq += 1;
        let stamp = FrameStamp {
            seq,
            mono_ns: monotonic_ns(),
            unix_ns: 1,
        };
        let len = 640 * 480 * 3;
        let mut truth = None;
        frames
            .publish_with(len, |h, px| truth = cam.render(0.0, stamp, h, px).ok())
            .expect("publish frame");
        truth.expect("a pose")
    };

    // (request id, result) of every reply, vision and view.
    let mut replies_seen: Vec<(u64, VisionResult)> = Vec::new();
    let mut next_id = 100u64;
    let mut sent_ids: Vec<u64> = Vec::new();

    // 1. Detections match the rendered targets.
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let (truth, state) = loop {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no matching detections"
        );
        vehicle_pub.publish(v).expect("publish vehicle");
        let truth = feed(&mut frames);
        tokio::time::sleep(Duration::from_millis(100)).await;
        let Some(st) = state_sub.latest().expect("state") else {
            continue;
        };
        let visible = truth.targets().iter().filter(|t| t.in_view == 1).count();
        if visible > 0 && st.detections().len() >= visible && st.streams[0].frames_processed >= 3 {
            break (truth, st);
        }
    };
    for t in truth.targets().iter().filter(|t| t.in_view == 1) {
        let pos = GeoPosition {
            lat_deg: t.lat_deg,
            lon_deg: t.lon_deg,
            alt_msl_m: f64::from(t.alt_msl_m),
        };
        let dir = YawPitch::of(&me.ned_to(&pos)).expect("direction");
        let best = state
            .detections()
            .iter()
            .min_by(|a, b| {
                let da = angle_diff_deg(f64::from(a.yaw_global_rad), dir.yaw)
                    .hypot(angle_diff_deg(f64::from(a.pitch_global_rad), dir.pitch));
                let db = angle_diff_deg(f64::from(b.yaw_global_rad), dir.yaw)
                    .hypot(angle_diff_deg(f64::from(b.pitch_global_rad), dir.pitch));
                da.total_cmp(&db)
            })
            .expect("a detection");
        assert!(
            angle_diff_deg(f64::from(best.pitch_global_rad), dir.pitch) < 1.0,
            "target {} pitch {} vs {}",
            t.id,
            deg(f64::from(best.pitch_global_rad)),
            deg(dir.pitch)
        );
        // Straight down the yaw is ill-conditioned; compare it only off nadir.
        if dir.pitch > -89.0f64.to_radians() {
            assert!(
                angle_diff_deg(f64::from(best.yaw_global_rad), dir.yaw) < 1.0,
                "target {} yaw {} vs {}",
                t.id,
                deg(f64::from(best.yaw_global_rad)),
                deg(dir.yaw)
            );
        }
        assert_eq!(best.geo_valid, 1, "{best:?}");
        let found = GeoPosition {
            lat_deg: best.lat_deg,
            lon_deg: best.lon_deg,
            alt_msl_m: f64::from(best.alt_msl_m),
        };
        let miss = pos.ned_to(&found);
        assert!(
            miss.x.hypot(miss.y) < 5.0,
            "target {} off by {miss:?}",
            t.id
        );
    }

    // 2. VIDEO_OUTPUT resizes the output; 3. CAM_TARGETING coordinal aims view 0;
    // 4. garbage is Invalid; every control gets one reply.
    let target = truth
        .targets()
        .iter()
        .find(|t| t.in_view == 1)
        .expect("a target");
    let tpos = GeoPosition {
        lat_deg: target.lat_deg,
        lon_deg: target.lon_deg,
        alt_msl_m: f64::from(target.alt_msl_m),
    };
    let tdir = YawPitch::of(&me.ned_to(&tpos)).expect("direction");
    let video = ViewControl {
        width: 800,
        height: 600,
        layout_mode: 0,
        overlay_mode: 2,
        ..ctl(0, ViewControlKind::Output)
    };
    let aim = ViewControl {
        cam: 0,
        targeting_mode: 1,
        lock_flags: 0b111,
        lat_deg: target.lat_deg,
        lon_deg: target.lon_deg,
        // Relative to the vehicle.
        alt_rel_m: f64::from(target.alt_msl_m) - f64::from(v.alt_msl_m),
        ..ctl(0, ViewControlKind::Targeting)
    };
    let garbage = ViewControl {
        pitch_rad: f64::NAN,
        ..ctl(0, ViewControlKind::Targeting)
    };
    for mut c in [video, aim, garbage] {
        c.request_id = next_id;
        next_id += 1;
        view_pub.publish(c).expect("publish view control");
        sent_ids.push(c.request_id);
    }
    let bogus_kind = VisionControl {
        request_id: next_id,
        kind: 99,
        ..VisionControl::default()
    };
    control.publish(bogus_kind).expect("publish control");
    sent_ids.push(bogus_kind.request_id);

    let deadline = tokio::time::Instant::now() + PATIENCE;
    let mut out_size = None;
    let mut aimed = None;
    while replies_seen.len() < sent_ids.len() || out_size != Some((800, 600)) || aimed.is_none() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "replies {replies_seen:?}, output {out_size:?}, aimed {aimed:?}"
        );
        vehicle_pub.publish(v).expect("publish vehicle");
        feed(&mut frames);
        tokio::time::sleep(Duration::from_millis(100)).await;
        while let Some(r) = replies.try_recv().expect("reply") {
            replies_seen.push((r.request_id, r.result()));
        }
        while let Some(r) = view_replies.try_recv().expect("view reply") {
            replies_seen.push((r.request_id, r.result()));
        }
        while let Some(sz) = output
            .try_recv_with(|h, _| (h.width, h.height))
            .expect("output")
        {
            out_size = Some(sz);
        }
        if let Some(st) = state_sub.latest().expect("state") {
            let c = st.streams[0].cams[0];
            if c.targeting_mode == 1 && c.aim_valid == 1 {
                aimed = Some(c);
            }
        }
    }

    // 5. The direction at the centre of view 0 is the view's own direction.
    let at = ctl(next_id + 1, ViewControlKind::DirectionAt);
    view_pub.publish(at).expect("publish view control");
    let reply = loop {
        let r = view_replies
            .recv_timeout(PATIENCE)
            .await
            .expect("view reply")
            .expect("a view reply");
        if r.request_id == at.request_id {
            break r;
        }
    };
    assert_eq!(reply.result(), VisionResult::Applied, "{reply:?}");
    let cam0 = state_sub.latest().expect("state").expect("a state").streams[0].cams[0];
    assert!(
        angle_diff_deg(reply.pitch_global_rad, f64::from(cam0.view_pitch_rad)) < 0.1
            && reply.yaw_camera_rad.abs() < 1e-3
            && reply.pitch_camera_rad.abs() < 1e-3,
        "{reply:?} vs {cam0:?}"
    );
    shutdown.cancel();
    task.await.expect("join").expect("vision run");

    for id in &sent_ids {
        let n = replies_seen.iter().filter(|r| r.0 == *id).count();
        assert_eq!(n, 1, "request {id}: {replies_seen:?}");
    }
    let result = |id: u64| replies_seen.iter().find(|r| r.0 == id).map(|r| r.1);
    assert_eq!(result(sent_ids[0]), Some(VisionResult::Applied));
    assert_eq!(result(sent_ids[1]), Some(VisionResult::Applied));
    assert_eq!(result(sent_ids[2]), Some(VisionResult::Invalid));
    assert_eq!(result(sent_ids[3]), Some(VisionResult::Invalid));
    let c = aimed.expect("aimed");
    assert!(
        angle_diff_deg(f64::from(c.view_pitch_rad), tdir.pitch) < 1.0,
        "view pitch {} vs {}",
        deg(f64::from(c.view_pitch_rad)),
        deg(tdir.pitch)
    );
    if tdir.pitch > -89.0f64.to_radians() {
        assert!(
            angle_diff_deg(f64::from(c.view_yaw_rad), tdir.yaw) < 1.0,
            "view yaw {} vs {}",
            deg(f64::from(c.view_yaw_rad)),
            deg(tdir.yaw)
        );
    }
    assert!(
        stats
            .value("skymesh_vision_frames_processed_total", "stream=main")
            .unwrap_or(0.0)
            >= 3.0
    );
}

/// The next camera demand word the pipeline publishes.
async fn next_word(words: &mut Subscriber<CameraDemand>) -> CameraDemand {
    words
        .recv_timeout(PATIENCE)
        .await
        .expect("camera demand")
        .expect("a camera demand word")
}

/// Polls `f` every millisecond until it holds; the time it took, or `None` after `limit`.
async fn until(limit: Duration, mut f: impl FnMut() -> bool) -> Option<Duration> {
    let t = std::time::Instant::now();
    while t.elapsed() < limit {
        if f() {
            return Some(t.elapsed());
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    None
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_are_read_only_on_demand_and_replies_follow_their_state() {
    let domain = unique_domain();
    let stats = Stats::new();
    let bus = Bus::open(
        &domain,
        "vision",
        ServiceId::VisionPipeline,
        0,
        stats.clone(),
    )
    .expect("bus");
    let tool = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut frames = tool
        .frame_publisher(&topics::camera_frames("main"), MAX_FRAME_LEN)
        .expect("frame publisher");
    let mut vehicle_pub = tool
        .publisher::<VehicleState>(&topics::vehicle_state(1))
        .expect("vehicle publisher");
    let mut view_pub = tool
        .publisher::<ViewControl>(&view::view_control())
        .expect("view control publisher");
    let mut demand = tool
        .publisher::<VisionDemand>(&topics::vision_demand())
        .expect("demand publisher");
    let mut view_replies = tool
        .subscriber::<ViewReply>(&view::view_reply())
        .expect("view reply subscriber");
    let state_sub = tool
        .subscriber::<VisionState>(&topics::vision_state())
        .expect("state subscriber");
    let mut camera_words = tool
        .subscriber::<CameraDemand>(&topics::camera_demand("main"))
        .expect("camera demand subscriber");

    let settings = edit::<skymesh_vision_pipeline::RawConfig>(&[
        ("thermal_zone = \"auto\"", "thermal_zone = \"none\""),
        ("control_hold_s = 10.0", "control_hold_s = 0.0"),
        ("width = 1280", "width = 640"),
        ("height = 720", "height = 480"),
    ]);
    let shutdown = CancellationToken::new();
    let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "vision");
    let task = tokio::spawn(skymesh_vision_pipeline::run(settings, ctx));

    let mut cam = camera();
    let v = vehicle();
    cam.update_vehicle(&v);
    let mut seq = 0u64;
    let mut feed = |frames: &mut skymesh_runtime::FramePublisher| {
        seq += 1;
        let stamp = FrameStamp {
            seq,
            mono_ns: monotonic_ns(),
            unix_ns: 1,
        };
        frames
            .publish_with(640 * 480 * 3, |h, px| {
                cam.render(0.0, stamp, h, px).expect("a pose");
            })
            .expect("publish frame");
    };
    let processed = || {
        stats
            .value("skymesh_vision_frames_processed_total", "stream=main")
            .unwrap_or(0.0)
    };

    // 1. Nothing uses the output: the frames have no reader, none is processed, and
    // the state says idle.
    let first = until(PATIENCE, || state_sub.latest().expect("state").is_some()).await;
    assert!(first.is_some(), "no state from the idle pipeline");
    vehicle_pub.publish(v).expect("publish vehicle");
    for _ in 0..5 {
        feed(&mut frames);
        tokio::time::sleep(Duration::from_millis(60)).await;
    }
    assert_eq!(
        frames.subscribers(),
        0,
        "idle, the pipeline reads no frames"
    );
    assert_eq!(processed(), 0.0);
    assert_eq!(stats.value("skymesh_vision_active", ""), Some(0.0));

    // 2. A consumer's word: the frames get a reader, the camera a word that they are
    // read, and frames are processed.
    let wanted = |wanted| VisionDemand {
        wanted,
        ..VisionDemand::default()
    };
    demand.publish(wanted(1)).expect("demand");
    let resumed = until(PATIENCE, || frames.subscribers() == 1)
        .await
        .expect("the pipeline never subscribed to the frames");
    eprintln!("vision: frames subscribed {resumed:?} after the demand word");
    let word = next_word(&mut camera_words).await;
    assert_eq!(word.wanted, 1, "{word:?}");
    assert_eq!(word.header.service, ServiceId::VisionPipeline.to_wire());
    let deadline = std::time::Instant::now() + PATIENCE;
    while processed() < 2.0 {
        assert!(std::time::Instant::now() < deadline, "no frame processed");
        vehicle_pub.publish(v).expect("publish vehicle");
        feed(&mut frames);
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let st = state_sub.latest().expect("state").expect("a state");
    assert_eq!(st.status, 1, "running while used");

    // 3. Read your writes: once the reply is in, the state that contains the change
    // is already there (published before the reply).
    for (i, (yaw, pitch)) in [(1.5, -0.5), (-1.0, -0.25), (0.5, -1.0)]
        .into_iter()
        .enumerate()
    {
        let id = 500 + i as u64;
        let aim = ViewControl {
            yaw_rad: yaw,
            pitch_rad: pitch,
            ..ctl(id, ViewControlKind::Targeting)
        };
        view_pub.publish(aim).expect("publish view control");
        let reply = loop {
            let r = view_replies
                .recv_timeout(PATIENCE)
                .await
                .expect("reply")
                .expect("a reply");
            if r.request_id == id {
                break r;
            }
        };
        assert_eq!(reply.result(), VisionResult::Applied);
        let st = state_sub
            .latest()
            .expect("state")
            .expect("the state before the reply");
        let c = st.streams[0].cams[0];
        assert!(
            (f64::from(c.yaw_rad) - yaw).abs() < 1e-6
                && (f64::from(c.pitch_rad) - pitch).abs() < 1e-6,
            "the state after the reply still has {c:?}"
        );
    }

    // 4. The word withdrawn: the reader goes, and the camera is told.
    demand.publish(wanted(0)).expect("demand");
    until(PATIENCE, || frames.subscribers() == 0)
        .await
        .expect("the pipeline kept reading");
    assert_eq!(stats.value("skymesh_vision_active", ""), Some(0.0));
    let word = loop {
        // Renewals of the `wanted` word may come before the withdrawal.
        let w = next_word(&mut camera_words).await;
        if w.wanted == 0 {
            break w;
        }
    };
    assert_eq!(word.header.service, ServiceId::VisionPipeline.to_wire());

    // 5. A word never renewed (its publisher died) lapses after the lease.
    let t = std::time::Instant::now();
    demand.publish(wanted(1)).expect("demand");
    until(PATIENCE, || frames.subscribers() == 1)
        .await
        .expect("resumed");
    until(PATIENCE, || frames.subscribers() == 0)
        .await
        .expect("the lapsed word kept the pipeline reading");
    // Not before the lease (a loaded machine only makes it later).
    let lapsed = t.elapsed();
    assert!(
        lapsed >= Duration::from_nanos(VISION_DEMAND_LEASE_NS),
        "lapsed after {lapsed:?}"
    );

    shutdown.cancel();
    task.await.expect("join").expect("clean stop");
}

/// The camera and the pipeline together, idle: neither makes nor reads a frame. A
/// consumer's `VisionDemand` word wakes the pipeline, whose `CameraDemand` word
/// wakes the camera: frames are made and processed. The word withdrawn, both idle
/// again and the camera makes no more frames. Each step waits for the event
/// (gauges, frame counters), never for a time.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_demand_word_wakes_the_idle_camera_and_pipeline() {
    let domain = unique_domain();
    let cam_stats = Stats::new();
    let vis_stats = Stats::new();
    let cam_bus =
        Bus::open(&domain, "camera", ServiceId::Camera, 0, cam_stats.clone()).expect("bus");
    let vis_bus = Bus::open(
        &domain,
        "vision",
        ServiceId::VisionPipeline,
        0,
        vis_stats.clone(),
    )
    .expect("bus");
    let tool = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut demand = tool
        .publisher::<VisionDemand>(&topics::vision_demand())
        .expect("demand publisher");

    // A camera that needs no vehicle (a configured origin), small frames.
    let cam_settings = edit::<skymesh_camera::RawConfig>(&[
        ("width = 1280", "width = 320"),
        ("height = 720", "height = 240"),
        ("# origin = {", "origin = {"),
    ]);
    let period = Duration::from_secs_f64(1.0 / f64::from(cam_settings.fps));
    let vis_settings = edit::<skymesh_vision_pipeline::RawConfig>(&[
        ("thermal_zone = \"auto\"", "thermal_zone = \"none\""),
        ("control_hold_s = 10.0", "control_hold_s = 0.0"),
        ("width = 1280", "width = 640"),
        ("height = 720", "height = 480"),
    ]);
    let shutdown = CancellationToken::new();
    let camera = tokio::spawn(skymesh_camera::run(
        cam_settings,
        Context::new(cam_bus, shutdown.clone(), cam_stats.clone(), "camera"),
    ));
    let vision = tokio::spawn(skymesh_vision_pipeline::run(
        vis_settings,
        Context::new(vis_bus, shutdown.clone(), vis_stats.clone(), "vision"),
    ));
    let made = || {
        cam_stats
            .value("skymesh_camera_frames_published_total", "")
            .unwrap_or(0.0)
    };
    let processed = || {
        vis_stats
            .value("skymesh_vision_frames_processed_total", "stream=main")
            .unwrap_or(0.0)
    };
    let cam_active = || cam_stats.value("skymesh_camera_active", "");
    let vis_active = || vis_stats.value("skymesh_vision_active", "");

    // 1. Idle: both say so, and nothing is made or processed however long that
    // lasts (ten frame periods here).
    until(PATIENCE, || {
        cam_active() == Some(0.0) && vis_active() == Some(0.0)
    })
    .await
    .expect("camera and pipeline never idle");
    tokio::time::sleep(period * 10).await;
    assert_eq!(made(), 0.0, "idle camera made frames");
    assert_eq!(processed(), 0.0, "idle pipeline processed frames");

    // 2. A consumer's word: the pipeline reads, the camera makes frames.
    demand
        .publish(VisionDemand {
            wanted: 1,
            ..VisionDemand::default()
        })
        .expect("demand");
    until(PATIENCE, || made() >= 3.0 && processed() >= 2.0)
        .await
        .expect("no frames made and processed after the demand word");
    assert_eq!(cam_active(), Some(1.0));
    assert_eq!(vis_active(), Some(1.0));

    // 3. Withdrawn: both idle, and the camera makes no more frames.
    demand
        .publish(VisionDemand {
            wanted: 0,
            ..VisionDemand::default()
        })
        .expect("demand");
    until(PATIENCE, || {
        cam_active() == Some(0.0) && vis_active() == Some(0.0)
    })
    .await
    .expect("camera and pipeline kept working");
    let stopped = made();
    tokio::time::sleep(period * 10).await;
    assert_eq!(made(), stopped, "frames after the demand was withdrawn");

    shutdown.cancel();
    camera.await.expect("join").expect("camera stop");
    vision.await.expect("join").expect("vision stop");
}
