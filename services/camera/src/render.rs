//! The synthetic scene's camera model and renderer: pure functions, no I/O.
//!
//! Frames (all right-handed):
//! - **scene frame**: local north, east, down metres around the scene origin; the
//!   ground is the plane `down = 0`.
//! - **mount frame**: the camera's body, x along the optical axis, y toward the
//!   image's right, z toward the image's bottom (FRD, like a vehicle body). Its
//!   orientation is a unit quaternion mount → NED (the frame header's
//!   `pose.attitude_q`).
//! - **pixels**: OpenCV convention, pixel `(i, j)` has its centre at `u = i`, `v = j`;
//!   the default principal point is the image centre `((w − 1)/2, (h − 1)/2)`.
//!
//! Rendering casts the ray of every pixel to the ground plane and shades the hit
//! point: targets first (discs or squares on the ground), then a procedural
//! checkerboard texture; rays that do not hit the ground are sky, hits farther than
//! [`MAX_RANGE_M`] are haze. Pixels are written straight into the caller's slice.

use nalgebra::{UnitQuaternion, Vector3};

/// Ground hits farther than this are rendered as haze (the texture would only alias).
pub const MAX_RANGE_M: f64 = 3000.0;
/// The camera is never placed lower than this above the ground (a landed vehicle).
pub const MIN_HEIGHT_M: f64 = 0.3;

pub const SKY_RGB: [u8; 3] = [135, 185, 235];
pub const HAZE_RGB: [u8; 3] = [180, 196, 206];
const GRID_RGB: [u8; 3] = [165, 160, 140];
const CHECK_A: [i32; 3] = [92, 124, 70];
const CHECK_B: [i32; 3] = [118, 140, 86];

/// The projection of the lens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lens {
    /// Ideal pinhole (no distortion).
    Pinhole,
    /// Equidistant fisheye: the distance from the principal point is `f·θ`.
    Fisheye,
}

/// Intrinsics of an ideal camera (the synthetic scene has no distortion).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub lens: Lens,
}

impl Intrinsics {
    /// Square pixels (`fx = fy`) from the horizontal field of view, principal point at
    /// the image centre.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64, lens: Lens) -> Self {
        let half = hfov_deg.to_radians() / 2.0;
        let half_w = f64::from(width) / 2.0;
        let f = match lens {
            Lens::Pinhole => half_w / half.tan(),
            Lens::Fisheye => half_w / half,
        };
        Intrinsics {
            fx: f,
            fy: f,
            cx: (f64::from(width) - 1.0) / 2.0,
            cy: (f64::from(height) - 1.0) / 2.0,
            lens,
        }
    }

    /// The frame header's intrinsics (no distortion coefficients).
    pub fn to_wire(&self) -> skymesh_ipc_types::CameraIntrinsics {
        skymesh_ipc_types::CameraIntrinsics {
            fx: self.fx as f32,
            fy: self.fy as f32,
            cx: self.cx as f32,
            cy: self.cy as f32,
            k: [0.0; 4],
            lens_model: match self.lens {
                Lens::Pinhole => skymesh_ipc_types::LensModel::Pinhole,
                Lens::Fisheye => skymesh_ipc_types::LensModel::Fisheye,
            }
            .to_wire(),
            valid: 1,
            reserved: [0; 2],
        }
    }

    /// The direction (not normalised) in the mount frame of pixel `(u, v)`; `None`
    /// beyond a fisheye's 180° from the axis.
    pub fn ray(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let x = (u - self.cx) / self.fx;
        let y = (v - self.cy) / self.fy;
        match self.lens {
            Lens::Pinhole => Some(Vector3::new(1.0, x, y)),
            Lens::Fisheye => {
                let theta = (x * x + y * y).sqrt();
                if theta >= std::f64::consts::PI {
                    return None;
                }
                if theta < 1e-12 {
                    return Some(Vector3::new(1.0, 0.0, 0.0));
                }
                let s = theta.sin() / theta;
                Some(Vector3::new(theta.cos(), x * s, y * s))
            }
        }
    }

    /// The pixel where the mount-frame point `p` appears; `None` if it cannot be seen
    /// (behind a pinhole camera, or on the fisheye's axis behind it).
    pub fn project(&self, p: &Vector3<f64>) -> Option<(f64, f64)> {
        match self.lens {
            Lens::Pinhole => {
                if p.x <= 1e-9 {
                    return None;
                }
                Some((self.cx + self.fx * p.y / p.x, self.cy + self.fy * p.z / p.x))
            }
            Lens::Fisheye => {
                let rho = (p.y * p.y + p.z * p.z).sqrt();
                if rho < 1e-12 {
                    return (p.x > 0.0).then_some((self.cx, self.cy));
                }
                let theta = rho.atan2(p.x);
                Some((
                    self.cx + self.fx * theta * p.y / rho,
                    self.cy + self.fy * theta * p.z / rho,
                ))
            }
        }
    }
}

/// Where the camera is and how it looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// Scene frame (north, east, down) metres; `down` negative above the ground.
    pub ned: Vector3<f64>,
    /// Mount → NED.
    pub attitude: UnitQuaternion<f64>,
}

impl CameraPose {
    /// A camera `height_m` above the scene point `(north, east)`, looking along
    /// `yaw_deg` (clockwise from north) and `pitch_deg` (down negative), no roll.
    pub fn looking(north: f64, east: f64, height_m: f64, yaw_deg: f64, pitch_deg: f64) -> Self {
        CameraPose {
            ned: Vector3::new(north, east, -height_m),
            attitude: mount_attitude(yaw_deg, pitch_deg, 0.0),
        }
    }

    /// Height above the ground used for rendering (at least [`MIN_HEIGHT_M`]).
    pub fn height(&self) -> f64 {
        (-self.ned.z).max(MIN_HEIGHT_M)
    }

    /// The pixel where the ground point `(north, east)` appears, if it can be seen.
    pub fn project_ground(&self, k: &Intrinsics, north: f64, east: f64) -> Option<(f64, f64)> {
        let eye = Vector3::new(self.ned.x, self.ned.y, -self.height());
        let p = self
            .attitude
            .inverse_transform_vector(&(Vector3::new(north, east, 0.0) - eye));
        k.project(&p)
    }

    /// The ground point `(north, east)` seen at pixel `(u, v)`, `None` above the horizon.
    pub fn ground_at(&self, k: &Intrinsics, u: f64, v: f64) -> Option<(f64, f64)> {
        let dir = self.attitude.transform_vector(&k.ray(u, v)?);
        ground_hit(&self.ned_eye(), &dir)
    }

    fn ned_eye(&self) -> Vector3<f64> {
        Vector3::new(self.ned.x, self.ned.y, -self.height())
    }
}

/// Mount → NED for a stabilised gimbal: yaw (clockwise from north), pitch (down
/// negative), roll, applied in that order (ZYX).
pub fn mount_attitude(yaw_deg: f64, pitch_deg: f64, roll_deg: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(
        roll_deg.to_radians(),
        pitch_deg.to_radians(),
        yaw_deg.to_radians(),
    )
}

fn ground_hit(eye: &Vector3<f64>, dir: &Vector3<f64>) -> Option<(f64, f64)> {
    if dir.z <= 1e-9 {
        return None;
    }
    let t = -eye.z / dir.z;
    Some((eye.x + t * dir.x, eye.y + t * dir.y))
}

/// The shape of a target on the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    Disc,
    /// Sides along north and east.
    Square,
}

/// A target where it is at the frame's capture time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedTarget {
    pub north: f64,
    pub east: f64,
    /// Diameter (disc) or side (square), m.
    pub size_m: f64,
    pub shape: Shape,
    pub rgb: [u8; 3],
}

/// What is on the ground.
#[derive(Debug, Clone, Copy)]
pub struct Scene<'a> {
    pub targets: &'a [PlacedTarget],
    /// Side of a checkerboard cell, m.
    pub cell_m: f64,
}

impl Scene<'_> {
    #[inline]
    fn inv_cell(&self) -> f64 {
        1.0 / self.cell_m
    }

    /// The colour seen along `dir` (NED) from `eye`.
    #[inline]
    fn shade(&self, eye: &Vector3<f64>, dir: &Vector3<f64>) -> [u8; 3] {
        if dir.z <= 1e-9 {
            return SKY_RGB;
        }
        let t = -eye.z / dir.z;
        let dx = t * dir.x;
        let dy = t * dir.y;
        if dx * dx + dy * dy + eye.z * eye.z > MAX_RANGE_M * MAX_RANGE_M {
            return HAZE_RGB;
        }
        let n = eye.x + dx;
        let e = eye.y + dy;
        for tg in self.targets {
            let r = tg.size_m / 2.0;
            let (a, b) = (n - tg.north, e - tg.east);
            let inside = match tg.shape {
                Shape::Disc => a * a + b * b <= r * r,
                Shape::Square => a.abs() <= r && b.abs() <= r,
            };
            if inside {
                return tg.rgb;
            }
        }
        self.texture(n, e)
    }

    /// Checkerboard of `cell_m` cells with a per-cell brightness variation and grid
    /// lines every five cells.
    #[inline]
    fn texture(&self, n: f64, e: f64) -> [u8; 3] {
        let gn = n * self.inv_cell();
        let ge = e * self.inv_cell();
        let (ci, cj) = (gn.floor(), ge.floor());
        // Lines 3 % of a cell wide, every five cells (`x − ⌊x⌋`: `rem_euclid` on
        // floats is a libm call, too slow for every pixel).
        const LINE: f64 = 0.03 / 5.0;
        let on_line = |g: f64| {
            let q = g * 0.2;
            let m = q - q.floor();
            !(LINE..=1.0 - LINE).contains(&m)
        };
        if on_line(gn) || on_line(ge) {
            return GRID_RGB;
        }
        let (i, j) = (ci as i64, cj as i64);
        let base = if (i + j).rem_euclid(2) == 0 {
            CHECK_A
        } else {
            CHECK_B
        };
        // A per-cell brightness offset in −8..=7 (a hash; no division per pixel).
        let h = (((i.wrapping_mul(73_856_093) ^ j.wrapping_mul(19_349_663)) >> 4) & 15) as i32 - 8;
        [
            (base[0] + h).clamp(0, 255) as u8,
            (base[1] + h).clamp(0, 255) as u8,
            (base[2] + h).clamp(0, 255) as u8,
        ]
    }
}

/// Calls `put(x, row, rgb)` for the pixels of rows `rows` (in units of `step`
/// pixels; `row` counts from the first of them), sampling every `step`-th pixel at
/// the centre of its `step × step` block.
#[allow(clippy::too_many_arguments)]
fn for_each_pixel(
    scene: &Scene<'_>,
    k: &Intrinsics,
    pose: &CameraPose,
    width: u32,
    rows: std::ops::Range<u32>,
    step: u32,
    mut put: impl FnMut(usize, usize, [u8; 3]),
) {
    let eye = pose.ned_eye();
    let r = pose.attitude.to_rotation_matrix();
    let off = f64::from(step - 1) / 2.0;
    let first = rows.start;
    let cols = (width / step) as usize;
    match k.lens {
        Lens::Pinhole => {
            // The ray is linear in (u, v): axis + (u − cx)·du + (v − cy)·dv.
            let axis = r * Vector3::x();
            let du = r * Vector3::y() / k.fx;
            let dv = r * Vector3::z() / k.fy;
            for y in rows {
                let v = f64::from(y * step) + off;
                let mut dir = axis + dv * (v - k.cy) + du * (off - k.cx);
                let du_step = du * f64::from(step);
                for x in 0..cols {
                    put(x, (y - first) as usize, scene.shade(&eye, &dir));
                    dir += du_step;
                }
            }
        }
        Lens::Fisheye => {
            for y in rows {
                let v = f64::from(y * step) + off;
                for x in 0..cols {
                    let u = (x as u32 * step) as f64 + off;
                    let rgb = match k.ray(u, v) {
                        Some(m) => scene.shade(&eye, &(r * m)),
                        None => [0, 0, 0],
                    };
                    put(x, (y - first) as usize, rgb);
                }
            }
        }
    }
}

/// Runs `f(first_row, band)` on `threads` scoped threads, each with a band of
/// consecutive rows (`row_bytes` each) of `out`.
fn in_bands(
    out: &mut [u8],
    row_bytes: usize,
    rows: u32,
    threads: usize,
    f: impl Fn(u32, &mut [u8]) + Sync,
) {
    let out = &mut out[..row_bytes * rows as usize];
    let threads = threads.clamp(1, rows.max(1) as usize);
    if threads == 1 {
        f(0, out);
        return;
    }
    let per = (rows as usize).div_ceil(threads);
    std::thread::scope(|scope| {
        for (i, band) in out.chunks_mut(per * row_bytes).enumerate() {
            let f = &f;
            scope.spawn(move || f((i * per) as u32, band));
        }
    });
}

/// Renders RGB24 into `out` (rows `stride` bytes apart, at least `stride × height`)
/// on `threads` threads.
#[allow(clippy::too_many_arguments)]
pub fn render_rgb24(
    scene: &Scene<'_>,
    k: &Intrinsics,
    pose: &CameraPose,
    width: u32,
    height: u32,
    stride: usize,
    threads: usize,
    out: &mut [u8],
) {
    in_bands(out, stride, height, threads, |first, band| {
        let rows = first..first + (band.len() / stride) as u32;
        for_each_pixel(scene, k, pose, width, rows, 1, |x, y, rgb| {
            let i = y * stride + x * 3;
            band[i..i + 3].copy_from_slice(&rgb);
        });
    });
}

/// Renders NV12 into `out` on `threads` threads: a luma plane of `height` rows,
/// then interleaved CbCr of `height / 2` rows (one sample per 2×2 block, taken at
/// the block's centre), both `stride` bytes apart. BT.601 full range (JPEG/JFIF).
#[allow(clippy::too_many_arguments)]
pub fn render_nv12(
    scene: &Scene<'_>,
    k: &Intrinsics,
    pose: &CameraPose,
    width: u32,
    height: u32,
    stride: usize,
    threads: usize,
    out: &mut [u8],
) {
    let (luma, chroma) = out.split_at_mut(stride * height as usize);
    in_bands(luma, stride, height, threads, |first, band| {
        let rows = first..first + (band.len() / stride) as u32;
        for_each_pixel(scene, k, pose, width, rows, 1, |x, y, rgb| {
            band[y * stride + x] = rgb_to_ycbcr(rgb)[0];
        });
    });
    in_bands(chroma, stride, height / 2, threads, |first, band| {
        let rows = first..first + (band.len() / stride) as u32;
        for_each_pixel(scene, k, pose, width, rows, 2, |x, y, rgb| {
            let [_, cb, cr] = rgb_to_ycbcr(rgb);
            let i = y * stride + x * 2;
            band[i] = cb;
            band[i + 1] = cr;
        });
    });
}

/// BT.601 full-range RGB → Y, Cb, Cr.
pub fn rgb_to_ycbcr([r, g, b]: [u8; 3]) -> [u8; 3] {
    let (r, g, b) = (f32::from(r), f32::from(g), f32::from(b));
    let y = 0.299 * r + 0.587 * g + 0.114 * b;
    let cb = 128.0 - 0.168_736 * r - 0.331_264 * g + 0.5 * b;
    let cr = 128.0 + 0.5 * r - 0.418_688 * g - 0.081_312 * b;
    [
        y.round().clamp(0.0, 255.0) as u8,
        cb.round().clamp(0.0, 255.0) as u8,
        cr.round().clamp(0.0, 255.0) as u8,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 640;
    const H: u32 = 480;
    const RED: [u8; 3] = [250, 0, 0];

    fn render(k: &Intrinsics, pose: &CameraPose, targets: &[PlacedTarget]) -> Vec<u8> {
        let mut out = vec![0u8; (W * H * 3) as usize];
        let scene = Scene {
            targets,
            cell_m: 10.0,
        };
        render_rgb24(&scene, k, pose, W, H, (W * 3) as usize, 3, &mut out);
        out
    }

    fn px(img: &[u8], x: u32, y: u32) -> [u8; 3] {
        let i = ((y * W + x) * 3) as usize;
        [img[i], img[i + 1], img[i + 2]]
    }

    /// Centroid and pixel count of the pixels of colour `rgb`.
    fn blob(img: &[u8], rgb: [u8; 3]) -> (f64, f64, usize) {
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
        for y in 0..H {
            for x in 0..W {
                if px(img, x, y) == rgb {
                    sx += f64::from(x);
                    sy += f64::from(y);
                    n += 1;
                }
            }
        }
        assert!(n > 0, "no pixel of colour {rgb:?}");
        (sx / n as f64, sy / n as f64, n)
    }

    fn target(north: f64, east: f64, size_m: f64) -> PlacedTarget {
        PlacedTarget {
            north,
            east,
            size_m,
            shape: Shape::Disc,
            rgb: RED,
        }
    }

    #[test]
    fn a_target_below_a_nadir_camera_renders_at_the_centre() {
        let k = Intrinsics::from_hfov(W, H, 90.0, Lens::Pinhole);
        let pose = CameraPose::looking(100.0, -40.0, 50.0, 37.0, -90.0);
        let img = render(&k, &pose, &[target(100.0, -40.0, 4.0)]);
        let (x, y, n) = blob(&img, RED);
        assert!(
            (x - k.cx).abs() < 0.25 && (y - k.cy).abs() < 0.25,
            "{x} {y}"
        );
        // A 4 m disc at 50 m: radius fx·2/50 pixels.
        let r = k.fx * 2.0 / 50.0;
        let area = std::f64::consts::PI * r * r;
        assert!((n as f64 - area).abs() < 0.1 * area, "{n} vs {area}");
    }

    #[test]
    fn a_ground_point_projects_where_the_intrinsics_say() {
        let k = Intrinsics::from_hfov(W, H, 90.0, Lens::Pinhole);
        assert!((k.fx - 320.0).abs() < 1e-9);
        // Nadir, heading north: image up is north, image right is east.
        let pose = CameraPose::looking(0.0, 0.0, 50.0, 0.0, -90.0);
        let (u, v) = pose.project_ground(&k, 10.0, 5.0).unwrap();
        assert!((u - (k.cx + k.fx * 5.0 / 50.0)).abs() < 1e-6, "{u}");
        assert!((v - (k.cy - k.fy * 10.0 / 50.0)).abs() < 1e-6, "{v}");
        // The renderer agrees.
        let img = render(&k, &pose, &[target(10.0, 5.0, 2.0)]);
        let (x, y, _) = blob(&img, RED);
        assert!(
            (x - u).abs() < 0.5 && (y - v).abs() < 0.5,
            "{x},{y} vs {u},{v}"
        );
        // Heading east, the same point is up-left.
        let east = CameraPose::looking(0.0, 0.0, 50.0, 90.0, -90.0);
        let (u, v) = east.project_ground(&k, 10.0, 5.0).unwrap();
        assert!((u - (k.cx - k.fx * 10.0 / 50.0)).abs() < 1e-6, "{u}");
        assert!((v - (k.cy - k.fy * 5.0 / 50.0)).abs() < 1e-6, "{v}");
    }

    #[test]
    fn an_oblique_view_projects_and_back_projects() {
        for lens in [Lens::Pinhole, Lens::Fisheye] {
            let k = Intrinsics::from_hfov(W, H, 120.0, lens);
            let pose = CameraPose {
                ned: Vector3::new(3.0, 4.0, -50.0),
                attitude: mount_attitude(-30.0, -40.0, 5.0),
            };
            let (u, v) = pose.project_ground(&k, 40.0, 10.0).unwrap();
            let (n, e) = pose.ground_at(&k, u, v).unwrap();
            assert!(
                (n - 40.0).abs() < 1e-6 && (e - 10.0).abs() < 1e-6,
                "{lens:?}"
            );
        }
    }

    #[test]
    fn the_horizon_of_a_level_camera_is_the_principal_row() {
        let k = Intrinsics::from_hfov(W, H, 90.0, Lens::Pinhole);
        let pose = CameraPose::looking(0.0, 0.0, 50.0, 0.0, 0.0);
        assert!(pose.ground_at(&k, k.cx, k.cy - 0.5).is_none());
        assert!(pose.ground_at(&k, k.cx, k.cy + 0.5).is_some());
        let img = render(&k, &pose, &[]);
        for x in [0, W / 2, W - 1] {
            // Every row above the centre is sky, the bottom rows are textured ground.
            assert_eq!(px(&img, x, H / 2 - 1), SKY_RGB);
            assert_eq!(px(&img, x, 0), SKY_RGB);
            let bottom = px(&img, x, H - 1);
            assert!(bottom != SKY_RGB && bottom != HAZE_RGB, "{bottom:?}");
        }
        // Pitched down 10°, the horizon moves up by fy·tan(10°).
        let down = CameraPose::looking(0.0, 0.0, 50.0, 0.0, -10.0);
        let row = k.cy - k.fy * 10f64.to_radians().tan();
        assert!(down.ground_at(&k, k.cx, row - 0.5).is_none());
        assert!(down.ground_at(&k, k.cx, row + 0.5).is_some());
    }

    #[test]
    fn nv12_carries_the_same_picture() {
        let k = Intrinsics::from_hfov(W, H, 90.0, Lens::Pinhole);
        let pose = CameraPose::looking(0.0, 0.0, 50.0, 0.0, -90.0);
        let scene = Scene {
            targets: &[target(0.0, 0.0, 10.0)],
            cell_m: 10.0,
        };
        let mut out = vec![0u8; (W * H * 3 / 2) as usize];
        render_nv12(&scene, &k, &pose, W, H, W as usize, 2, &mut out);
        let [y, cb, cr] = rgb_to_ycbcr(RED);
        let c = (H / 2 * W + W / 2) as usize;
        assert_eq!(out[c], y);
        let ci = (W * H + H / 4 * W + W / 2) as usize;
        assert_eq!((out[ci], out[ci + 1]), (cb, cr));
        assert_eq!(rgb_to_ycbcr([255, 255, 255]), [255, 128, 128]);
    }
}
