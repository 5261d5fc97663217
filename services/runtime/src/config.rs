//! Config goes raw → validated: a serde struct with `deny_unknown_fields` is turned
//! into a `Settings` type; the rest of a service sees only `Settings`.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A service's raw TOML configuration.
pub trait ServiceConfig: DeserializeOwned {
    /// The validated form the service runs with.
    type Settings: Send + 'static;
    /// The commented default config (`deploy/<service>.toml`), used when no `--config`
    /// is given and printed by `--print-default-config`.
    const DEFAULT_TOML: &'static str;
    /// Checks ranges and parses addresses, durations and enums.
    fn validate(self) -> Result<Self::Settings, ConfigError>;
}

/// Why a configuration was refused. Every variant means exit code 64.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read config file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("config file {0}")]
    File(FileReadError),
    #[error("config {origin} is not valid TOML for this service: {message}")]
    Parse { origin: String, message: String },
    #[error("config field `{field}`: {message}")]
    Invalid { field: String, message: String },
    #[error("environment variable {name}: {message}")]
    Env { name: &'static str, message: String },
    #[error("iceoryx2 config {origin}: {message}")]
    Ipc { origin: String, message: String },
}

impl ConfigError {
    /// Shorthand for a field that failed validation.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        ConfigError::Invalid {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// Parses TOML text into the raw config and validates it.
pub fn parse<C: ServiceConfig>(text: &str, origin: &str) -> Result<C::Settings, ConfigError> {
    let raw: C = toml::from_str(text).map_err(|e| ConfigError::Parse {
        origin: origin.to_string(),
        message: e.to_string(),
    })?;
    raw.validate()
}

/// Loads `path` (or the embedded default when `None`) and validates it.
pub fn load<C: ServiceConfig>(path: Option<&Path>) -> Result<C::Settings, ConfigError> {
    match path {
        None => parse::<C>(C::DEFAULT_TOML, "<embedded default>"),
        Some(p) => {
            let text = read_config_text(p)?;
            parse::<C>(&text, &p.display().to_string())
        }
    }
}

/// The largest config file `load` reads (the shipped ones are a few KiB).
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Why [`read_regular_file`] refused a path.
#[derive(Debug, thiserror::Error)]
pub enum FileReadError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{0}: not a regular file (a device, FIFO or directory is refused without being \
         opened: /dev/zero would fill memory, /dev/stdin or a FIFO would block)"
    )]
    NotAFile(PathBuf),
    #[error("{path}: larger than {max} bytes")]
    TooLarge { path: PathBuf, max: u64 },
}

/// Reads a file named by configuration (a config, key, certificate, CA bundle,
/// animation): only a regular file (symlinks followed), and at most `max` bytes of
/// it, checked before and while reading (it may grow meanwhile).
pub fn read_regular_file(path: &Path, max: u64) -> Result<Vec<u8>, FileReadError> {
    use std::io::Read as _;
    let io = |source| FileReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(FileReadError::NotAFile(path.to_path_buf()));
    }
    let too_large = || FileReadError::TooLarge {
        path: path.to_path_buf(),
        max,
    };
    if meta.len() > max {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(max.saturating_add(1)).read_to_end(&mut bytes))
        .map_err(io)?;
    if bytes.len() as u64 > max {
        return Err(too_large());
    }
    Ok(bytes)
}

/// Reads a config file named on the command line: a regular file of at most
/// [`MAX_CONFIG_BYTES`], UTF-8.
pub fn read_config_text(path: &Path) -> Result<String, ConfigError> {
    let bytes = read_regular_file(path, MAX_CONFIG_BYTES).map_err(|e| match e {
        FileReadError::Io { path, source } => ConfigError::Read { path, source },
        other => ConfigError::File(other),
    })?;
    String::from_utf8(bytes).map_err(|_| ConfigError::Parse {
        origin: path.display().to_string(),
        message: "not UTF-8 text".into(),
    })
}

/// Parses `host:port` into a socket address, naming the field on error.
pub fn socket_addr(field: &str, value: &str) -> Result<std::net::SocketAddr, ConfigError> {
    value.parse().map_err(|e| {
        ConfigError::invalid(field, format!("`{value}` is not an ip:port address ({e})"))
    })
}

/// Refuses NaN and infinities, naming the field on error.
pub fn finite(field: &str, v: f64) -> Result<f64, ConfigError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ConfigError::invalid(
            field,
            format!("{v} is not a finite number"),
        ))
    }
}

/// Checks `min <= value <= max`, naming the field on error.
pub fn in_range<T: PartialOrd + std::fmt::Display + Copy>(
    field: &str,
    value: T,
    min: T,
    max: T,
) -> Result<T, ConfigError> {
    if value < min || value > max {
        return Err(ConfigError::invalid(
            field,
            format!("{value} is outside {min}..={max}"),
        ));
    }
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Raw {
        #[serde(default = "default_rate")]
        rate_hz: u32,
    }
    fn default_rate() -> u32 {
        10
    }
    impl ServiceConfig for Raw {
        type Settings = u32;
        const DEFAULT_TOML: &'static str = "# defaults\nrate_hz = 10\n";
        fn validate(self) -> Result<u32, ConfigError> {
            in_range("rate_hz", self.rate_hz, 1, 100)
        }
    }

    #[test]
    fn default_parses_and_errors_name_the_problem() {
        assert_eq!(load::<Raw>(None).unwrap(), 10);
        let e = parse::<Raw>("rate_hz = 1000", "t").unwrap_err();
        assert!(e.to_string().contains("rate_hz"), "{e}");
        let e = parse::<Raw>("bogus = 1", "t").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
        let e = load::<Raw>(Some(Path::new("/nonexistent/x.toml"))).unwrap_err();
        assert!(matches!(e, ConfigError::Read { .. }));
    }

    #[test]
    fn only_regular_files_of_bounded_size_are_read() {
        // Devices and directories are refused without being opened (reading /dev/zero
        // would never end, /dev/stdin could block).
        for p in ["/dev/zero", "/dev/null", "/dev/stdin", "/"] {
            let e = read_regular_file(Path::new(p), 1024).unwrap_err();
            assert!(matches!(e, FileReadError::NotAFile(_)), "{p}: {e}");
            let e = load::<Raw>(Some(Path::new(p))).unwrap_err();
            assert!(matches!(e, ConfigError::File(_)), "{p}: {e}");
            assert!(e.to_string().contains("not a regular file"), "{e}");
        }
        let dir = std::env::temp_dir().join(format!("skymesh-rrf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("c.toml");
        std::fs::write(&f, "rate_hz = 20\n").unwrap();
        assert_eq!(read_regular_file(&f, 13).unwrap().len(), 13);
        let e = read_regular_file(&f, 12).unwrap_err();
        assert!(matches!(e, FileReadError::TooLarge { max: 12, .. }), "{e}");
        assert_eq!(load::<Raw>(Some(&f)).unwrap(), 20);
        std::fs::write(&f, [0xff, 0xfe]).unwrap();
        assert!(matches!(
            load::<Raw>(Some(&f)).unwrap_err(),
            ConfigError::Parse { .. }
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
