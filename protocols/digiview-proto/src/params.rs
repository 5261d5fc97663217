//! Typed payloads of every parameter type, both directions, at the offsets of
//! FACTS.md's table. Bytes a layout does not use are written as zero and ignored on
//! reading. Reading refuses only what the type cannot hold (a bool byte other than
//! 0/1, unknown CAPTURE flag bits, a name that is not UTF-8, more than four views);
//! value ranges are [`Param::validate`]'s job (`validate.rs`).

use crate::fixed::{
    from_milli, from_offset, from_ratio, i16_at, i32_at, put, to_milli, to_offset, to_ratio,
    u16_at, u32_at, Data, FixedName, ModelName, StreamName,
};
use crate::frame::ParamType;
use crate::validate::{PayloadError, Problem};
use crate::DATA_LEN;

/// SYSTEM_STATUS: `0 status u8, 1 error u8, 2 temp i32`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SystemStatus {
    /// 0 idle, 1 running, 2 finished, 3 error.
    pub status: u8,
    /// Unused by DigiView, always 0.
    pub error: u8,
    /// Degrees Celsius.
    pub temperature: f64,
}

/// AI: `0 ai_enabled u8, 1 track_model char[16], 17 scan_model char[16]`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Ai {
    pub enabled: bool,
    pub track_model: ModelName,
    pub scan_model: ModelName,
}

/// MODEL: `0 model_name char[16]`, one CURRENT reply per model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Model {
    pub name: ModelName,
}

/// A rectangle in output pixels, top-left corner plus size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoundingBox {
    pub x: u16,
    pub y: u16,
    pub w: u16,
    pub h: u16,
}

/// The most user views a VIDEO_OUTPUT carries (layouts have 1–4 cameras).
pub const MAX_VIEWS: usize = 4;

/// VIDEO_OUTPUT: `0 stream[8], 8 width u16, 10 height u16, 12 fps u8, 13 layout_mode
/// u8 (GET reply: views in high nibble), 14 overlay_mode u8, 15 num_views u8, 16 views
/// n×{x,y,w,h u16}, then overlay_box, then single_detection_size u16`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VideoOutput {
    pub stream: StreamName,
    pub width: u16,
    pub height: u16,
    /// Unused by DigiView.
    pub fps: u8,
    /// Low nibble of byte 13: layout 0–6.
    pub layout_mode: u8,
    /// High nibble of byte 13: user views of the layout (GET replies, 1–4; 0 in SET).
    pub layout_views: u8,
    pub overlay_mode: u8,
    /// `num_views` on the wire is `views.len()`; at most [`MAX_VIEWS`].
    pub views: Vec<BoundingBox>,
    pub overlay_box: BoundingBox,
    pub single_detection_size: u16,
}

/// CAPTURE: `0 stream[8], 8 flags u8 (bit0 single image, bit1 video), 9 images u16,
/// 11 videos u16`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Capture {
    pub stream: StreamName,
    pub single_image: bool,
    pub record_video: bool,
    pub images_captured: u16,
    pub videos_captured: u16,
}

/// CAPTURE flag: capture one image.
pub const CAPTURE_SINGLE_IMAGE: u8 = 0b01;
/// CAPTURE flag: record video.
pub const CAPTURE_RECORD_VIDEO: u8 = 0b10;

/// DETECTION: `0 mode, 1 sorting_mode, 2 track_conf, 3 scan_conf, 4 track_overlap,
/// 5 scan_overlap (u8 ×255), 6 creation_score, 7 bonus_det, 8 bonus_redet,
/// 9 missed_det_penalty, 10 missed_redet_penalty`. Score bytes of 255 mean "keep".
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Detection {
    pub mode: u8,
    pub sorting_mode: u8,
    pub track_confidence: f64,
    pub scan_confidence: f64,
    pub track_overlap: f64,
    pub scan_overlap: f64,
    pub creation_score: u8,
    pub bonus_detection: u8,
    pub bonus_redetection: u8,
    pub missed_detection_penalty: u8,
    pub missed_redetection_penalty: u8,
}

/// DETECTION score byte meaning "keep the previous value".
pub const SCORE_KEEP: u8 = 255;

/// DETECTED_ROI: `0 index u8, 1 score u8, 2 total u8, 3 type i16, 5 yaw_g i32,
/// 9 pitch_g i32, 13 rel_frame u8, 14 yaw_rel i32, 18 pitch_rel i32, 22 lat i32,
/// 26 lon i32, 30 alt i32, 34 dist i32`. Angles in radians, lat/lon in degrees,
/// alt and distance in metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DetectedRoi {
    pub index: u8,
    pub score: u8,
    pub total: u8,
    pub object_type: i16,
    pub yaw_global: f64,
    pub pitch_global: f64,
    /// 0 global, 1 autopilot heading, 2 camera.
    pub rel_frame: u8,
    pub yaw_rel: f64,
    pub pitch_rel: f64,
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
    pub distance: f64,
}

/// CAM_TARGETING: `0 stream[8], 8 cam u8, 9 mode u8, 10 euler_delta u8, 11 yaw i32,
/// 15 pitch i32, 19 roll i32, 23 lock_flags u8, 24 x i16, 26 y i16, 28 lat i32,
/// 32 lon i32, 36 alt i32`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CamTargeting {
    pub stream: StreamName,
    pub cam: u8,
    /// 0 directional, 1 coordinal, 2 detection, 3 single target tracking.
    pub mode: u8,
    pub euler_delta: bool,
    pub yaw: f64,
    pub pitch: f64,
    pub roll: f64,
    /// Bits 0–2: lock yaw, pitch, roll.
    pub lock_flags: u8,
    pub x_offset: f64,
    pub y_offset: f64,
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
}

/// CAM_OPTICS_AND_CONTROL: `0 stream[8], 8 cam u8, 9 zoom i8, 10 fov i32, 14 crop_mode u8`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CamOpticsAndControl {
    pub stream: StreamName,
    pub cam: u8,
    pub zoom: i8,
    /// Radians.
    pub fov: f64,
    pub crop_mode: u8,
}

/// CAM_OFFSET: `0 stream[8], 8 cam u8, 9 x i16, 11 y i16, 13 yaw_g i32, 17 pitch_g i32,
/// 21 yaw_rel i32, 25 pitch_rel i32`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CamOffset {
    pub stream: StreamName,
    pub cam: u8,
    pub x: f64,
    pub y: f64,
    pub yaw_global: f64,
    pub pitch_global: f64,
    pub yaw_rel: f64,
    pub pitch_rel: f64,
}

/// SENSOR: `0 min_exp u32, 4 max_exp u32, 8 min_gain u32, 12 max_gain u32,
/// 16 brightness i32` (raw integers; DigiView has it disabled).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sensor {
    pub min_exposure: u32,
    pub max_exposure: u32,
    pub min_gain: u32,
    pub max_gain: u32,
    pub brightness: i32,
}

/// CAM_DEPTH_ESTIMATION: `0 stream[8], 8 cam u8, 9 mode u8, 10 depth i32` (metres).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CamDepthEstimation {
    pub stream: StreamName,
    pub cam: u8,
    pub mode: u8,
    pub depth: f64,
}

/// SINGLE_TARGET_TRACKING: `0 command u8, 1 stream[8], 9 cam u8, 10 x i16, 12 y i16,
/// 14 detection_id u8, 15 zoom u16, 17 confidence i32, 21 yaw_g i32, 25 pitch_g i32,
/// 29 rel_frame u8, 30 yaw_rel i32, 34 pitch_rel i32`. `confidence` is carried
/// `× 1000` like the document's other floats.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SingleTargetTracking {
    /// 0 disable, 1 direction, 2 detection id, 3 nudge, 4 no-op.
    pub command: u8,
    pub stream: StreamName,
    pub cam: u8,
    pub x_offset: f64,
    pub y_offset: f64,
    pub detection_id: u8,
    pub zoom: u16,
    pub confidence: f64,
    pub yaw_global: f64,
    pub pitch_global: f64,
    pub rel_frame: u8,
    pub yaw_rel: f64,
    pub pitch_rel: f64,
}

/// One parameter payload, typed.
#[derive(Debug, Clone, PartialEq)]
pub enum Param {
    SystemStatus(SystemStatus),
    Ai(Ai),
    Model(Model),
    VideoOutput(VideoOutput),
    Capture(Capture),
    Detection(Detection),
    DetectedRoi(DetectedRoi),
    CamTargeting(CamTargeting),
    CamOpticsAndControl(CamOpticsAndControl),
    CamOffset(CamOffset),
    Sensor(Sensor),
    CamDepthEstimation(CamDepthEstimation),
    SingleTargetTracking(SingleTargetTracking),
}

/// Reads fields of one parameter, naming the field in errors.
struct Rd<'a> {
    d: &'a Data,
    param: ParamType,
}

impl Rd<'_> {
    fn err(&self, field: &'static str, problem: Problem) -> PayloadError {
        PayloadError {
            param: self.param,
            field,
            problem,
        }
    }
    fn u8(&self, at: usize) -> u8 {
        self.d[at]
    }
    fn bool(&self, at: usize, field: &'static str) -> Result<bool, PayloadError> {
        match self.d[at] {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(self.err(field, Problem::NotBool(v))),
        }
    }
    fn name<const N: usize>(
        &self,
        at: usize,
        field: &'static str,
    ) -> Result<FixedName<N>, PayloadError> {
        FixedName::from_wire(&self.d[at..at + N]).map_err(|e| self.err(field, Problem::Name(e)))
    }
    fn milli(&self, at: usize) -> f64 {
        from_milli(i32_at(self.d, at))
    }
    fn offset(&self, at: usize) -> f64 {
        from_offset(i16_at(self.d, at))
    }
    fn bbox(&self, at: usize) -> BoundingBox {
        BoundingBox {
            x: u16_at(self.d, at),
            y: u16_at(self.d, at + 2),
            w: u16_at(self.d, at + 4),
            h: u16_at(self.d, at + 6),
        }
    }
}

/// Writes fields into a zeroed payload.
struct Wr(Data);

impl Wr {
    fn u8(&mut self, at: usize, v: u8) {
        self.0[at] = v;
    }
    fn u16(&mut self, at: usize, v: u16) {
        put(&mut self.0, at, &v.to_le_bytes());
    }
    fn u32(&mut self, at: usize, v: u32) {
        put(&mut self.0, at, &v.to_le_bytes());
    }
    fn i32(&mut self, at: usize, v: i32) {
        put(&mut self.0, at, &v.to_le_bytes());
    }
    fn milli(&mut self, at: usize, v: f64) {
        self.i32(at, to_milli(v));
    }
    fn offset(&mut self, at: usize, v: f64) {
        put(&mut self.0, at, &to_offset(v).to_le_bytes());
    }
    fn name<const N: usize>(&mut self, at: usize, n: &FixedName<N>) {
        put(&mut self.0, at, &n.wire());
    }
    fn bbox(&mut self, at: usize, b: &BoundingBox) {
        self.u16(at, b.x);
        self.u16(at + 2, b.y);
        self.u16(at + 4, b.w);
        self.u16(at + 6, b.h);
    }
}

impl Param {
    pub fn param_type(&self) -> ParamType {
        match self {
            Param::SystemStatus(_) => ParamType::SystemStatus,
            Param::Ai(_) => ParamType::Ai,
            Param::Model(_) => ParamType::Model,
            Param::VideoOutput(_) => ParamType::VideoOutput,
            Param::Capture(_) => ParamType::Capture,
            Param::Detection(_) => ParamType::Detection,
            Param::DetectedRoi(_) => ParamType::DetectedRoi,
            Param::CamTargeting(_) => ParamType::CamTargeting,
            Param::CamOpticsAndControl(_) => ParamType::CamOpticsAndControl,
            Param::CamOffset(_) => ParamType::CamOffset,
            Param::Sensor(_) => ParamType::Sensor,
            Param::CamDepthEstimation(_) => ParamType::CamDepthEstimation,
            Param::SingleTargetTracking(_) => ParamType::SingleTargetTracking,
        }
    }

    /// The payload of a SET or CURRENT frame, typed.
    pub fn decode(param_type: ParamType, data: &[u8; DATA_LEN]) -> Result<Param, PayloadError> {
        let r = Rd {
            d: data,
            param: param_type,
        };
        Ok(match param_type {
            ParamType::SystemStatus => Param::SystemStatus(SystemStatus {
                status: r.u8(0),
                error: r.u8(1),
                temperature: r.milli(2),
            }),
            ParamType::Ai => Param::Ai(Ai {
                enabled: r.bool(0, "ai_enabled")?,
                track_model: r.name(1, "track_model")?,
                scan_model: r.name(17, "scan_model")?,
            }),
            ParamType::Model => Param::Model(Model {
                name: r.name(0, "model_name")?,
            }),
            ParamType::VideoOutput => {
                let n = usize::from(r.u8(15));
                if n > MAX_VIEWS {
                    return Err(r.err(
                        "num_views",
                        Problem::OutOfRange {
                            value: n as f64,
                            min: 0.0,
                            max: MAX_VIEWS as f64,
                        },
                    ));
                }
                let views = (0..n).map(|i| r.bbox(16 + 8 * i)).collect();
                let after = 16 + 8 * n;
                Param::VideoOutput(VideoOutput {
                    stream: r.name(0, "stream")?,
                    width: u16_at(data, 8),
                    height: u16_at(data, 10),
                    fps: r.u8(12),
                    layout_mode: r.u8(13) & 0x0F,
                    layout_views: r.u8(13) >> 4,
                    overlay_mode: r.u8(14),
                    views,
                    overlay_box: r.bbox(after),
                    single_detection_size: u16_at(data, after + 8),
                })
            }
            ParamType::Capture => {
                let flags = r.u8(8);
                if flags & !(CAPTURE_SINGLE_IMAGE | CAPTURE_RECORD_VIDEO) != 0 {
                    return Err(r.err("flags", Problem::UnknownBits(flags)));
                }
                Param::Capture(Capture {
                    stream: r.name(0, "stream")?,
                    single_image: flags & CAPTURE_SINGLE_IMAGE != 0,
                    record_video: flags & CAPTURE_RECORD_VIDEO != 0,
                    images_captured: u16_at(data, 9),
                    videos_captured: u16_at(data, 11),
                })
            }
            ParamType::Detection => Param::Detection(Detection {
                mode: r.u8(0),
                sorting_mode: r.u8(1),
                track_confidence: from_ratio(r.u8(2)),
                scan_confidence: from_ratio(r.u8(3)),
                track_overlap: from_ratio(r.u8(4)),
                scan_overlap: from_ratio(r.u8(5)),
                creation_score: r.u8(6),
                bonus_detection: r.u8(7),
                bonus_redetection: r.u8(8),
                missed_detection_penalty: r.u8(9),
                missed_redetection_penalty: r.u8(10),
            }),
            ParamType::DetectedRoi => Param::DetectedRoi(DetectedRoi {
                index: r.u8(0),
                score: r.u8(1),
                total: r.u8(2),
                object_type: i16_at(data, 3),
                yaw_global: r.milli(5),
                pitch_global: r.milli(9),
                rel_frame: r.u8(13),
                yaw_rel: r.milli(14),
                pitch_rel: r.milli(18),
                latitude: r.milli(22),
                longitude: r.milli(26),
                altitude: r.milli(30),
                distance: r.milli(34),
            }),
            ParamType::CamTargeting => Param::CamTargeting(CamTargeting {
                stream: r.name(0, "stream")?,
                cam: r.u8(8),
                mode: r.u8(9),
                euler_delta: r.bool(10, "euler_delta")?,
                yaw: r.milli(11),
                pitch: r.milli(15),
                roll: r.milli(19),
                lock_flags: r.u8(23),
                x_offset: r.offset(24),
                y_offset: r.offset(26),
                latitude: r.milli(28),
                longitude: r.milli(32),
                altitude: r.milli(36),
            }),
            ParamType::CamOpticsAndControl => Param::CamOpticsAndControl(CamOpticsAndControl {
                stream: r.name(0, "stream")?,
                cam: r.u8(8),
                zoom: i8::from_le_bytes([r.u8(9)]),
                fov: r.milli(10),
                crop_mode: r.u8(14),
            }),
            ParamType::CamOffset => Param::CamOffset(CamOffset {
                stream: r.name(0, "stream")?,
                cam: r.u8(8),
                x: r.offset(9),
                y: r.offset(11),
                yaw_global: r.milli(13),
                pitch_global: r.milli(17),
                yaw_rel: r.milli(21),
                pitch_rel: r.milli(25),
            }),
            ParamType::Sensor => Param::Sensor(Sensor {
                min_exposure: u32_at(data, 0),
                max_exposure: u32_at(data, 4),
                min_gain: u32_at(data, 8),
                max_gain: u32_at(data, 12),
                brightness: i32_at(data, 16),
            }),
            ParamType::CamDepthEstimation => Param::CamDepthEstimation(CamDepthEstimation {
                stream: r.name(0, "stream")?,
                cam: r.u8(8),
                mode: r.u8(9),
                depth: r.milli(10),
            }),
            ParamType::SingleTargetTracking => Param::SingleTargetTracking(SingleTargetTracking {
                command: r.u8(0),
                stream: r.name(1, "stream")?,
                cam: r.u8(9),
                x_offset: r.offset(10),
                y_offset: r.offset(12),
                detection_id: r.u8(14),
                zoom: u16_at(data, 15),
                confidence: r.milli(17),
                yaw_global: r.milli(21),
                pitch_global: r.milli(25),
                rel_frame: r.u8(29),
                yaw_rel: r.milli(30),
                pitch_rel: r.milli(34),
            }),
        })
    }

    /// The parameter type and its 64 payload bytes (unused bytes zero). More than
    /// [`MAX_VIEWS`] views are cut to the first four; [`Param::validate`] refuses them.
    pub fn encode(&self) -> (ParamType, [u8; DATA_LEN]) {
        let mut w = Wr([0; DATA_LEN]);
        match self {
            Param::SystemStatus(p) => {
                w.u8(0, p.status);
                w.u8(1, p.error);
                w.milli(2, p.temperature);
            }
            Param::Ai(p) => {
                w.u8(0, u8::from(p.enabled));
                w.name(1, &p.track_model);
                w.name(17, &p.scan_model);
            }
            Param::Model(p) => w.name(0, &p.name),
            Param::VideoOutput(p) => {
                let n = p.views.len().min(MAX_VIEWS);
                w.name(0, &p.stream);
                w.u16(8, p.width);
                w.u16(10, p.height);
                w.u8(12, p.fps);
                w.u8(13, (p.layout_views << 4) | (p.layout_mode & 0x0F));
                w.u8(14, p.overlay_mode);
                w.u8(15, n as u8);
                for (i, v) in p.views.iter().take(n).enumerate() {
                    w.bbox(16 + 8 * i, v);
                }
                let after = 16 + 8 * n;
                w.bbox(after, &p.overlay_box);
                w.u16(after + 8, p.single_detection_size);
            }
            Param::Capture(p) => {
                w.name(0, &p.stream);
                let mut flags = 0;
                if p.single_image {
                    flags |= CAPTURE_SINGLE_IMAGE;
                }
                if p.record_video {
                    flags |= CAPTURE_RECORD_VIDEO;
                }
                w.u8(8, flags);
                w.u16(9, p.images_captured);
                w.u16(11, p.videos_captured);
            }
            Param::Detection(p) => {
                w.u8(0, p.mode);
                w.u8(1, p.sorting_mode);
                w.u8(2, to_ratio(p.track_confidence));
                w.u8(3, to_ratio(p.scan_confidence));
                w.u8(4, to_ratio(p.track_overlap));
                w.u8(5, to_ratio(p.scan_overlap));
                w.u8(6, p.creation_score);
                w.u8(7, p.bonus_detection);
                w.u8(8, p.bonus_redetection);
                w.u8(9, p.missed_detection_penalty);
                w.u8(10, p.missed_redetection_penalty);
            }
            Param::DetectedRoi(p) => {
                w.u8(0, p.index);
                w.u8(1, p.score);
                w.u8(2, p.total);
                put(&mut w.0, 3, &p.object_type.to_le_bytes());
                w.milli(5, p.yaw_global);
                w.milli(9, p.pitch_global);
                w.u8(13, p.rel_frame);
                w.milli(14, p.yaw_rel);
                w.milli(18, p.pitch_rel);
                w.milli(22, p.latitude);
                w.milli(26, p.longitude);
                w.milli(30, p.altitude);
                w.milli(34, p.distance);
            }
            Param::CamTargeting(p) => {
                w.name(0, &p.stream);
                w.u8(8, p.cam);
                w.u8(9, p.mode);
                w.u8(10, u8::from(p.euler_delta));
                w.milli(11, p.yaw);
                w.milli(15, p.pitch);
                w.milli(19, p.roll);
                w.u8(23, p.lock_flags);
                w.offset(24, p.x_offset);
                w.offset(26, p.y_offset);
                w.milli(28, p.latitude);
                w.milli(32, p.longitude);
                w.milli(36, p.altitude);
            }
            Param::CamOpticsAndControl(p) => {
                w.name(0, &p.stream);
                w.u8(8, p.cam);
                w.u8(9, p.zoom.to_le_bytes()[0]);
                w.milli(10, p.fov);
                w.u8(14, p.crop_mode);
            }
            Param::CamOffset(p) => {
                w.name(0, &p.stream);
                w.u8(8, p.cam);
                w.offset(9, p.x);
                w.offset(11, p.y);
                w.milli(13, p.yaw_global);
                w.milli(17, p.pitch_global);
                w.milli(21, p.yaw_rel);
                w.milli(25, p.pitch_rel);
            }
            Param::Sensor(p) => {
                w.u32(0, p.min_exposure);
                w.u32(4, p.max_exposure);
                w.u32(8, p.min_gain);
                w.u32(12, p.max_gain);
                w.i32(16, p.brightness);
            }
            Param::CamDepthEstimation(p) => {
                w.name(0, &p.stream);
                w.u8(8, p.cam);
                w.u8(9, p.mode);
                w.milli(10, p.depth);
            }
            Param::SingleTargetTracking(p) => {
                w.u8(0, p.command);
                w.name(1, &p.stream);
                w.u8(9, p.cam);
                w.offset(10, p.x_offset);
                w.offset(12, p.y_offset);
                w.u8(14, p.detection_id);
                w.u16(15, p.zoom);
                w.milli(17, p.confidence);
                w.milli(21, p.yaw_global);
                w.milli(25, p.pitch_global);
                w.u8(29, p.rel_frame);
                w.milli(30, p.yaw_rel);
                w.milli(34, p.pitch_rel);
            }
        }
        (self.param_type(), w.0)
    }
}
