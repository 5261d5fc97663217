//! One frame through the pipeline: work image, detection and tracking,
//! geolocation, single-target tracking, aiming the views, rendering the output in
//! place, capture hooks, state.

use std::time::Instant;

use nalgebra::{Point2, UnitQuaternion};
use skymesh_ipc_types::{
    CameraIntrinsics, FrameHeader, LensModel, PixelFormat, VisionDetection, VISION_MAX_CAMS,
};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::FramePublisher;

use crate::capture::CaptureError;
use crate::detect::{PixelBox, WorkImage};
use crate::geometry::{intersect_ground, CameraModel, CameraPose, Direction, GeoPosition};
use crate::ipc::Sinks;
use crate::layout::{self};
use crate::render::{TileSpec, ViewSpec};
use crate::views::AimContext;

use super::pipeline::Pipeline;
use super::FRESH;

impl Pipeline {
    pub(super) fn bad(&mut self, i: usize, reason: &'static str, error: &dyn std::fmt::Display) {
        let now = Instant::now();
        let s = &mut self.streams[i];
        s.last_frame = Some(now);
        s.bad_since.get_or_insert(now);
        self.metrics.streams[i].bad(reason);
        if let Some(hidden) = self.warn.allow(reason, now) {
            tracing::warn!(stream = %s.name, reason, error = %error, hidden, "frame not usable");
        }
    }

    pub(super) fn frame(
        &mut self,
        i: usize,
        header: &FrameHeader,
        pixels: &[u8],
        output: &mut FramePublisher,
        sinks: &mut Sinks,
    ) -> anyhow::Result<()> {
        let began = Instant::now();
        // A frame the camera made before the pipeline (re)subscribed (the topic's
        // history) is not news: skipped, counted dropped.
        let age_ns = monotonic_ns().saturating_sub(header.capture_mono_ns);
        if header.capture_mono_ns > 0 && age_ns > FRESH.as_nanos() as u64 {
            self.streams[i].frames_dropped += 1;
            self.metrics.streams[i].dropped.inc();
            return Ok(());
        }
        let model = match CameraModel::from_header(header) {
            Ok(m) => m,
            Err(e) => {
                self.bad(i, "intrinsics", &e);
                return Ok(());
            }
        };
        let pose = match CameraPose::from_capture(header) {
            Ok(p) => p,
            Err(e) => {
                self.bad(i, "pose", &e);
                return Ok(());
            }
        };
        let work = match WorkImage::from_frame(header, pixels, self.settings.detector.work_width) {
            Ok(w) => w,
            Err(e) => {
                self.bad(i, "work_image", &e);
                return Ok(());
            }
        };
        let position = GeoPosition::from_capture(&header.pose).ok();
        // Height above the ground under the vehicle: its height above home.
        let height = self
            .vehicle
            .filter(|v| v.position_valid != 0 && v.alt_rel_m.is_finite())
            .map(|v| f64::from(v.alt_rel_m));
        let vehicle_attitude = self
            .vehicle
            .filter(|v| v.attitude_valid != 0)
            .and_then(|v| {
                let q = v.attitude_q.map(f64::from);
                let q = nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
                let n = q.norm();
                (n.is_finite() && (n - 1.0).abs() < 0.01)
                    .then(|| UnitQuaternion::from_quaternion(q))
            })
            .unwrap_or_else(|| UnitQuaternion::from_euler_angles(0.0, 0.0, pose.heading()));
        let dt_s = {
            let s = &self.streams[i];
            if s.last_capture_ns > 0 && header.capture_mono_ns > s.last_capture_ns {
                (header.capture_mono_ns - s.last_capture_ns) as f64 / 1e9
            } else {
                0.0
            }
        };

        let ai = self.params.ai_enabled;
        let p = self.params.streams[i].clone();
        let s = &mut self.streams[i];

        // Detection and tracking.
        if ai {
            if let Some(scan) = s.scan.as_mut() {
                let hits = scan.scan(&work);
                let track = &mut s.track;
                s.tracker.update(&hits, &mut |b: &PixelBox| {
                    track.as_mut().and_then(|d| d.verify(&work, b))
                });
            }
        }
        let lay = layout::compute(p.layout_mode, p.overlay_mode, p.out_width, p.out_height);
        s.tracker.assign_overlay(lay.tiles.len());

        // Geolocation.
        s.detections.clear();
        for t in s.tracker.tracks() {
            let (cx, cy) = t.bbox.center();
            let pixel = Point2::new(f64::from(cx), f64::from(cy));
            let mut d = VisionDetection {
                id: t.id,
                score: t.score,
                stream: i as u8,
                overlay_slot: t.overlay_slot.unwrap_or(255),
                model: t.model,
                age_frames: t.age_frames,
                confidence: t.confidence,
                bbox: t.bbox.to_wire(),
                ..VisionDetection::default()
            };
            if let Some(dir) = Direction::of_pixel(&model, &pose, &pixel) {
                d.yaw_global_rad = dir.global.yaw as f32;
                d.pitch_global_rad = dir.global.pitch as f32;
                d.yaw_heading_rad = dir.heading.yaw as f32;
                d.pitch_heading_rad = dir.heading.pitch as f32;
                d.yaw_camera_rad = dir.camera.yaw as f32;
                d.pitch_camera_rad = dir.camera.pitch as f32;
                let hit = position
                    .zip(height)
                    .and_then(|(pos, h)| intersect_ground(&pos, h, &dir.ned));
                if let Some(hit) = hit {
                    d.geo_valid = 1;
                    d.lat_deg = hit.position.lat_deg;
                    d.lon_deg = hit.position.lon_deg;
                    d.alt_msl_m = hit.position.alt_msl_m as f32;
                    d.distance_m = hit.distance_m as f32;
                }
            }
            s.detections.push(d);
        }

        // Single-target tracking.
        s.stt.update(&work, &model, &pose, s.tracker.tracks());

        // Aim the cameras the layout shows.
        let tracks = s.tracker.tracks();
        let detection = |id: u8| {
            let t = tracks.iter().find(|t| t.id == id)?;
            let (cx, cy) = t.bbox.center();
            Direction::of_pixel(&model, &pose, &Point2::new(f64::from(cx), f64::from(cy)))
                .map(|d| d.ned)
        };
        let ctx = AimContext {
            vehicle: vehicle_attitude,
            position,
            detection: &detection,
            single_target: s.stt.target(),
            dt_s,
        };
        let mut view_specs: Vec<ViewSpec> = Vec::with_capacity(lay.views.len());
        for (c, rect) in lay.views.iter().enumerate().take(VISION_MAX_CAMS) {
            let cam = &mut s.cams[c];
            // Offsets are fractions of this view: its aspect sets the vertical FOV.
            cam.set_view_size(rect[2], rect[3]);
            let aim = if lay.debug_source {
                Some(pose.ned_from_camera())
            } else {
                cam.aim(&ctx).or(s.aims[c])
            };
            if let Some(q) = aim {
                if !lay.debug_source {
                    s.aims[c] = Some(q);
                }
                view_specs.push(ViewSpec {
                    rect: *rect,
                    ned_from_view: q,
                    hfov: cam.effective_hfov(),
                    crop: cam.crop_mode(),
                });
            }
        }
        let tiles: Vec<TileSpec> = tracks
            .iter()
            .filter_map(|t| {
                let rect = *lay.tiles.get(usize::from(t.overlay_slot?))?;
                let side = (t.bbox.w.max(t.bbox.h) * 1.5).max(16.0);
                let (cx, cy) = t.bbox.center();
                Some(TileSpec {
                    rect,
                    source: PixelBox {
                        x: cx - side / 2.0,
                        y: cy - side / 2.0,
                        w: side,
                        h: side,
                    },
                })
            })
            .collect();

        // Render in place, then the capture hooks on the rendered pixels.
        let (w, h) = (u32::from(p.out_width), u32::from(p.out_height));
        let stride = w * 3;
        let len = (stride * h) as usize;
        let view0 = view_specs.first().copied().filter(|_| !lay.debug_source);
        let mut render_error = None;
        let mut capture_errors: Vec<CaptureError> = Vec::new();
        let renderer = &mut s.renderer;
        let capturer = &mut s.capturer;
        let pending_image = &mut s.pending_image;
        let debug_source = lay.debug_source;
        let sent = output.publish_with(len, |out_h, out| {
            out_h.set_geometry(PixelFormat::Rgb24, w, h, stride);
            out_h.frame_seq = header.frame_seq;
            out_h.capture_mono_ns = header.capture_mono_ns;
            out_h.capture_unix_ns = header.capture_unix_ns;
            out_h.vehicle_heading_deg = header.vehicle_heading_deg;
            out_h.pose = header.pose;
            if let Some(v) = view0 {
                out_h.pose.attitude_q = [
                    v.ned_from_view.w,
                    v.ned_from_view.i,
                    v.ned_from_view.j,
                    v.ned_from_view.k,
                ]
                .map(|x| x as f32);
                out_h.intrinsics = view_intrinsics(&v);
            }
            if let Err(e) = renderer.render(
                header,
                pixels,
                &model,
                &pose,
                &view_specs,
                debug_source,
                &tiles,
                out,
                w,
                h,
                stride,
            ) {
                render_error = Some(e);
            }
            if let Some(c) = capturer.as_mut() {
                if std::mem::take(pending_image) {
                    match c.image(out, w, h, stride) {
                        Ok(path) => tracing::info!(path = %path.display(), "image captured"),
                        Err(e) => capture_errors.push(e),
                    }
                }
                if c.recording() {
                    if let Err(e) = c.video_frame(out, w, h, stride) {
                        capture_errors.push(e);
                    }
                }
            }
        });
        s.layout = lay;
        s.pose = Some(pose);
        s.source = (header.width, header.height);
        s.heading = pose.heading() as f32;
        s.last_seq = header.frame_seq;
        s.last_capture_ns = header.capture_mono_ns;
        s.last_processed_ns = monotonic_ns();
        let now = Instant::now();
        s.last_frame = Some(now);
        s.last_good = Some(now);
        s.bad_since = None;
        s.frames_processed += 1;
        let name = s.name.clone();
        self.metrics.streams[i].processed.inc();
        for e in capture_errors {
            self.metrics.capture_errors.inc();
            if let Some(hidden) = self.warn.allow("capture", now) {
                tracing::warn!(stream = %name, error = %e, hidden, "capture failed");
            }
        }
        if let Some(e) = render_error {
            self.bad(i, "render", &e);
        }
        if let Err(e) = sent {
            self.bad(i, "publish", &e);
        }
        self.publish_state(sinks)?;
        let m = &self.metrics.streams[i];
        m.process_seconds.observe(began.elapsed().as_secs_f64());
        let latency_ns = monotonic_ns().saturating_sub(header.capture_mono_ns);
        if header.capture_mono_ns > 0 {
            m.latency_seconds.observe(latency_ns as f64 / 1e9);
        }
        Ok(())
    }
}

/// Pinhole intrinsics of a rectified view in output-frame pixels (the output header
/// describes view 0); unknown (`valid` 0) for a panoramic view.
pub(super) fn view_intrinsics(v: &ViewSpec) -> CameraIntrinsics {
    let [x, y, w, h] = v.rect.map(f64::from);
    let half = (v.hfov / 2.0).tan();
    if v.crop == skymesh_ipc_types::CropMode::Panoramic || !(half.is_finite() && half > 0.0) {
        return CameraIntrinsics::default();
    }
    let f = (w / 2.0) / half;
    CameraIntrinsics {
        fx: f as f32,
        fy: f as f32,
        cx: (x + (w - 1.0) / 2.0) as f32,
        cy: (y + (h - 1.0) / 2.0) as f32,
        k: [0.0; 4],
        lens_model: LensModel::Pinhole.to_wire(),
        valid: 1,
        reserved: [0; 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::CropMode;

    #[test]
    fn view_intrinsics_describe_view_zero() {
        let v = ViewSpec {
            rect: [100, 50, 640, 480],
            ned_from_view: UnitQuaternion::identity(),
            hfov: std::f64::consts::FRAC_PI_2,
            crop: CropMode::Rectified,
        };
        let k = view_intrinsics(&v);
        assert_eq!(k.valid, 1);
        assert!((k.fx - 320.0).abs() < 1e-3 && k.fx == k.fy);
        assert_eq!((k.cx, k.cy), (419.5, 289.5));
        let pano = view_intrinsics(&ViewSpec {
            crop: CropMode::Panoramic,
            ..v
        });
        assert_eq!(pano.valid, 0);
    }
}
