//! The `[signing]` table: the key file and the endpoints that require signing.

use serde::Deserialize;
use skymesh_runtime::ConfigError;

use super::Endpoint;
use crate::signing::{load_key, SigningSettings};

/// The `[signing]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawSigning {
    /// A file holding the 32-byte secret key as 64 hex digits.
    pub key_file: Option<String>,
    /// Entries of `endpoints` (as written there) that require signing.
    pub endpoints: Vec<String>,
}

impl RawSigning {
    /// `endpoints` are the validated router endpoints the entries must name.
    pub(super) fn validate(
        self,
        endpoints: &[Endpoint],
    ) -> Result<Option<SigningSettings>, ConfigError> {
        const FIELD: &str = "signing.endpoints";
        let Some(path) = self.key_file else {
            if self.endpoints.is_empty() {
                return Ok(None);
            }
            return Err(ConfigError::invalid(
                "signing.key_file",
                "signing.endpoints are listed but no key_file is given",
            ));
        };
        if path.trim().is_empty() {
            return Err(ConfigError::invalid("signing.key_file", "is empty"));
        }
        if self.endpoints.is_empty() {
            return Err(ConfigError::invalid(
                FIELD,
                "a key_file is given but no endpoint requires signing; list them here",
            ));
        }
        let mut indices = Vec::new();
        for s in &self.endpoints {
            let e = Endpoint::parse(FIELD, s)?;
            let i = endpoints.iter().position(|x| *x == e).ok_or_else(|| {
                ConfigError::invalid(FIELD, format!("`{s}` is not one of `endpoints`"))
            })?;
            if indices.contains(&i) {
                return Err(ConfigError::invalid(
                    FIELD,
                    format!("`{s}` is listed twice"),
                ));
            }
            indices.push(i);
        }
        indices.sort_unstable();
        // The key's bytes never appear in an error.
        let key = load_key(std::path::Path::new(&path))
            .map_err(|e| ConfigError::invalid("signing.key_file", e.to_string()))?;
        Ok(Some(SigningSettings {
            key,
            endpoints: indices,
        }))
    }
}
