//! `deploy/vision-pipeline.toml` → [`Settings`].

use std::path::PathBuf;

use serde::Deserialize;
use skymesh_ipc_types::VISION_MAX_STREAMS;
use skymesh_runtime::config::{finite, in_range};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::capture::ImageFormat;
use crate::detect::{DetectorConfig, MODELS};
use crate::thermal::ThermalSource;
use crate::track::TrackerParams;

/// The raw TOML.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    #[serde(default = "d_vehicle")]
    vehicle_id: u8,
    #[serde(default = "d_thermal")]
    thermal_zone: String,
    #[serde(default)]
    always_on: bool,
    #[serde(default = "d_control_hold")]
    control_hold_s: f64,
    #[serde(default)]
    capture: RawCapture,
    #[serde(default)]
    ai: RawAi,
    #[serde(default)]
    detector: RawDetector,
    #[serde(default)]
    detection: RawDetection,
    #[serde(default = "d_streams")]
    streams: Vec<RawStream>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCapture {
    #[serde(default)]
    dir: String,
    #[serde(default = "d_format")]
    format: String,
    #[serde(default = "d_quality")]
    jpeg_quality: u8,
}

impl Default for RawCapture {
    fn default() -> Self {
        RawCapture {
            dir: String::new(),
            format: d_format(),
            jpeg_quality: d_quality(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAi {
    #[serde(default = "d_true")]
    enabled: bool,
    #[serde(default = "d_model")]
    scan_model: String,
    #[serde(default = "d_model")]
    track_model: String,
}

impl Default for RawAi {
    fn default() -> Self {
        RawAi {
            enabled: true,
            scan_model: d_model(),
            track_model: d_model(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDetector {
    #[serde(default = "d_work_width")]
    work_width: u32,
    #[serde(default = "d_min_area")]
    min_area_px: f64,
    #[serde(default = "d_max_area")]
    max_area_frac: f64,
}

impl Default for RawDetector {
    fn default() -> Self {
        let d = DetectorConfig::default();
        RawDetector {
            work_width: d.work_width,
            min_area_px: f64::from(d.min_area_px),
            max_area_frac: f64::from(d.max_area_frac),
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDetection {
    sorting_mode: Option<u8>,
    track_confidence: Option<f64>,
    scan_confidence: Option<f64>,
    track_overlap: Option<f64>,
    scan_overlap: Option<f64>,
    creation_score: Option<u8>,
    bonus_detection: Option<u8>,
    bonus_redetection: Option<u8>,
    missed_detection_penalty: Option<u8>,
    missed_redetection_penalty: Option<u8>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStream {
    name: String,
    #[serde(default = "d_width")]
    width: u16,
    #[serde(default = "d_height")]
    height: u16,
    #[serde(default)]
    layout: u8,
    #[serde(default = "d_overlay")]
    overlay: u8,
    #[serde(default = "d_fov")]
    fov_deg: f64,
}

fn d_control_hold() -> f64 {
    10.0
}

fn d_vehicle() -> u8 {
    1
}
fn d_thermal() -> String {
    "auto".into()
}
fn d_format() -> String {
    "png".into()
}
fn d_quality() -> u8 {
    85
}
fn d_true() -> bool {
    true
}
fn d_model() -> String {
    MODELS[0].into()
}
fn d_work_width() -> u32 {
    DetectorConfig::default().work_width
}
fn d_min_area() -> f64 {
    f64::from(DetectorConfig::default().min_area_px)
}
fn d_max_area() -> f64 {
    f64::from(DetectorConfig::default().max_area_frac)
}
fn d_width() -> u16 {
    1280
}
fn d_height() -> u16 {
    720
}
fn d_overlay() -> u8 {
    2
}
fn d_fov() -> f64 {
    60.0
}
fn d_streams() -> Vec<RawStream> {
    vec![RawStream {
        name: "main".into(),
        width: d_width(),
        height: d_height(),
        layout: 0,
        overlay: d_overlay(),
        fov_deg: d_fov(),
    }]
}

/// Captures (CAPTURE, ImageCapture, RecordStart).
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureSettings {
    /// `None`: captures disabled.
    pub dir: Option<PathBuf>,
    pub format: ImageFormat,
    pub jpeg_quality: u8,
}

/// One stream's start-up output parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamSettings {
    pub name: String,
    pub width: u16,
    pub height: u16,
    pub layout: u8,
    pub overlay: u8,
    /// Virtual cameras' horizontal FOV at start, radians.
    pub fov_rad: f64,
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub vehicle_id: u8,
    pub thermal: ThermalSource,
    /// Process frames even while nothing uses the output.
    pub always_on: bool,
    /// A control keeps the pipeline processing for this long (a ground station
    /// steering a virtual camera, a DigiView SET).
    pub control_hold: std::time::Duration,
    pub capture: CaptureSettings,
    pub ai_enabled: bool,
    pub scan_model: String,
    pub track_model: String,
    pub detector: DetectorConfig,
    pub tracker: TrackerParams,
    pub streams: Vec<StreamSettings>,
}

fn model(field: &str, name: String) -> Result<String, ConfigError> {
    if MODELS.contains(&name.as_str()) {
        Ok(name)
    } else {
        Err(ConfigError::invalid(
            field,
            format!("unknown model `{name}` (have: {})", MODELS.join(", ")),
        ))
    }
}

/// A confidence or overlap: 0 <= x < 0.99 (DigiView's range).
fn ratio(field: &str, v: Option<f64>, default: f32) -> Result<f32, ConfigError> {
    match v {
        None => Ok(default),
        Some(v) => {
            let v = finite(field, v)?;
            if (0.0..0.99).contains(&v) {
                Ok(v as f32)
            } else {
                Err(ConfigError::invalid(
                    field,
                    format!("{v} is outside 0..0.99"),
                ))
            }
        }
    }
}

fn score(field: &str, v: Option<u8>, default: u8) -> Result<u8, ConfigError> {
    match v {
        None => Ok(default),
        Some(v) => in_range(field, v, 0, 254),
    }
}

/// A stream name the camera would accept: 1..=8 bytes of a-z, 0-9, - or _.
pub fn valid_stream_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 8
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../deploy/vision-pipeline.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        let thermal = ThermalSource::parse(&self.thermal_zone)
            .map_err(|m| ConfigError::invalid("thermal_zone", m))?;

        let c = self.capture;
        let dir = if c.dir.is_empty() {
            None
        } else {
            let p = PathBuf::from(&c.dir);
            if !p.is_absolute() {
                return Err(ConfigError::invalid(
                    "capture.dir",
                    format!("`{}` is not an absolute path (or \"\" to disable)", c.dir),
                ));
            }
            Some(p)
        };
        let format = match c.format.as_str() {
            "png" => ImageFormat::Png,
            "jpeg" | "jpg" => ImageFormat::Jpeg,
            other => {
                return Err(ConfigError::invalid(
                    "capture.format",
                    format!("unknown image format `{other}` (png, jpeg)"),
                ))
            }
        };
        let jpeg_quality = in_range("capture.jpeg_quality", c.jpeg_quality, 1, 100)?;

        let scan_model = model("ai.scan_model", self.ai.scan_model)?;
        let track_model = model("ai.track_model", self.ai.track_model)?;

        let d = self.detector;
        let work_width = in_range("detector.work_width", d.work_width, 64, 1920)?;
        let min_area = finite("detector.min_area_px", d.min_area_px)?;
        if min_area <= 0.0 {
            return Err(ConfigError::invalid(
                "detector.min_area_px",
                format!("{min_area} must be positive"),
            ));
        }
        let max_frac = finite("detector.max_area_frac", d.max_area_frac)?;
        if max_frac <= 0.0 || max_frac > 1.0 {
            return Err(ConfigError::invalid(
                "detector.max_area_frac",
                format!("{max_frac} is outside 0 < x <= 1"),
            ));
        }

        let t = self.detection;
        let def = TrackerParams::default();
        let tracker = TrackerParams {
            sorting_mode: in_range(
                "detection.sorting_mode",
                t.sorting_mode.unwrap_or(def.sorting_mode),
                0,
                2,
            )?,
            track_confidence: ratio(
                "detection.track_confidence",
                t.track_confidence,
                def.track_confidence,
            )?,
            scan_confidence: ratio(
                "detection.scan_confidence",
                t.scan_confidence,
                def.scan_confidence,
            )?,
            track_overlap: ratio(
                "detection.track_overlap",
                t.track_overlap,
                def.track_overlap,
            )?,
            scan_overlap: ratio("detection.scan_overlap", t.scan_overlap, def.scan_overlap)?,
            creation_score: score(
                "detection.creation_score",
                t.creation_score,
                def.creation_score,
            )?,
            bonus_detection: score(
                "detection.bonus_detection",
                t.bonus_detection,
                def.bonus_detection,
            )?,
            bonus_redetection: score(
                "detection.bonus_redetection",
                t.bonus_redetection,
                def.bonus_redetection,
            )?,
            missed_detection_penalty: score(
                "detection.missed_detection_penalty",
                t.missed_detection_penalty,
                def.missed_detection_penalty,
            )?,
            missed_redetection_penalty: score(
                "detection.missed_redetection_penalty",
                t.missed_redetection_penalty,
                def.missed_redetection_penalty,
            )?,
        };

        if self.streams.is_empty() || self.streams.len() > VISION_MAX_STREAMS {
            return Err(ConfigError::invalid(
                "streams",
                format!(
                    "{} streams configured, need 1..={VISION_MAX_STREAMS}",
                    self.streams.len()
                ),
            ));
        }
        let mut streams: Vec<StreamSettings> = Vec::with_capacity(self.streams.len());
        for (i, s) in self.streams.into_iter().enumerate() {
            let f = |name: &str| format!("streams[{i}].{name}");
            if !valid_stream_name(&s.name) {
                return Err(ConfigError::invalid(
                    f("name"),
                    format!("`{}` is not 1..=8 bytes of a-z, 0-9, - or _", s.name),
                ));
            }
            if streams.iter().any(|o| o.name == s.name) {
                return Err(ConfigError::invalid(
                    f("name"),
                    format!("stream `{}` is configured twice", s.name),
                ));
            }
            let fov = in_range(&f("fov_deg"), finite(&f("fov_deg"), s.fov_deg)?, 1.0, 170.0)?;
            streams.push(StreamSettings {
                width: in_range(&f("width"), s.width, 640, 1920)?,
                height: in_range(&f("height"), s.height, 480, 1080)?,
                layout: in_range(&f("layout"), s.layout, 0, 6)?,
                overlay: in_range(&f("overlay"), s.overlay, 0, 5)?,
                fov_rad: fov.to_radians(),
                name: s.name,
            });
        }

        let hold = in_range(
            "control_hold_s",
            finite("control_hold_s", self.control_hold_s)?,
            0.0,
            3600.0,
        )?;
        Ok(Settings {
            vehicle_id: self.vehicle_id,
            thermal,
            always_on: self.always_on,
            control_hold: std::time::Duration::from_secs_f64(hold),
            capture: CaptureSettings {
                dir,
                format,
                jpeg_quality,
            },
            ai_enabled: self.ai.enabled,
            scan_model,
            track_model,
            detector: DetectorConfig {
                work_width,
                min_area_px: min_area as f32,
                max_area_frac: max_frac as f32,
            },
            tracker,
            streams,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_runtime::config::parse;

    fn with(edits: &[(&str, &str)]) -> Result<Settings, ConfigError> {
        let mut text = RawConfig::DEFAULT_TOML.to_string();
        for (from, to) in edits {
            assert!(text.contains(from), "the shipped config has no `{from}`");
            text = text.replacen(from, to, 1);
        }
        parse::<RawConfig>(&text, "test")
    }

    #[test]
    fn the_shipped_config_parses_to_the_defaults() {
        let s = with(&[]).unwrap();
        assert_eq!(s.vehicle_id, 1);
        assert_eq!(s.thermal, ThermalSource::Auto);
        assert_eq!(s.capture.dir, None);
        assert_eq!(s.capture.format, ImageFormat::Png);
        assert!(s.ai_enabled);
        assert_eq!(s.scan_model, "contrast-blob");
        assert_eq!(s.detector, DetectorConfig::default());
        assert_eq!(s.tracker, TrackerParams::default());
        assert_eq!(s.streams.len(), 1);
        let st = &s.streams[0];
        assert_eq!(
            (st.name.as_str(), st.width, st.height, st.layout, st.overlay),
            ("main", 1280, 720, 0, 2)
        );
        assert!((st.fov_rad - 60f64.to_radians()).abs() < 1e-12);
        // An empty file gives the same pipeline.
        assert_eq!(parse::<RawConfig>("", "empty").unwrap(), s);
    }

    #[test]
    fn bad_values_are_refused_naming_the_field() {
        for (edit, field) in [
            (
                ("name = \"main\"", "name = \"toolongname\""),
                "streams[0].name",
            ),
            (("name = \"main\"", "name = \"a/b\""), "streams[0].name"),
            (("width = 1280", "width = 600"), "streams[0].width"),
            (("height = 720", "height = 1081"), "streams[0].height"),
            (("layout = 0", "layout = 7"), "streams[0].layout"),
            (("overlay = 2", "overlay = 6"), "streams[0].overlay"),
            (("fov_deg = 60.0", "fov_deg = 0.5"), "streams[0].fov_deg"),
            (("dir = \"\"", "dir = \"relative/dir\""), "capture.dir"),
            (("format = \"png\"", "format = \"gif\""), "capture.format"),
            (
                ("jpeg_quality = 85", "jpeg_quality = 0"),
                "capture.jpeg_quality",
            ),
            (
                ("scan_model = \"contrast-blob\"", "scan_model = \"yolo\""),
                "ai.scan_model",
            ),
            (
                ("track_model = \"contrast-blob\"", "track_model = \"\""),
                "ai.track_model",
            ),
            (
                ("work_width = 480", "work_width = 10"),
                "detector.work_width",
            ),
            (
                ("min_area_px = 40.0", "min_area_px = 0.0"),
                "detector.min_area_px",
            ),
            (
                ("max_area_frac = 0.05", "max_area_frac = 1.5"),
                "detector.max_area_frac",
            ),
            (
                ("sorting_mode = 0", "sorting_mode = 3"),
                "detection.sorting_mode",
            ),
            (
                ("track_confidence = 0.3", "track_confidence = 0.99"),
                "detection.track_confidence",
            ),
            (
                ("creation_score = 60", "creation_score = 255"),
                "detection.creation_score",
            ),
            (
                ("thermal_zone = \"auto\"", "thermal_zone = \"zone0\""),
                "thermal_zone",
            ),
        ] {
            let e = with(&[edit]).unwrap_err();
            assert!(
                matches!(&e, ConfigError::Invalid { field: f, .. } if f == field),
                "{edit:?}: {e}"
            );
        }
        assert!(matches!(
            with(&[("vehicle_id = 1", "vehicle_id = 1\nbogus = 1")]),
            Err(ConfigError::Parse { .. })
        ));
    }

    #[test]
    fn stream_counts_and_duplicates() {
        let two = "[[streams]]\nname = \"a\"\n[[streams]]\nname = \"b\"\n";
        let s = parse::<RawConfig>(two, "t").unwrap();
        assert_eq!(s.streams.len(), 2);
        assert_eq!(s.streams[1].width, 1280);
        let dup = "[[streams]]\nname = \"a\"\n[[streams]]\nname = \"a\"\n";
        let e = parse::<RawConfig>(dup, "t").unwrap_err();
        assert!(e.to_string().contains("streams[1].name"), "{e}");
        let three = format!("{two}[[streams]]\nname = \"c\"\n");
        let e = parse::<RawConfig>(&three, "t").unwrap_err();
        assert!(matches!(&e, ConfigError::Invalid { field, .. } if field == "streams"));
        let e = parse::<RawConfig>("streams = []", "t").unwrap_err();
        assert!(matches!(&e, ConfigError::Invalid { field, .. } if field == "streams"));
    }

    #[test]
    fn captures_thermal_and_jpeg_parse() {
        let s = with(&[
            ("dir = \"\"", "dir = \"/var/lib/skymesh/captures\""),
            ("format = \"png\"", "format = \"jpeg\""),
            ("thermal_zone = \"auto\"", "thermal_zone = \"none\""),
        ])
        .unwrap();
        assert_eq!(
            s.capture.dir.as_deref(),
            Some(std::path::Path::new("/var/lib/skymesh/captures"))
        );
        assert_eq!(s.capture.format, ImageFormat::Jpeg);
        assert_eq!(s.thermal, ThermalSource::None);
    }
}
