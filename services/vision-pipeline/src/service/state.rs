//! The published [`VisionState`]: SYSTEM_STATUS and every parameter, stream, view
//! and detection, written in place.

use std::time::Instant;

use skymesh_ipc_types::{
    FixedStr, SttState, VisionState, VISION_MAX_CAMS, VISION_MAX_DETECTIONS, VISION_MAX_MODELS,
};

use crate::detect::MODELS;
use crate::ipc::Sinks;

use super::pipeline::Pipeline;
use super::{FRESH, IDLE_PERIOD};

impl Pipeline {
    /// SYSTEM_STATUS: 3 if a stream's frames have been unusable for over a second,
    /// 1 if a usable frame came within the last second, else 0 (idle).
    pub(super) fn status(&self, now: Instant) -> u8 {
        let error = self.streams.iter().any(|s| {
            s.bad_since
                .is_some_and(|t| now.saturating_duration_since(t) > FRESH)
        });
        let running = self.streams.iter().any(|s| {
            s.last_good
                .is_some_and(|t| now.saturating_duration_since(t) <= FRESH)
        });
        if error {
            3
        } else if running {
            1
        } else {
            0
        }
    }

    pub(super) fn publish_state(&mut self, ports: &mut Sinks) -> anyhow::Result<()> {
        let now = Instant::now();
        if self
            .temperature_read
            .is_none_or(|t| now.saturating_duration_since(t) >= IDLE_PERIOD)
        {
            self.temperature = self.thermometer.read();
            self.temperature_read = Some(now);
        }
        let total: usize = self.streams.iter().map(|s| s.detections.len()).sum();
        self.metrics.detections.set(total as f64);
        let status = self.status(now);
        ports.state(|st| self.fill_state(st, status, now))?;
        self.last_state = now;
        Ok(())
    }

    pub(super) fn fill_state(&self, st: &mut VisionState, status: u8, now: Instant) {
        let p = &self.params;
        st.status = status;
        st.ai_enabled = u8::from(p.ai_enabled);
        st.model_count = MODELS.len().min(VISION_MAX_MODELS) as u8;
        for (slot, m) in st.models.iter_mut().zip(MODELS) {
            *slot = skymesh_ipc_types::vision::ModelName::new(m);
        }
        st.stream_count = self.streams.len() as u8;
        st.temperature_valid = u8::from(self.temperature.is_some());
        st.temperature_c = self.temperature.unwrap_or(0.0);
        st.detection_mode = p.detection_mode;
        let t = &p.tracker;
        st.sorting_mode = t.sorting_mode;
        st.track_confidence = t.track_confidence;
        st.scan_confidence = t.scan_confidence;
        st.track_overlap = t.track_overlap;
        st.scan_overlap = t.scan_overlap;
        st.creation_score = t.creation_score;
        st.bonus_detection = t.bonus_detection;
        st.bonus_redetection = t.bonus_redetection;
        st.missed_detection_penalty = t.missed_detection_penalty;
        st.missed_redetection_penalty = t.missed_redetection_penalty;
        st.track_model = skymesh_ipc_types::vision::ModelName::new(&p.track_model);
        st.scan_model = skymesh_ipc_types::vision::ModelName::new(&p.scan_model);
        for ((out, s), sp) in st.streams.iter_mut().zip(&self.streams).zip(&p.streams) {
            out.name = FixedStr::new(&s.name);
            out.configured = 1;
            out.receiving = u8::from(
                s.last_frame
                    .is_some_and(|t| now.saturating_duration_since(t) <= FRESH),
            );
            out.layout_mode = sp.layout_mode;
            out.overlay_mode = sp.overlay_mode;
            out.num_views = s.layout.views.len().min(VISION_MAX_CAMS) as u8;
            out.out_width = sp.out_width;
            out.out_height = sp.out_height;
            out.overlay_box = s.layout.overlay_box;
            out.single_detection_size = s.layout.tile_size;
            if let Some(c) = s.capturer.as_ref() {
                out.recording = u8::from(c.recording());
                (out.images_captured, out.videos_captured) = c.counts();
            }
            (out.source_width, out.source_height) = s.source;
            out.vehicle_heading_rad = s.heading;
            out.frames_processed = s.frames_processed;
            out.frames_dropped = s.frames_dropped;
            out.last_frame_seq = s.last_seq;
            out.last_capture_mono_ns = s.last_capture_ns;
            out.last_processed_mono_ns = s.last_processed_ns;
            for (c, cam) in s.cams.iter().enumerate().take(VISION_MAX_CAMS) {
                let rect = s.layout.views.get(c).copied();
                let active = rect.is_some() && !s.layout.debug_source;
                out.cams[c] = cam.state(active, rect.unwrap_or([0; 4]));
            }
            out.stt = s
                .pose
                .map_or_else(SttState::default, |pose| s.stt.state(&pose));
        }
        let mut n = 0;
        for (slot, d) in st
            .detections
            .iter_mut()
            .zip(self.streams.iter().flat_map(|s| s.detections.iter()))
            .take(VISION_MAX_DETECTIONS)
        {
            *slot = *d;
            n += 1;
        }
        st.detection_count = n as u8;
    }
}
