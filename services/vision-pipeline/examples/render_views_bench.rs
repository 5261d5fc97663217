//! Render benchmark: 1280×720 output frames remapped from a 1920×1080 source.
//!
//! `cargo run --release -p skymesh-vision-pipeline --example render_views_bench`
//! prints per-frame times (one core, the calling thread) for: one view whose grid is
//! reused, one view turning every frame (grid rebuilt), four views plus a detection
//! column, an NV12 source and a fisheye source. Numbers only, no thresholds.

use std::time::{Duration, Instant};

use nalgebra::UnitQuaternion;
use skymesh_ipc_types::frame::{CameraIntrinsics, LensModel};
use skymesh_ipc_types::{CropMode, FrameHeader, PixelFormat};
use skymesh_vision_pipeline::detect::PixelBox;
use skymesh_vision_pipeline::geometry::{CameraModel, CameraPose};
use skymesh_vision_pipeline::layout;
use skymesh_vision_pipeline::render::{Renderer, TileSpec, ViewSpec};

const SW: u32 = 1920;
const SH: u32 = 1080;
const OW: u32 = 1280;
const OH: u32 = 720;
const FRAMES: usize = 120;

fn source(format: PixelFormat, lens: LensModel) -> (FrameHeader, Vec<u8>) {
    let mut header = FrameHeader::default();
    let (stride, len) = match format {
        PixelFormat::Rgb24 => (SW * 3, SW * SH * 3),
        PixelFormat::Nv12 => (SW, SW * SH * 3 / 2),
    };
    header.set_geometry(format, SW, SH, stride);
    header.payload_len = len;
    let f = match lens {
        LensModel::Pinhole => 1000.0,
        LensModel::Fisheye => 600.0,
    };
    header.intrinsics = CameraIntrinsics {
        fx: f,
        fy: f,
        cx: SW as f32 / 2.0,
        cy: SH as f32 / 2.0,
        k: [0.0; 4],
        lens_model: lens.to_wire(),
        valid: 1,
        reserved: [0; 2],
    };
    let data = (0..len as usize)
        .map(|i| ((i * 31 + i / 5_760 * 17) % 251) as u8)
        .collect();
    (header, data)
}

fn pose(yaw_deg: f64, pitch_deg: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(0.0, pitch_deg.to_radians(), yaw_deg.to_radians())
}

struct Case<'a> {
    name: &'a str,
    format: PixelFormat,
    lens: LensModel,
    layout: u8,
    overlay: u8,
    turning: bool,
}

fn run(case: &Case<'_>) {
    let (header, src) = source(case.format, case.lens);
    let model = CameraModel::from_header(&header).expect("model");
    let src_pose = CameraPose::from_parts(pose(0.0, -30.0), 0.0);
    let l = layout::compute(case.layout, case.overlay, OW as u16, OH as u16);
    let tiles: Vec<TileSpec> = l
        .tiles
        .iter()
        .enumerate()
        .map(|(i, rect)| TileSpec {
            rect: *rect,
            source: PixelBox {
                x: 200.0 + 250.0 * i as f32,
                y: 500.0,
                w: 60.0,
                h: 40.0,
            },
        })
        .collect();
    let mut out = vec![0u8; (OW * OH * 3) as usize];
    let mut renderer = Renderer::default();
    let mut times = Vec::with_capacity(FRAMES);
    for frame in 0..FRAMES {
        let turn = if case.turning {
            frame as f64 * 0.1
        } else {
            0.0
        };
        let views: Vec<ViewSpec> = l
            .views
            .iter()
            .enumerate()
            .map(|(i, rect)| ViewSpec {
                rect: *rect,
                ned_from_view: pose(-20.0 + 15.0 * i as f64 + turn, -35.0),
                hfov: 1.0,
                crop: if i == 3 {
                    CropMode::Panoramic
                } else {
                    CropMode::Rectified
                },
            })
            .collect();
        let start = Instant::now();
        renderer
            .render(
                &header,
                &src,
                &model,
                &src_pose,
                &views,
                false,
                &tiles,
                &mut out,
                OW,
                OH,
                OW * 3,
            )
            .expect("render");
        times.push(start.elapsed());
    }
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mean = times.iter().sum::<Duration>() / FRAMES as u32;
    println!(
        "{:<44} mean {:6.2} ms  p50 {:6.2} ms  p99 {:6.2} ms  grids built {}",
        case.name,
        ms(mean),
        ms(times[FRAMES / 2]),
        ms(times[FRAMES * 99 / 100]),
        renderer.grid_builds()
    );
}

fn main() {
    println!("{FRAMES} frames of {OW}x{OH} from a {SW}x{SH} source, one core:");
    let cases = [
        Case {
            name: "1 view, RGB24 pinhole, grid reused",
            format: PixelFormat::Rgb24,
            lens: LensModel::Pinhole,
            layout: 0,
            overlay: 0,
            turning: false,
        },
        Case {
            name: "1 view, RGB24 pinhole, turning (grid rebuilt)",
            format: PixelFormat::Rgb24,
            lens: LensModel::Pinhole,
            layout: 0,
            overlay: 0,
            turning: true,
        },
        Case {
            name: "4 views + column of 5 tiles, RGB24",
            format: PixelFormat::Rgb24,
            lens: LensModel::Pinhole,
            layout: 4,
            overlay: 2,
            turning: false,
        },
        Case {
            name: "1 view, NV12 pinhole, grid reused",
            format: PixelFormat::Nv12,
            lens: LensModel::Pinhole,
            layout: 0,
            overlay: 0,
            turning: false,
        },
        Case {
            name: "1 view, RGB24 fisheye, turning",
            format: PixelFormat::Rgb24,
            lens: LensModel::Fisheye,
            layout: 0,
            overlay: 0,
            turning: true,
        },
    ];
    for case in &cases {
        run(case);
    }
}
