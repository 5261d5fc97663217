//! SYSTEM_STATUS temperature: read from a Linux thermal zone (a file holding
//! millidegrees Celsius). Nothing is ever invented: without a readable zone the state
//! says `temperature_valid = 0`.

use std::path::{Path, PathBuf};

/// Where the temperature comes from (config `thermal_zone`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ThermalSource {
    /// The first readable `/sys/class/thermal/thermal_zone*/temp`, found at start.
    Auto,
    /// This file.
    Path(PathBuf),
    /// No temperature.
    None,
}

impl ThermalSource {
    /// `"auto"`, `"none"` or an absolute path.
    pub fn parse(text: &str) -> Result<ThermalSource, String> {
        match text {
            "auto" => Ok(ThermalSource::Auto),
            "none" => Ok(ThermalSource::None),
            p if Path::new(p).is_absolute() => Ok(ThermalSource::Path(PathBuf::from(p))),
            other => Err(format!(
                "`{other}` is not \"auto\", \"none\" or an absolute path"
            )),
        }
    }

    /// The file to read, resolving `Auto` under `root` (normally `/sys/class/thermal`).
    pub fn resolve(&self, root: &Path) -> Option<PathBuf> {
        match self {
            ThermalSource::None => None,
            ThermalSource::Path(p) => Some(p.clone()),
            ThermalSource::Auto => first_readable_zone(root),
        }
    }
}

/// The first `thermal_zone*/temp` under `root` (in zone number order) that reads as a
/// temperature.
pub fn first_readable_zone(root: &Path) -> Option<PathBuf> {
    let mut zones: Vec<(u32, PathBuf)> = std::fs::read_dir(root)
        .ok()?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name();
            let n = name.to_str()?.strip_prefix("thermal_zone")?.parse().ok()?;
            Some((n, e.path().join("temp")))
        })
        .collect();
    zones.sort();
    zones
        .into_iter()
        .map(|(_, p)| p)
        .find(|p| read_celsius(p).is_some())
}

/// Millidegrees text (`"45123\n"`) → degrees Celsius; `None` if not a plausible
/// temperature (−273..=500 °C).
pub fn parse_millidegrees(text: &str) -> Option<f32> {
    let milli: i64 = text.trim().parse().ok()?;
    let c = milli as f64 / 1000.0;
    (-273.0..=500.0).contains(&c).then_some(c as f32)
}

/// Reads one temperature file.
pub fn read_celsius(path: &Path) -> Option<f32> {
    parse_millidegrees(&std::fs::read_to_string(path).ok()?)
}

/// The pipeline's thermometer: a resolved file (or none).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Thermometer {
    path: Option<PathBuf>,
}

impl Thermometer {
    pub fn new(source: &ThermalSource) -> Thermometer {
        Thermometer {
            path: source.resolve(Path::new("/sys/class/thermal")),
        }
    }

    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// Degrees Celsius now, if readable.
    pub fn read(&self) -> Option<f32> {
        read_celsius(self.path.as_deref()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn millidegrees_parse_and_nonsense_is_refused() {
        assert_eq!(parse_millidegrees("45123\n"), Some(45.123));
        assert_eq!(parse_millidegrees("-5000"), Some(-5.0));
        assert_eq!(parse_millidegrees(""), None);
        assert_eq!(parse_millidegrees("hot"), None);
        assert_eq!(parse_millidegrees("999999999"), None);
    }

    #[test]
    fn sources_parse() {
        assert_eq!(ThermalSource::parse("auto"), Ok(ThermalSource::Auto));
        assert_eq!(ThermalSource::parse("none"), Ok(ThermalSource::None));
        assert_eq!(
            ThermalSource::parse("/x/temp"),
            Ok(ThermalSource::Path("/x/temp".into()))
        );
        assert!(ThermalSource::parse("zone0").is_err());
        assert_eq!(ThermalSource::None.resolve(Path::new("/")), None);
    }

    #[test]
    fn auto_takes_the_first_readable_zone_in_number_order() {
        let root = tempfile::tempdir().unwrap();
        for (zone, text) in [
            ("thermal_zone10", "70000"),
            ("thermal_zone2", "x"),
            ("thermal_zone3", "51000"),
        ] {
            std::fs::create_dir(root.path().join(zone)).unwrap();
            std::fs::write(root.path().join(zone).join("temp"), text).unwrap();
        }
        std::fs::create_dir(root.path().join("cooling_device0")).unwrap();
        let p = ThermalSource::Auto.resolve(root.path()).unwrap();
        assert_eq!(p, root.path().join("thermal_zone3").join("temp"));
        assert_eq!(read_celsius(&p), Some(51.0));
        let empty = tempfile::tempdir().unwrap();
        assert_eq!(ThermalSource::Auto.resolve(empty.path()), None);
        let t = Thermometer { path: None };
        assert_eq!(t.read(), None);
    }
}
