//! Render time of the synthetic scene per frame (prints numbers; no assertions).
//!
//! `cargo run --release -p skymesh-camera --example render_bench`

use std::time::Instant;

use skymesh_camera::render::{
    render_nv12, render_rgb24, CameraPose, Intrinsics, Lens, PlacedTarget, Scene, Shape,
};

fn main() {
    let targets: Vec<PlacedTarget> = (0..8)
        .map(|i| PlacedTarget {
            north: f64::from(i) * 7.0 - 20.0,
            east: f64::from(i) * -5.0 + 10.0,
            size_m: 3.0,
            shape: if i % 2 == 0 {
                Shape::Disc
            } else {
                Shape::Square
            },
            rgb: [200, 40, 40],
        })
        .collect();
    let scene = Scene {
        targets: &targets,
        cell_m: 10.0,
    };
    let pose = CameraPose::looking(0.0, 0.0, 50.0, 30.0, -45.0);
    for (w, h) in [(640u32, 480u32), (1280, 720), (1920, 1080)] {
        for lens in [Lens::Pinhole, Lens::Fisheye] {
            let k = Intrinsics::from_hfov(w, h, 90.0, lens);
            let mut rgb = vec![0u8; (w * h * 3) as usize];
            let mut nv12 = vec![0u8; (w * h * 3 / 2) as usize];
            let n = 20;
            for threads in [1, 2, 4] {
                let t0 = Instant::now();
                for _ in 0..n {
                    render_rgb24(&scene, &k, &pose, w, h, (w * 3) as usize, threads, &mut rgb);
                }
                let rgb_ms = t0.elapsed().as_secs_f64() * 1e3 / f64::from(n);
                let t0 = Instant::now();
                for _ in 0..n {
                    render_nv12(&scene, &k, &pose, w, h, w as usize, threads, &mut nv12);
                }
                let nv12_ms = t0.elapsed().as_secs_f64() * 1e3 / f64::from(n);
                println!(
                    "{w}x{h} {lens:?} {threads} thread(s): rgb24 {rgb_ms:.2} ms/frame, nv12 {nv12_ms:.2} ms/frame"
                );
            }
        }
    }
}
