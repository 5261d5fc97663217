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
            let text = std::fs::read_to_string(p).map_err(|source| ConfigError::Read {
                path: p.to_path_buf(),
                source,
            })?;
            parse::<C>(&text, &p.display().to_string())
        }
    }
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
}
