//! Prints per-frame times of the detect step (work image + contrast-blob scan +
//! a verify per hit) on synthetic 1080p and 720p frames, RGB24 and NV12.
//!
//! `cargo run --release -p skymesh-vision-pipeline --example detect_bench [frames]`

use std::time::{Duration, Instant};

use skymesh_camera::render::{
    render_nv12, render_rgb24, CameraPose, Intrinsics, Lens, PlacedTarget, Scene, Shape,
};
use skymesh_ipc_types::frame::PixelFormat;
use skymesh_ipc_types::FrameHeader;
use skymesh_vision_pipeline::detect::{Detector, DetectorConfig, WorkImage};

fn main() {
    let frames: u32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(50);
    let targets = [
        PlacedTarget {
            north: 15.0,
            east: 3.0,
            size_m: 3.0,
            shape: Shape::Disc,
            rgb: [220, 40, 40],
        },
        PlacedTarget {
            north: -7.0,
            east: 12.0,
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
    ];
    let scene = Scene {
        targets: &targets,
        cell_m: 10.0,
    };
    let config = DetectorConfig::default();
    println!(
        "frames per case: {frames}, work width {}",
        config.work_width
    );
    for (w, h) in [(1920u32, 1080u32), (1280, 720)] {
        for format in [PixelFormat::Rgb24, PixelFormat::Nv12] {
            let k = Intrinsics::from_hfov(w, h, 90.0, Lens::Pinhole);
            let pose = CameraPose::looking(0.0, 0.0, 50.0, 0.0, -90.0);
            let mut header = FrameHeader::default();
            let pixels = match format {
                PixelFormat::Rgb24 => {
                    let mut buf = vec![0u8; (w * h * 3) as usize];
                    render_rgb24(&scene, &k, &pose, w, h, (w * 3) as usize, 2, &mut buf);
                    header.set_geometry(format, w, h, w * 3);
                    buf
                }
                PixelFormat::Nv12 => {
                    let mut buf = vec![0u8; (w * h * 3 / 2) as usize];
                    render_nv12(&scene, &k, &pose, w, h, w as usize, 2, &mut buf);
                    header.set_geometry(format, w, h, w);
                    buf
                }
            };
            header.payload_len = pixels.len() as u32;
            let mut det = Detector::new("contrast-blob", config).expect("model");
            let (mut reduce, mut scan, mut verify) = (Vec::new(), Vec::new(), Vec::new());
            let mut hits = 0;
            for _ in 0..frames {
                let t0 = Instant::now();
                let image = match WorkImage::from_frame(&header, &pixels, config.work_width) {
                    Ok(i) => i,
                    Err(e) => {
                        eprintln!("{e}");
                        return;
                    }
                };
                let t1 = Instant::now();
                let found = det.scan(&image);
                let t2 = Instant::now();
                for d in &found {
                    let _ = det.verify(&image, &d.bbox);
                }
                let t3 = Instant::now();
                hits = found.len();
                reduce.push(t1 - t0);
                scan.push(t2 - t1);
                verify.push(t3 - t2);
            }
            let total: Vec<Duration> = (0..reduce.len())
                .map(|i| reduce[i] + scan[i] + verify[i])
                .collect();
            println!(
                "{w}x{h} {format}: {hits} hits | work image {} | scan {} | verify×{hits} {} | total {}",
                stats(&mut reduce),
                stats(&mut scan),
                stats(&mut verify),
                stats(&mut total.clone()),
            );
        }
    }
}

/// "median / p95 / max" in milliseconds.
fn stats(v: &mut [Duration]) -> String {
    v.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let p = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    format!(
        "med {:.2} p95 {:.2} max {:.2} ms",
        ms(p(0.5)),
        ms(p(0.95)),
        ms(p(1.0))
    )
}
