//! `deploy/camera.toml` → [`Settings`].

use std::path::{Path, PathBuf};

use serde::Deserialize;
use skymesh_ipc_types::{PixelFormat, SCENE_MAX_TARGETS};
use skymesh_runtime::config::finite;
use skymesh_runtime::config::in_range;
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::render::{Intrinsics, Lens, Shape};
use crate::scene::{Motion, Origin, TargetSpec};
use crate::y4m::{Y4mHeader, Y4mReader};
use crate::yuv::Range;

/// The raw TOML.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    #[serde(default = "d_vehicle")]
    vehicle_id: u8,
    #[serde(default = "d_stream")]
    stream: String,
    #[serde(default = "d_source")]
    source: String,
    #[serde(default = "d_width")]
    width: u32,
    #[serde(default = "d_height")]
    height: u32,
    #[serde(default = "d_fps")]
    fps: u32,
    #[serde(default = "d_format")]
    format: String,
    #[serde(default)]
    always_on: bool,
    #[serde(default)]
    lens: RawLens,
    #[serde(default)]
    mount: RawMount,
    #[serde(default)]
    synthetic: RawSynthetic,
    #[serde(default)]
    y4m: RawY4m,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawY4m {
    path: Option<String>,
    #[serde(default = "d_true", rename = "loop")]
    looping: bool,
    #[serde(default = "d_range")]
    range: String,
}

impl Default for RawY4m {
    fn default() -> Self {
        RawY4m {
            path: None,
            looping: true,
            range: d_range(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLens {
    #[serde(default = "d_lens")]
    model: String,
    #[serde(default = "d_hfov")]
    hfov_deg: f64,
    cx: Option<f64>,
    cy: Option<f64>,
}

impl Default for RawLens {
    fn default() -> Self {
        RawLens {
            model: d_lens(),
            hfov_deg: d_hfov(),
            cx: None,
            cy: None,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMount {
    #[serde(default = "d_true")]
    use_gimbal: bool,
    #[serde(default = "d_pitch")]
    pitch_deg: f64,
    #[serde(default)]
    yaw_deg: f64,
}

impl Default for RawMount {
    fn default() -> Self {
        RawMount {
            use_gimbal: true,
            pitch_deg: d_pitch(),
            yaw_deg: 0.0,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSynthetic {
    #[serde(default = "d_cell")]
    cell_m: f64,
    #[serde(default = "d_standby")]
    standby_height_m: f64,
    #[serde(default = "d_threads")]
    render_threads: usize,
    origin: Option<RawOrigin>,
    #[serde(default)]
    targets: Vec<RawTarget>,
}

impl Default for RawSynthetic {
    fn default() -> Self {
        RawSynthetic {
            cell_m: d_cell(),
            standby_height_m: d_standby(),
            render_threads: d_threads(),
            origin: None,
            targets: Vec::new(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOrigin {
    lat_deg: f64,
    lon_deg: f64,
    ground_alt_msl_m: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTarget {
    id: u32,
    #[serde(default = "d_shape")]
    shape: String,
    size_m: f64,
    rgb: [u8; 3],
    circle: Option<RawCircle>,
    line: Option<RawLine>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCircle {
    center_ne_m: [f64; 2],
    radius_m: f64,
    speed_mps: f64,
    #[serde(default)]
    phase_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLine {
    from_ne_m: [f64; 2],
    to_ne_m: [f64; 2],
    speed_mps: f64,
}

fn d_vehicle() -> u8 {
    1
}
fn d_stream() -> String {
    "main".into()
}
fn d_source() -> String {
    "synthetic".into()
}
fn d_width() -> u32 {
    1280
}
fn d_height() -> u32 {
    720
}
fn d_fps() -> u32 {
    30
}
fn d_format() -> String {
    "rgb24".into()
}
fn d_lens() -> String {
    "pinhole".into()
}
fn d_hfov() -> f64 {
    90.0
}
fn d_true() -> bool {
    true
}
fn d_pitch() -> f64 {
    -90.0
}
fn d_cell() -> f64 {
    10.0
}
fn d_standby() -> f64 {
    50.0
}
fn d_threads() -> usize {
    2
}
fn d_shape() -> String {
    "disc".into()
}
fn d_range() -> String {
    "full".into()
}

/// Where the camera looks when the gimbal's attitude is not used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mount {
    pub use_gimbal: bool,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
}

/// The synthetic source's scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticSettings {
    pub cell_m: f64,
    pub standby_height_m: f64,
    /// Threads rendering bands of rows of each frame.
    pub render_threads: usize,
    pub origin: Option<Origin>,
    pub targets: Vec<TargetSpec>,
}

/// A Y4M file source.
#[derive(Debug, Clone, PartialEq)]
pub struct Y4mSettings {
    /// Absolute path of the file.
    pub path: PathBuf,
    /// At the end of the file start again; else stop publishing (and stay up).
    pub looping: bool,
    /// The value range of the file's samples (Y4M headers do not say).
    pub range: Range,
    /// The file's header as read when the configuration was checked.
    pub header: Y4mHeader,
}

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// The synthetic scene (`[synthetic]`).
    Synthetic,
    /// A YUV4MPEG2 file (`[y4m]`).
    Y4m(Y4mSettings),
}

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub vehicle_id: u8,
    pub stream: String,
    pub source: Source,
    pub width: u32,
    pub height: u32,
    pub fps: u32,
    pub format: PixelFormat,
    /// Make frames even while nobody subscribes to them (a real camera feeding a
    /// recorder); otherwise frames are made only while the frame topic has a reader.
    pub always_on: bool,
    pub intrinsics: Intrinsics,
    pub mount: Mount,
    pub synthetic: SyntheticSettings,
}

impl Settings {
    /// Bytes from one row to the next.
    pub fn stride(&self) -> u32 {
        self.width * self.format.bytes_per_pixel()
    }

    /// Bytes of one frame.
    pub fn frame_len(&self) -> usize {
        self.format
            .frame_len(self.width, self.height, self.stride())
            .unwrap_or(0) as usize
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = include_str!("../../../../deploy/camera.toml");

    fn validate(self) -> Result<Settings, ConfigError> {
        let stream_ok = !self.stream.is_empty()
            && self.stream.len() <= 8
            && self
                .stream
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_');
        if !stream_ok {
            return Err(ConfigError::invalid(
                "stream",
                format!("`{}` is not 1..=8 bytes of a-z, 0-9, - or _", self.stream),
            ));
        }
        let y4m_wanted = match self.source.as_str() {
            "synthetic" => false,
            "y4m" => true,
            "v4l2" => {
                return Err(ConfigError::invalid(
                    "source",
                    "source `v4l2` is not implemented yet; use \"synthetic\" or \"y4m\"",
                ))
            }
            other => {
                return Err(ConfigError::invalid(
                    "source",
                    format!("unknown source `{other}` (synthetic, y4m)"),
                ))
            }
        };
        let width = in_range("width", self.width, 16, 1920)?;
        let height = in_range("height", self.height, 16, 1080)?;
        let fps = in_range("fps", self.fps, 1, 60)?;
        let format = match self.format.as_str() {
            "rgb24" => PixelFormat::Rgb24,
            "nv12" => PixelFormat::Nv12,
            other => {
                return Err(ConfigError::invalid(
                    "format",
                    format!("unknown pixel format `{other}` (rgb24, nv12)"),
                ))
            }
        };
        if format == PixelFormat::Nv12 && (width % 2 != 0 || height % 2 != 0) {
            return Err(ConfigError::invalid(
                "width",
                "nv12 needs an even width and height",
            ));
        }
        let (lens, max_fov) = match self.lens.model.as_str() {
            "pinhole" => (Lens::Pinhole, 170.0),
            "fisheye" => (Lens::Fisheye, 360.0),
            other => {
                return Err(ConfigError::invalid(
                    "lens.model",
                    format!("unknown lens model `{other}` (pinhole, fisheye)"),
                ))
            }
        };
        let hfov = in_range(
            "lens.hfov_deg",
            finite("lens.hfov_deg", self.lens.hfov_deg)?,
            1.0,
            max_fov,
        )?;
        let mut intrinsics = Intrinsics::from_hfov(width, height, hfov, lens);
        if let Some(cx) = self.lens.cx {
            intrinsics.cx = in_range("lens.cx", finite("lens.cx", cx)?, 0.0, f64::from(width))?;
        }
        if let Some(cy) = self.lens.cy {
            intrinsics.cy = in_range("lens.cy", finite("lens.cy", cy)?, 0.0, f64::from(height))?;
        }
        let mount = Mount {
            use_gimbal: self.mount.use_gimbal,
            pitch_deg: in_range(
                "mount.pitch_deg",
                finite("mount.pitch_deg", self.mount.pitch_deg)?,
                -90.0,
                90.0,
            )?,
            yaw_deg: in_range(
                "mount.yaw_deg",
                finite("mount.yaw_deg", self.mount.yaw_deg)?,
                -360.0,
                360.0,
            )?,
        };
        let range = match self.y4m.range.as_str() {
            "full" => Range::Full,
            "limited" => Range::Limited,
            other => {
                return Err(ConfigError::invalid(
                    "y4m.range",
                    format!("unknown range `{other}` (full, limited)"),
                ))
            }
        };
        let source = if y4m_wanted {
            let Some(path) = self.y4m.path else {
                return Err(ConfigError::invalid(
                    "y4m.path",
                    "source \"y4m\" needs `[y4m] path`",
                ));
            };
            let path = PathBuf::from(path);
            if !path.is_absolute() {
                return Err(ConfigError::invalid(
                    "y4m.path",
                    format!("`{}` is not an absolute path", path.display()),
                ));
            }
            let header = read_y4m_header(&path)
                .map_err(|message| ConfigError::invalid("y4m.path", message))?;
            check_y4m_size(&path, &header, width, height)
                .map_err(|message| ConfigError::invalid("y4m.path", message))?;
            Source::Y4m(Y4mSettings {
                path,
                looping: self.y4m.looping,
                range,
                header,
            })
        } else {
            Source::Synthetic
        };
        let s = self.synthetic;
        let cell_m = in_range(
            "synthetic.cell_m",
            finite("synthetic.cell_m", s.cell_m)?,
            0.5,
            1000.0,
        )?;
        let standby_height_m = in_range(
            "synthetic.standby_height_m",
            finite("synthetic.standby_height_m", s.standby_height_m)?,
            1.0,
            10_000.0,
        )?;
        let origin = match s.origin {
            None => None,
            Some(o) => Some(Origin {
                lat_deg: in_range(
                    "synthetic.origin.lat_deg",
                    finite("synthetic.origin.lat_deg", o.lat_deg)?,
                    -85.0,
                    85.0,
                )?,
                lon_deg: in_range(
                    "synthetic.origin.lon_deg",
                    finite("synthetic.origin.lon_deg", o.lon_deg)?,
                    -180.0,
                    180.0,
                )?,
                ground_alt_msl_m: in_range(
                    "synthetic.origin.ground_alt_msl_m",
                    finite("synthetic.origin.ground_alt_msl_m", o.ground_alt_msl_m)?,
                    -500.0,
                    9000.0,
                )?,
            }),
        };
        if s.targets.len() > SCENE_MAX_TARGETS {
            return Err(ConfigError::invalid(
                "synthetic.targets",
                format!("{} targets, at most {SCENE_MAX_TARGETS}", s.targets.len()),
            ));
        }
        let mut targets: Vec<TargetSpec> = Vec::with_capacity(s.targets.len());
        for (i, t) in s.targets.into_iter().enumerate() {
            let f = |name: &str| format!("synthetic.targets[{i}].{name}");
            if targets.iter().any(|o| o.id == t.id) {
                return Err(ConfigError::invalid(
                    f("id"),
                    format!("id {} is used twice", t.id),
                ));
            }
            let shape = match t.shape.as_str() {
                "disc" => Shape::Disc,
                "square" => Shape::Square,
                other => {
                    return Err(ConfigError::invalid(
                        f("shape"),
                        format!("unknown shape `{other}` (disc, square)"),
                    ))
                }
            };
            let size_m = in_range(&f("size_m"), finite(&f("size_m"), t.size_m)?, 0.1, 100.0)?;
            let ne = |name: &str, v: [f64; 2]| -> Result<[f64; 2], ConfigError> {
                for x in v {
                    in_range(&f(name), finite(&f(name), x)?, -10_000.0, 10_000.0)?;
                }
                Ok(v)
            };
            let motion = match (t.circle, t.line) {
                (Some(c), None) => Motion::Circle {
                    center_ne_m: ne("circle.center_ne_m", c.center_ne_m)?,
                    radius_m: in_range(
                        &f("circle.radius_m"),
                        finite(&f("circle.radius_m"), c.radius_m)?,
                        0.0,
                        10_000.0,
                    )?,
                    speed_mps: in_range(
                        &f("circle.speed_mps"),
                        finite(&f("circle.speed_mps"), c.speed_mps)?,
                        0.0,
                        50.0,
                    )?,
                    phase_deg: finite(&f("circle.phase_deg"), c.phase_deg)?,
                },
                (None, Some(l)) => Motion::Line {
                    from_ne_m: ne("line.from_ne_m", l.from_ne_m)?,
                    to_ne_m: ne("line.to_ne_m", l.to_ne_m)?,
                    speed_mps: in_range(
                        &f("line.speed_mps"),
                        finite(&f("line.speed_mps"), l.speed_mps)?,
                        0.0,
                        50.0,
                    )?,
                },
                _ => {
                    return Err(ConfigError::invalid(
                        f("circle"),
                        "a target needs exactly one of `circle` or `line`",
                    ))
                }
            };
            targets.push(TargetSpec {
                id: t.id,
                shape,
                size_m,
                rgb: t.rgb,
                motion,
            });
        }
        Ok(Settings {
            vehicle_id: self.vehicle_id,
            stream: self.stream,
            source,
            width,
            height,
            fps,
            format,
            always_on: self.always_on,
            intrinsics,
            mount,
            synthetic: SyntheticSettings {
                cell_m,
                standby_height_m,
                render_threads: in_range("synthetic.render_threads", s.render_threads, 1, 16)?,
                origin,
                targets,
            },
        })
    }
}

/// Opens `path` and reads its Y4M header; the error names the file. Only a regular
/// file is opened: a FIFO or `/dev/stdin` would block the config check, and neither
/// can be read again from the start for `loop`.
pub fn read_y4m_header(path: &Path) -> Result<Y4mHeader, String> {
    let cannot_open = |e| format!("cannot open Y4M file {}: {e}", path.display());
    let meta = std::fs::metadata(path).map_err(cannot_open)?;
    if !meta.is_file() {
        return Err(format!(
            "Y4M file {} is not a regular file (a device, FIFO or directory cannot be read again from its start)",
            path.display()
        ));
    }
    let file = std::fs::File::open(path).map_err(cannot_open)?;
    Y4mReader::new(std::io::BufReader::new(file))
        .map(|r| *r.header())
        .map_err(|e| format!("Y4M file {}: {e}", path.display()))
}

/// The file's frames must be the configured size (frames are not scaled).
pub fn check_y4m_size(
    path: &Path,
    header: &Y4mHeader,
    width: u32,
    height: u32,
) -> Result<(), String> {
    if (header.width, header.height) == (width, height) {
        return Ok(());
    }
    Err(format!(
        "Y4M file {} has {}×{} frames but the config's width × height is {width}×{height} \
         (frames are not scaled: set width = {} and height = {})",
        path.display(),
        header.width,
        header.height,
        header.width,
        header.height
    ))
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod y4m_tests;
