//! Single-target tracking (DigiView SINGLE_TARGET_TRACKING).
//!
//! Two ways to follow a target, both ending in a **NED direction** (so the target
//! survives the vehicle turning) and a box in the physical camera's frame:
//!
//! - **Direction** ([`SttCommand::Direction`]): at the first update after the
//!   command, a luma template is cut from the [`WorkImage`] around the pixel where
//!   the direction projects in the physical camera; its side is
//!   [`zoom_box_fraction`] of the frame's shorter side (zoom 0: 30 %, zoom 10: 3 %,
//!   geometric in between). Every later frame it is searched by normalised
//!   cross-correlation in a window around the predicted position (the direction
//!   re-projected with the current pose, plus the target's own image motion of the
//!   last frame), the peak refined to sub-pixel by a parabola, and the direction set
//!   to the peak's ray. A peak below [`LOST_NCC`] unlocks (`locked = 0`, the last
//!   direction held, a twice as wide window searched); at [`REACQUIRE_NCC`] or more
//!   it locks again. A confident match (≥ [`TEMPLATE_UPDATE_NCC`]) blends 10 % of
//!   the new patch into the template so it follows slow changes of appearance. If
//!   the direction is not in the picture the template is taken once it comes in.
//! - **Detection** ([`SttCommand::Detection`]): follows the tracker's object with
//!   that id (an unknown id is refused, nothing changes). While the object is seen
//!   its box centre gives the direction; when it is not seen in a frame `locked` is
//!   0 and the direction held; once it is deleted it is gone for good (a later
//!   object with the same id is a different one).
//!
//! Disable forgets the target and records `cam` and `rel_frame`; NoOp changes
//! nothing at all (zoom, cam and frame of reference are not stored either).

use nalgebra::{Point2, Unit, Vector3};
use skymesh_ipc_types::vision::SttMode;
use skymesh_ipc_types::SttState;

use crate::detect::{PixelBox, WorkImage};
use crate::geometry::{CameraModel, CameraPose, Direction};
use crate::track::Track;

/// Below this normalised cross-correlation the target is lost.
pub const LOST_NCC: f32 = 0.5;
/// A lost target is locked again at this correlation or more.
pub const REACQUIRE_NCC: f32 = 0.6;
/// Matches at least this good refresh the template a little.
pub const TEMPLATE_UPDATE_NCC: f32 = 0.85;
const TEMPLATE_BLEND: f32 = 0.1;
/// Template samples per side at most (larger boxes are sampled sparsely).
const MAX_SAMPLES: usize = 24;
/// The smallest template side, work pixels.
const MIN_SIDE: usize = 5;
/// The largest zoom level.
pub const MAX_ZOOM: u16 = 10;

/// Tracking box side as a fraction of the frame's shorter side: `0.3 × 0.1^(zoom/10)`
/// (zoom 0 → 0.3, 5 → 0.095, 10 → 0.03).
pub fn zoom_box_fraction(zoom_level: u16) -> f64 {
    0.3 * 0.1f64.powf(f64::from(zoom_level.min(MAX_ZOOM)) / 10.0)
}

/// A command, as the pipeline resolved it (a nudge is turned into `Direction` by
/// the pipeline, which knows the named view's geometry).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SttCommand {
    Disable,
    /// Track whatever is in this NED direction.
    Direction(Unit<Vector3<f64>>),
    /// Follow this detection id.
    Detection(u8),
    NoOp,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SttError {
    #[error("detection {0} is not known")]
    UnknownDetection(u8),
    #[error("zoom level {0} is out of 0..=10")]
    Zoom(u16),
}

/// A luma template: `gw × gh` samples `step` work pixels apart around its centre,
/// zero-mean and unit-norm.
#[derive(Debug, Clone)]
struct Template {
    gw: usize,
    gh: usize,
    step: usize,
    /// Raw luma (for blending).
    raw: Vec<f32>,
    /// Normalised (zero mean, unit norm); empty if the patch is flat.
    norm: Vec<f32>,
}

impl Template {
    fn offsets(&self) -> impl Iterator<Item = (isize, isize)> + '_ {
        let (hw, hh) = (self.gw as isize / 2, self.gh as isize / 2);
        let s = self.step as isize;
        (0..self.gh as isize)
            .flat_map(move |j| (0..self.gw as isize).map(move |i| ((i - hw) * s, (j - hh) * s)))
    }

    /// Half extent in work pixels (how far samples reach from the centre).
    fn reach(&self) -> (isize, isize) {
        let s = self.step as isize;
        ((self.gw as isize / 2) * s, (self.gh as isize / 2) * s)
    }

    fn fits(&self, image: &WorkImage, cx: isize, cy: isize) -> bool {
        let (rx, ry) = self.reach();
        let (w, h) = (image.width() as isize, image.height() as isize);
        let s = self.step as isize;
        let x_hi = (self.gw as isize - 1 - self.gw as isize / 2) * s;
        let y_hi = (self.gh as isize - 1 - self.gh as isize / 2) * s;
        cx - rx >= 0 && cy - ry >= 0 && cx + x_hi < w && cy + y_hi < h
    }

    fn cut(image: &WorkImage, cx: isize, cy: isize, side: usize) -> Option<Template> {
        let side = side.max(MIN_SIDE);
        let step = side.div_ceil(MAX_SAMPLES).max(1);
        let g = (side / step).max(MIN_SIDE.min(side));
        let mut t = Template {
            gw: g,
            gh: g,
            step,
            raw: Vec::new(),
            norm: Vec::new(),
        };
        if !t.fits(image, cx, cy) {
            return None;
        }
        t.raw = t.sample(image, cx, cy);
        t.normalise();
        Some(t)
    }

    fn sample(&self, image: &WorkImage, cx: isize, cy: isize) -> Vec<f32> {
        let w = image.width() as isize;
        let luma = image.luma();
        self.offsets()
            .map(|(dx, dy)| f32::from(luma[((cy + dy) * w + cx + dx) as usize]))
            .collect()
    }

    fn normalise(&mut self) {
        let n = self.raw.len() as f32;
        let mean = self.raw.iter().sum::<f32>() / n;
        let var: f32 = self.raw.iter().map(|v| (v - mean) * (v - mean)).sum();
        self.norm = if var > 1e-3 * n {
            let k = var.sqrt();
            self.raw.iter().map(|v| (v - mean) / k).collect()
        } else {
            Vec::new()
        };
    }

    /// NCC of the template centred at `(cx, cy)` (−1..1; 0 for a flat patch).
    fn ncc(&self, image: &WorkImage, cx: isize, cy: isize) -> f32 {
        if self.norm.is_empty() {
            return 0.0;
        }
        let w = image.width() as isize;
        let luma = image.luma();
        let (mut s, mut s2, mut st) = (0.0f32, 0.0f32, 0.0f32);
        for ((dx, dy), t) in self.offsets().zip(&self.norm) {
            let v = f32::from(luma[((cy + dy) * w + cx + dx) as usize]);
            s += v;
            s2 += v * v;
            st += v * t;
        }
        let n = self.norm.len() as f32;
        let var = s2 - s * s / n;
        if var <= 1e-3 * n {
            return 0.0;
        }
        st / var.sqrt()
    }
}

#[derive(Debug)]
pub struct SingleTargetTracker {
    mode: SttMode,
    cam: u8,
    zoom_level: u16,
    rel_frame: u8,
    detection_id: u8,
    /// The target direction, NED.
    target: Option<Unit<Vector3<f64>>>,
    template: Option<Template>,
    locked: bool,
    confidence: f32,
    /// Source pixels.
    bbox: PixelBox,
    /// The target's own image motion in the last frame, work pixels.
    velocity: (f32, f32),
    /// Detection mode: the followed object was deleted.
    detection_gone: bool,
}

impl Default for SingleTargetTracker {
    fn default() -> Self {
        SingleTargetTracker {
            mode: SttMode::Disabled,
            cam: 0,
            zoom_level: 0,
            rel_frame: 0,
            detection_id: 255,
            target: None,
            template: None,
            locked: false,
            confidence: 0.0,
            bbox: PixelBox::default(),
            velocity: (0.0, 0.0),
            detection_gone: false,
        }
    }
}

impl SingleTargetTracker {
    /// Applies a command; `tracks` to check a detection id exists.
    pub fn command(
        &mut self,
        command: SttCommand,
        cam: u8,
        zoom_level: u16,
        rel_frame: u8,
        tracks: &[Track],
    ) -> Result<(), SttError> {
        match command {
            SttCommand::NoOp => return Ok(()),
            SttCommand::Disable => {
                *self = SingleTargetTracker {
                    cam,
                    rel_frame,
                    zoom_level: self.zoom_level,
                    ..SingleTargetTracker::default()
                };
                return Ok(());
            }
            SttCommand::Direction(_) | SttCommand::Detection(_) => {}
        }
        if zoom_level > MAX_ZOOM {
            return Err(SttError::Zoom(zoom_level));
        }
        let fresh = SingleTargetTracker {
            cam,
            zoom_level,
            rel_frame,
            ..SingleTargetTracker::default()
        };
        match command {
            SttCommand::Direction(dir) => {
                *self = SingleTargetTracker {
                    mode: SttMode::Direction,
                    target: Some(dir),
                    ..fresh
                };
            }
            SttCommand::Detection(id) => {
                if !tracks.iter().any(|t| t.id == id) {
                    return Err(SttError::UnknownDetection(id));
                }
                *self = SingleTargetTracker {
                    mode: SttMode::Detection,
                    detection_id: id,
                    // Until the next frame the last direction stands.
                    target: self.target,
                    ..fresh
                };
            }
            SttCommand::Disable | SttCommand::NoOp => {}
        }
        Ok(())
    }

    /// One frame of the physical camera.
    pub fn update(
        &mut self,
        image: &WorkImage,
        model: &CameraModel,
        pose: &CameraPose,
        tracks: &[Track],
    ) {
        match self.mode {
            SttMode::Disabled => {}
            SttMode::Detection => self.follow_detection(model, pose, tracks),
            SttMode::Direction => self.follow_template(image, model, pose),
        }
    }

    fn follow_detection(&mut self, model: &CameraModel, pose: &CameraPose, tracks: &[Track]) {
        if self.detection_gone {
            self.locked = false;
            return;
        }
        match tracks.iter().find(|t| t.id == self.detection_id) {
            None => {
                self.detection_gone = true;
                self.locked = false;
            }
            Some(t) if !t.seen => self.locked = false,
            Some(t) => {
                let (cx, cy) = t.bbox.center();
                let ray = model.pixel_to_ray(&Point2::new(f64::from(cx), f64::from(cy)));
                match ray.and_then(|r| Unit::try_new(pose.camera_to_ned(&r), 0.0)) {
                    Some(ned) => {
                        self.target = Some(ned);
                        self.bbox = t.bbox;
                        self.confidence = t.confidence;
                        self.locked = true;
                    }
                    None => self.locked = false,
                }
            }
        }
    }

    /// Source pixels per model pixel (the model may describe another resolution).
    fn source_per_model(image: &WorkImage, model: &CameraModel) -> (f64, f64) {
        let (sw, sh) = image.source_size();
        (
            f64::from(sw) / model.width(),
            f64::from(sh) / model.height(),
        )
    }

    /// The work-image position where `target` appears, continuous work pixels.
    fn project(
        image: &WorkImage,
        model: &CameraModel,
        pose: &CameraPose,
        target: &Unit<Vector3<f64>>,
    ) -> Option<(f32, f32)> {
        let p = model.ray_to_pixel(&pose.ned_to_camera(target))?;
        let (kx, ky) = Self::source_per_model(image, model);
        let s = f64::from(image.scale());
        let (x, y) = (p.x * kx / s, p.y * ky / s);
        (x.is_finite() && y.is_finite()).then_some((x as f32, y as f32))
    }

    fn side_work(&self, image: &WorkImage) -> usize {
        let (sw, sh) = image.source_size();
        let side = zoom_box_fraction(self.zoom_level) * f64::from(sw.min(sh));
        ((side / f64::from(image.scale())).round() as usize).max(MIN_SIDE)
    }

    fn set_box(&mut self, image: &WorkImage, cx: f32, cy: f32, side: usize) {
        let s = image.scale() as f32;
        let side = side as f32 * s;
        self.bbox = PixelBox {
            x: cx * s - side / 2.0,
            y: cy * s - side / 2.0,
            w: side,
            h: side,
        };
    }

    fn follow_template(&mut self, image: &WorkImage, model: &CameraModel, pose: &CameraPose) {
        let Some(target) = self.target else {
            self.locked = false;
            return;
        };
        let Some((px, py)) = Self::project(image, model, pose, &target) else {
            self.locked = false;
            return;
        };
        let side = self.side_work(image);
        // Continuous work coordinates: pixel i spans i..i+1, its centre is i + 0.5.
        let (ix, iy) = ((px - 0.5).round() as isize, (py - 0.5).round() as isize);
        let Some(template) = self.template.as_ref() else {
            // First frame after the command: take the template.
            match Template::cut(image, ix, iy, side) {
                Some(t) => {
                    self.template = Some(t);
                    self.locked = true;
                    self.confidence = 1.0;
                    self.velocity = (0.0, 0.0);
                    self.set_box(image, px, py, side);
                }
                None => self.locked = false,
            }
            return;
        };
        let (rx, ry) = template.reach();
        let base = (rx.max(ry) as f32).clamp(4.0, 16.0);
        let radius = if self.locked { base } else { 2.0 * base } as isize;
        let (vx, vy) = self.velocity;
        let (ex, ey) = (
            (px - 0.5 + vx).round() as isize,
            (py - 0.5 + vy).round() as isize,
        );
        let mut best: Option<(f32, isize, isize)> = None;
        for cy in ey - radius..=ey + radius {
            for cx in ex - radius..=ex + radius {
                if !template.fits(image, cx, cy) {
                    continue;
                }
                let c = template.ncc(image, cx, cy);
                if best.is_none_or(|b| c > b.0) {
                    best = Some((c, cx, cy));
                }
            }
        }
        let need = if self.locked { LOST_NCC } else { REACQUIRE_NCC };
        let Some((score, bx, by)) = best.filter(|b| b.0 >= need) else {
            self.locked = false;
            self.confidence = best.map_or(0.0, |b| b.0.max(0.0));
            self.velocity = (0.0, 0.0);
            return;
        };
        // Sub-pixel peak: a parabola through the neighbours on each axis.
        let refine = |lo: Option<f32>, hi: Option<f32>| match (lo, hi) {
            (Some(l), Some(h)) => {
                let d = l - 2.0 * score + h;
                if d < -1e-6 {
                    (0.5 * (l - h) / d).clamp(-0.5, 0.5)
                } else {
                    0.0
                }
            }
            _ => 0.0,
        };
        let at = |x: isize, y: isize| {
            template
                .fits(image, x, y)
                .then(|| template.ncc(image, x, y))
        };
        let fx = bx as f32 + 0.5 + refine(at(bx - 1, by), at(bx + 1, by));
        let fy = by as f32 + 0.5 + refine(at(bx, by - 1), at(bx, by + 1));
        let s = f64::from(image.scale());
        let (kx, ky) = Self::source_per_model(image, model);
        let pixel = Point2::new(f64::from(fx) * s / kx, f64::from(fy) * s / ky);
        let Some(ned) = model
            .pixel_to_ray(&pixel)
            .and_then(|r| Unit::try_new(pose.camera_to_ned(&r), 0.0))
        else {
            self.locked = false;
            return;
        };
        if score >= TEMPLATE_UPDATE_NCC {
            let patch = template.sample(image, bx, by);
            if let Some(t) = self.template.as_mut() {
                for (r, p) in t.raw.iter_mut().zip(patch) {
                    *r += TEMPLATE_BLEND * (p - *r);
                }
                t.normalise();
            }
        }
        let lim = radius as f32;
        self.velocity = ((fx - px).clamp(-lim, lim), (fy - py).clamp(-lim, lim));
        self.target = Some(ned);
        self.locked = true;
        self.confidence = score.clamp(0.0, 1.0);
        self.set_box(image, fx, fy, side);
    }

    /// The target's direction in NED, if tracking.
    pub fn target(&self) -> Option<Unit<Vector3<f64>>> {
        match self.mode {
            SttMode::Disabled => None,
            _ => self.target,
        }
    }

    /// Whether the target was found in the last frame.
    pub fn locked(&self) -> bool {
        self.locked
    }

    /// The bus state for `pose` (the current frame's camera pose).
    pub fn state(&self, pose: &CameraPose) -> SttState {
        let mut st = SttState {
            mode: self.mode.to_wire(),
            cam: self.cam,
            detection_id: if self.mode == SttMode::Detection {
                self.detection_id
            } else {
                255
            },
            locked: u8::from(self.locked && self.mode != SttMode::Disabled),
            rel_frame: self.rel_frame,
            zoom_level: self.zoom_level,
            confidence: self.confidence,
            bbox: self.bbox.to_wire(),
            ..SttState::default()
        };
        let dir = self
            .target()
            .and_then(|t| Direction::of_camera_ray(pose, &pose.ned_to_camera(&t)));
        if let Some(d) = dir {
            st.yaw_global_rad = d.global.yaw as f32;
            st.pitch_global_rad = d.global.pitch as f32;
            st.yaw_heading_rad = d.heading.yaw as f32;
            st.pitch_heading_rad = d.heading.pitch as f32;
            st.yaw_camera_rad = d.camera.yaw as f32;
            st.pitch_camera_rad = d.camera.pitch as f32;
        }
        st
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;
    use skymesh_ipc_types::frame::PixelFormat;
    use skymesh_ipc_types::FrameHeader;

    const W: u32 = 320;
    const H: u32 = 240;

    /// Static noise background (deterministic LCG) with a patterned bright square.
    fn frame(square: Option<(u32, u32)>) -> WorkImage {
        let mut px = vec![0u8; (W * H * 3) as usize];
        let mut seed = 12345u32;
        for y in 0..H {
            for x in 0..W {
                seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12345);
                let mut v = 90 + ((seed >> 16) % 40) as u8;
                if let Some((sx, sy)) = square {
                    if (sx..sx + 16).contains(&x) && (sy..sy + 16).contains(&y) {
                        v = if ((x - sx) / 4 + (y - sy) / 4) % 2 == 0 {
                            240
                        } else {
                            180
                        };
                    }
                }
                let i = ((y * W + x) * 3) as usize;
                px[i..i + 3].copy_from_slice(&[v, v, v]);
            }
        }
        let mut hd = FrameHeader::default();
        hd.set_geometry(PixelFormat::Rgb24, W, H, W * 3);
        WorkImage::from_frame(&hd, &px, W).unwrap()
    }

    fn setup() -> (CameraModel, CameraPose) {
        (
            CameraModel::from_hfov(f64::from(W), f64::from(H), 1.2).unwrap(),
            CameraPose::from_parts(UnitQuaternion::from_euler_angles(0.0, -0.3, 0.4), 0.2),
        )
    }

    fn dir_of(model: &CameraModel, pose: &CameraPose, x: f64, y: f64) -> Unit<Vector3<f64>> {
        Direction::of_pixel(model, pose, &Point2::new(x, y))
            .unwrap()
            .ned
    }

    fn pixel_of(model: &CameraModel, pose: &CameraPose, d: &Unit<Vector3<f64>>) -> Point2<f64> {
        model.ray_to_pixel(&pose.ned_to_camera(d)).unwrap()
    }

    #[test]
    fn zoom_mapping() {
        assert!((zoom_box_fraction(0) - 0.3).abs() < 1e-12);
        assert!((zoom_box_fraction(10) - 0.03).abs() < 1e-12);
        assert!(zoom_box_fraction(5) < zoom_box_fraction(4));
    }

    #[test]
    fn follows_loses_and_reacquires_a_moving_square() {
        let (model, pose) = setup();
        let mut stt = SingleTargetTracker::default();
        // Square at (100, 80)..(116, 96): centre (108, 88).
        let d = dir_of(&model, &pose, 108.0, 88.0);
        stt.command(SttCommand::Direction(d), 1, 6, 0, &[]).unwrap();
        let mut pos = (100u32, 80u32);
        stt.update(&frame(Some(pos)), &model, &pose, &[]);
        assert!(stt.locked());
        for _ in 0..15 {
            pos = (pos.0 + 3, pos.1 + 1);
            stt.update(&frame(Some(pos)), &model, &pose, &[]);
            assert!(stt.locked());
            let p = pixel_of(&model, &pose, &stt.target().unwrap());
            let truth = (pos.0 as f64 + 8.0, pos.1 as f64 + 8.0);
            assert!(
                (p.x - truth.0).abs() < 1.5 && (p.y - truth.1).abs() < 1.5,
                "{p:?} vs {truth:?}"
            );
            let st = stt.state(&pose);
            assert_eq!((st.locked, st.mode, st.cam, st.zoom_level), (1, 1, 1, 6));
            assert!(st.confidence > 0.8);
            let (bx, by) = (st.bbox[0] + st.bbox[2] / 2, st.bbox[1] + st.bbox[3] / 2);
            assert!((f64::from(bx) - truth.0).abs() <= 2.0, "{st:?}");
            assert!((f64::from(by) - truth.1).abs() <= 2.0, "{st:?}");
        }
        // Gone: unlocked, direction held.
        let held = stt.target().unwrap();
        for _ in 0..3 {
            stt.update(&frame(None), &model, &pose, &[]);
            assert!(!stt.locked());
            assert_eq!(stt.target().unwrap(), held);
            assert_eq!(stt.state(&pose).locked, 0);
        }
        // Back a little further along: found again.
        pos = (pos.0 + 6, pos.1 + 3);
        stt.update(&frame(Some(pos)), &model, &pose, &[]);
        assert!(stt.locked());
        let p = pixel_of(&model, &pose, &stt.target().unwrap());
        assert!((p.x - (pos.0 as f64 + 8.0)).abs() < 1.5, "{p:?}");
    }

    #[test]
    fn survives_a_vehicle_turn() {
        let (model, pose) = setup();
        let mut stt = SingleTargetTracker::default();
        let d = dir_of(&model, &pose, 160.0, 120.0);
        stt.command(SttCommand::Direction(d), 0, 6, 0, &[]).unwrap();
        stt.update(&frame(Some((152, 112))), &model, &pose, &[]);
        // The camera turns so that the (fixed) target moves 12 px left in the image:
        // the square is drawn where the old direction now projects.
        let turned = CameraPose::from_parts(
            pose.ned_from_camera() * UnitQuaternion::from_euler_angles(0.0, 0.0, 0.06),
            0.26,
        );
        let p = pixel_of(&model, &turned, &d);
        let sq = ((p.x - 8.0).round() as u32, (p.y - 8.0).round() as u32);
        stt.update(&frame(Some(sq)), &model, &turned, &[]);
        assert!(stt.locked());
        let q = pixel_of(&model, &turned, &stt.target().unwrap());
        assert!(
            (q.x - (f64::from(sq.0) + 8.0)).abs() < 1.5,
            "{q:?} vs {sq:?}"
        );
        assert!(
            (q.y - (f64::from(sq.1) + 8.0)).abs() < 1.5,
            "{q:?} vs {sq:?}"
        );
    }

    fn track(id: u8, x: f32, seen: bool) -> Track {
        Track {
            id,
            score: 100,
            age_frames: 3,
            bbox: PixelBox {
                x,
                y: 50.0,
                w: 20.0,
                h: 10.0,
            },
            confidence: 0.7,
            model: 0,
            overlay_slot: None,
            seen,
        }
    }

    #[test]
    fn detection_mode_follows_and_holds() {
        let (model, pose) = setup();
        let img = frame(None);
        let mut stt = SingleTargetTracker::default();
        let tracks = [track(5, 100.0, true), track(9, 200.0, true)];
        assert_eq!(
            stt.command(SttCommand::Detection(7), 0, 3, 1, &tracks),
            Err(SttError::UnknownDetection(7))
        );
        assert_eq!(stt.state(&pose).mode, 0);
        assert_eq!(
            stt.command(SttCommand::Detection(5), 0, 11, 1, &tracks),
            Err(SttError::Zoom(11))
        );
        stt.command(SttCommand::Detection(5), 2, 3, 1, &tracks)
            .unwrap();
        stt.update(&img, &model, &pose, &tracks);
        let st = stt.state(&pose);
        assert_eq!(
            (st.mode, st.detection_id, st.locked, st.rel_frame),
            (2, 5, 1, 1)
        );
        assert_eq!(st.bbox, [100, 50, 20, 10]);
        let p = pixel_of(&model, &pose, &stt.target().unwrap());
        assert!((p.x - 110.0).abs() < 1e-6 && (p.y - 55.0).abs() < 1e-6);
        // Camera-frame angles of that pixel.
        let ray = model.pixel_to_ray(&Point2::new(110.0, 55.0)).unwrap();
        assert!((f64::from(st.yaw_camera_rad) - ray.y.atan2(ray.x)).abs() < 1e-5);
        // Moves.
        let moved = [track(5, 130.0, true)];
        stt.update(&img, &model, &pose, &moved);
        let p = pixel_of(&model, &pose, &stt.target().unwrap());
        assert!((p.x - 140.0).abs() < 1e-6);
        // Not seen this frame: unlocked, held.
        stt.update(&img, &model, &pose, &[track(5, 160.0, false)]);
        assert_eq!(stt.state(&pose).locked, 0);
        let held = stt.target().unwrap();
        // Deleted: unlocked for good, even if the id comes back for something else.
        stt.update(&img, &model, &pose, &[]);
        stt.update(&img, &model, &pose, &[track(5, 10.0, true)]);
        assert_eq!(stt.state(&pose).locked, 0);
        assert_eq!(stt.target().unwrap(), held);
    }

    #[test]
    fn disable_clears_and_noop_changes_nothing() {
        let (model, pose) = setup();
        let mut stt = SingleTargetTracker::default();
        let d = dir_of(&model, &pose, 108.0, 88.0);
        stt.command(SttCommand::Direction(d), 1, 4, 2, &[]).unwrap();
        stt.update(&frame(Some((100, 80))), &model, &pose, &[]);
        let before = stt.state(&pose);
        stt.command(SttCommand::NoOp, 3, 99, 0, &[]).unwrap();
        assert_eq!(stt.state(&pose), before);
        stt.command(SttCommand::Disable, 3, 0, 0, &[]).unwrap();
        let st = stt.state(&pose);
        assert_eq!(
            (st.mode, st.locked, st.cam, st.detection_id),
            (0, 0, 3, 255)
        );
        assert_eq!(st.bbox, [0; 4]);
        assert_eq!(st.yaw_global_rad, 0.0);
        assert!(stt.target().is_none());
        stt.update(&frame(Some((100, 80))), &model, &pose, &[]);
        assert_eq!(stt.state(&pose).locked, 0);
    }

    #[test]
    fn direction_out_of_view_waits() {
        let (model, pose) = setup();
        let mut stt = SingleTargetTracker::default();
        // Behind the camera.
        let back = Unit::new_normalize(-pose.camera_to_ned(&Vector3::x()));
        stt.command(SttCommand::Direction(back), 0, 5, 0, &[])
            .unwrap();
        stt.update(&frame(None), &model, &pose, &[]);
        assert!(!stt.locked());
        assert_eq!(stt.target(), Some(back));
    }
}
