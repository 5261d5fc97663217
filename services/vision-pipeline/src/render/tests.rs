//! Tests of the output renderer: views, tiles, debug source, RGB24 and NV12 sources.

use super::*;
use nalgebra::Point2;
use skymesh_ipc_types::frame::{CameraIntrinsics, LensModel};

use crate::geometry::{Lens, YawPitch};
use crate::views::view_model;

const SW: u32 = 640;
const SH: u32 = 480;

/// A colour per 16 px checker square, distinct across the image.
fn checker(x: u32, y: u32) -> [u8; 3] {
    let (cx, cy) = ((x + 8) / 16, (y + 8) / 16);
    [
        (cx * 6 % 256) as u8,
        (cy * 8 % 256) as u8,
        if (cx + cy) % 2 == 0 { 40 } else { 220 },
    ]
}

fn header(format: PixelFormat, w: u32, h: u32, stride: u32, len: usize) -> FrameHeader {
    let mut header = FrameHeader::default();
    header.set_geometry(format, w, h, stride);
    header.payload_len = len as u32;
    header.intrinsics = CameraIntrinsics {
        fx: 400.0,
        fy: 400.0,
        cx: w as f32 / 2.0,
        cy: h as f32 / 2.0,
        k: [0.0; 4],
        lens_model: LensModel::Pinhole.to_wire(),
        valid: 1,
        reserved: [0; 2],
    };
    header
}

fn rgb_source(paint: impl Fn(u32, u32) -> [u8; 3]) -> (FrameHeader, Vec<u8>) {
    let stride = SW * 3 + 4;
    let mut data = vec![0u8; (stride * SH) as usize];
    for y in 0..SH {
        for x in 0..SW {
            let at = (y * stride + x * 3) as usize;
            data[at..at + 3].copy_from_slice(&paint(x, y));
        }
    }
    (header(PixelFormat::Rgb24, SW, SH, stride, data.len()), data)
}

fn pixel(out: &[u8], stride: u32, x: u32, y: u32) -> [u8; 3] {
    let at = (y * stride + x * 3) as usize;
    [out[at], out[at + 1], out[at + 2]]
}

fn pose(yaw_deg: f64, pitch_deg: f64) -> CameraPose {
    CameraPose::from_parts(
        UnitQuaternion::from_euler_angles(0.0, pitch_deg.to_radians(), yaw_deg.to_radians()),
        yaw_deg.to_radians(),
    )
}

/// Renders `views` alone (no debug view, no tiles) into a packed `w`×`h` output.
fn render_views(
    r: &mut Renderer,
    (header, src): (&FrameHeader, &[u8]),
    model: &CameraModel,
    pose: &CameraPose,
    views: &[ViewSpec],
    out: &mut [u8],
    (w, h): (u32, u32),
) -> Result<(), RenderError> {
    r.render(
        header,
        src,
        model,
        pose,
        views,
        false,
        &[],
        out,
        w,
        h,
        w * 3,
    )
}

fn near(a: [u8; 3], b: [u8; 3], tolerance: i32) -> bool {
    a.iter()
        .zip(b.iter())
        .all(|(x, y)| (i32::from(*x) - i32::from(*y)).abs() <= tolerance)
}

#[test]
fn a_view_aimed_like_the_source_reproduces_it() {
    let (h, src) = rgb_source(checker);
    let model = CameraModel::from_header(&h).unwrap();
    let src_pose = pose(30.0, -20.0);
    let hfov = 2.0 * (320.0f64 / 400.0).atan();
    let view = ViewSpec {
        rect: [0, 0, 640, 480],
        ned_from_view: src_pose.ned_from_camera(),
        hfov,
        crop: CropMode::Rectified,
    };
    let mut out = vec![7u8; 640 * 480 * 3];
    let mut r = Renderer::default();
    render_views(
        &mut r,
        (&h, &src),
        &model,
        &src_pose,
        &[view],
        &mut out,
        (640, 480),
    )
    .unwrap();
    assert_eq!(pixel(&out, 640 * 3, 320, 240), checker(320, 240));
    // Identity mapping: every pixel centre lands on its own source pixel centre.
    for (x, y) in [(0, 0), (5, 9), (100, 200), (639, 479), (333, 17)] {
        assert_eq!(pixel(&out, 640 * 3, x, y), checker(x, y), "({x}, {y})");
    }
    // Rendering again reuses the grid; a turned view rebuilds it.
    render_views(
        &mut r,
        (&h, &src),
        &model,
        &src_pose,
        &[view],
        &mut out,
        (640, 480),
    )
    .unwrap();
    assert_eq!(r.grid_builds(), 1);
    let turned = ViewSpec {
        ned_from_view: pose(40.0, -20.0).ned_from_camera(),
        ..view
    };
    render_views(
        &mut r,
        (&h, &src),
        &model,
        &src_pose,
        &[turned],
        &mut out,
        (640, 480),
    )
    .unwrap();
    assert_eq!(r.grid_builds(), 2);
    // Turned 10° right: the view's left part shows the source's right side...
    let p = model
        .ray_to_pixel(
            &YawPitch {
                yaw: 10f64.to_radians(),
                pitch: 0.0,
            }
            .direction(),
        )
        .unwrap();
    let shown = pixel(&out, 640 * 3, 320, 240);
    assert!(
        near(shown, checker(p.x as u32, p.y as u32), 40),
        "{shown:?} vs {p}"
    );
    // ...and beyond the source's right edge is black.
    assert_eq!(pixel(&out, 640 * 3, 639, 240), [0, 0, 0]);
}

#[test]
fn a_view_aimed_at_a_target_shows_its_colour() {
    // A red disc at 25° right, 10° down of the source's axis.
    let model = CameraModel::new(
        640.0,
        480.0,
        400.0,
        400.0,
        320.0,
        240.0,
        Lens::IDEAL_PINHOLE,
    )
    .unwrap();
    let target = YawPitch {
        yaw: 25f64.to_radians(),
        pitch: -10f64.to_radians(),
    }
    .direction();
    let at = model.ray_to_pixel(&target).unwrap();
    let (h, src) = rgb_source(|x, y| {
        let d = Point2::new(f64::from(x) + 0.5, f64::from(y) + 0.5) - at;
        if d.norm() < 12.0 {
            [230, 10, 10]
        } else {
            checker(x, y)
        }
    });
    let src_pose = pose(-70.0, 5.0);
    let ned = src_pose.camera_to_ned(&target);
    let aim = YawPitch::of(&ned).unwrap();
    let view = ViewSpec {
        rect: [100, 50, 320, 180],
        ned_from_view: UnitQuaternion::from_euler_angles(0.0, aim.pitch, aim.yaw),
        hfov: 0.3,
        crop: CropMode::Rectified,
    };
    let (ow, oh) = (640u32, 360u32);
    let mut out = vec![0u8; (ow * oh * 3) as usize];
    render_views(
        &mut Renderer::default(),
        (&h, &src),
        &model,
        &src_pose,
        &[view],
        &mut out,
        (ow, oh),
    )
    .unwrap();
    assert_eq!(pixel(&out, ow * 3, 260, 140), [230, 10, 10]);
    // Outside the view's rect: black.
    assert_eq!(pixel(&out, ow * 3, 50, 20), [0, 0, 0]);
    // The same through an NV12 source.
    let (nh, nsrc) = nv12_of(&src, h.stride);
    let mut out2 = vec![0u8; (ow * oh * 3) as usize];
    render_views(
        &mut Renderer::default(),
        (&nh, &nsrc),
        &model,
        &src_pose,
        &[view],
        &mut out2,
        (ow, oh),
    )
    .unwrap();
    assert!(near(pixel(&out2, ow * 3, 260, 140), [230, 10, 10], 6));
}

/// NV12 of an RGB24 image (BT.601 full range, chroma of each 2×2 block's top-left).
fn nv12_of(rgb: &[u8], stride: u32) -> (FrameHeader, Vec<u8>) {
    let (w, hgt) = (SW as usize, SH as usize);
    let mut data = vec![0u8; w * hgt * 3 / 2];
    for y in 0..hgt {
        for x in 0..w {
            let at = y * stride as usize + x * 3;
            let [yy, cb, cr] =
                skymesh_camera::render::rgb_to_ycbcr([rgb[at], rgb[at + 1], rgb[at + 2]]);
            data[y * w + x] = yy;
            if x % 2 == 0 && y % 2 == 0 {
                let c = w * hgt + (y / 2) * w + x;
                data[c] = cb;
                data[c + 1] = cr;
            }
        }
    }
    (header(PixelFormat::Nv12, SW, SH, SW, data.len()), data)
}

#[test]
fn panoramic_centre_column_matches_the_source() {
    let (h, src) = rgb_source(checker);
    let model = CameraModel::from_header(&h).unwrap();
    let src_pose = pose(0.0, 0.0);
    let hfov = 2.0 * (320.0f64 / 400.0).atan();
    let view = ViewSpec {
        rect: [0, 0, 640, 480],
        ned_from_view: src_pose.ned_from_camera(),
        hfov,
        crop: CropMode::Panoramic,
    };
    let mut out = vec![0u8; 640 * 480 * 3];
    render_views(
        &mut Renderer::default(),
        (&h, &src),
        &model,
        &src_pose,
        &[view],
        &mut out,
        (640, 480),
    )
    .unwrap();
    // Yaw 0 column: the panoramic mapping is the pinhole there.
    let vf = 640.0 / hfov;
    for y in [10u32, 100, 240, 400, 470] {
        let v = f64::from(y) + 0.5;
        let sy = 240.0 + 400.0 * (v - 240.0) / vf;
        assert!(
            near(pixel(&out, 640 * 3, 320, y), checker(320, sy as u32), 60),
            "row {y}"
        );
    }
    assert_eq!(pixel(&out, 640 * 3, 320, 240), checker(320, 240));
    // Yaw linear: a quarter of the width is a quarter of the FOV.
    let yaw = hfov / 4.0;
    let p = model
        .ray_to_pixel(&YawPitch { yaw, pitch: 0.0 }.direction())
        .unwrap();
    assert!(near(
        pixel(&out, 640 * 3, 480, 240),
        checker(p.x as u32, 240),
        60
    ));
}

#[test]
fn debug_view_and_tiles() {
    let (h, src) = rgb_source(checker);
    let model = CameraModel::from_header(&h).unwrap();
    let p = pose(0.0, 0.0);
    let view = ViewSpec {
        rect: [0, 0, 320, 180],
        ned_from_view: p.ned_from_camera(),
        hfov: 1.0,
        crop: CropMode::Rectified,
    };
    let tile = TileSpec {
        rect: [400, 0, 96, 96],
        source: PixelBox {
            x: 300.0,
            y: 220.0,
            w: 40.0,
            h: 40.0,
        },
    };
    let (ow, oh) = (640u32, 360u32);
    let mut out = vec![0u8; (ow * oh * 3) as usize];
    Renderer::default()
        .render(
            &h,
            &src,
            &model,
            &p,
            &[view],
            true,
            &[tile],
            &mut out,
            ow,
            oh,
            ow * 3,
        )
        .unwrap();
    // 640×480 into 320×180: scale 0.375, 240 wide, centred at x 40.
    assert_eq!(pixel(&out, ow * 3, 39, 90), [0, 0, 0]);
    assert_eq!(pixel(&out, ow * 3, 280, 90), [0, 0, 0]);
    let sx = (100.0 + 0.5) / 0.375;
    let sy = (90.0 + 0.5) / 0.375;
    assert!(near(
        pixel(&out, ow * 3, 140, 90),
        checker(sx as u32, sy as u32),
        60
    ));
    // Tile: border, then the crop: 50 px around (320, 240) in 96 px.
    assert_eq!(pixel(&out, ow * 3, 400, 40), TILE_BORDER);
    assert_eq!(pixel(&out, ow * 3, 495, 95), TILE_BORDER);
    assert!(near(pixel(&out, ow * 3, 448, 48), checker(320, 240), 60));
}

#[test]
fn bad_buffers_are_refused_and_odd_rects_clipped() {
    let (h, src) = rgb_source(checker);
    let model = CameraModel::from_header(&h).unwrap();
    let p = pose(0.0, 0.0);
    let mut r = Renderer::default();
    let mut out = vec![0u8; 100 * 100 * 3];
    let short = &src[..src.len() - 1];
    assert!(render_views(&mut r, (&h, short), &model, &p, &[], &mut out, (100, 100)).is_err());
    assert!(render_views(&mut r, (&h, &src), &model, &p, &[], &mut out, (100, 101)).is_err());
    assert!(r
        .render(
            &h,
            &src,
            &model,
            &p,
            &[],
            false,
            &[],
            &mut out,
            100,
            100,
            299
        )
        .is_err());
    assert!(r
        .render(&h, &src, &model, &p, &[], false, &[], &mut out, 0, 100, 300)
        .is_err());
    let other = view_model(320, 240, 1.0).unwrap();
    assert!(render_views(&mut r, (&h, &src), &other, &p, &[], &mut out, (100, 100)).is_err());
    // Views and tiles partly or wholly outside, degenerate FOVs and boxes: no panic.
    let views = [
        ViewSpec {
            rect: [50, 50, 500, 500],
            ned_from_view: p.ned_from_camera(),
            hfov: 1.0,
            crop: CropMode::Rectified,
        },
        ViewSpec {
            rect: [5000, 0, 10, 10],
            ned_from_view: p.ned_from_camera(),
            hfov: 1.0,
            crop: CropMode::Rectified,
        },
        ViewSpec {
            rect: [0, 0, 1, 1],
            ned_from_view: p.ned_from_camera(),
            hfov: f64::NAN,
            crop: CropMode::Panoramic,
        },
        ViewSpec {
            rect: [0, 0, 7, 3],
            ned_from_view: p.ned_from_camera(),
            hfov: 3.5,
            crop: CropMode::Rectified,
        },
    ];
    let tiles = [
        TileSpec {
            rect: [90, 90, 30, 30],
            source: PixelBox {
                x: f32::NAN,
                y: 0.0,
                w: 1.0,
                h: 1.0,
            },
        },
        TileSpec {
            rect: [0, 0, 1, 1],
            source: PixelBox {
                x: -500.0,
                y: 1e9,
                w: 0.0,
                h: 0.0,
            },
        },
    ];
    r.render(
        &h, &src, &model, &p, &views, true, &tiles, &mut out, 100, 100, 300,
    )
    .unwrap();
    r.render(
        &h, &src, &model, &p, &views, false, &tiles, &mut out, 100, 100, 300,
    )
    .unwrap();
    // A view looking backwards from a pinhole sees nothing.
    let back = ViewSpec {
        rect: [0, 0, 100, 100],
        ned_from_view: pose(180.0, 0.0).ned_from_camera(),
        hfov: 1.0,
        crop: CropMode::Rectified,
    };
    out.fill(9);
    render_views(
        &mut r,
        (&h, &src),
        &model,
        &p,
        &[back],
        &mut out,
        (100, 100),
    )
    .unwrap();
    assert!(out.iter().all(|&b| b == 0));
}
