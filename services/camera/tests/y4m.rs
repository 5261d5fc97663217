//! The camera service on a Y4M file, in-process on the real bus (its own iceoryx2
//! domain): frames reach a `FrameSubscriber` with the file's pixels converted to the
//! configured format, in file order, looping or stopping at the end.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use skymesh_camera::render::rgb_to_ycbcr;
use skymesh_camera::y4m::{Chroma, Y4mHeader};
use skymesh_camera::{run, RawConfig, Settings};
use skymesh_ipc_types::{topics, FrameHeader, LensModel, PixelFormat, ServiceId, VehicleState};
use skymesh_runtime::ipc::DomainGuard;
use skymesh_runtime::{Bus, CancellationToken, Context, Domain, FrameSubscriber, Stats};

/// Generous bound for anything that should take a moment.
const PATIENCE: Duration = Duration::from_secs(30);
const W: u32 = 64;
const H: u32 = 48;
/// The colour of each frame of the test file (its top-left 16×16 block is white).
const COLOURS: [[u8; 3]; 3] = [[220, 40, 40], [40, 200, 60], [30, 60, 210]];

fn unique(prefix: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "{prefix}{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// A 64×48 4:2:0 file of three frames, removed on drop.
struct TestFile(PathBuf);

impl TestFile {
    fn new() -> Self {
        let header = Y4mHeader {
            width: W,
            height: H,
            rate: Some((25, 1)),
            chroma: Chroma::C420,
        };
        let mut data = header.line().into_bytes();
        let (w, h) = (W as usize, H as usize);
        for rgb in COLOURS {
            let [y, cb, cr] = rgb_to_ycbcr(rgb);
            data.extend_from_slice(b"FRAME\n");
            for j in 0..h {
                for i in 0..w {
                    data.push(if i < 16 && j < 16 { 255 } else { y });
                }
            }
            for plane in [cb, cr] {
                for j in 0..h / 2 {
                    for i in 0..w / 2 {
                        data.push(if i < 8 && j < 8 { 128 } else { plane });
                    }
                }
            }
        }
        let path = std::env::temp_dir().join(format!("{}.y4m", unique("skymesh-camera-test-")));
        std::fs::write(&path, data).expect("write the test file");
        TestFile(path)
    }
}

impl Drop for TestFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The file's config: `top` keys (and tables) first, then `y4m` keys in `[y4m]`.
fn settings(file: &TestFile, top: &str, y4m: &str) -> Settings {
    let text = format!(
        "source = \"y4m\"\nwidth = {W}\nheight = {H}\n{top}\n[y4m]\npath = \"{}\"\n{y4m}\n",
        file.0.display()
    );
    skymesh_runtime::config::parse::<RawConfig>(&text, "test").expect("config")
}

struct Running {
    frames: FrameSubscriber,
    tool: Bus,
    stats: Stats,
    shutdown: CancellationToken,
    task: tokio::task::JoinHandle<anyhow::Result<()>>,
    /// Last: the domain's files go after its ports.
    _domain: DomainGuard,
}

fn start(settings: Settings) -> Running {
    let domain = DomainGuard(Domain::load(&unique("camy"), None).expect("domain"));
    let stats = Stats::new();
    let bus = Bus::open(&domain, "camera", ServiceId::Camera, 0, stats.clone()).expect("bus");
    let tool = Bus::open(&domain, "viewer", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let frames = tool
        .frame_subscriber(&topics::camera_frames("main"))
        .expect("frame subscriber");
    let shutdown = CancellationToken::new();
    let ctx = Context::new(bus, shutdown.clone(), stats.clone(), "camera");
    let task = tokio::spawn(run(settings, ctx));
    Running {
        frames,
        tool,
        stats,
        shutdown,
        task,
        _domain: domain,
    }
}

impl Running {
    async fn next(&mut self) -> (FrameHeader, Vec<u8>) {
        tokio::time::timeout(PATIENCE, self.frames.recv_with(|h, px| (*h, px.to_vec())))
            .await
            .expect("a frame in time")
            .expect("receive frame")
    }

    async fn stop(self) -> Stats {
        self.shutdown.cancel();
        self.task.await.expect("join").expect("camera run");
        self.stats
    }
}

/// Which test colour a frame shows at (40, 30).
fn colour_index(px: [u8; 3]) -> usize {
    COLOURS
        .iter()
        .position(|c| c.iter().zip(px).all(|(a, b)| a.abs_diff(b) <= 2))
        .unwrap_or_else(|| panic!("{px:?} is none of the test colours"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rgb24_frames_loop_through_the_file() {
    let file = TestFile::new();
    let mut cam = start(settings(&file, "fps = 60", ""));
    let mut vehicle = cam
        .tool
        .publisher::<VehicleState>(&topics::vehicle_state(1))
        .expect("vehicle publisher");
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
    let mut order = Vec::new();
    let mut last = None;
    let mut with_pose = None;
    while order.len() < 7 || with_pose.is_none() {
        // Published until frames carry it: a subscriber that connects late gets the
        // history only when the publisher sends again.
        vehicle.publish(state).expect("publish vehicle state");
        let (h, px) = cam.next().await;
        assert_eq!(h.validate(px.len()), Ok(PixelFormat::Rgb24));
        assert_eq!((h.width, h.height, h.stride), (W, H, W * 3));
        assert_eq!(h.header.service, ServiceId::Camera.to_wire());
        assert_eq!(h.lens_model(), Ok(LensModel::Pinhole));
        assert_eq!(h.intrinsics.valid, 1);
        assert!((h.intrinsics.fx - 32.0).abs() < 1e-3, "{}", h.intrinsics.fx);
        if h.pose.valid == 1 {
            with_pose = Some(h);
        }
        let at = |x: u32, y: u32| {
            let i = (y * h.stride + x * 3) as usize;
            [px[i], px[i + 1], px[i + 2]]
        };
        assert_eq!(at(2, 2), [255, 255, 255]);
        assert_eq!(at(15, 15), [255, 255, 255]);
        let c = colour_index(at(40, 30));
        assert_eq!(colour_index(at(63, 47)), c);
        assert_eq!(colour_index(at(16, 0)), c);
        if let Some(prev) = last {
            assert!(h.frame_seq > prev, "frame_seq {} after {prev}", h.frame_seq);
        }
        last = Some(h.frame_seq);
        order.push((h.frame_seq, c));
    }
    let stats = cam.stop().await;
    // The header's pose is the vehicle's, the camera looking down (mount pitch −90°).
    let h = with_pose.expect("a frame with a pose");
    assert_eq!(
        (h.pose.lat_deg, h.pose.lon_deg),
        (state.lat_deg, state.lon_deg)
    );
    assert_eq!(h.pose.alt_m, 538.0);
    assert!((h.vehicle_heading_deg - 90.0).abs() < 1e-3);
    let [w, x, y, z] = h.pose.attitude_q.map(f64::from);
    let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let axis = q.transform_vector(&nalgebra::Vector3::x());
    assert!((axis.z - 1.0).abs() < 1e-5, "{axis:?}");
    // Frames come in file order, and after the third the first again: consecutive
    // received frames (by frame_seq) step through the file modulo 3.
    for w in order.windows(2) {
        let ((s0, c0), (s1, c1)) = (w[0], w[1]);
        assert_eq!(
            c1,
            (c0 + (s1 - s0) as usize) % 3,
            "frame {s1} after frame {s0}: {order:?}"
        );
    }
    assert!(order.iter().any(|&(s, _)| s > 3), "{order:?}");
    assert!(
        stats
            .value("skymesh_camera_file_rewinds_total", "")
            .unwrap_or(0.0)
            >= 1.0
    );
    assert_eq!(
        stats.value("skymesh_camera_file_errors_total", ""),
        Some(0.0)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nv12_frames_stop_at_the_end_without_loop_and_without_a_vehicle_have_no_pose() {
    let file = TestFile::new();
    let mut cam = start(settings(
        &file,
        "fps = 5\nformat = \"nv12\"",
        "loop = false",
    ));
    let mut seen = Vec::new();
    // The three frames of the file (the subscriber keeps up at 5 fps; a frame lost
    // to a slow test would show as a gap, never as a wrong picture).
    while seen.last() != Some(&3) {
        let (h, px) = cam.next().await;
        assert_eq!(h.validate(px.len()), Ok(PixelFormat::Nv12));
        assert_eq!(px.len(), (W * H * 3 / 2) as usize);
        assert_eq!(h.stride, W);
        // No vehicle: published anyway, without a pose.
        assert_eq!(h.pose.valid, 0);
        let y = |x: u32, r: u32| px[(r * W + x) as usize];
        let uv = |x: u32, r: u32| {
            let i = (W * H + r * W + 2 * x) as usize;
            (px[i], px[i + 1])
        };
        assert_eq!(y(3, 3), 255);
        assert_eq!(uv(3, 3), (128, 128));
        assert!((1..=3).contains(&h.frame_seq), "frame {}", h.frame_seq);
        let [yy, cb, cr] = rgb_to_ycbcr(COLOURS[(h.frame_seq - 1) as usize]);
        assert_eq!(y(40, 30), yy, "frame {}", h.frame_seq);
        assert_eq!(y(63, 47), yy, "frame {}", h.frame_seq);
        assert_eq!(uv(20, 15), (cb, cr), "frame {}", h.frame_seq);
        assert_eq!(uv(31, 23), (cb, cr), "frame {}", h.frame_seq);
        seen.push(h.frame_seq);
    }
    assert!(seen.windows(2).all(|w| w[1] > w[0]), "{seen:?}");

    // After the end: no more frames, and the service is still running.
    let more = tokio::time::timeout(
        Duration::from_millis(600),
        cam.frames.recv_with(|h, _| h.frame_seq),
    )
    .await;
    assert!(more.is_err(), "a frame after the end: {more:?}");
    assert!(!cam.task.is_finished());
    let stats = cam.stop().await;
    assert_eq!(
        stats.value("skymesh_camera_frames_published_total", ""),
        Some(3.0)
    );
    assert_eq!(
        stats.value("skymesh_camera_file_rewinds_total", ""),
        Some(0.0)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_file_replaced_by_another_size_fails_the_start_naming_both_sizes() {
    let file = TestFile::new();
    let s = settings(&file, "", "");
    // After the config check, the file changes under the service.
    let other = Y4mHeader {
        width: 32,
        height: 16,
        rate: None,
        chroma: Chroma::Mono,
    };
    let mut data = other.line().into_bytes();
    data.extend_from_slice(b"FRAME\n");
    data.extend(std::iter::repeat_n(9u8, 32 * 16));
    std::fs::write(&file.0, data).expect("rewrite");
    let cam = start(s);
    let e = tokio::time::timeout(PATIENCE, cam.task)
        .await
        .expect("ends")
        .expect("join")
        .expect_err("must fail");
    let text = format!("{e:#}");
    assert!(text.contains("32×16") && text.contains("64×48"), "{text}");
    assert!(text.contains(&file.0.display().to_string()), "{text}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_truncated_last_frame_is_counted_and_the_file_loops_on() {
    let file = TestFile::new();
    let mut data = std::fs::read(&file.0).expect("read");
    data.extend_from_slice(b"FRAME\n");
    data.extend_from_slice(&[1; 100]);
    std::fs::write(&file.0, data).expect("append a cut frame");
    let mut cam = start(settings(&file, "fps = 60", ""));
    let mut order = Vec::new();
    while order.len() < 8 {
        let (h, px) = cam.next().await;
        let i = (30 * h.stride + 40 * 3) as usize;
        order.push((h.frame_seq, colour_index([px[i], px[i + 1], px[i + 2]])));
    }
    let stats = cam.stop().await;
    for w in order.windows(2) {
        let ((s0, c0), (s1, c1)) = (w[0], w[1]);
        assert_eq!(c1, (c0 + (s1 - s0) as usize) % 3, "{order:?}");
    }
    assert!(
        stats
            .value("skymesh_camera_file_errors_total", "")
            .unwrap_or(0.0)
            >= 1.0
    );
}
