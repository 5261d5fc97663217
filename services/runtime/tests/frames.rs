//! Camera frames through real iceoryx2 shared memory: between two processes (this
//! test binary re-runs itself as the publisher), and in place (no copy).

use std::io::{BufRead, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

use skymesh_ipc_types::{topics, FrameHeader, LensModel, PixelFormat, ServiceId, MAX_FRAME_LEN};
use skymesh_runtime::ipc::DomainGuard;
use skymesh_runtime::{Bus, Domain, FrameError, FrameSubscriber, Stats};

/// Set in the child process: the domain to publish in.
const CHILD_DOMAIN_ENV: &str = "SKYMESH_FRAMES_TEST_CHILD_DOMAIN";
const STREAM: &str = "test";

/// A fresh domain per test, its files removed at the end of the test.
fn domain(tag: &str) -> DomainGuard {
    DomainGuard(Domain::load(&format!("fr{}{tag}", std::process::id()), None).unwrap())
}

/// The frames the child publishes, in order: (format, width, height, stride).
const FRAMES: [(PixelFormat, u32, u32, u32); 5] = [
    (PixelFormat::Rgb24, 1920, 1080, 1920 * 3),
    (PixelFormat::Rgb24, 640, 480, 640 * 3),
    (PixelFormat::Nv12, 1280, 720, 1280),
    (PixelFormat::Rgb24, 33, 17, 100),
    (PixelFormat::Nv12, 2, 2, 2),
];

fn frame_len(k: usize) -> usize {
    let (f, w, h, s) = FRAMES[k];
    f.frame_len(w, h, s).unwrap() as usize
}

fn pattern(seed: usize, i: usize) -> u8 {
    ((i.wrapping_mul(2_654_435_761) ^ seed.wrapping_mul(40_503)) >> 7) as u8
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn expected_checksum(k: usize) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for i in 0..frame_len(k) {
        h = (h ^ u64::from(pattern(k, i))).wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Everything but the runtime-stamped `header` and `payload_len`.
fn expected_header(k: usize) -> FrameHeader {
    let (f, w, h, s) = FRAMES[k];
    let mut hd = FrameHeader {
        frame_seq: 1000 + k as u64,
        capture_mono_ns: 5_000_000 + k as u64,
        capture_unix_ns: 1_760_000_000_000_000_000 + k as u64,
        ..Default::default()
    };
    hd.set_geometry(f, w, h, s);
    hd.intrinsics.fx = 1000.5;
    hd.intrinsics.fy = 999.25;
    hd.intrinsics.cx = w as f32 / 2.0;
    hd.intrinsics.cy = h as f32 / 2.0;
    hd.intrinsics.k = [0.1, -0.02, 0.003, k as f32];
    hd.intrinsics.lens_model = LensModel::Fisheye.to_wire();
    hd.intrinsics.valid = 1;
    hd.pose.lat_deg = 47.397742;
    hd.pose.lon_deg = 8.545594;
    hd.pose.alt_m = 488.5;
    hd.pose.attitude_q = [0.6, 0.0, 0.0, 0.8];
    hd.pose.valid = 1;
    hd
}

/// The `/proc/self/maps` path of the mapping that holds `addr`, if any.
fn mapping_of(addr: usize) -> Option<String> {
    let maps = std::fs::read_to_string("/proc/self/maps").ok()?;
    maps.lines().find_map(|line| {
        let mut parts = line.split_whitespace();
        let range = parts.next()?;
        let (start, end) = range.split_once('-')?;
        let start = usize::from_str_radix(start, 16).ok()?;
        let end = usize::from_str_radix(end, 16).ok()?;
        if (start..end).contains(&addr) {
            Some(parts.nth(4).unwrap_or("").to_string())
        } else {
            None
        }
    })
}

/// The publisher half of [`a_frame_crosses_processes_intact`]: does nothing unless
/// started by it (with the domain in `CHILD_DOMAIN_ENV`).
#[test]
fn child_publisher() {
    let Ok(name) = std::env::var(CHILD_DOMAIN_ENV) else {
        return;
    };
    let d = Domain::load(&name, None).unwrap();
    let bus = Bus::open(&d, "frame-child", ServiceId::Camera, 2, Stats::new()).unwrap();
    let mut publ = bus
        .frame_publisher(&topics::camera_frames(STREAM), MAX_FRAME_LEN)
        .unwrap();
    let stdin = std::io::stdin();
    let mut lines = stdin.lock().lines();
    for k in 0..FRAMES.len() {
        let seq = publ
            .publish_with(frame_len(k), |hd, pixels| {
                *hd = expected_header(k);
                for (i, p) in pixels.iter_mut().enumerate() {
                    *p = pattern(k, i);
                }
            })
            .unwrap();
        assert_eq!(seq, k as u64 + 1);
        // Wait until the parent has read this frame.
        match lines.next() {
            Some(Ok(_)) => {}
            _ => return,
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_crosses_processes_intact() {
    let d = domain("x");
    let stats = Stats::new();
    let bus = Bus::open(&d, "frame-parent", ServiceId::Tool, 0, stats.clone()).unwrap();
    let topic = topics::camera_frames(STREAM);
    let mut sub = bus.frame_subscriber(&topic).unwrap();

    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["child_publisher", "--exact", "--test-threads=1"])
        .env(CHILD_DOMAIN_ENV, &d.name)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let mut to_child = child.stdin.take().unwrap();

    for k in 0..FRAMES.len() {
        let read = |hd: &FrameHeader, pixels: &[u8]| {
            (
                *hd,
                pixels.len(),
                fnv1a(pixels),
                mapping_of(pixels.as_ptr() as usize),
            )
        };
        // Even frames through `recv_with`, odd ones through `latest_with` (the
        // publisher waits for each frame to be read, so none is skipped).
        let (hd, len, sum, mapping) = if k % 2 == 0 {
            tokio::time::timeout(Duration::from_secs(20), sub.recv_with(read))
                .await
                .expect("frame not received in time")
                .unwrap()
        } else {
            let (got, skipped) =
                tokio::time::timeout(Duration::from_secs(20), sub.latest_with(read))
                    .await
                    .expect("frame not received in time")
                    .unwrap();
            assert_eq!(skipped, 0, "frame {k}");
            got
        };
        assert_eq!(len, frame_len(k), "frame {k}");
        assert_eq!(hd.payload_len as usize, len);
        assert_eq!(sum, expected_checksum(k), "pixels of frame {k}");
        let mut want = expected_header(k);
        want.header = hd.header;
        want.payload_len = hd.payload_len;
        assert_eq!(hd, want, "header of frame {k}");
        assert_eq!(hd.header.seq, k as u64 + 1);
        assert_eq!(hd.header.service, ServiceId::Camera.to_wire());
        assert_eq!(hd.header.instance, 2);
        assert!(hd.header.stamp_ns > 0);
        // Read where the publisher wrote it: the slice lies in the domain's shared memory.
        let mapping = mapping.unwrap_or_default();
        assert!(
            mapping.starts_with(&format!("/dev/shm/{}", d.prefix())),
            "frame {k} read from `{mapping}`, not from shared memory"
        );
        writeln!(to_child, "next").unwrap();
    }
    drop(to_child);
    let status = tokio::task::spawn_blocking(move || child.wait())
        .await
        .unwrap()
        .unwrap();
    assert!(status.success(), "publisher process failed: {status}");

    let labels = [("topic", topic.name.as_str())];
    assert_eq!(
        stats
            .counter("skymesh_topic_samples_received_total", &labels)
            .get(),
        FRAMES.len() as u64
    );
    assert_eq!(
        stats
            .counter("skymesh_topic_samples_lost_total", &labels)
            .get(),
        0
    );
}

#[test]
fn frames_are_written_and_read_in_place_in_shared_memory() {
    let d = domain("p");
    let a = Bus::open(&d, "cam", ServiceId::Camera, 0, Stats::new()).unwrap();
    let b = Bus::open(&d, "reader", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::camera_frames("inplace");
    let sub = b.frame_subscriber(&topic).unwrap();
    let mut publ = a.frame_publisher(&topic, MAX_FRAME_LEN).unwrap();
    assert_eq!(publ.max_len(), MAX_FRAME_LEN);

    let mut written_at = 0usize;
    publ.publish_with(MAX_FRAME_LEN, |hd, pixels| {
        *hd = expected_header(0);
        written_at = pixels.as_ptr() as usize;
        assert_eq!(pixels.len(), MAX_FRAME_LEN);
        // The loan starts zeroed: nothing of an earlier frame or process leaks.
        assert!(pixels.iter().all(|&p| p == 0));
        pixels[0] = 0xAB;
        pixels[MAX_FRAME_LEN - 1] = 0xCD;
    })
    .unwrap();
    let prefix = format!("/dev/shm/{}", d.prefix());
    let w = mapping_of(written_at).unwrap_or_default();
    assert!(w.starts_with(&prefix), "written into `{w}`");

    let (len, first, last, read_at) = sub
        .try_recv_with(|_, pixels| {
            (
                pixels.len(),
                pixels[0],
                pixels[pixels.len() - 1],
                pixels.as_ptr() as usize,
            )
        })
        .unwrap()
        .expect("frame pending");
    assert_eq!(len, MAX_FRAME_LEN);
    assert_eq!((first, last), (0xAB, 0xCD));
    let r = mapping_of(read_at).unwrap_or_default();
    assert!(r.starts_with(&prefix), "read from `{r}`");
    assert!(sub.try_recv_with(|_, _| ()).unwrap().is_none());
}

#[test]
fn a_frame_larger_than_the_publisher_maximum_is_refused() {
    let d = domain("l");
    let stats = Stats::new();
    let bus = Bus::open(&d, "cam", ServiceId::Camera, 0, stats.clone()).unwrap();
    let topic = topics::camera_frames("small");
    let sub = bus.frame_subscriber(&topic).unwrap();
    let vga = 640 * 480 * 3;
    let mut publ = bus.frame_publisher(&topic, vga).unwrap();

    let mut called = false;
    let err = publ
        .publish_with(MAX_FRAME_LEN, |_, _| called = true)
        .unwrap_err();
    assert!(!called, "fill ran for a refused frame");
    assert!(
        matches!(err, FrameError::TooLarge { len, max, .. } if len == MAX_FRAME_LEN && max == vga),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(msg.contains("exceeds") && msg.contains("6220800"), "{msg}");
    assert!(sub.try_recv_with(|_, _| ()).unwrap().is_none());
    assert_eq!(
        stats
            .counter(
                "skymesh_topic_samples_published_total",
                &[("topic", topic.name.as_str())]
            )
            .get(),
        0
    );

    // The largest allowed frame still goes through.
    publ.publish_with(vga, |hd, _| {
        hd.set_geometry(PixelFormat::Rgb24, 640, 480, 640 * 3)
    })
    .unwrap();
    assert_eq!(sub.try_recv_with(|_, p| p.len()).unwrap(), Some(vga));
}

#[test]
fn a_frame_whose_header_does_not_describe_its_pixels_is_not_sent() {
    let d = domain("h");
    let bus = Bus::open(&d, "cam", ServiceId::Camera, 0, Stats::new()).unwrap();
    let topic = topics::camera_frames("bad");
    let sub = bus.frame_subscriber(&topic).unwrap();
    let mut publ = bus.frame_publisher(&topic, MAX_FRAME_LEN).unwrap();
    // 1080p header on a VGA-sized payload.
    let err = publ
        .publish_with(640 * 480 * 3, |hd, _| {
            hd.set_geometry(PixelFormat::Rgb24, 1920, 1080, 1920 * 3)
        })
        .unwrap_err();
    assert!(matches!(err, FrameError::InvalidHeader { .. }), "{err:?}");
    // No format at all.
    let err = publ.publish_with(16, |_, _| ()).unwrap_err();
    assert!(matches!(err, FrameError::InvalidHeader { .. }), "{err:?}");
    assert!(sub.try_recv_with(|_, _| ()).unwrap().is_none());

    // Sequence numbers continue without gaps after refusals.
    let seq = publ
        .publish_with(6, |hd, _| hd.set_geometry(PixelFormat::Nv12, 2, 2, 2))
        .unwrap();
    assert_eq!(seq, 1);
}

/// Publishes `n` small frames on `topic` from another thread, one every `period`
/// (on a fixed schedule), each taking `write_time` to write (a camera's capture into
/// the loaned frame), while `sub` receives them with the async `recv_with`: each
/// must arrive, in order; then a receive with nothing published times out.
fn async_receive_takes_a_periodic_stream(
    bus: &Bus,
    topic: &skymesh_ipc_types::Topic,
    mut sub: FrameSubscriber,
    n: u64,
    period: Duration,
    write_time: Duration,
) {
    let (f, w, h, s) = FRAMES[4];
    let len = f.frame_len(w, h, s).unwrap() as usize;
    let mut publ = bus.frame_publisher(topic, len).unwrap();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    std::thread::scope(|scope| {
        scope.spawn(move || {
            let t0 = std::time::Instant::now();
            for i in 1..=n {
                let due = t0 + period * i as u32;
                std::thread::sleep(due.saturating_duration_since(std::time::Instant::now()));
                publ.publish_with(len, |hd, pixels| {
                    hd.frame_seq = i;
                    hd.set_geometry(f, w, h, s);
                    std::thread::sleep(write_time);
                    pixels.fill(i as u8);
                })
                .unwrap();
            }
        });
        rt.block_on(async {
            for i in 1..=n {
                let (seq, first) = tokio::time::timeout(
                    Duration::from_secs(5),
                    sub.recv_with(|hd, pixels| (hd.frame_seq, pixels[0])),
                )
                .await
                .expect("every frame arrives")
                .unwrap();
                assert_eq!((seq, first), (i, i as u8));
            }
        });
    });
    rt.block_on(async {
        let t0 = std::time::Instant::now();
        let quiet = Duration::from_millis(30);
        assert!(tokio::time::timeout(quiet, sub.recv_with(|_, _| ()))
            .await
            .is_err());
        assert!(t0.elapsed() >= quiet);
    });
}

/// Set in the child that dies in the middle of a frame: the domain to publish in.
const DIE_MID_FRAME_ENV: &str = "SKYMESH_FRAMES_TEST_DIE_MID_FRAME";

/// The publisher half of [`a_publisher_killed_mid_frame_does_not_stall_the_stream`]:
/// starts a frame, says so on stdout and never finishes it.
#[test]
fn child_dies_mid_frame() {
    let Ok(name) = std::env::var(DIE_MID_FRAME_ENV) else {
        return;
    };
    let d = Domain::load(&name, None).unwrap();
    let bus = Bus::open(&d, "frame-dier", ServiceId::Camera, 3, Stats::new()).unwrap();
    let (f, w, h, s) = FRAMES[4];
    let len = f.frame_len(w, h, s).unwrap() as usize;
    let mut publ = bus
        .frame_publisher(&topics::camera_frames("dier"), len)
        .unwrap();
    let _ = publ.publish_with(len, |_, _| {
        println!("filling");
        std::io::stdout().flush().unwrap();
        std::thread::sleep(Duration::from_secs(600));
    });
}

/// A camera killed between a frame's loan and its send leaves a frame that never
/// comes: the subscriber still receives every frame of the next publisher, in order.
#[test]
fn a_publisher_killed_mid_frame_does_not_stall_the_stream() {
    let d = domain("die");
    let bus = Bus::open(&d, "frame-die", ServiceId::Tool, 0, Stats::new()).unwrap();
    let topic = topics::camera_frames("dier");
    let sub = bus.frame_subscriber(&topic).unwrap();
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "child_dies_mid_frame",
            "--exact",
            "--test-threads=1",
            "--nocapture",
        ])
        .env(DIE_MID_FRAME_ENV, &d.name)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    while !line.contains("filling") {
        line.clear();
        assert!(out.read_line(&mut line).unwrap() > 0, "child ended early");
    }
    child.kill().unwrap();
    child.wait().unwrap();
    d.cleanup_dead_nodes();
    let (period, write) = (Duration::from_millis(20), Duration::from_millis(5));
    async_receive_takes_a_periodic_stream(&bus, &topic, sub, 40, period, write);
}
