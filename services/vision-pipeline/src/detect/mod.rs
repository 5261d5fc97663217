//! Detection (DigiView's "models") on a reduced work image.
//!
//! Every frame is reduced to a [`WorkImage`] once: box-averaged by an integer factor
//! to at most `work_width` columns, as luma (BT.601) plus the two chroma channels
//! (Cb, Cr), with an integral image of each so a local background (the mean of a
//! square window) costs four reads per pixel. The scan model searches all of it, the
//! track model ([`Detector::verify`]) looks near known objects, the single-target
//! tracker matches templates in its luma.
//!
//! # Models ([`MODELS`])
//!
//! - **`contrast-blob`**: a pixel's *strength* is the larger of its luma contrast
//!   `|Y − mean Y|` and its colour contrast `|Cb − mean Cb| + |Cr − mean Cr|` against
//!   the mean of a square window around it (side ≈ 1/8 of the work image's long
//!   side, see [`background_radius`]), each divided by its threshold. Thresholds are
//!   adaptive: `k × σ` where σ is a robust noise estimate of that contrast over the
//!   whole image (1.4826 × median, from a histogram), but never below a floor
//!   ([`LUMA_FLOOR`], [`CHROMA_FLOOR`]) so a flat image does not turn its quantisation
//!   noise into objects. Pixels with strength ≥ 1 form 8-connected components (no
//!   hysteresis: growing through weaker pixels glued targets to the grid lines they
//!   sit on, which the shape filter then rejected). A component is an object if its area is within
//!   `min_area_px ..= max_area_frac × frame` (source pixels) and it is compact: the
//!   ratio of its principal axes (from second moments, so rotation does not matter)
//!   ≤ [`MAX_ASPECT`] and it fills ≥ [`MIN_FILL`] of its box, which rejects lines,
//!   edges, roads and their fragments (the synthetic scene's grid lines). Confidence
//!   is `1 − 0.6 / mean strength` (0.4 at the threshold, 0.8 at three times it),
//!   lowered for components smaller than 4 × `min_area_px`.
//!
//!   Limits: it finds things that differ from their surroundings in brightness or
//!   colour and are clearly smaller than the background window (larger ones are
//!   partly absorbed into their own background); camouflaged objects, objects in
//!   clutter with as much contrast as they have, and touching objects (one
//!   component) are missed or merged. It knows nothing of object classes.
//! - **`motion-bg`**: a running-average background (per work pixel, Y/Cb/Cr,
//!   `α` = [`MOTION_ALPHA`], slower where the pixel is foreground) and the same
//!   strength → components → filters on `|frame − background|`. It needs
//!   [`MOTION_WARMUP_FRAMES`] frames after start or a change of image size before it
//!   reports anything, and it only makes sense for a camera that does not move (a
//!   moving camera makes the whole ground "move"). Its background is updated once per
//!   work image, by whichever of `scan` / `verify` sees the image first.
//!
//! Boxes are returned in source-frame pixels (continuous coordinates: work pixel
//! `i` spans source `i·s .. (i+1)·s`).

use std::sync::atomic::{AtomicU64, Ordering};

use skymesh_ipc_types::frame::PixelFormat;
use skymesh_ipc_types::FrameHeader;

/// The detector models this pipeline has (DigiView MODEL replies, AI's model names).
pub const MODELS: [&str; 2] = ["contrast-blob", "motion-bg"];

/// Luma contrast below this (0–255 levels) never makes a pixel an object.
pub const LUMA_FLOOR: f32 = 30.0;
/// Colour contrast (`|ΔCb| + |ΔCr|`) below this never makes a pixel an object.
pub const CHROMA_FLOOR: f32 = 36.0;
/// Threshold = `NOISE_K` × robust noise estimate (when above the floor).
pub const NOISE_K: f32 = 5.0;
/// Major / minor principal axis of an object (second moments), at most.
pub const MAX_ASPECT: f32 = 3.0;
/// Object pixels / box pixels, at least.
pub const MIN_FILL: f32 = 0.25;
/// motion-bg: background learning rate per frame (background pixels).
pub const MOTION_ALPHA: f32 = 0.05;
/// motion-bg: frames needed after a (re)start before anything is reported.
pub const MOTION_WARMUP_FRAMES: u32 = 8;
/// motion-bg floors (frame − background contrast).
const MOTION_LUMA_FLOOR: f32 = 20.0;
const MOTION_CHROMA_FLOOR: f32 = 24.0;

static NEXT_IMAGE_ID: AtomicU64 = AtomicU64::new(1);

/// A box in source-frame pixels (continuous coordinates, top-left + size).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PixelBox {
    pub x: f32,
    pub y: f32,
    pub w: f32,
    pub h: f32,
}

impl PixelBox {
    pub fn center(&self) -> (f32, f32) {
        (self.x + self.w / 2.0, self.y + self.h / 2.0)
    }
    /// Intersection over union, 0..1 (0 for empty or non-finite boxes).
    pub fn iou(&self, other: &PixelBox) -> f32 {
        let ix = (self.x + self.w).min(other.x + other.w) - self.x.max(other.x);
        let iy = (self.y + self.h).min(other.y + other.h) - self.y.max(other.y);
        // Written so that NaN anywhere gives 0.
        let overlaps = ix > 0.0 && iy > 0.0;
        let inter = ix * iy;
        let union = self.w * self.h + other.w * other.h - inter;
        if overlaps && union.is_finite() && union > 0.0 {
            (inter / union).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }
    /// `[x, y, w, h]` rounded and clamped to u16 for the bus (NaN → 0).
    pub fn to_wire(&self) -> [u16; 4] {
        // `as` saturates for floats (NaN → 0), after rounding.
        let c = |v: f32| v.round().clamp(0.0, f32::from(u16::MAX)) as u16;
        [c(self.x), c(self.y), c(self.w), c(self.h)]
    }
}

/// One detector hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawDetection {
    pub bbox: PixelBox,
    /// 0..1.
    pub confidence: f32,
    /// Index into [`MODELS`].
    pub model: u8,
}

#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    #[error("unknown detector model `{0}` (have: contrast-blob, motion-bg)")]
    UnknownModel(String),
    #[error("frame not usable: {0}")]
    Frame(String),
}

/// Detector tuning (config `[detector]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorConfig {
    /// Columns of the work image (the frame is reduced by an integer factor to at most this).
    pub work_width: u32,
    /// Smallest object, source pixels of area.
    pub min_area_px: f32,
    /// Largest object, fraction of the frame area.
    pub max_area_frac: f32,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        DetectorConfig {
            work_width: 480,
            min_area_px: 40.0,
            max_area_frac: 0.05,
        }
    }
}

/// Half-side of the background window, work pixels: 1/16 of the long side (a window
/// of about 1/8 of the image), 4..=48.
pub fn background_radius(width: usize, height: usize) -> usize {
    (width.max(height) / 16).clamp(4, 48)
}

/// A frame reduced for detection.
#[derive(Debug)]
pub struct WorkImage {
    id: u64,
    width: usize,
    height: usize,
    scale: u32,
    source_width: u32,
    source_height: u32,
    luma: Vec<u8>,
    cb: Vec<u8>,
    cr: Vec<u8>,
    /// Integral images, `(width + 1) × (height + 1)`.
    int_y: Vec<u32>,
    int_cb: Vec<u32>,
    int_cr: Vec<u32>,
    radius: usize,
    /// contrast-blob thresholds (luma, chroma).
    thresholds: (f32, f32),
}

impl WorkImage {
    /// From a frame (RGB24 or NV12). The header is checked against the slice: an
    /// unknown format, impossible geometry or too short a slice is
    /// [`DetectError::Frame`], never a panic.
    pub fn from_frame(
        header: &FrameHeader,
        pixels: &[u8],
        work_width: u32,
    ) -> Result<WorkImage, DetectError> {
        let format = header
            .pixel_format()
            .map_err(|e| DetectError::Frame(e.to_string()))?;
        let (w, h, stride) = (header.width, header.height, header.stride);
        let needed = format.frame_len(w, h, stride).ok_or_else(|| {
            DetectError::Frame(format!(
                "impossible geometry {w}x{h} stride {stride} for {format}"
            ))
        })?;
        if (pixels.len() as u64) < needed {
            return Err(DetectError::Frame(format!(
                "{} bytes of pixels, {format} {w}x{h} stride {stride} needs {needed}",
                pixels.len()
            )));
        }
        if work_width == 0 {
            return Err(DetectError::Frame("work width 0".into()));
        }
        let scale = w.div_ceil(work_width).max(1);
        let (ww, wh) = ((w / scale) as usize, (h / scale) as usize);
        if ww == 0 || wh == 0 {
            return Err(DetectError::Frame(format!(
                "{w}x{h} is smaller than the reduction factor {scale}"
            )));
        }
        let n = ww * wh;
        let mut img = WorkImage {
            id: NEXT_IMAGE_ID.fetch_add(1, Ordering::Relaxed),
            width: ww,
            height: wh,
            scale,
            source_width: w,
            source_height: h,
            luma: vec![0; n],
            cb: vec![0; n],
            cr: vec![0; n],
            int_y: Vec::new(),
            int_cb: Vec::new(),
            int_cr: Vec::new(),
            radius: background_radius(ww, wh),
            thresholds: (LUMA_FLOOR, CHROMA_FLOOR),
        };
        let s = scale as usize;
        let stride = stride as usize;
        match format {
            PixelFormat::Rgb24 => img.reduce_rgb(pixels, stride, s),
            PixelFormat::Nv12 => img.reduce_nv12(pixels, stride, h as usize, s),
        }
        img.int_y = integral(&img.luma, ww, wh);
        img.int_cb = integral(&img.cb, ww, wh);
        img.int_cr = integral(&img.cr, ww, wh);
        img.thresholds = img.estimate_thresholds();
        Ok(img)
    }

    fn reduce_rgb(&mut self, pixels: &[u8], stride: usize, s: usize) {
        let ww = self.width;
        let mut acc = vec![0u32; ww * 3];
        let n = (s * s) as i64;
        for wy in 0..self.height {
            acc.fill(0);
            for sy in wy * s..(wy + 1) * s {
                let row = &pixels[sy * stride..sy * stride + ww * s * 3];
                for (block, a) in row.chunks_exact(s * 3).zip(acc.chunks_exact_mut(3)) {
                    for px in block.chunks_exact(3) {
                        a[0] += u32::from(px[0]);
                        a[1] += u32::from(px[1]);
                        a[2] += u32::from(px[2]);
                    }
                }
            }
            for (wx, a) in acc.chunks_exact(3).enumerate() {
                let (r, g, b) = (i64::from(a[0]), i64::from(a[1]), i64::from(a[2]));
                let d = 256 * n;
                let i = wy * ww + wx;
                self.luma[i] = ((77 * r + 150 * g + 29 * b) / d).clamp(0, 255) as u8;
                self.cb[i] = (128 + (-43 * r - 85 * g + 128 * b) / d).clamp(0, 255) as u8;
                self.cr[i] = (128 + (128 * r - 107 * g - 21 * b) / d).clamp(0, 255) as u8;
            }
        }
    }

    fn reduce_nv12(&mut self, pixels: &[u8], stride: usize, height: usize, s: usize) {
        let ww = self.width;
        let mut acc = vec![0u32; ww];
        let n = (s * s) as u32;
        for wy in 0..self.height {
            acc.fill(0);
            for sy in wy * s..(wy + 1) * s {
                let row = &pixels[sy * stride..sy * stride + ww * s];
                for (block, a) in row.chunks_exact(s).zip(acc.iter_mut()) {
                    *a += block.iter().map(|&v| u32::from(v)).sum::<u32>();
                }
            }
            for (wx, a) in acc.iter().enumerate() {
                self.luma[wy * ww + wx] = (a / n) as u8;
            }
        }
        // Chroma: one CbCr pair per 2×2 source block; a work pixel averages the pairs
        // its source block touches (at least one).
        let chroma = &pixels[stride * height..];
        let span = |i: usize| {
            let a = i * s / 2;
            (a, ((i + 1) * s / 2).max(a + 1))
        };
        for wy in 0..self.height {
            let (y0, y1) = span(wy);
            for wx in 0..ww {
                let (x0, x1) = span(wx);
                let (mut sb, mut sr, mut k) = (0u32, 0u32, 0u32);
                for cy in y0..y1 {
                    let row = &chroma[cy * stride..];
                    for cx in x0..x1 {
                        sb += u32::from(row[2 * cx]);
                        sr += u32::from(row[2 * cx + 1]);
                        k += 1;
                    }
                }
                self.cb[wy * ww + wx] = (sb / k) as u8;
                self.cr[wy * ww + wx] = (sr / k) as u8;
            }
        }
    }

    /// Source pixels per work pixel.
    pub fn scale(&self) -> u32 {
        self.scale
    }
    /// Work image columns.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Work image rows.
    pub fn height(&self) -> usize {
        self.height
    }
    /// The frame's size.
    pub fn source_size(&self) -> (u32, u32) {
        (self.source_width, self.source_height)
    }
    /// Luma, row-major, `width()` per row.
    pub fn luma(&self) -> &[u8] {
        &self.luma
    }
    /// The contrast-blob thresholds in use for this image: (luma, colour).
    pub fn thresholds(&self) -> (f32, f32) {
        self.thresholds
    }
    /// Source-pixel box of work pixels `x0..x1` × `y0..y1`.
    pub fn to_source(&self, x0: usize, y0: usize, x1: usize, y1: usize) -> PixelBox {
        let s = self.scale as f32;
        PixelBox {
            x: x0 as f32 * s,
            y: y0 as f32 * s,
            w: (x1 - x0) as f32 * s,
            h: (y1 - y0) as f32 * s,
        }
    }

    /// Window mean of the three channels around `(x, y)`, clipped to the image.
    #[inline]
    fn background(&self, x: usize, y: usize) -> (f32, f32, f32) {
        let r = self.radius;
        let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(self.width));
        let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(self.height));
        let n = ((x1 - x0) * (y1 - y0)) as f32;
        let stride = self.width + 1;
        let sum = |t: &[u32]| {
            let a = t[y1 * stride + x1].wrapping_add(t[y0 * stride + x0]);
            let b = t[y0 * stride + x1].wrapping_add(t[y1 * stride + x0]);
            a.wrapping_sub(b) as f32 / n
        };
        (sum(&self.int_y), sum(&self.int_cb), sum(&self.int_cr))
    }

    /// Luma and colour contrast of pixel `(x, y)` against its background.
    #[inline]
    fn contrast(&self, x: usize, y: usize) -> (f32, f32) {
        let (my, mb, mr) = self.background(x, y);
        let i = y * self.width + x;
        (
            (f32::from(self.luma[i]) - my).abs(),
            (f32::from(self.cb[i]) - mb).abs() + (f32::from(self.cr[i]) - mr).abs(),
        )
    }

    fn estimate_thresholds(&self) -> (f32, f32) {
        let mut hy = [0u32; 256];
        let mut hc = [0u32; 512];
        for y in (0..self.height).step_by(2) {
            for x in (0..self.width).step_by(2) {
                let (dy, dc) = self.contrast(x, y);
                hy[(dy as usize).min(255)] += 1;
                hc[(dc as usize).min(511)] += 1;
            }
        }
        (
            (NOISE_K * robust_sigma(&hy)).max(LUMA_FLOOR),
            (NOISE_K * robust_sigma(&hc)).max(CHROMA_FLOOR),
        )
    }
}

/// 1.4826 × the median of a histogram of absolute deviations (≥ 1).
fn robust_sigma(hist: &[u32]) -> f32 {
    let total: u64 = hist.iter().map(|&c| u64::from(c)).sum();
    let mut seen = 0u64;
    for (v, &c) in hist.iter().enumerate() {
        seen += u64::from(c);
        if seen * 2 >= total {
            return (1.4826 * (v as f32 + 0.5)).max(1.0);
        }
    }
    1.0
}

fn integral(channel: &[u8], w: usize, h: usize) -> Vec<u32> {
    let stride = w + 1;
    let mut t = vec![0u32; stride * (h + 1)];
    for y in 0..h {
        let mut row_sum = 0u32;
        for x in 0..w {
            row_sum += u32::from(channel[y * w + x]);
            t[(y + 1) * stride + x + 1] = t[y * stride + x + 1] + row_sum;
        }
    }
    t
}

/// A rectangle of work pixels, `x0..x1` × `y0..y1`.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

/// One connected component.
#[derive(Debug, Clone, Copy)]
struct Component {
    area: usize,
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
    strength_sum: f32,
    /// Σx, Σy, Σx², Σy², Σxy relative to the first pixel (second moments).
    moments: [f64; 5],
}

impl Component {
    /// Major / minor axis ratio of the pixel distribution.
    fn elongation(&self) -> f32 {
        let n = self.area as f64;
        let [sx, sy, sxx, syy, sxy] = self.moments;
        let (mx, my) = (sx / n, sy / n);
        // Each pixel is a unit square: add its own variance 1/12 on both axes.
        let cxx = sxx / n - mx * mx + 1.0 / 12.0;
        let cyy = syy / n - my * my + 1.0 / 12.0;
        let cxy = sxy / n - mx * my;
        let tr = cxx + cyy;
        let disc = ((cxx - cyy) * (cxx - cyy) + 4.0 * cxy * cxy).sqrt();
        let (l1, l2) = ((tr + disc) / 2.0, ((tr - disc) / 2.0).max(1e-9));
        (l1 / l2).sqrt() as f32
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Model {
    ContrastBlob,
    MotionBg,
}

/// motion-bg state.
#[derive(Debug, Default)]
struct Background {
    width: usize,
    height: usize,
    frames: u32,
    last_image: u64,
    /// Y, Cb, Cr per pixel.
    mean: Vec<[f32; 3]>,
}

/// One detector model with its state (the motion model keeps a background).
#[derive(Debug)]
pub struct Detector {
    model: Model,
    config: DetectorConfig,
    background: Background,
    /// Per-pixel strength (contrast / threshold) of the last segmented region.
    strength: Vec<f32>,
    /// Flood-fill marks (cleared again over the labelled rectangle).
    visited: Vec<bool>,
    stack: Vec<(usize, usize)>,
    components: Vec<Component>,
}

impl Detector {
    pub fn new(model: &str, config: DetectorConfig) -> Result<Detector, DetectError> {
        let model = match model {
            "contrast-blob" => Model::ContrastBlob,
            "motion-bg" => Model::MotionBg,
            other => return Err(DetectError::UnknownModel(other.to_string())),
        };
        Ok(Detector {
            model,
            config,
            background: Background::default(),
            strength: Vec::new(),
            visited: Vec::new(),
            stack: Vec::new(),
            components: Vec::new(),
        })
    }
    /// Index into [`MODELS`].
    pub fn model(&self) -> u8 {
        match self.model {
            Model::ContrastBlob => 0,
            Model::MotionBg => 1,
        }
    }
    /// Every object in the image.
    pub fn scan(&mut self, image: &WorkImage) -> Vec<RawDetection> {
        let rect = Rect {
            x0: 0,
            y0: 0,
            x1: image.width,
            y1: image.height,
        };
        if !self.segment(image, rect) {
            return Vec::new();
        }
        let comps = std::mem::take(&mut self.components);
        let out = comps.iter().filter_map(|c| self.accept(image, c)).collect();
        self.components = comps;
        out
    }
    /// Looks for the object last seen at `around` in its neighbourhood (a window
    /// twice its size, at least 3 work pixels around it): the best component there,
    /// preferring confidence and overlap with `around`.
    pub fn verify(&mut self, image: &WorkImage, around: &PixelBox) -> Option<RawDetection> {
        let s = image.scale as f32;
        let (cx, cy) = around.center();
        let hw = (around.w.max(0.0) / s).max(3.0) + 3.0;
        let hh = (around.h.max(0.0) / s).max(3.0) + 3.0;
        let (cx, cy) = (cx / s, cy / s);
        if !(cx.is_finite() && cy.is_finite() && hw.is_finite() && hh.is_finite()) {
            return None;
        }
        let clip = |v: f32, max: usize| (v.max(0.0) as usize).min(max);
        let rect = Rect {
            x0: clip(cx - hw, image.width),
            y0: clip(cy - hh, image.height),
            x1: clip((cx + hw).ceil(), image.width),
            y1: clip((cy + hh).ceil(), image.height),
        };
        if rect.x0 >= rect.x1 || rect.y0 >= rect.y1 || !self.segment(image, rect) {
            return None;
        }
        let comps = std::mem::take(&mut self.components);
        let best = comps
            .iter()
            .filter_map(|c| self.accept(image, c))
            .max_by(|a, b| {
                let ka = a.confidence + a.bbox.iou(around);
                let kb = b.confidence + b.bbox.iou(around);
                ka.total_cmp(&kb)
            });
        self.components = comps;
        best
    }

    /// Fills `self.components` with the components of `rect`; false while the
    /// motion model warms up.
    fn segment(&mut self, image: &WorkImage, rect: Rect) -> bool {
        let n = image.width * image.height;
        if self.strength.len() != n {
            self.strength = vec![0.0; n];
            self.visited = vec![false; n];
        }
        match self.model {
            Model::ContrastBlob => {
                let (ty, tc) = image.thresholds;
                for y in rect.y0..rect.y1 {
                    for x in rect.x0..rect.x1 {
                        let (dy, dc) = image.contrast(x, y);
                        self.strength[y * image.width + x] = (dy / ty).max(dc / tc);
                    }
                }
            }
            Model::MotionBg => {
                self.update_background(image);
                if self.background.frames < MOTION_WARMUP_FRAMES {
                    return false;
                }
            }
        }
        self.label(image, rect);
        true
    }

    /// motion-bg: strength of the whole image against the background, then the
    /// background learns the image; once per image.
    fn update_background(&mut self, image: &WorkImage) {
        let bg = &mut self.background;
        if bg.last_image == image.id {
            return;
        }
        bg.last_image = image.id;
        let n = image.width * image.height;
        if bg.width != image.width || bg.height != image.height || bg.mean.len() != n {
            bg.width = image.width;
            bg.height = image.height;
            bg.frames = 1;
            bg.mean = (0..n)
                .map(|i| {
                    [
                        f32::from(image.luma[i]),
                        f32::from(image.cb[i]),
                        f32::from(image.cr[i]),
                    ]
                })
                .collect();
            self.strength.fill(0.0);
            return;
        }
        let mut hy = [0u32; 256];
        let mut hc = [0u32; 512];
        for (i, m) in bg.mean.iter().enumerate().step_by(3) {
            let dy = (f32::from(image.luma[i]) - m[0]).abs();
            let dc = (f32::from(image.cb[i]) - m[1]).abs() + (f32::from(image.cr[i]) - m[2]).abs();
            hy[(dy as usize).min(255)] += 1;
            hc[(dc as usize).min(511)] += 1;
        }
        // While warming up the background is the plain mean of the frames so far.
        let alpha = MOTION_ALPHA.max(1.0 / (bg.frames as f32 + 1.0));
        let ty = (NOISE_K * robust_sigma(&hy)).max(MOTION_LUMA_FLOOR);
        let tc = (NOISE_K * robust_sigma(&hc)).max(MOTION_CHROMA_FLOOR);
        for (i, m) in bg.mean.iter_mut().enumerate() {
            let v = [
                f32::from(image.luma[i]),
                f32::from(image.cb[i]),
                f32::from(image.cr[i]),
            ];
            let dy = (v[0] - m[0]).abs();
            let dc = (v[1] - m[1]).abs() + (v[2] - m[2]).abs();
            let s = (dy / ty).max(dc / tc);
            self.strength[i] = s;
            // Foreground learns 10× slower so a stopped object fades in, not at once.
            let a = if s >= 1.0 { alpha * 0.1 } else { alpha };
            for k in 0..3 {
                m[k] += a * (v[k] - m[k]);
            }
        }
        bg.frames = bg.frames.saturating_add(1);
    }

    /// 8-connected components of the pixels of `rect` with strength ≥ 1.
    fn label(&mut self, image: &WorkImage, rect: Rect) {
        self.components.clear();
        let w = image.width;
        for y in rect.y0..rect.y1 {
            for x in rect.x0..rect.x1 {
                let i = y * w + x;
                if self.strength[i] < 1.0 || self.visited[i] {
                    continue;
                }
                self.visited[i] = true;
                self.stack.clear();
                self.stack.push((x, y));
                let mut c = Component {
                    area: 0,
                    x0: x,
                    y0: y,
                    x1: x + 1,
                    y1: y + 1,
                    strength_sum: 0.0,
                    moments: [0.0; 5],
                };
                while let Some((px, py)) = self.stack.pop() {
                    c.area += 1;
                    c.strength_sum += self.strength[py * w + px].min(4.0);
                    let (dx, dy) = (px as f64 - x as f64, py as f64 - y as f64);
                    let m = &mut c.moments;
                    m[0] += dx;
                    m[1] += dy;
                    m[2] += dx * dx;
                    m[3] += dy * dy;
                    m[4] += dx * dy;
                    c.x0 = c.x0.min(px);
                    c.x1 = c.x1.max(px + 1);
                    c.y0 = c.y0.min(py);
                    c.y1 = c.y1.max(py + 1);
                    for ny in py.saturating_sub(1).max(rect.y0)..(py + 2).min(rect.y1) {
                        for nx in px.saturating_sub(1).max(rect.x0)..(px + 2).min(rect.x1) {
                            let j = ny * w + nx;
                            if !self.visited[j] && self.strength[j] >= 1.0 {
                                self.visited[j] = true;
                                self.stack.push((nx, ny));
                            }
                        }
                    }
                }
                self.components.push(c);
            }
        }
        // The next call must see fresh marks: clear ours.
        for y in rect.y0..rect.y1 {
            self.visited[y * w + rect.x0..y * w + rect.x1].fill(false);
        }
    }

    /// The component as a detection, if it passes the area and shape filters.
    fn accept(&self, image: &WorkImage, c: &Component) -> Option<RawDetection> {
        let s2 = (image.scale * image.scale) as f32;
        let area_src = c.area as f32 * s2;
        let (src_w, src_h) = image.source_size();
        let max_area = self.config.max_area_frac * src_w as f32 * src_h as f32;
        if area_src < self.config.min_area_px || area_src > max_area {
            return None;
        }
        let (bw, bh) = ((c.x1 - c.x0) as f32, (c.y1 - c.y0) as f32);
        let max_aspect = match self.model {
            Model::ContrastBlob => MAX_ASPECT,
            Model::MotionBg => 2.0 * MAX_ASPECT,
        };
        if c.elongation() > max_aspect || (c.area as f32) < MIN_FILL * bw * bh {
            return None;
        }
        let mean = c.strength_sum / c.area as f32;
        let contrast = (1.0 - 0.6 / mean.max(0.6)).clamp(0.0, 1.0);
        let size = (area_src / (4.0 * self.config.min_area_px.max(1.0)))
            .sqrt()
            .min(1.0);
        Some(RawDetection {
            bbox: image.to_source(c.x0, c.y0, c.x1, c.y1),
            confidence: (contrast * (0.6 + 0.4 * size)).clamp(0.0, 1.0),
            model: self.model(),
        })
    }
}

#[cfg(test)]
mod tests;
