//! contrast-blob on the camera service's synthetic scene: every target in view is
//! found where the renderer put it, nothing on plain ground.

use skymesh_camera::render::{
    render_nv12, render_rgb24, CameraPose, Intrinsics, Lens, PlacedTarget, Scene, Shape,
};
use skymesh_ipc_types::frame::PixelFormat;
use skymesh_ipc_types::FrameHeader;
use skymesh_vision_pipeline::detect::{Detector, DetectorConfig, RawDetection, WorkImage};

// deploy/camera.toml defaults.
const W: u32 = 1280;
const H: u32 = 720;
const HFOV_DEG: f64 = 90.0;
const CELL_M: f64 = 10.0;

fn targets() -> Vec<PlacedTarget> {
    vec![
        PlacedTarget {
            north: 15.0,
            east: 0.0,
            size_m: 3.0,
            shape: Shape::Disc,
            rgb: [220, 40, 40],
        },
        PlacedTarget {
            north: -7.3,
            east: 12.4,
            size_m: 2.5,
            shape: Shape::Square,
            rgb: [40, 70, 220],
        },
        PlacedTarget {
            north: 2.0,
            east: -18.0,
            size_m: 2.0,
            shape: Shape::Disc,
            rgb: [235, 215, 40],
        },
        // On a grid line (every 50 m).
        PlacedTarget {
            north: -10.0,
            east: -25.0,
            size_m: 2.0,
            shape: Shape::Disc,
            rgb: [220, 40, 40],
        },
    ]
}

fn detect(pose: &CameraPose, targets: &[PlacedTarget], format: PixelFormat) -> Vec<RawDetection> {
    let k = Intrinsics::from_hfov(W, H, HFOV_DEG, Lens::Pinhole);
    let scene = Scene {
        targets,
        cell_m: CELL_M,
    };
    let mut header = FrameHeader::default();
    let pixels = match format {
        PixelFormat::Rgb24 => {
            let mut buf = vec![0u8; (W * H * 3) as usize];
            render_rgb24(&scene, &k, pose, W, H, (W * 3) as usize, 2, &mut buf);
            header.set_geometry(format, W, H, W * 3);
            buf
        }
        PixelFormat::Nv12 => {
            let mut buf = vec![0u8; (W * H * 3 / 2) as usize];
            render_nv12(&scene, &k, pose, W, H, W as usize, 2, &mut buf);
            header.set_geometry(format, W, H, W);
            buf
        }
    };
    header.payload_len = pixels.len() as u32;
    let image = WorkImage::from_frame(&header, &pixels, DetectorConfig::default().work_width)
        .expect("work image");
    let mut det = Detector::new("contrast-blob", DetectorConfig::default()).unwrap();
    det.scan(&image)
}

/// The renderer puts pixel i's centre at u = i; boxes are continuous (centre i + 0.5).
fn truth(pose: &CameraPose, t: &PlacedTarget) -> Option<(f64, f64)> {
    let k = Intrinsics::from_hfov(W, H, HFOV_DEG, Lens::Pinhole);
    let (u, v) = pose.project_ground(&k, t.north, t.east)?;
    let margin = 30.0;
    let inside = (margin..f64::from(W) - margin).contains(&u)
        && (margin..f64::from(H) - margin).contains(&v);
    inside.then_some((u + 0.5, v + 0.5))
}

fn check_scene(pose: &CameraPose, format: PixelFormat) {
    let targets = targets();
    let hits = detect(pose, &targets, format);
    let mut expected = 0;
    for t in &targets {
        let Some((u, v)) = truth(pose, t) else {
            continue;
        };
        expected += 1;
        let found = hits.iter().any(|d| {
            let (cx, cy) = d.bbox.center();
            (f64::from(cx) - u).abs() <= 3.0 && (f64::from(cy) - v).abs() <= 3.0
        });
        assert!(
            found,
            "{format}: target {t:?} at ({u:.1}, {v:.1}) not found in {hits:?}"
        );
    }
    assert!(expected >= 3, "test scene must have targets in view");
    assert_eq!(hits.len(), expected, "{format}: false positives: {hits:?}");
    for d in &hits {
        assert!(d.confidence >= 0.5, "{d:?}");
    }
}

#[test]
fn finds_every_target_at_50m_looking_down() {
    let pose = CameraPose::looking(0.0, 0.0, 50.0, 0.0, -90.0);
    check_scene(&pose, PixelFormat::Rgb24);
    check_scene(&pose, PixelFormat::Nv12);
}

#[test]
fn finds_every_target_turned_and_shifted() {
    let pose = CameraPose::looking(-4.0, -6.0, 50.0, 33.0, -90.0);
    check_scene(&pose, PixelFormat::Rgb24);
    let pose = CameraPose::looking(0.0, 0.0, 40.0, 10.0, -75.0);
    check_scene(&pose, PixelFormat::Rgb24);
}

#[test]
fn no_detections_on_plain_ground() {
    for (n, e, h, yaw, pitch) in [
        (0.0, 0.0, 50.0, 0.0, -90.0),
        (23.0, -48.0, 50.0, 0.0, -90.0),
        (50.0, 50.0, 50.0, 45.0, -90.0),
        (-20.0, 30.0, 60.0, 120.0, -90.0),
        (0.0, 0.0, 30.0, 17.0, -90.0),
        (10.0, 0.0, 50.0, 0.0, -60.0),
    ] {
        let pose = CameraPose::looking(n, e, h, yaw, pitch);
        for format in [PixelFormat::Rgb24, PixelFormat::Nv12] {
            let hits = detect(&pose, &[], format);
            assert!(
                hits.is_empty(),
                "{format} at {n},{e},{h},{yaw},{pitch}: {hits:?}"
            );
        }
    }
}
