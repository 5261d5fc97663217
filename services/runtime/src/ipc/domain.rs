//! One mesh's iceoryx2 configuration (the domain), its live and dead nodes, and the
//! files it leaves in `/dev/shm` and under the iceoryx2 root.

use std::path::{Path, PathBuf};

use iceoryx2::config::Config;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

use super::Svc;
use crate::config::ConfigError;

/// Environment variable naming the mesh's domain (iceoryx2 resource prefix).
pub const DOMAIN_ENV: &str = "SKYMESH_DOMAIN";
/// Environment variable naming the iceoryx2 config file.
pub const IPC_CONFIG_ENV: &str = "SKYMESH_IPC_CONFIG";
/// The domain when `SKYMESH_DOMAIN` is unset.
pub const DEFAULT_DOMAIN: &str = "skymesh";
/// `deploy/iceoryx2.toml`, used when no file is named.
pub const EMBEDDED_IPC_CONFIG: &str = include_str!("../../../../deploy/iceoryx2.toml");

/// One mesh's iceoryx2 configuration: the loaded config file with the domain prefix applied.
#[derive(Debug, Clone)]
pub struct Domain {
    pub name: String,
    pub config: Config,
    /// Where the config came from (file path or `<embedded>`), for logs.
    pub origin: String,
}

/// True if `name` can be a domain (it prefixes file names in `/dev/shm`).
pub fn is_valid_domain(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 24
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

impl Domain {
    /// Loads the iceoryx2 config (`path`, else `$SKYMESH_IPC_CONFIG`, else the embedded
    /// `deploy/iceoryx2.toml`) and applies the domain from `$SKYMESH_DOMAIN`.
    pub fn from_env(path: Option<&Path>) -> Result<Domain, ConfigError> {
        let name = match std::env::var(DOMAIN_ENV) {
            Ok(v) if !v.is_empty() => v,
            _ => DEFAULT_DOMAIN.to_string(),
        };
        let path: Option<PathBuf> = path
            .map(Path::to_path_buf)
            .or_else(|| std::env::var_os(IPC_CONFIG_ENV).map(PathBuf::from));
        Domain::load(&name, path.as_deref())
    }

    /// Loads the config for domain `name` from `path` (or the embedded default).
    pub fn load(name: &str, path: Option<&Path>) -> Result<Domain, ConfigError> {
        if !is_valid_domain(name) {
            return Err(ConfigError::Env {
                name: DOMAIN_ENV,
                message: format!("`{name}` must be 1-24 characters of [A-Za-z0-9_-]"),
            });
        }
        let (text, origin) = match path {
            Some(p) => (
                std::fs::read_to_string(p).map_err(|source| ConfigError::Read {
                    path: p.to_path_buf(),
                    source,
                })?,
                p.display().to_string(),
            ),
            None => (
                EMBEDDED_IPC_CONFIG.to_string(),
                "<embedded deploy/iceoryx2.toml>".to_string(),
            ),
        };
        let mut config: Config = toml::from_str(&text).map_err(|e| ConfigError::Ipc {
            origin: origin.clone(),
            message: e.to_string(),
        })?;
        config.global.prefix =
            FileName::new(format!("{name}_").as_bytes()).map_err(|e| ConfigError::Ipc {
                origin: origin.clone(),
                message: format!("domain prefix: {e:?}"),
            })?;
        Ok(Domain {
            name: name.to_string(),
            config,
            origin,
        })
    }

    /// The prefix of every iceoryx2 file of this domain.
    pub fn prefix(&self) -> String {
        format!("{}_", self.name)
    }

    /// Removes the stale resources of every dead node of this domain. Returns the
    /// names of the nodes cleaned and how many could not be.
    ///
    /// A dead node is only recognisable once its process has been reaped, so the
    /// supervisor calls this after `waitpid`.
    pub fn cleanup_dead_nodes(&self) -> (Vec<String>, usize) {
        cleanup_dead::<Svc>(&self.config)
    }

    /// Names and pids of the live nodes of this domain.
    pub fn live_nodes(&self) -> Vec<(String, i32)> {
        let mut out = Vec::new();
        let _ = Node::<Svc>::list(&self.config, |state| {
            if let NodeState::Alive(view) = state {
                if let Some(d) = view.details() {
                    out.push((d.name().as_str().to_string(), d.process_id().value()));
                }
            }
            CallbackProgression::Continue
        });
        out
    }

    /// Files this domain left in `/dev/shm` and under the iceoryx2 root path.
    pub fn leftover_files(&self) -> Vec<PathBuf> {
        let prefix = self.prefix();
        let root = PathBuf::from(self.config.global.root_path().to_string());
        let mut dirs = vec![PathBuf::from("/dev/shm")];
        for sub in ["", "services", "nodes"] {
            dirs.push(root.join(sub));
        }
        let mut out = Vec::new();
        let mut stack: Vec<PathBuf> = dirs;
        while let Some(dir) = stack.pop() {
            let Ok(rd) = std::fs::read_dir(&dir) else {
                continue;
            };
            for entry in rd.flatten() {
                let name = entry.file_name();
                let name = name.to_string_lossy();
                if name.starts_with(prefix.as_str()) {
                    out.push(entry.path());
                }
            }
        }
        out.sort();
        out.dedup();
        out
    }

    /// Removes [`Domain::leftover_files`]. Only call when no node of the domain is alive.
    pub fn remove_leftover_files(&self) -> usize {
        let mut removed = 0;
        for path in self.leftover_files() {
            let res = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            match res {
                Ok(()) => removed += 1,
                Err(e) => {
                    tracing::warn!(path = %path.display(), error = %e, "cannot remove leftover file")
                }
            }
        }
        removed
    }
}

/// A domain whose shared-memory files are removed when this is dropped, however a
/// test or a benchmark ends (declare it before the buses of the domain: locals drop
/// in reverse order, so the nodes are gone first).
#[derive(Debug)]
pub struct DomainGuard(pub Domain);

impl std::ops::Deref for DomainGuard {
    type Target = Domain;
    fn deref(&self) -> &Domain {
        &self.0
    }
}

impl Drop for DomainGuard {
    fn drop(&mut self) {
        self.remove_leftover_files();
    }
}

/// Removes the stale resources of every dead node of service kind `S` under
/// `config`; the names cleaned and how many could not be.
fn cleanup_dead<S: iceoryx2::service::Service>(config: &Config) -> (Vec<String>, usize) {
    let mut cleaned = Vec::new();
    let mut failed = 0;
    let result = Node::<S>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            let name = view
                .details()
                .as_ref()
                .map(|d| d.name().as_str().to_string())
                .unwrap_or_default();
            match view.try_remove_stale_resources() {
                Ok(()) => cleaned.push(name),
                Err(e) => {
                    tracing::warn!(node = %name, error = ?e, "stale node cleanup failed");
                    failed += 1;
                }
            }
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!(error = ?e, "listing iceoryx2 nodes failed");
    }
    (cleaned, failed)
}
