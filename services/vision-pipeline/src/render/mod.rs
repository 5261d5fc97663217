//! Rendering the output frame from the wide source frame.
//!
//! Every output pixel of a user view is a ray of the view (rectified: a pinhole with
//! the view's HFOV; panoramic: yaw linear across the width, see
//! [`crate::views::view_ray`]), turned into the source camera's frame
//! (`src_from_view = ned_from_src⁻¹ · ned_from_view`) and projected through the source
//! lens model; the source is sampled there **bilinearly** (RGB24 directly; NV12 with
//! bilinear luma and nearest chroma, BT.601 full range — the camera service's
//! conversion). Pixels whose ray the source does not see are black.
//!
//! **Speed.** The exact mapping is computed only on a grid of nodes every
//! [`GRID_STEP`] pixels and interpolated linearly inside each cell; the grid is kept
//! per view slot and reused while the view's rectangle, FOV, crop mode, source model
//! and its orientation relative to the source camera are unchanged (exact quaternion
//! comparison). A cell whose four corners all project is interpolated; a cell with no
//! corner projecting is black; a mixed cell (the edge of what a fisheye or a pinhole
//! sees) is computed pixel by pixel. Interpolation error inside a cell is the mapping's
//! curvature over 8 px: sub-pixel for the lenses of this stack.
//!
//! The debug view (layout 6) shows the whole source letterboxed into `views[0]`
//! (aspect kept). Detection tiles show a square crop around each box, 1.25× the box's
//! longer side (at least 8 px), scaled to the tile, with a 2 px border (1 px below
//! 48 px tiles).

use nalgebra::UnitQuaternion;
use skymesh_ipc_types::{CropMode, FrameHeader, PixelFormat};

use crate::detect::PixelBox;
use crate::geometry::{CameraModel, CameraPose};
use crate::views::view_ray;

/// Pixels between two grid nodes.
pub const GRID_STEP: usize = 8;
/// Detection tile crop: the box's longer side times this.
pub const TILE_MARGIN: f32 = 1.25;
/// Tile border colour.
pub const TILE_BORDER: [u8; 3] = [255, 220, 0];

/// One user view to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSpec {
    pub rect: [u16; 4],
    /// camera → NED of the view.
    pub ned_from_view: UnitQuaternion<f64>,
    pub hfov: f64,
    pub crop: CropMode,
}

/// One detection tile: a square crop of the source around a detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileSpec {
    pub rect: [u16; 4],
    pub source: PixelBox,
}

/// What a grid was computed for.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GridKey {
    rect: [u16; 4],
    src_from_view: UnitQuaternion<f64>,
    hfov: f64,
    crop: CropMode,
    model: CameraModel,
}

/// Source coordinates at the grid nodes of one view (NaN: the source does not see).
#[derive(Debug, Clone)]
struct Grid {
    key: GridKey,
    /// Nodes per row.
    nx: usize,
    nodes: Vec<[f32; 2]>,
}

/// Keeps per-view lookup grids between frames.
#[derive(Debug, Default)]
pub struct Renderer {
    grids: Vec<Option<Grid>>,
    /// Grids computed (not reused) so far.
    grid_builds: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("{0}")]
    Frame(String),
}

impl Renderer {
    /// Grids computed so far (a grid reused for an unchanged view does not count).
    pub fn grid_builds(&self) -> u64 {
        self.grid_builds
    }

    /// Draws `views` (remapped from the source through `src_model`/`src_pose`), the
    /// debug view (`debug_source`: the whole source scaled into `views[0]`'s rect) and
    /// `tiles` into `out` (RGB24, `out_w`×`out_h`, `stride` bytes per row; black where
    /// nothing is drawn or the source does not see).
    #[allow(clippy::too_many_arguments)]
    pub fn render(
        &mut self,
        src_header: &FrameHeader,
        src: &[u8],
        src_model: &CameraModel,
        src_pose: &CameraPose,
        views: &[ViewSpec],
        debug_source: bool,
        tiles: &[TileSpec],
        out: &mut [u8],
        out_w: u32,
        out_h: u32,
        stride: u32,
    ) -> Result<(), RenderError> {
        let format = src_header
            .validate(src.len())
            .map_err(|e| RenderError::Frame(format!("source frame: {e}")))?;
        let (sw, sh) = (src_header.width, src_header.height);
        if src_model.width() != f64::from(sw) || src_model.height() != f64::from(sh) {
            return Err(RenderError::Frame(format!(
                "source model is {}x{}, the frame {sw}x{sh}",
                src_model.width(),
                src_model.height()
            )));
        }
        let mut target = Output::new(out, out_w, out_h, stride)?;
        target.clear();
        let plane = Plane {
            stride: src_header.stride as usize,
            w: sw as usize,
            h: sh as usize,
        };
        let scene = Scene {
            model: src_model,
            pose: src_pose,
            views,
            debug_source,
            tiles,
        };
        match format {
            PixelFormat::Rgb24 => {
                self.draw_all(&RgbSource { data: src, plane }, &scene, &mut target);
            }
            PixelFormat::Nv12 => {
                let (luma, chroma) = src.split_at(plane.stride * plane.h);
                let source = Nv12Source {
                    luma,
                    chroma,
                    plane,
                };
                self.draw_all(&source, &scene, &mut target);
            }
        }
        Ok(())
    }

    fn draw_all<S: Source>(&mut self, source: &S, scene: &Scene<'_>, out: &mut Output<'_>) {
        let Scene {
            model,
            pose,
            views,
            debug_source,
            tiles,
        } = *scene;
        if self.grids.len() < views.len() {
            self.grids.resize(views.len(), None);
        }
        for (i, view) in views.iter().enumerate() {
            let Some(rect) = out.clip(view.rect) else {
                continue;
            };
            if i == 0 && debug_source {
                draw_debug(source, rect, out);
                continue;
            }
            let key = GridKey {
                rect: view.rect,
                src_from_view: pose.ned_from_camera().inverse() * view.ned_from_view,
                hfov: view.hfov,
                crop: view.crop,
                model: *model,
            };
            let grid = match &mut self.grids[i] {
                Some(grid) if grid.key == key => grid,
                slot => {
                    self.grid_builds += 1;
                    slot.insert(build_grid(key))
                }
            };
            draw_view(source, grid, rect, out);
        }
        for tile in tiles {
            if let Some(rect) = out.clip(tile.rect) {
                draw_tile(source, &tile.source, rect, out);
            }
        }
    }
}

/// What [`Renderer::render`] draws, apart from the source frame and the output.
struct Scene<'a> {
    model: &'a CameraModel,
    pose: &'a CameraPose,
    views: &'a [ViewSpec],
    debug_source: bool,
    tiles: &'a [TileSpec],
}

/// The exact source pixel of the continuous view pixel `(u, v)`.
fn map_pixel(key: &GridKey, u: f64, v: f64) -> Option<[f32; 2]> {
    let [_, _, w, h] = key.rect;
    let ray = view_ray(key.crop, f64::from(w), f64::from(h), key.hfov, u, v)?;
    let p = key.model.ray_to_pixel(&(key.src_from_view * ray))?;
    let (x, y) = (p.x as f32, p.y as f32);
    (x.is_finite() && y.is_finite()).then_some([x, y])
}

fn build_grid(key: GridKey) -> Grid {
    let [_, _, w, h] = key.rect;
    let nx = (usize::from(w).max(1) - 1) / GRID_STEP + 2;
    let ny = (usize::from(h).max(1) - 1) / GRID_STEP + 2;
    let mut nodes = Vec::with_capacity(nx * ny);
    for gy in 0..ny {
        for gx in 0..nx {
            let u = (gx * GRID_STEP) as f64 + 0.5;
            let v = (gy * GRID_STEP) as f64 + 0.5;
            nodes.push(map_pixel(&key, u, v).unwrap_or([f32::NAN; 2]));
        }
    }
    Grid { key, nx, nodes }
}

/// Draws one view into the (clipped) `rect` of the output from its grid.
fn draw_view<S: Source>(source: &S, grid: &Grid, rect: Clip, out: &mut Output<'_>) {
    let step = GRID_STEP as f32;
    let nx = grid.nx;
    for j in 0..rect.h {
        let cy = j / GRID_STEP;
        let ty = (j % GRID_STEP) as f32 / step;
        let row = out.row(rect.y + j);
        let mut i = 0;
        while i < rect.w {
            let cx = i / GRID_STEP;
            let end = ((cx + 1) * GRID_STEP).min(rect.w);
            let c00 = grid.nodes[cy * nx + cx];
            let c10 = grid.nodes[cy * nx + cx + 1];
            let c01 = grid.nodes[(cy + 1) * nx + cx];
            let c11 = grid.nodes[(cy + 1) * nx + cx + 1];
            let valid = [c00, c10, c01, c11]
                .iter()
                .filter(|c| !c[0].is_nan())
                .count();
            if valid == 4 {
                let lx = c00[0] + (c01[0] - c00[0]) * ty;
                let ly = c00[1] + (c01[1] - c00[1]) * ty;
                let rx = c10[0] + (c11[0] - c10[0]) * ty;
                let ry = c10[1] + (c11[1] - c10[1]) * ty;
                let (dx, dy) = ((rx - lx) / step, (ry - ly) / step);
                let xs = [c00[0], c10[0], c01[0], c11[0]];
                let ys = [c00[1], c10[1], c01[1], c11[1]];
                // Bilinear values stay within the corners' range: if that is inside
                // the source (a neighbour to the right and below), no pixel needs a
                // bounds test or clamp.
                if inner(&xs, source.width()) && inner(&ys, source.height()) {
                    let t0 = (i - cx * GRID_STEP) as f32;
                    let mut fx = ((lx + dx * t0 - 0.5) * 256.0) as i32;
                    let mut fy = ((ly + dy * t0 - 0.5) * 256.0) as i32;
                    let (sx, sy) = ((dx * 256.0) as i32, (dy * 256.0) as i32);
                    let span = &mut row[(rect.x + i) * 3..(rect.x + end) * 3];
                    for px in span.chunks_exact_mut(3) {
                        px.copy_from_slice(&source.sample_fixed(fx as u32, fy as u32));
                        fx += sx;
                        fy += sy;
                    }
                    i = end;
                    continue;
                }
                for k in i..end {
                    let t = (k - cx * GRID_STEP) as f32;
                    if let Some(px) = source.sample(lx + dx * t, ly + dy * t) {
                        put(row, rect.x + k, &px);
                    }
                }
            } else if valid > 0 {
                for k in i..end {
                    let mapped = map_pixel(&grid.key, k as f64 + 0.5, j as f64 + 0.5);
                    if let Some(px) = mapped.and_then(|[x, y]| source.sample(x, y)) {
                        put(row, rect.x + k, &px);
                    }
                }
            }
            i = end;
        }
    }
}

/// The whole source, letterboxed into `rect`.
fn draw_debug<S: Source>(source: &S, rect: Clip, out: &mut Output<'_>) {
    let (sw, sh) = (source.width() as f32, source.height() as f32);
    let scale = (rect.w as f32 / sw).min(rect.h as f32 / sh);
    if scale.is_nan() || scale <= 0.0 {
        return;
    }
    let dw = ((sw * scale) as usize).min(rect.w);
    let dh = ((sh * scale) as usize).min(rect.h);
    let (ox, oy) = (rect.x + (rect.w - dw) / 2, rect.y + (rect.h - dh) / 2);
    for j in 0..dh {
        let sy = (j as f32 + 0.5) / scale;
        let row = out.row(oy + j);
        for i in 0..dw {
            if let Some(px) = source.sample((i as f32 + 0.5) / scale, sy) {
                put(row, ox + i, &px);
            }
        }
    }
}

/// A square crop around `bbox`, scaled into `rect`, with a border.
fn draw_tile<S: Source>(source: &S, bbox: &PixelBox, rect: Clip, out: &mut Output<'_>) {
    let (cx, cy) = bbox.center();
    let side = (bbox.w.max(bbox.h) * TILE_MARGIN).max(8.0);
    if cx.is_finite() && cy.is_finite() && side.is_finite() {
        let (x0, y0) = (cx - side / 2.0, cy - side / 2.0);
        let (sx, sy) = (side / rect.w as f32, side / rect.h as f32);
        for j in 0..rect.h {
            let y = y0 + (j as f32 + 0.5) * sy;
            let row = out.row(rect.y + j);
            for i in 0..rect.w {
                let px = source
                    .sample(x0 + (i as f32 + 0.5) * sx, y)
                    .unwrap_or([0; 3]);
                put(row, rect.x + i, &px);
            }
        }
    }
    let border = if rect.w.min(rect.h) < 48 { 1 } else { 2 };
    for j in 0..rect.h {
        let row = out.row(rect.y + j);
        for i in 0..rect.w {
            let edge = i < border || j < border || i + border >= rect.w || j + border >= rect.h;
            if edge {
                put(row, rect.x + i, &TILE_BORDER);
            }
        }
    }
}

/// Stores RGB `px` at column `x` of an output row.
#[inline(always)]
fn put(row: &mut [u8], x: usize, px: &[u8; 3]) {
    row[x * 3..x * 3 + 3].copy_from_slice(px);
}

/// A rectangle inside the output, in pixels.
#[derive(Debug, Clone, Copy)]
struct Clip {
    x: usize,
    y: usize,
    w: usize,
    h: usize,
}

/// The output buffer, checked once.
struct Output<'a> {
    buf: &'a mut [u8],
    w: usize,
    h: usize,
    stride: usize,
}

impl<'a> Output<'a> {
    fn new(buf: &'a mut [u8], w: u32, h: u32, stride: u32) -> Result<Output<'a>, RenderError> {
        let (w, h, stride) = (w as usize, h as usize, stride as usize);
        if w == 0 || h == 0 {
            return Err(RenderError::Frame(format!("output size {w}x{h}")));
        }
        let row = w
            .checked_mul(3)
            .ok_or_else(|| RenderError::Frame(format!("output width {w}")))?;
        if stride < row {
            return Err(RenderError::Frame(format!(
                "output stride {stride} < {row} bytes of a row"
            )));
        }
        let needed = stride
            .checked_mul(h - 1)
            .and_then(|n| n.checked_add(row))
            .ok_or_else(|| RenderError::Frame("output size overflows".into()))?;
        if buf.len() < needed {
            return Err(RenderError::Frame(format!(
                "output buffer of {} bytes, {w}x{h} stride {stride} needs {needed}",
                buf.len()
            )));
        }
        Ok(Output { buf, w, h, stride })
    }

    fn clear(&mut self) {
        for y in 0..self.h {
            self.row(y).fill(0);
        }
    }

    /// Row `y`'s pixels (`w × 3` bytes).
    fn row(&mut self, y: usize) -> &mut [u8] {
        let start = y * self.stride;
        &mut self.buf[start..start + self.w * 3]
    }

    /// `r` clipped to the output; `None` if nothing is left.
    fn clip(&self, r: [u16; 4]) -> Option<Clip> {
        let x = usize::from(r[0]);
        let y = usize::from(r[1]);
        let w = (x + usize::from(r[2])).min(self.w).checked_sub(x)?;
        let h = (y + usize::from(r[3])).min(self.h).checked_sub(y)?;
        (w > 0 && h > 0).then_some(Clip { x, y, w, h })
    }
}

/// Whether continuous coordinates `v` all lie where a sample and its next neighbour
/// exist (`0.5 < v < len − 0.5`, with a margin for the fixed-point stepping).
#[inline(always)]
fn inner(v: &[f32; 4], len: usize) -> bool {
    // The fixed-point steps truncate: fewer than GRID_STEP units of 1/256 px drift
    // over a cell; the margin is twice that.
    const MARGIN: f32 = 16.0 / 256.0;
    let hi = len as f32 - 0.5 - MARGIN;
    v.iter().all(|&c| c >= 0.5 + MARGIN && c < hi)
}

/// Size and row pitch of a source image (of its luma plane for NV12).
#[derive(Debug, Clone, Copy)]
struct Plane {
    /// Bytes per row.
    stride: usize,
    w: usize,
    h: usize,
}

/// A source image sampled at continuous pixel coordinates.
trait Source {
    fn plane(&self) -> Plane;

    fn width(&self) -> usize {
        self.plane().w
    }

    fn height(&self) -> usize {
        self.plane().h
    }

    /// Bilinear RGB of the samples `taps`; `(x, y)` is the pixel holding the point
    /// (NV12 takes its chroma there).
    fn blend_taps(&self, taps: Taps, x: usize, y: usize) -> [u8; 3];

    /// Bilinear RGB at `(x, y)` (the image spans `0..w × 0..h`); `None` outside.
    #[inline(always)]
    fn sample(&self, x: f32, y: f32) -> Option<[u8; 3]> {
        let Plane { w, h, .. } = self.plane();
        let taps = bilinear_at(x, y, w, h)?;
        Some(self.blend_taps(taps, x as usize, y as usize))
    }

    /// Bilinear RGB at fixed-point `((x − 0.5) × 256, (y − 0.5) × 256)`, which the
    /// caller keeps where the sample's right and lower neighbours exist.
    fn sample_fixed(&self, fx: u32, fy: u32) -> [u8; 3];
}

/// The four samples of one bilinear lookup: the top-left one `(x0, y0)`, the next
/// column/row offsets (1, or 0 at the last column/row) and the weights of the next
/// column/row (0..256).
#[derive(Debug, Clone, Copy)]
struct Taps {
    x0: usize,
    y0: usize,
    dx: usize,
    dy: usize,
    wx: u32,
    wy: u32,
}

/// Fixed-point (8 fractional bits) bilinear samples of `(x, y)` in a `w × h` image;
/// `None` outside it.
#[inline(always)]
fn bilinear_at(x: f32, y: f32, w: usize, h: usize) -> Option<Taps> {
    if !(x >= 0.0 && y >= 0.0 && x <= w as f32 && y <= h as f32) {
        return None;
    }
    let fx = ((x - 0.5).clamp(0.0, (w - 1) as f32) * 256.0) as u32;
    let fy = ((y - 0.5).clamp(0.0, (h - 1) as f32) * 256.0) as u32;
    let (x0, y0) = ((fx >> 8) as usize, (fy >> 8) as usize);
    let dx = usize::from(x0 + 1 < w);
    let dy = usize::from(y0 + 1 < h);
    Some(Taps {
        x0,
        y0,
        dx,
        dy,
        wx: fx & 255,
        wy: fy & 255,
    })
}

#[inline(always)]
fn blend(a: u8, b: u8, c: u8, d: u8, wx: u32, wy: u32) -> u32 {
    // Three multiplies: lerp the rows (×256), then between them (×65536).
    let (wx, wy) = (wx as i32, wy as i32);
    let top = (i32::from(a) << 8) + (i32::from(b) - i32::from(a)) * wx;
    let bottom = (i32::from(c) << 8) + (i32::from(d) - i32::from(c)) * wx;
    (((top << 8) + (bottom - top) * wy + (1 << 15)) >> 16) as u32
}

struct RgbSource<'a> {
    data: &'a [u8],
    plane: Plane,
}

impl Source for RgbSource<'_> {
    fn plane(&self) -> Plane {
        self.plane
    }

    #[inline(always)]
    fn blend_taps(&self, taps: Taps, _x: usize, _y: usize) -> [u8; 3] {
        let a = taps.y0 * self.plane.stride + taps.x0 * 3;
        let b = a + taps.dx * 3;
        let c = a + taps.dy * self.plane.stride;
        let d = c + taps.dx * 3;
        let (p, wx, wy) = (self.data, taps.wx, taps.wy);
        let mut px = [0u8; 3];
        for (k, out) in px.iter_mut().enumerate() {
            // At most 255 by the weights.
            *out = blend(p[a + k], p[b + k], p[c + k], p[d + k], wx, wy) as u8;
        }
        px
    }

    #[inline(always)]
    fn sample_fixed(&self, fx: u32, fy: u32) -> [u8; 3] {
        let (x0, y0) = ((fx >> 8) as usize, (fy >> 8) as usize);
        let (wx, wy) = (fx & 255, fy & 255);
        let stride = self.plane.stride;
        let a = y0 * stride + x0 * 3;
        let top = &self.data[a..a + 6];
        let bottom = &self.data[a + stride..a + stride + 6];
        // At most 255 by the weights.
        [
            blend(top[0], top[3], bottom[0], bottom[3], wx, wy) as u8,
            blend(top[1], top[4], bottom[1], bottom[4], wx, wy) as u8,
            blend(top[2], top[5], bottom[2], bottom[5], wx, wy) as u8,
        ]
    }
}

struct Nv12Source<'a> {
    luma: &'a [u8],
    chroma: &'a [u8],
    /// Of the luma plane; the interleaved chroma plane has the same stride.
    plane: Plane,
}

impl Source for Nv12Source<'_> {
    fn plane(&self) -> Plane {
        self.plane
    }

    #[inline(always)]
    fn blend_taps(&self, taps: Taps, x: usize, y: usize) -> [u8; 3] {
        let a = taps.y0 * self.plane.stride + taps.x0;
        let c = a + taps.dy * self.plane.stride;
        let (l, dx) = (self.luma, taps.dx);
        let luma = blend(l[a], l[a + dx], l[c], l[c + dx], taps.wx, taps.wy) as i32;
        self.to_rgb(luma, x, y)
    }

    #[inline(always)]
    fn sample_fixed(&self, fx: u32, fy: u32) -> [u8; 3] {
        let (x0, y0) = ((fx >> 8) as usize, (fy >> 8) as usize);
        let stride = self.plane.stride;
        let a = y0 * stride + x0;
        let top = &self.luma[a..a + 2];
        let bottom = &self.luma[a + stride..a + stride + 2];
        let luma = blend(top[0], top[1], bottom[0], bottom[1], fx & 255, fy & 255) as i32;
        self.to_rgb(luma, ((fx + 128) >> 8) as usize, ((fy + 128) >> 8) as usize)
    }
}

impl Nv12Source<'_> {
    /// RGB of `luma` with the chroma of the 2×2 block holding pixel `(x, y)`.
    #[inline(always)]
    fn to_rgb(&self, luma: i32, x: usize, y: usize) -> [u8; 3] {
        let Plane { stride, w, h } = self.plane;
        let (cx, cy) = ((x / 2).min(w / 2 - 1), (y / 2).min(h / 2 - 1));
        let at = cy * stride + cx * 2;
        let cb = i32::from(self.chroma[at]) - 128;
        let cr = i32::from(self.chroma[at + 1]) - 128;
        // BT.601 full range, 16 fractional bits.
        let r = luma + ((91_881 * cr + (1 << 15)) >> 16);
        let g = luma - ((22_554 * cb + 46_802 * cr - (1 << 15)) >> 16);
        let b = luma + ((116_130 * cb + (1 << 15)) >> 16);
        // Clamped into u8 range.
        [
            r.clamp(0, 255) as u8,
            g.clamp(0, 255) as u8,
            b.clamp(0, 255) as u8,
        ]
    }
}

#[cfg(test)]
mod tests;
