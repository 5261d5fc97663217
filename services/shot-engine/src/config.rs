//! Configuration: the raw TOML shape ([`RawConfig`]) and the validated [`Settings`]
//! the rest of the crate sees.
//!
//! Every key is optional; the shipped, commented defaults are
//! `deploy/shot-engine.toml` (embedded as [`ServiceConfig::DEFAULT_TOML`]).

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use skymesh_runtime::config::finite;
use skymesh_runtime::config::in_range;
use skymesh_runtime::ipc::{DEFAULT_DOMAIN, DOMAIN_ENV};
use skymesh_runtime::{ConfigError, ServiceConfig};

use crate::shots::Limits;

/// The shipped default configuration, with every option commented.
pub const DEFAULT_CONFIG_TOML: &str = include_str!("../../../deploy/shot-engine.toml");

/// Name of the state file inside the state directory.
pub const STATE_FILE_NAME: &str = "shot-engine.json";

/// The validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The `{id}` of the vehicle topics.
    pub vehicle_id: u8,
    /// One control-loop tick. App messages and buttons that change a flying shot's
    /// guidance also step it at once, between ticks (the engine's "Event steps").
    pub loop_period: Duration,
    /// `max_age_ms` of every velocity setpoint.
    pub setpoint_max_age_ms: u32,
    /// What every shot obeys.
    pub limits: Limits,
    pub selfie_cruise_speed: f32,
    pub orbit_initial_speed: f32,
    pub cable_initial_speed: f32,
    pub follow_cruise_speed: f32,
    /// Multipoint cable cam: speed along the path until SPLINE_PATH_SETTINGS gives a
    /// desired time, m/s.
    pub multipoint_cruise_speed: f32,
    /// Multipoint cable cam: keypoints closer than this (3-D) are "too close", m.
    pub keypoint_min_spacing_m: f64,
    /// Rewind: speed back along the breadcrumbs, m/s.
    pub rewind_speed_mps: f32,
    /// No follow target for this long → hover and tell the app.
    pub follow_lost: Duration,
    /// Entry is refused at or below this battery percentage; 0 = never.
    pub battery_critical_pct: u8,
    /// No `AppSession` for this long → the app counts as disconnected.
    pub app_session_timeout: Duration,
    /// The JSON state file.
    pub state_file: PathBuf,
    /// Geofence: the deceleration the predictive check assumes, m/s².
    pub geofence_deceleration_mps2: f32,
    /// Geofence: reaction time added to the stopping distance, s.
    pub geofence_latency_s: f32,
    /// Geofence: ceiling and floor of the `GeofenceSet` given to the arbiter, m above home.
    pub geofence_ceiling_m: f32,
    pub geofence_floor_m: f32,
    /// Site Scan: inspect, structure scan and survey.
    pub site_scan: SiteScanSettings,
}

/// Site Scan settings (`inspect_*`, `scan_*`, `survey_*`, `camera_*` keys).
#[derive(Debug, Clone, PartialEq)]
pub struct SiteScanSettings {
    /// Highest takeoff altitude or waypoint the app may ask for, m above home.
    pub max_alt_m: f32,
    /// Structure scan geometry (radius, levels, overlap, camera).
    pub scan: crate::shots::ScanConfig,
    /// Structure scan speed around the circle, m/s (positive counter-clockwise).
    pub scan_speed_mps: f32,
    /// The structure to scan when no shot has an ROI; `None` = where the camera looks.
    pub scan_center: Option<crate::shots::GeoPoint>,
    /// Survey geometry (altitude, overlaps, camera, lane heading).
    pub survey: crate::shots::SurveyConfig,
    /// Survey speed along the lanes, m/s.
    pub survey_speed_mps: f32,
    /// The area to survey when no keep-in geofence is set (empty = none).
    pub survey_area: Vec<crate::shots::GeoPoint>,
}

/// The configuration file as written. Unknown keys are an error (exit code 64).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawConfig {
    pub vehicle_id: i64,
    pub loop_hz: f64,
    pub setpoint_max_age_ms: i64,
    pub max_speed_mps: f64,
    pub max_accel_mps2: f64,
    pub max_climb_mps: f64,
    pub position_gain: f64,
    pub selfie_cruise_speed: f64,
    pub orbit_initial_speed: f64,
    pub cable_initial_speed: f64,
    pub follow_cruise_speed: f64,
    pub multipoint_cruise_speed: f64,
    pub keypoint_min_spacing_m: f64,
    pub rewind_speed_mps: f64,
    pub follow_lost_s: f64,
    pub battery_critical_pct: i64,
    pub app_session_timeout_s: f64,
    /// Empty → [`default_state_file`].
    pub state_file: String,
    pub geofence_deceleration_mps2: f64,
    pub geofence_latency_s: f64,
    pub geofence_ceiling_m: f64,
    pub geofence_floor_m: f64,
    pub site_scan_max_alt_m: f64,
    pub camera_hfov_deg: f64,
    pub camera_vfov_deg: f64,
    /// 0 → the vehicle's distance from the structure when the scan starts.
    pub scan_radius_m: f64,
    pub scan_altitude_step_m: f64,
    pub scan_min_altitude_m: f64,
    pub scan_overlap: f64,
    pub scan_speed_mps: f64,
    /// `[lat, lon]`, or empty.
    pub scan_center: Vec<f64>,
    pub survey_altitude_m: f64,
    pub survey_overlap: f64,
    pub survey_sidelap: f64,
    pub survey_speed_mps: f64,
    /// Absent → along the area's longest edge.
    pub survey_heading_deg: Option<f64>,
    /// `[[lat, lon], ...]`, or empty.
    pub survey_area: Vec<[f64; 2]>,
}

impl Default for RawConfig {
    fn default() -> Self {
        RawConfig {
            vehicle_id: 1,
            loop_hz: 25.0,
            setpoint_max_age_ms: 500,
            max_speed_mps: 6.0,
            max_accel_mps2: 2.0,
            max_climb_mps: 1.5,
            position_gain: 0.5,
            selfie_cruise_speed: 2.0,
            orbit_initial_speed: 0.0,
            cable_initial_speed: 0.0,
            follow_cruise_speed: 0.0,
            multipoint_cruise_speed: 3.0,
            keypoint_min_spacing_m: crate::shots::KEYPOINT_MIN_SPACING_M,
            rewind_speed_mps: 3.5,
            follow_lost_s: 3.0,
            battery_critical_pct: 10,
            app_session_timeout_s: 3.0,
            state_file: String::new(),
            geofence_deceleration_mps2: 1.5,
            geofence_latency_s: 0.5,
            geofence_ceiling_m: 10_000.0,
            geofence_floor_m: -1_000.0,
            site_scan_max_alt_m: 120.0,
            camera_hfov_deg: 122.6,
            camera_vfov_deg: 94.4,
            scan_radius_m: 0.0,
            scan_altitude_step_m: 5.0,
            scan_min_altitude_m: 5.0,
            scan_overlap: 0.7,
            scan_speed_mps: 2.0,
            scan_center: Vec::new(),
            survey_altitude_m: 30.0,
            survey_overlap: 0.75,
            survey_sidelap: 0.65,
            survey_speed_mps: 4.0,
            survey_heading_deg: None,
            survey_area: Vec::new(),
        }
    }
}

/// Where the state file lives when `state_file` is empty: under systemd's
/// `STATE_DIRECTORY` (the first entry if it lists several), else under
/// `/tmp/skymesh-<domain>/`.
pub fn default_state_file(state_directory: Option<&str>, domain: Option<&str>) -> PathBuf {
    if let Some(dir) = state_directory
        .and_then(|d| d.split(':').next())
        .filter(|d| !d.is_empty())
    {
        return Path::new(dir).join(STATE_FILE_NAME);
    }
    let domain = domain.filter(|d| !d.is_empty()).unwrap_or(DEFAULT_DOMAIN);
    PathBuf::from(format!("/tmp/skymesh-{domain}")).join(STATE_FILE_NAME)
}

fn range_f(field: &str, v: f64, min: f64, max: f64) -> Result<f64, ConfigError> {
    in_range(field, finite(field, v)?, min, max)
}

fn seconds(field: &str, v: f64, min: f64, max: f64) -> Result<Duration, ConfigError> {
    Ok(Duration::from_secs_f64(range_f(field, v, min, max)?))
}

impl RawConfig {
    /// Checks ranges and resolves the state file against the environment.
    pub fn validate_with_env(
        self,
        state_directory: Option<&str>,
        domain: Option<&str>,
    ) -> Result<Settings, ConfigError> {
        let vehicle_id = in_range("vehicle_id", self.vehicle_id, 1, 255)? as u8;
        let loop_hz = range_f("loop_hz", self.loop_hz, 1.0, 100.0)?;
        let setpoint_max_age_ms =
            in_range("setpoint_max_age_ms", self.setpoint_max_age_ms, 20, 2000)? as u32;
        let loop_period = Duration::from_secs_f64(1.0 / loop_hz);
        if Duration::from_millis(setpoint_max_age_ms.into()) <= loop_period {
            return Err(ConfigError::invalid(
                "setpoint_max_age_ms",
                format!(
                    "{setpoint_max_age_ms} ms is not longer than one loop tick ({loop_period:?}): every setpoint would expire before the next"
                ),
            ));
        }
        let max_speed = range_f("max_speed_mps", self.max_speed_mps, 0.5, 20.0)?;
        let limits = Limits {
            max_speed_mps: max_speed as f32,
            max_accel_mps2: range_f("max_accel_mps2", self.max_accel_mps2, 0.1, 10.0)? as f32,
            max_climb_mps: range_f("max_climb_mps", self.max_climb_mps, 0.1, 10.0)? as f32,
            position_gain: range_f("position_gain", self.position_gain, 0.05, 5.0)? as f32,
        };
        let speed = |field: &str, v: f64, min: f64| -> Result<f32, ConfigError> {
            Ok(range_f(field, v, min, max_speed)? as f32)
        };
        let state_file = if self.state_file.trim().is_empty() {
            default_state_file(state_directory, domain)
        } else {
            PathBuf::from(self.state_file.trim())
        };
        if state_file.file_name().is_none() {
            return Err(ConfigError::invalid(
                "state_file",
                format!("`{}` does not name a file", state_file.display()),
            ));
        }
        Ok(Settings {
            vehicle_id,
            loop_period,
            setpoint_max_age_ms,
            limits,
            selfie_cruise_speed: speed("selfie_cruise_speed", self.selfie_cruise_speed, 0.0)?,
            orbit_initial_speed: speed(
                "orbit_initial_speed",
                self.orbit_initial_speed,
                -max_speed,
            )?,
            cable_initial_speed: speed(
                "cable_initial_speed",
                self.cable_initial_speed,
                -max_speed,
            )?,
            follow_cruise_speed: speed(
                "follow_cruise_speed",
                self.follow_cruise_speed,
                -max_speed,
            )?,
            multipoint_cruise_speed: speed(
                "multipoint_cruise_speed",
                self.multipoint_cruise_speed,
                0.1,
            )?,
            keypoint_min_spacing_m: range_f(
                "keypoint_min_spacing_m",
                self.keypoint_min_spacing_m,
                0.1,
                50.0,
            )?,
            rewind_speed_mps: speed("rewind_speed_mps", self.rewind_speed_mps, 0.1)?,
            follow_lost: seconds("follow_lost_s", self.follow_lost_s, 0.5, 60.0)?,
            battery_critical_pct: in_range(
                "battery_critical_pct",
                self.battery_critical_pct,
                0,
                100,
            )? as u8,
            app_session_timeout: seconds(
                "app_session_timeout_s",
                self.app_session_timeout_s,
                1.0,
                60.0,
            )?,
            state_file,
            geofence_deceleration_mps2: range_f(
                "geofence_deceleration_mps2",
                self.geofence_deceleration_mps2,
                0.1,
                10.0,
            )? as f32,
            geofence_latency_s: range_f("geofence_latency_s", self.geofence_latency_s, 0.0, 5.0)?
                as f32,
            geofence_ceiling_m: range_f(
                "geofence_ceiling_m",
                self.geofence_ceiling_m,
                1.0,
                10_000.0,
            )? as f32,
            geofence_floor_m: range_f(
                "geofence_floor_m",
                self.geofence_floor_m,
                -1_000.0,
                self.geofence_ceiling_m - 1.0,
            )? as f32,
            site_scan: self.site_scan(max_speed)?,
        })
    }

    fn site_scan(&self, max_speed: f64) -> Result<SiteScanSettings, ConfigError> {
        let point = |field: &str, p: [f64; 2]| -> Result<crate::shots::GeoPoint, ConfigError> {
            Ok(crate::shots::GeoPoint {
                lat_deg: range_f(field, p[0], -90.0, 90.0)?,
                lon_deg: range_f(field, p[1], -180.0, 180.0)?,
                alt_rel_m: 0.0,
            })
        };
        let hfov = range_f("camera_hfov_deg", self.camera_hfov_deg, 1.0, 170.0)? as f32;
        let vfov = range_f("camera_vfov_deg", self.camera_vfov_deg, 1.0, 170.0)? as f32;
        let radius = range_f("scan_radius_m", self.scan_radius_m, 0.0, 1_000.0)?;
        if radius > 0.0 && radius < f64::from(crate::shots::sitescan::MIN_SCAN_RADIUS_M) {
            return Err(ConfigError::invalid(
                "scan_radius_m",
                format!(
                    "{radius} m: 0 (the vehicle's distance) or at least {} m",
                    crate::shots::sitescan::MIN_SCAN_RADIUS_M
                ),
            ));
        }
        let scan_center = match self.scan_center[..] {
            [] => None,
            [lat, lon] => Some(point("scan_center", [lat, lon])?),
            _ => {
                return Err(ConfigError::invalid(
                    "scan_center",
                    "expected [] or [lat, lon]".to_string(),
                ))
            }
        };
        let survey_area = self
            .survey_area
            .iter()
            .map(|p| point("survey_area", *p))
            .collect::<Result<Vec<_>, _>>()?;
        if !survey_area.is_empty() {
            crate::shots::Survey::new(
                &survey_area,
                &crate::shots::SurveyConfig {
                    altitude_m: 10.0,
                    overlap: 0.0,
                    sidelap: 0.0,
                    hfov_deg: 90.0,
                    vfov_deg: 90.0,
                    heading_deg: None,
                },
            )
            .map_err(|e| ConfigError::invalid("survey_area", e.to_string()))?;
        }
        let max_alt_m = range_f(
            "site_scan_max_alt_m",
            self.site_scan_max_alt_m,
            2.0,
            1_000.0,
        )?;
        let scan_speed = range_f("scan_speed_mps", self.scan_speed_mps, -max_speed, max_speed)?;
        if scan_speed.abs() < 0.1 {
            return Err(ConfigError::invalid(
                "scan_speed_mps",
                format!("{scan_speed} m/s: a scan needs a speed (at least 0.1 m/s either way)"),
            ));
        }
        let heading_deg = self
            .survey_heading_deg
            .map(|h| range_f("survey_heading_deg", h, -360.0, 360.0))
            .transpose()?
            .map(|h| h as f32);
        Ok(SiteScanSettings {
            max_alt_m: max_alt_m as f32,
            scan: crate::shots::ScanConfig {
                radius_m: (radius > 0.0).then_some(radius as f32),
                altitude_step_m: range_f(
                    "scan_altitude_step_m",
                    self.scan_altitude_step_m,
                    0.5,
                    100.0,
                )? as f32,
                min_altitude_m: range_f(
                    "scan_min_altitude_m",
                    self.scan_min_altitude_m,
                    1.0,
                    max_alt_m,
                )? as f32,
                overlap: range_f("scan_overlap", self.scan_overlap, 0.0, 0.95)? as f32,
                hfov_deg: hfov,
            },
            scan_speed_mps: scan_speed as f32,
            scan_center,
            survey: crate::shots::SurveyConfig {
                altitude_m: range_f("survey_altitude_m", self.survey_altitude_m, 2.0, max_alt_m)?
                    as f32,
                overlap: range_f("survey_overlap", self.survey_overlap, 0.0, 0.95)? as f32,
                sidelap: range_f("survey_sidelap", self.survey_sidelap, 0.0, 0.95)? as f32,
                hfov_deg: hfov,
                vfov_deg: vfov,
                heading_deg,
            },
            survey_speed_mps: range_f("survey_speed_mps", self.survey_speed_mps, 0.1, max_speed)?
                as f32,
            survey_area,
        })
    }
}

impl ServiceConfig for RawConfig {
    type Settings = Settings;
    const DEFAULT_TOML: &'static str = DEFAULT_CONFIG_TOML;

    fn validate(self) -> Result<Settings, ConfigError> {
        let state_directory = std::env::var("STATE_DIRECTORY").ok();
        let domain = std::env::var(DOMAIN_ENV).ok();
        self.validate_with_env(state_directory.as_deref(), domain.as_deref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Settings, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: "test".into(),
            message: e.to_string(),
        })?;
        raw.validate_with_env(None, Some("testdomain"))
    }

    #[test]
    fn shipped_defaults_parse_and_match_the_code_defaults() {
        let shipped = parse(DEFAULT_CONFIG_TOML).unwrap();
        let code = RawConfig::default()
            .validate_with_env(None, Some("testdomain"))
            .unwrap();
        assert_eq!(shipped, code);
        assert_eq!(shipped.vehicle_id, 1);
        assert_eq!(shipped.loop_period, Duration::from_millis(40));
        assert_eq!(shipped.setpoint_max_age_ms, 500);
        assert_eq!(shipped.follow_lost, Duration::from_secs(3));
        assert_eq!(
            shipped.state_file,
            PathBuf::from("/tmp/skymesh-testdomain/shot-engine.json")
        );
    }

    #[test]
    fn every_shipped_key_is_known() {
        // deny_unknown_fields: the shipped file parses, so every key in it is one of ours;
        // and a typo is refused.
        let e = parse("loop_hzz = 10").unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    }

    #[test]
    fn out_of_range_values_name_their_field() {
        for (text, field) in [
            ("vehicle_id = 0", "vehicle_id"),
            ("loop_hz = 0.5", "loop_hz"),
            ("loop_hz = nan", "loop_hz"),
            ("setpoint_max_age_ms = 10", "setpoint_max_age_ms"),
            (
                "loop_hz = 1\nsetpoint_max_age_ms = 900",
                "setpoint_max_age_ms",
            ),
            ("max_speed_mps = 50", "max_speed_mps"),
            ("selfie_cruise_speed = 7", "selfie_cruise_speed"),
            ("orbit_initial_speed = -7", "orbit_initial_speed"),
            ("follow_lost_s = 0", "follow_lost_s"),
            ("multipoint_cruise_speed = 0", "multipoint_cruise_speed"),
            ("keypoint_min_spacing_m = 0", "keypoint_min_spacing_m"),
            ("rewind_speed_mps = 7", "rewind_speed_mps"),
            ("battery_critical_pct = 101", "battery_critical_pct"),
            ("app_session_timeout_s = 0.1", "app_session_timeout_s"),
            ("state_file = \"/\"", "state_file"),
            ("geofence_latency_s = -1", "geofence_latency_s"),
            ("geofence_floor_m = 20000", "geofence_floor_m"),
            ("scan_radius_m = 2", "scan_radius_m"),
            ("scan_center = [1.0]", "scan_center"),
            ("scan_center = [95.0, 0.0]", "scan_center"),
            ("survey_area = [[0.0, 0.0], [0.0, 0.001]]", "survey_area"),
            ("survey_speed_mps = 0", "survey_speed_mps"),
            ("survey_altitude_m = 500", "survey_altitude_m"),
            ("camera_hfov_deg = 180", "camera_hfov_deg"),
            ("scan_speed_mps = 0", "scan_speed_mps"),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.to_string().contains(field), "{text}: {e}");
        }
    }

    #[test]
    fn site_scan_areas_and_centres_parse() {
        let s = parse(
            "scan_center = [-35.36, 149.16]\nscan_radius_m = 12\nsurvey_heading_deg = 45\n\
             survey_area = [[-35.36, 149.16], [-35.36, 149.17], [-35.37, 149.165]]\n\
             geofence_ceiling_m = 60\ngeofence_floor_m = -5",
        )
        .unwrap();
        let ss = &s.site_scan;
        assert_eq!(
            ss.scan_center.map(|c| (c.lat_deg, c.lon_deg)),
            Some((-35.36, 149.16))
        );
        assert_eq!(ss.scan.radius_m, Some(12.0));
        assert_eq!(ss.survey.heading_deg, Some(45.0));
        assert_eq!(ss.survey_area.len(), 3);
        assert_eq!((s.geofence_ceiling_m, s.geofence_floor_m), (60.0, -5.0));
        let d = parse("").unwrap();
        assert_eq!(
            d.site_scan.scan.radius_m, None,
            "0 = the vehicle's distance"
        );
        assert!(d.site_scan.scan_center.is_none() && d.site_scan.survey_area.is_empty());
        assert_eq!(d.site_scan.survey.heading_deg, None);
    }

    #[test]
    fn state_file_defaults_follow_systemd_then_the_domain() {
        assert_eq!(
            default_state_file(Some("/var/lib/skymesh"), Some("x")),
            PathBuf::from("/var/lib/skymesh/shot-engine.json")
        );
        assert_eq!(
            default_state_file(Some("/var/lib/a:/var/lib/b"), None),
            PathBuf::from("/var/lib/a/shot-engine.json")
        );
        assert_eq!(
            default_state_file(None, None),
            PathBuf::from("/tmp/skymesh-skymesh/shot-engine.json")
        );
        assert_eq!(
            default_state_file(Some(""), Some("")),
            PathBuf::from("/tmp/skymesh-skymesh/shot-engine.json")
        );
        let s = parse("state_file = \"/srv/x.json\"").unwrap();
        assert_eq!(s.state_file, PathBuf::from("/srv/x.json"));
    }
}
