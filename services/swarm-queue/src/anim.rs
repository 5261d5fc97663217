//! Animations: one keyframe file per drone, played by `CMD_EXT_PLAYBACK_ANIM`.
//!
//! ## File format
//!
//! `animations_dir/drone_<id>.csv` (`<id>` = GroundControl drone id, decimal), UTF-8
//! text:
//!
//! ```text
//! # comments and blank lines are ignored
//! time_s,x,y,z,yaw_deg,r,g,b
//! 0.0,1.0,0.0,2.5,90,1,0,0
//! 0.5,0.7,0.7,2.5,135,0,1,0
//! ```
//!
//! - the first non-comment line is this header, exactly these columns in this order;
//! - one row per keyframe; the frame number of `PLAYBACK_ANIM` is the row index
//!   (0 = the first row after the header), rows strictly increasing in `time_s`;
//! - `x, y, z`: site frame metres (x east, y north, z up above the site origin),
//!   within ±10 km; `yaw_deg`: counter-clockwise degrees from x (east), as
//!   GroundControl; `r, g, b`: LED colour 0..1;
//! - at most [`MAX_FRAMES`] rows and [`MAX_FILE_BYTES`] bytes.
//!
//! Between keyframes position and colour are interpolated linearly, yaw along the
//! shorter way round.
//!
//! ## Reloading
//!
//! Every file is read when the service starts (problems are logged, not fatal), and
//! again whenever a command needs it (`PLAYBACK_ANIM`, `RESET_HOME_POSITION_TO_ANIM`,
//! `RESET_ANIM_POSITION_TO_DRONE`) and its modification time or size changed: edit a
//! file and the next playback uses it, no restart. An animation that is playing
//! keeps the version it started with. A missing file is refused "no animation for
//! drone N"; a file that does not parse is refused with the line at fault.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::SystemTime;

use skymesh_ipc_types::swarm::SWARM_MAX_SITE_M;

/// Most keyframes in one file.
pub const MAX_FRAMES: usize = 200_000;
/// Largest file read.
pub const MAX_FILE_BYTES: u64 = 16 * 1024 * 1024;
/// The header line.
pub const HEADER: &str = "time_s,x,y,z,yaw_deg,r,g,b";

/// One keyframe (or an interpolated point between two).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keyframe {
    pub time_s: f64,
    /// Site frame, metres.
    pub pos: [f32; 3],
    /// CCW degrees from east.
    pub yaw_deg: f32,
    /// 0..1.
    pub rgb: [f32; 3],
}

/// A parsed animation: at least one keyframe, strictly increasing in time.
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    frames: Vec<Keyframe>,
}

/// Why a file is not an animation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnimError {
    #[error("line {line}: {message}")]
    Line { line: usize, message: String },
    #[error("no header `{HEADER}`")]
    NoHeader,
    #[error("no keyframes")]
    Empty,
    #[error("more than {MAX_FRAMES} keyframes")]
    TooLong,
}

fn shortest(from: f32, to: f32) -> f32 {
    crate::site::wrap_deg(to - from)
}

impl Animation {
    /// An animation from keyframes (checked as a file's rows are).
    pub fn new(frames: Vec<Keyframe>) -> Result<Self, AnimError> {
        if frames.is_empty() {
            return Err(AnimError::Empty);
        }
        if frames.len() > MAX_FRAMES {
            return Err(AnimError::TooLong);
        }
        for (i, f) in frames.iter().enumerate() {
            check_frame(f).map_err(|message| AnimError::Line {
                line: i + 1,
                message,
            })?;
            if i > 0 && f.time_s <= frames[i - 1].time_s {
                return Err(AnimError::Line {
                    line: i + 1,
                    message: "time_s does not increase".into(),
                });
            }
        }
        Ok(Animation { frames })
    }

    /// Parses the CSV format above.
    pub fn parse(text: &str) -> Result<Self, AnimError> {
        let mut frames = Vec::new();
        let mut header = false;
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            if !header {
                let cols: Vec<String> = line
                    .split(',')
                    .map(|c| c.trim().to_ascii_lowercase())
                    .collect();
                if cols.join(",") != HEADER {
                    return Err(AnimError::NoHeader);
                }
                header = true;
                continue;
            }
            let err = |message: String| AnimError::Line {
                line: n + 1,
                message,
            };
            let vals = line
                .split(',')
                .map(|c| c.trim().parse::<f64>())
                .collect::<Result<Vec<f64>, _>>()
                .map_err(|e| err(format!("not a number ({e})")))?;
            if vals.len() != 8 {
                return Err(err(format!("{} columns, want 8", vals.len())));
            }
            let f = Keyframe {
                time_s: vals[0],
                pos: [vals[1] as f32, vals[2] as f32, vals[3] as f32],
                yaw_deg: vals[4] as f32,
                rgb: [vals[5] as f32, vals[6] as f32, vals[7] as f32],
            };
            check_frame(&f).map_err(err)?;
            if let Some(prev) = frames.last() {
                let prev: &Keyframe = prev;
                if f.time_s <= prev.time_s {
                    return Err(err("time_s does not increase".into()));
                }
            }
            if frames.len() == MAX_FRAMES {
                return Err(AnimError::TooLong);
            }
            frames.push(f);
        }
        if !header {
            return Err(AnimError::NoHeader);
        }
        if frames.is_empty() {
            return Err(AnimError::Empty);
        }
        Ok(Animation { frames })
    }

    pub fn frames(&self) -> &[Keyframe] {
        &self.frames
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The index of the keyframe at or before `t` (0 before the first).
    pub fn frame_at(&self, t: f64) -> usize {
        self.frames
            .partition_point(|f| f.time_s <= t)
            .saturating_sub(1)
    }

    /// The interpolated keyframe at time `t` (clamped to the animation) and the index
    /// of the keyframe at or before it.
    pub fn sample(&self, t: f64) -> (Keyframe, usize) {
        let i = self.frame_at(t);
        let a = &self.frames[i];
        let Some(b) = self.frames.get(i + 1) else {
            return (*a, i);
        };
        if t <= a.time_s {
            return (*a, i);
        }
        let u = ((t - a.time_s) / (b.time_s - a.time_s)).clamp(0.0, 1.0) as f32;
        let lerp = |x: f32, y: f32| x + (y - x) * u;
        let k = Keyframe {
            time_s: t,
            pos: [
                lerp(a.pos[0], b.pos[0]),
                lerp(a.pos[1], b.pos[1]),
                lerp(a.pos[2], b.pos[2]),
            ],
            yaw_deg: crate::site::wrap_deg(a.yaw_deg + shortest(a.yaw_deg, b.yaw_deg) * u),
            rgb: [
                lerp(a.rgb[0], b.rgb[0]),
                lerp(a.rgb[1], b.rgb[1]),
                lerp(a.rgb[2], b.rgb[2]),
            ],
        };
        (k, i)
    }

    /// Speed along the path around time `t`, m/s (0 at a single keyframe).
    pub fn speed_at(&self, t: f64) -> f32 {
        let i = self.frame_at(t);
        let (a, b) = match (self.frames.get(i), self.frames.get(i + 1)) {
            (Some(a), Some(b)) => (a, b),
            _ => return 0.0,
        };
        let d: f32 = (0..3)
            .map(|k| (b.pos[k] - a.pos[k]).powi(2))
            .sum::<f32>()
            .sqrt();
        d / (b.time_s - a.time_s) as f32
    }
}

fn check_frame(f: &Keyframe) -> Result<(), String> {
    if !f.time_s.is_finite() {
        return Err("time_s is not finite".into());
    }
    for (v, name) in f.pos.iter().zip(["x", "y", "z"]) {
        if !v.is_finite() || v.abs() > SWARM_MAX_SITE_M {
            return Err(format!("{name} = {v} is not within ±{SWARM_MAX_SITE_M} m"));
        }
    }
    if !f.yaw_deg.is_finite() {
        return Err("yaw_deg is not finite".into());
    }
    for (v, name) in f.rgb.iter().zip(["r", "g", "b"]) {
        if !v.is_finite() || !(0.0..=1.0).contains(v) {
            return Err(format!("{name} = {v} is not within 0..1"));
        }
    }
    Ok(())
}

#[derive(Debug)]
enum Source {
    File {
        modified: Option<SystemTime>,
        len: u64,
    },
    /// Given in memory (tests, benchmarks): never reloaded.
    Memory,
}

#[derive(Debug)]
struct Cached {
    source: Source,
    anim: Arc<Animation>,
}

/// The animations of every drone, read from `dir` on demand.
#[derive(Debug)]
pub struct AnimLibrary {
    dir: PathBuf,
    cache: HashMap<u16, Cached>,
}

impl AnimLibrary {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        AnimLibrary {
            dir: dir.into(),
            cache: HashMap::new(),
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The file of drone `id`.
    pub fn path(&self, id: u16) -> PathBuf {
        self.dir.join(format!("drone_{id}.csv"))
    }

    /// Uses `anim` for drone `id` instead of its file.
    pub fn insert(&mut self, id: u16, anim: Animation) {
        self.cache.insert(
            id,
            Cached {
                source: Source::Memory,
                anim: Arc::new(anim),
            },
        );
    }

    /// Drone `id`'s animation, read again if the file changed. The error is the
    /// reply's reason.
    pub fn get(&mut self, id: u16) -> Result<Arc<Animation>, String> {
        if let Some(Cached {
            source: Source::Memory,
            anim,
        }) = self.cache.get(&id)
        {
            return Ok(anim.clone());
        }
        let path = self.path(id);
        let meta = match std::fs::metadata(&path) {
            Ok(m) => m,
            Err(_) => {
                self.cache.remove(&id);
                return Err(format!("no animation for drone {id}"));
            }
        };
        let (modified, len) = (meta.modified().ok(), meta.len());
        if let Some(Cached {
            source:
                Source::File {
                    modified: m,
                    len: l,
                },
            anim,
        }) = self.cache.get(&id)
        {
            if *m == modified && *l == len && modified.is_some() {
                return Ok(anim.clone());
            }
        }
        // A regular file of bounded size only: a symlink to /dev/zero passes the size
        // check above (length 0) and would be read until memory runs out.
        let bytes = skymesh_runtime::config::read_regular_file(&path, MAX_FILE_BYTES)
            .map_err(|e| format!("animation for drone {id}: {e}"))?;
        let text = String::from_utf8(bytes)
            .map_err(|_| format!("animation for drone {id}: not UTF-8 text"))?;
        let anim = Animation::parse(&text).map_err(|e| {
            tracing::warn!(path = %path.display(), error = %e, "animation file refused");
            format!("animation for drone {id}: {e}")
        })?;
        tracing::info!(path = %path.display(), frames = anim.len(), "animation loaded");
        let anim = Arc::new(anim);
        self.cache.insert(
            id,
            Cached {
                source: Source::File { modified, len },
                anim: anim.clone(),
            },
        );
        Ok(anim)
    }

    /// Reads every drone's file now (at start); returns how many loaded.
    pub fn load_all(&mut self, ids: impl IntoIterator<Item = u16>) -> usize {
        let mut n = 0;
        for id in ids {
            match self.get(id) {
                Ok(_) => n += 1,
                Err(e) if e.starts_with("no animation") => {}
                Err(e) => tracing::warn!(drone = id, error = %e, "animation not loaded"),
            }
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SQUARE: &str = "# a square\n\ntime_s, x, y, z, yaw_deg, r, g, b\n0,0,0,2,0,1,0,0\n1,2,0,2,90,0,1,0\n2,2,2,2,180,0,0,1\n";

    #[test]
    fn parses_and_interpolates() {
        let a = Animation::parse(SQUARE).unwrap();
        assert_eq!(a.len(), 3);
        let (k, i) = a.sample(0.5);
        assert_eq!(i, 0);
        assert_eq!(k.pos, [1.0, 0.0, 2.0]);
        assert_eq!(k.yaw_deg, 45.0);
        assert_eq!(k.rgb, [0.5, 0.5, 0.0]);
        let (k, i) = a.sample(1.5);
        assert_eq!(i, 1);
        assert_eq!(k.pos, [2.0, 1.0, 2.0]);
        assert_eq!(a.sample(9.0).1, 2);
        assert_eq!(a.sample(9.0).0.pos, [2.0, 2.0, 2.0]);
        assert_eq!(a.sample(-1.0).0.pos, [0.0, 0.0, 2.0]);
        assert_eq!(a.speed_at(0.2), 2.0);
    }

    #[test]
    fn yaw_goes_the_short_way_round() {
        let a =
            Animation::parse("time_s,x,y,z,yaw_deg,r,g,b\n0,0,0,0,170,0,0,0\n1,0,0,0,-170,0,0,0\n")
                .unwrap();
        assert_eq!(a.sample(0.5).0.yaw_deg, 180.0);
    }

    #[test]
    fn bad_files_say_where() {
        for (text, want) in [
            ("", "no header"),
            ("time,x,y,z\n0,0,0,0\n", "no header"),
            ("time_s,x,y,z,yaw_deg,r,g,b\n", "no keyframes"),
            (
                "time_s,x,y,z,yaw_deg,r,g,b\n0,0,0,0,0,0,0\n",
                "line 2: 7 columns",
            ),
            (
                "time_s,x,y,z,yaw_deg,r,g,b\n0,0,0,0,0,0,0,x\n",
                "line 2: not a number",
            ),
            (
                "time_s,x,y,z,yaw_deg,r,g,b\n0,0,0,0,0,0,0,2\n",
                "line 2: b = 2",
            ),
            (
                "time_s,x,y,z,yaw_deg,r,g,b\n0,0,0,NaN,0,0,0,0\n",
                "line 2: z",
            ),
            (
                "time_s,x,y,z,yaw_deg,r,g,b\n1,0,0,0,0,0,0,0\n1,0,0,0,0,0,0,0\n",
                "line 3: time_s does not increase",
            ),
        ] {
            let e = Animation::parse(text).unwrap_err().to_string();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }

    #[test]
    fn files_are_reloaded_when_they_change() {
        let dir = tempfile::tempdir().unwrap();
        let mut lib = AnimLibrary::new(dir.path());
        assert_eq!(lib.get(3).unwrap_err(), "no animation for drone 3");
        std::fs::write(lib.path(3), SQUARE).unwrap();
        assert_eq!(lib.get(3).unwrap().len(), 3);
        assert_eq!(lib.load_all([1, 2, 3]), 1);
        // A different size is a change even within the file system's time resolution.
        std::fs::write(lib.path(3), format!("{SQUARE}3,0,0,2,0,1,1,1\n")).unwrap();
        assert_eq!(lib.get(3).unwrap().len(), 4);
        std::fs::write(lib.path(3), "garbage").unwrap();
        assert!(lib.get(3).unwrap_err().contains("no header"));
        std::fs::remove_file(lib.path(3)).unwrap();
        assert!(lib.get(3).is_err());
        lib.insert(3, Animation::parse(SQUARE).unwrap());
        assert_eq!(lib.get(3).unwrap().len(), 3);
    }

    /// A symlink to /dev/zero passes the size check (length 0): refused before reading.
    #[test]
    fn a_device_behind_the_file_name_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut lib = AnimLibrary::new(dir.path());
        std::os::unix::fs::symlink("/dev/zero", lib.path(4)).unwrap();
        let e = lib.get(4).unwrap_err();
        assert!(e.contains("not a regular file"), "{e}");
    }

    #[test]
    fn the_shipped_example_parses() {
        let text = include_str!("../../../deploy/animations/drone_1.csv");
        let a = Animation::parse(text).unwrap();
        assert!(a.len() >= 10);
        let dur = a.frames().last().unwrap().time_s - a.frames()[0].time_s;
        assert!((2.0..=20.0).contains(&dur), "a few seconds: {dur}");
    }
}
