//! The `[arbiter]` table: authority, freshness, in-air and geofence envelope
//! settings.

use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::in_range;
use skymesh_runtime::ConfigError;

use super::{number, seconds};
use crate::arbiter::ArbiterSettings;

/// The `[arbiter]` table as written (see `deploy/autopilot-link.toml`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawArbiter {
    pub authority_timeout_s: f64,
    pub setpoint_max_age_ms: i64,
    pub setpoint_max_age_cap_ms: i64,
    /// Source name (`vision`, `shot_engine`, ...) → default maximum age, ms.
    pub setpoint_max_age_by_source: std::collections::BTreeMap<String, i64>,
    pub max_horizontal_speed_mps: f64,
    pub max_climb_mps: f64,
    pub max_descent_mps: f64,
    pub max_yaw_rate_dps: f64,
    pub fence_deceleration_mps2: f64,
    pub fence_margin_m: f64,
    pub fence_vertical_margin_m: f64,
    pub fence_response_s: f64,
    pub in_air_alt_m: f64,
    pub in_air_speed_mps: f64,
    /// Servo channels (1..=32) a `Servo` command may drive in the air.
    pub servo_channels_in_flight: Vec<i64>,
    pub max_home_move_m: f64,
    pub max_home_alt_change_m: f64,
}

impl Default for RawArbiter {
    fn default() -> Self {
        RawArbiter {
            authority_timeout_s: 5.0,
            setpoint_max_age_ms: 500,
            setpoint_max_age_cap_ms: 2000,
            setpoint_max_age_by_source: std::collections::BTreeMap::new(),
            max_horizontal_speed_mps: 12.0,
            max_climb_mps: 5.0,
            max_descent_mps: 3.0,
            max_yaw_rate_dps: 180.0,
            fence_deceleration_mps2: 1.5,
            fence_margin_m: 2.0,
            fence_vertical_margin_m: 1.0,
            fence_response_s: 0.3,
            in_air_alt_m: 0.5,
            in_air_speed_mps: 0.5,
            servo_channels_in_flight: Vec::new(),
            max_home_move_m: 50.0,
            max_home_alt_change_m: 1.0,
        }
    }
}
impl RawArbiter {
    pub(super) fn validate(self) -> Result<ArbiterSettings, ConfigError> {
        let ms = |field: &str, v: i64, max: i64| -> Result<Duration, ConfigError> {
            Ok(Duration::from_millis(in_range(field, v, 20, max)? as u64))
        };
        let cap_ms = in_range(
            "arbiter.setpoint_max_age_cap_ms",
            self.setpoint_max_age_cap_ms,
            20,
            10_000,
        )?;
        let mut by_source = Vec::new();
        for (name, age) in &self.setpoint_max_age_by_source {
            let field = format!("arbiter.setpoint_max_age_by_source.{name}");
            let source = skymesh_ipc_types::CommandSource::ALL
                .iter()
                .copied()
                .find(|s| s.as_str() == name)
                .ok_or_else(|| ConfigError::invalid(&field, "not a command source name"))?;
            by_source.push((source, ms(&field, *age, cap_ms)?));
        }
        Ok(ArbiterSettings {
            authority_timeout: seconds(
                "arbiter.authority_timeout_s",
                self.authority_timeout_s,
                0.5,
                300.0,
            )?,
            setpoint_max_age: ms(
                "arbiter.setpoint_max_age_ms",
                self.setpoint_max_age_ms,
                cap_ms,
            )?,
            setpoint_max_age_cap: Duration::from_millis(cap_ms as u64),
            setpoint_max_age_by_source: by_source,
            max_horizontal_speed_mps: number(
                "arbiter.max_horizontal_speed_mps",
                self.max_horizontal_speed_mps,
                0.5,
                50.0,
            )?,
            max_climb_mps: number("arbiter.max_climb_mps", self.max_climb_mps, 0.1, 50.0)?,
            max_descent_mps: number("arbiter.max_descent_mps", self.max_descent_mps, 0.1, 50.0)?,
            max_yaw_rate_dps: number(
                "arbiter.max_yaw_rate_dps",
                self.max_yaw_rate_dps,
                1.0,
                720.0,
            )?,
            fence_deceleration_mps2: number(
                "arbiter.fence_deceleration_mps2",
                self.fence_deceleration_mps2,
                0.2,
                20.0,
            )?,
            fence_margin_m: number("arbiter.fence_margin_m", self.fence_margin_m, 0.0, 100.0)?,
            fence_vertical_margin_m: number(
                "arbiter.fence_vertical_margin_m",
                self.fence_vertical_margin_m,
                0.0,
                100.0,
            )?,
            fence_response_s: number("arbiter.fence_response_s", self.fence_response_s, 0.0, 5.0)?,
            in_air_alt_m: number("arbiter.in_air_alt_m", self.in_air_alt_m, 0.1, 10.0)?,
            in_air_speed_mps: number("arbiter.in_air_speed_mps", self.in_air_speed_mps, 0.1, 10.0)?,
            servo_channels_in_flight: servo_channels(&self.servo_channels_in_flight)?,
            max_home_move_m: number(
                "arbiter.max_home_move_m",
                self.max_home_move_m,
                0.0,
                10_000.0,
            )?,
            max_home_alt_change_m: number(
                "arbiter.max_home_alt_change_m",
                self.max_home_alt_change_m,
                0.0,
                100.0,
            )?,
        })
    }
}

/// `arbiter.servo_channels_in_flight`: each a servo channel (1..=32), none twice;
/// returned sorted.
fn servo_channels(list: &[i64]) -> Result<Vec<u8>, ConfigError> {
    const FIELD: &str = "arbiter.servo_channels_in_flight";
    let range = skymesh_ipc_types::command::limits::SERVO_CHANNELS;
    let mut out = Vec::with_capacity(list.len());
    for &channel in list {
        let channel = in_range(
            FIELD,
            channel,
            i64::from(*range.start()),
            i64::from(*range.end()),
        )? as u8;
        if out.contains(&channel) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("channel {channel} is listed twice"),
            ));
        }
        out.push(channel);
    }
    out.sort_unstable();
    Ok(out)
}
