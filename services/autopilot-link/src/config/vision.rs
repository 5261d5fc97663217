//! The `[vision]` table: gimbal protocol v2 for the vision pipeline's virtual
//! cameras.

use serde::Deserialize;
use skymesh_runtime::config::in_range;
use skymesh_runtime::ConfigError;

use crate::gimbal_v2::VisionSettings;

/// The `[vision]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawVision {
    pub enabled: bool,
    pub stream: i64,
    pub components: Vec<i64>,
    pub forward_payload: bool,
}

impl Default for RawVision {
    fn default() -> Self {
        let d = VisionSettings::default();
        RawVision {
            enabled: d.enabled,
            stream: i64::from(d.stream),
            components: d.components.iter().map(|c| i64::from(*c)).collect(),
            forward_payload: d.forward_payload,
        }
    }
}

impl RawVision {
    pub(super) fn validate(self) -> Result<VisionSettings, ConfigError> {
        let max_streams = skymesh_ipc_types::VISION_MAX_STREAMS as i64;
        let stream = in_range("vision.stream", self.stream, 0, max_streams - 1)? as u8;
        let max = skymesh_ipc_types::VISION_MAX_CAMS;
        if self.components.is_empty() || self.components.len() > max {
            return Err(ConfigError::invalid(
                "vision.components",
                format!("1 to {max} component ids (one per virtual camera)"),
            ));
        }
        let mut components: Vec<u8> = Vec::new();
        for c in &self.components {
            let c = in_range("vision.components", *c, 1, 255)? as u8;
            if c == crate::requests::OWN_COMPONENT {
                return Err(ConfigError::invalid(
                    "vision.components",
                    format!("{c} is autopilot-link's own component"),
                ));
            }
            if c == crate::telemetry::AUTOPILOT_COMPONENT {
                return Err(ConfigError::invalid(
                    "vision.components",
                    format!("{c} is the autopilot's component"),
                ));
            }
            if components.contains(&c) {
                return Err(ConfigError::invalid(
                    "vision.components",
                    format!("{c} is listed twice"),
                ));
            }
            components.push(c);
        }
        Ok(VisionSettings {
            enabled: self.enabled,
            stream,
            components,
            forward_payload: self.forward_payload,
        })
    }
}
