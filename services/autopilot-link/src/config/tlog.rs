//! The `[tlog]` table: flight logs ([`crate::tlog`]). No table, no logs.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::in_range;
use skymesh_runtime::ipc::{DEFAULT_DOMAIN, DOMAIN_ENV};
use skymesh_runtime::ConfigError;

use crate::tlog::{Limits, TlogMode, TlogSettings};

const MB: u64 = 1_000_000;

/// The `[tlog]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawTlog {
    /// Empty → [`default_dir`].
    pub dir: String,
    /// `"arming"` or `"connection"`.
    pub mode: String,
    pub max_files: i64,
    pub max_total_mb: i64,
    pub max_file_mb: i64,
    pub min_free_mb: i64,
    pub queue_frames: i64,
    pub flush_s: f64,
}

impl Default for RawTlog {
    fn default() -> Self {
        RawTlog {
            dir: String::new(),
            mode: "arming".into(),
            max_files: 100,
            max_total_mb: 2000,
            max_file_mb: 500,
            min_free_mb: 500,
            queue_frames: 4096,
            flush_s: 1.0,
        }
    }
}

/// Where logs go when `dir` is empty: systemd's `LOGS_DIRECTORY` (its first entry,
/// `LogsDirectory=` in the unit) + `/tlog`, else `/tmp/skymesh-<domain>/tlog`.
pub fn default_dir(logs_directory: Option<&str>, domain: Option<&str>) -> PathBuf {
    if let Some(dir) = logs_directory
        .and_then(|d| d.split(':').next())
        .filter(|d| !d.is_empty())
    {
        return Path::new(dir).join("tlog");
    }
    let domain = domain.filter(|d| !d.is_empty()).unwrap_or(DEFAULT_DOMAIN);
    PathBuf::from(format!("/tmp/skymesh-{domain}/tlog"))
}

impl RawTlog {
    pub(super) fn validate(self, vehicle_id: u8) -> Result<TlogSettings, ConfigError> {
        let dir = if self.dir.trim().is_empty() {
            let logs = std::env::var("LOGS_DIRECTORY").ok();
            let domain = std::env::var(DOMAIN_ENV).ok();
            default_dir(logs.as_deref(), domain.as_deref())
        } else {
            let dir = PathBuf::from(self.dir.trim());
            if !dir.is_absolute() {
                return Err(ConfigError::invalid(
                    "tlog.dir",
                    format!("`{}` is not an absolute path", dir.display()),
                ));
            }
            dir
        };
        // Created when the first log opens; something else in its place is an error now.
        if dir.exists() && !dir.is_dir() {
            return Err(ConfigError::invalid(
                "tlog.dir",
                format!("`{}` exists and is not a directory", dir.display()),
            ));
        }
        let mode = match self.mode.as_str() {
            "arming" => TlogMode::Arming,
            "connection" => TlogMode::Connection,
            other => {
                return Err(ConfigError::invalid(
                    "tlog.mode",
                    format!("`{other}`: must be \"arming\" or \"connection\""),
                ))
            }
        };
        let max_files = in_range("tlog.max_files", self.max_files, 1, 100_000)? as u32;
        let max_total_mb = in_range("tlog.max_total_mb", self.max_total_mb, 1, 10_000_000)?;
        let max_file_mb = in_range("tlog.max_file_mb", self.max_file_mb, 1, max_total_mb)?;
        let min_free_mb = in_range("tlog.min_free_mb", self.min_free_mb, 0, 10_000_000)?;
        let queue_frames = in_range("tlog.queue_frames", self.queue_frames, 64, 65_536)? as usize;
        if !self.flush_s.is_finite() {
            return Err(ConfigError::invalid(
                "tlog.flush_s",
                "must be a finite number",
            ));
        }
        let flush_s = in_range("tlog.flush_s", self.flush_s, 0.05, 60.0)?;
        Ok(TlogSettings {
            dir,
            mode,
            vehicle_id,
            limits: Limits {
                max_files,
                max_total: max_total_mb as u64 * MB,
                min_free: min_free_mb as u64 * MB,
            },
            max_file_bytes: max_file_mb as u64 * MB,
            queue_frames,
            flush_interval: Duration::from_secs_f64(flush_s),
        })
    }
}
