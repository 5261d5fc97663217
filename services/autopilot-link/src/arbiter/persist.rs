//! What of the arbiter survives a restart of autopilot-link: the emergency stops in
//! force (who engaged them, with the command id) and every source's geofence, in a
//! small JSON file (`state_file` in the config).
//!
//! - Written after every change (a stop engaged, released or cleared; a fence set
//!   or cleared), atomically: a temporary file in the same directory, flushed to
//!   disk, then renamed over the old one, so a crash mid-write leaves the old or the
//!   new file, never half of one.
//! - Read once at start, before the first command is decided ([`start`]): the stops
//!   are in force again (safety holds flight authority) and the fences are enforced.
//!   Authority holders are not restored: after a restart nobody holds authority and
//!   sources grab it again.
//! - `clean_exit` is written `false` at start and `true` when the service stops
//!   cleanly, so the log says whether the last run ended in a crash. A stop is
//!   restored either way: only its engagers or a `ClearEmergency` lift it.
//! - A file that cannot be parsed (or names an unknown source, a bad polygon, another
//!   format version) is moved aside to `<file>.corrupt` and the service starts
//!   LATCHED, with an emergency stop engaged by safety and no fences: it cannot tell
//!   whether a stop was in force, and a stop that is not needed costs an operator's
//!   `ClearEmergency`, while a forgotten one lets a still-streaming source fly on. A
//!   file that cannot be read at all is left alone and also starts latched. A
//!   missing file is a first start: nothing is restored.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use skymesh_ipc_types::arbiter::MAX_FENCE_POLYGONS;
use skymesh_ipc_types::{ArbiterEventKind, CommandSource, FenceKind, GeofenceSet, NO_HOLDER};
use skymesh_runtime::state_file;

use super::authority::Engagement;
use super::{Arbiter, ArbiterSettings, Effect};

/// Format version written to the file.
pub const FORMAT_VERSION: u32 = 1;

/// One emergency stop in force.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EngagementRecord {
    /// A [`CommandSource`] name (`dji_drc`, `operator`, ...).
    pub source: String,
    pub command_id: u32,
}

/// One polygon of a fence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolygonRecord {
    /// `keep_in` or `keep_out`.
    pub kind: String,
    /// Latitude, longitude in degrees.
    pub vertices: Vec<[f64; 2]>,
}

/// One source's fence, as its `GeofenceSet` carried it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FenceRecord {
    pub source: String,
    pub ceiling_m: f32,
    pub floor_m: f32,
    pub polygons: Vec<PolygonRecord>,
}

/// The file's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Persisted {
    pub version: u32,
    /// `false` while the service runs; `true` once it stopped cleanly.
    pub clean_exit: bool,
    pub emergency: Vec<EngagementRecord>,
    pub fences: Vec<FenceRecord>,
}

impl Default for Persisted {
    fn default() -> Self {
        Persisted {
            version: FORMAT_VERSION,
            clean_exit: false,
            emergency: Vec::new(),
            fences: Vec::new(),
        }
    }
}

fn source_named(name: &str) -> Result<CommandSource, String> {
    CommandSource::ALL
        .iter()
        .copied()
        .find(|s| s.as_str() == name)
        .ok_or_else(|| format!("unknown source `{name}`"))
}

impl Persisted {
    /// The arbiter's persistent state now (`clean_exit` false).
    pub fn of(engaged: &[Engagement], fences: &[GeofenceSet]) -> Self {
        Persisted {
            version: FORMAT_VERSION,
            clean_exit: false,
            emergency: engaged
                .iter()
                .map(|e| EngagementRecord {
                    source: e.source.as_str().to_string(),
                    command_id: e.command_id,
                })
                .collect(),
            fences: fences
                .iter()
                .map(|set| FenceRecord {
                    source: CommandSource::try_from(set.source)
                        .map_or("unknown", CommandSource::as_str)
                        .to_string(),
                    ceiling_m: set.ceiling_m,
                    floor_m: set.floor_m,
                    polygons: set.polygons
                        [..usize::from(set.polygon_count).min(MAX_FENCE_POLYGONS)]
                        .iter()
                        .map(|p| PolygonRecord {
                            kind: FenceKind::try_from(p.kind)
                                .map_or("unknown", FenceKind::as_str)
                                .to_string(),
                            vertices: p.vertices
                                [..usize::from(p.vertex_count).min(p.vertices.len())]
                                .to_vec(),
                        })
                        .collect(),
                })
                .collect(),
        }
    }

    /// The stops and fence samples (for `vehicle_id`) the file holds, every number
    /// checked as a `GeofenceSet` from the bus would be.
    pub fn restore(&self, vehicle_id: u8) -> Result<(Vec<Engagement>, Vec<GeofenceSet>), String> {
        if self.version != FORMAT_VERSION {
            return Err(format!(
                "format version {} (this build reads {FORMAT_VERSION})",
                self.version
            ));
        }
        let mut engaged: Vec<Engagement> = Vec::new();
        for e in &self.emergency {
            let source = source_named(&e.source)?;
            if engaged.iter().any(|x| x.source == source) {
                return Err(format!("stop of {source} listed twice"));
            }
            engaged.push(Engagement {
                source,
                command_id: e.command_id,
            });
        }
        let mut sets: Vec<GeofenceSet> = Vec::new();
        for f in &self.fences {
            let source = source_named(&f.source)?;
            if sets.iter().any(|s| s.source == source.to_wire()) {
                return Err(format!("fence of {source} listed twice"));
            }
            let mut set = GeofenceSet {
                vehicle_id,
                enabled: 1,
                source: source.to_wire(),
                ceiling_m: f.ceiling_m,
                floor_m: f.floor_m,
                target_source: NO_HOLDER,
                ..GeofenceSet::default()
            };
            for p in &f.polygons {
                let kind = FenceKind::ALL
                    .iter()
                    .copied()
                    .find(|k| k.as_str() == p.kind)
                    .ok_or_else(|| {
                        format!("fence of {source}: unknown polygon kind `{}`", p.kind)
                    })?;
                if !set.push_polygon(kind, &p.vertices) {
                    return Err(format!(
                        "fence of {source}: more than {MAX_FENCE_POLYGONS} polygons or a polygon of {} vertices",
                        p.vertices.len()
                    ));
                }
            }
            set.polygons()
                .map_err(|e| format!("fence of {source}: {e}"))?;
            sets.push(set);
        }
        Ok((engaged, sets))
    }
}

/// Why the state file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PersistError {
    #[error("{op} {path}: {source}")]
    Io {
        op: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("encoding the state: {0}")]
    Encode(#[from] serde_json::Error),
}

/// What [`Store::open`] found.
#[derive(Debug, Clone, PartialEq)]
pub enum Loaded {
    /// No file yet.
    Fresh,
    /// Read and parsed.
    Existing(Persisted),
    /// Could not be parsed or checked; moved to `kept` (when the move worked).
    Corrupt {
        error: String,
        kept: Option<PathBuf>,
    },
    /// Could not be read (permissions, I/O); left alone.
    Unreadable { error: String },
}

/// The state file and what was last written to it.
#[derive(Debug)]
pub struct Store {
    path: PathBuf,
    written: Option<Persisted>,
}

impl Store {
    /// Reads `path` (checked for `vehicle_id`); never fails (see [`Loaded`]).
    pub fn open(path: impl Into<PathBuf>, vehicle_id: u8) -> (Store, Loaded) {
        let path = path.into();
        let (state, loaded) = state_file::load(&path, |text| {
            let p = serde_json::from_str::<Persisted>(text).map_err(|e| e.to_string())?;
            p.restore(vehicle_id).map(|_| p)
        });
        let loaded = match (state, loaded) {
            (Some(p), _) => Loaded::Existing(p),
            (None, state_file::Loaded::Corrupt { error, kept }) => Loaded::Corrupt { error, kept },
            (None, state_file::Loaded::Unreadable { error }) => Loaded::Unreadable { error },
            (None, _) => Loaded::Fresh,
        };
        (
            Store {
                path,
                written: None,
            },
            loaded,
        )
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes `state` unless it is what was last written.
    pub fn save(&mut self, state: &Persisted) -> Result<(), PersistError> {
        if self.written.as_ref() == Some(state) {
            return Ok(());
        }
        self.write(state)?;
        self.written = Some(state.clone());
        Ok(())
    }

    fn write(&self, state: &Persisted) -> Result<(), PersistError> {
        let io = |op: &'static str, path: &Path| {
            let path = path.to_path_buf();
            move |source| PersistError::Io { op, path, source }
        };
        let mut text = serde_json::to_string_pretty(state)?;
        text.push('\n');
        let dir = self.path.parent().filter(|d| !d.as_os_str().is_empty());
        if let Some(dir) = dir {
            std::fs::create_dir_all(dir).map_err(io("creating directory", dir))?;
        }
        state_file::write_atomic(&self.path, text.as_bytes()).map_err(io("writing", &self.path))?;
        Ok(())
    }
}

/// Builds the arbiter and restores it from `store`'s file: the effects (authority
/// changes, events) are for the service to publish once its ports are open. Also
/// says in the log what was found.
pub fn start(
    settings: ArbiterSettings,
    loaded: Loaded,
    path: &Path,
    vehicle_id: u8,
    now_ns: u64,
) -> (Arbiter, Vec<Effect>) {
    let mut arbiter = Arbiter::new(settings);
    let path = path.display().to_string();
    let latch = |why: String| {
        (
            vec![Engagement {
                source: CommandSource::Safety,
                command_id: 0,
            }],
            Vec::new(),
            why,
        )
    };
    let (engaged, sets, why) = match loaded {
        Loaded::Fresh => {
            tracing::info!(state_file = %path, "no arbiter state file yet: no stop, no fence");
            (Vec::new(), Vec::new(), String::new())
        }
        Loaded::Existing(p) => {
            let (engaged, sets) = p.restore(vehicle_id).unwrap_or_default();
            tracing::info!(
                state_file = %path,
                clean_exit = p.clean_exit,
                stops = engaged.len(),
                fences = sets.len(),
                "arbiter state restored"
            );
            if !p.clean_exit {
                tracing::warn!(state_file = %path, "the last run did not end cleanly");
            }
            (engaged, sets, "restored after a restart".to_string())
        }
        Loaded::Corrupt { error, kept } => {
            tracing::error!(state_file = %path, error, kept = ?kept, "arbiter state file is corrupt: starting LATCHED (emergency stop by safety), no fences; an operator clear_emergency lifts it");
            latch("state file corrupt: latched".to_string())
        }
        Loaded::Unreadable { error } => {
            tracing::error!(state_file = %path, error, "cannot read the arbiter state file: starting LATCHED (emergency stop by safety), no fences");
            latch("state file unreadable: latched".to_string())
        }
    };
    let mut effects = Vec::new();
    for set in &sets {
        effects.extend(arbiter.set_geofence(set, vehicle_id));
    }
    if !engaged.is_empty() {
        effects.extend(
            arbiter
                .authority
                .restore_emergency(&engaged, now_ns)
                .map(Effect::Authority),
        );
        let by: Vec<CommandSource> = engaged.iter().map(|e| e.source).collect();
        effects.push(Effect::Event {
            kind: ArbiterEventKind::EmergencyStop,
            source: Some(by[0]),
            detail: format!("{why}; engaged by {}", super::emergency::names(&by)),
        });
    }
    (arbiter, effects)
}

impl Arbiter {
    /// What the state file should hold now.
    pub fn persisted(&self) -> Persisted {
        Persisted::of(&self.authority.engagements(), &self.fence_sets())
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{fence_set, flying, sample, settings, S};
    use super::*;
    use skymesh_ipc_types::{AuthorityChange, Command, RefusalReason};
    use CommandSource::*;

    /// An arbiter with two stops (dji_drc, operator), two fences and a holder.
    fn busy() -> Arbiter {
        let mut a = Arbiter::new(settings());
        let v = flying(0.0, 0.0, [0.0; 3]);
        a.decide(S, &sample(ShotEngine, Command::GrabPayloadAuthority, S), &v);
        let mut stop = sample(DjiDrc, Command::EmergencyStop, S);
        stop.command_id = 77;
        a.decide(S, &stop, &v);
        a.decide(S, &sample(Operator, Command::EmergencyStop, S), &v);
        a.set_geofence(&fence_set(Operator, 50.0, None), 1);
        a.set_geofence(
            &fence_set(ShotEngine, 80.0, Some([(5.0, 5.0), (15.0, 15.0)])),
            1,
        );
        a
    }

    #[test]
    fn stops_and_fences_round_trip_and_holders_are_not_restored() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nested/link.json");
        let a = busy();
        let (mut store, loaded) = Store::open(&path, 1);
        assert_eq!(loaded, Loaded::Fresh);
        store.save(&a.persisted()).unwrap();
        let files: Vec<_> = std::fs::read_dir(dir.path().join("nested"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(files, ["link.json"], "the temporary file is renamed");
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.contains("\"dji_drc\"") && text.contains("\"keep_out\""),
            "{text}"
        );

        let (_, loaded) = Store::open(&path, 1);
        let Loaded::Existing(p) = &loaded else {
            panic!("{loaded:?}");
        };
        assert_eq!(p, &a.persisted());
        assert!(!p.clean_exit);
        let (b, effects) = start(settings(), loaded, &path, 1, 10 * S);
        assert_eq!(b.authority().engagements(), a.authority().engagements());
        assert_eq!(b.authority().engagements()[0].command_id, 77);
        assert_eq!(b.fence_sets(), a.fence_sets());
        let st = b.authority().state(1);
        assert_eq!((st.flight(), st.emergency), (Some(Safety), 1));
        assert_eq!(st.payload(), None, "holders are not restored");
        assert!(effects.contains(&Effect::Event {
            kind: ArbiterEventKind::EmergencyStop,
            source: Some(DjiDrc),
            detail: "restored after a restart; engaged by dji_drc, operator".into(),
        }));
        assert!(effects.iter().any(|e| matches!(
            e,
            Effect::Authority(c) if c.change == AuthorityChange::Emergency
        )));
    }

    #[test]
    fn a_restored_stop_refuses_a_streaming_source_until_its_engagers_release() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("link.json");
        let (mut store, _) = Store::open(&path, 1);
        store.save(&busy().persisted()).unwrap();
        let (_, loaded) = Store::open(&path, 1);
        let (mut b, _) = start(settings(), loaded, &path, 1, 10 * S);
        let v = flying(0.0, 0.0, [0.0; 3]);
        let stream = Command::VelocityNed {
            vel_ned_mps: [2.0, 0.0, 0.0],
            yaw_rate_dps: None,
        };
        let d = b.decide(11 * S, &sample(DjiDrc, stream, 11 * S), &v);
        assert_eq!(d.reason(), RefusalReason::Emergency);
        b.decide(
            12 * S,
            &sample(DjiDrc, Command::ReleaseEmergency, 12 * S),
            &v,
        );
        let d = b.decide(12 * S, &sample(DjiDrc, stream, 12 * S), &v);
        assert_eq!(
            d.reason(),
            RefusalReason::Emergency,
            "operator's stop remains"
        );
        b.decide(
            13 * S,
            &sample(Operator, Command::ReleaseEmergency, 13 * S),
            &v,
        );
        // The fence came back too: 2 m/s north from inside is allowed, a GoTo 60 m
        // north (outside the operator's 50 m keep-in) is not.
        let d = b.decide(13 * S, &sample(DjiDrc, stream, 13 * S), &v);
        assert_ne!(d.reason(), RefusalReason::Emergency);
        let far = flying(60.0, 0.0, [0.0; 3]).position.unwrap();
        let goto = Command::GoTo {
            lat_deg: far.lat_deg,
            lon_deg: far.lon_deg,
            alt_rel_m: 10.0,
            yaw_deg: None,
            speed_mps: None,
        };
        let d = b.decide(14 * S, &sample(DjiDrc, goto, 14 * S), &v);
        assert_eq!(d.reason(), RefusalReason::Geofence);
        assert_eq!(b.persisted().emergency, Vec::new());
    }

    #[test]
    fn a_corrupt_or_unreadable_file_starts_latched_without_fences() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("link.json");
        let good = serde_json::to_string(&busy().persisted()).unwrap();
        for garbage in [
            "{not json".to_string(),
            good.replace("\"operator\"", "\"pilot\""),
            good.replace("\"version\":1", "\"version\":9"),
            good.replace("\"keep_out\"", "\"keep_sideways\""),
            good.replace("\"ceiling_m\":30.0", "\"ceiling_m\":-30.0"),
        ] {
            assert_ne!(garbage, good);
            std::fs::write(&path, &garbage).unwrap();
            let (_, loaded) = Store::open(&path, 1);
            let Loaded::Corrupt {
                kept: Some(kept), ..
            } = &loaded
            else {
                panic!("{garbage}: {loaded:?}");
            };
            assert_eq!(std::fs::read_to_string(kept).unwrap(), garbage);
            assert!(!path.exists());
            let (a, effects) = start(settings(), loaded, &path, 1, S);
            assert_eq!(
                a.authority().engagements(),
                [Engagement {
                    source: Safety,
                    command_id: 0
                }]
            );
            assert!(a.fence_sets().is_empty());
            assert!(effects.iter().any(|e| matches!(
                e,
                Effect::Event { kind: ArbiterEventKind::EmergencyStop, detail, .. }
                    if detail == "state file corrupt: latched; engaged by safety"
            )));
        }
        // A directory where the file should be cannot be read: latched too.
        std::fs::create_dir(&path).unwrap();
        let (_, loaded) = Store::open(&path, 1);
        assert!(matches!(loaded, Loaded::Unreadable { .. }), "{loaded:?}");
        let (a, _) = start(settings(), loaded, &path, 1, S);
        assert!(a.authority().in_emergency());
        // An operator clears it.
        let mut a = a;
        let v = flying(0.0, 0.0, [0.0; 3]);
        a.decide(2 * S, &sample(Operator, Command::ClearEmergency, 2 * S), &v);
        assert!(!a.authority().in_emergency());
    }

    #[test]
    fn only_changes_are_written_and_clean_exit_is_recorded() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("link.json");
        let (mut store, _) = Store::open(&path, 1);
        let a = busy();
        store.save(&a.persisted()).unwrap();
        std::fs::remove_file(&path).unwrap();
        store.save(&a.persisted()).unwrap();
        assert!(!path.exists(), "unchanged: not written again");
        let mut clean = a.persisted();
        clean.clean_exit = true;
        store.save(&clean).unwrap();
        let (_, loaded) = Store::open(&path, 1);
        assert!(matches!(loaded, Loaded::Existing(p) if p.clean_exit));
        // A state for another vehicle id: its fences do not match vehicle 2's
        // samples, but the file is still valid (vehicle ids are not stored).
        let (_, loaded) = Store::open(&path, 2);
        assert!(matches!(loaded, Loaded::Existing(_)));
    }
}
