//! One verdict on the whole mesh, shared by `skymesh status` (its exit code) and the
//! supervisor's `GET /healthz` (200 or 503), so both always agree.
//!
//! - [`Health::Ok`] (exit 0, HTTP 200): every service is `running`.
//! - [`Health::Degraded`] (exit 1, HTTP 503): some service is not `running` — degraded,
//!   starting, restarting (backoff), stopping, or a non-critical one stopped/failed.
//! - [`Health::Critical`] (exit 2, HTTP 503): a critical service is down and nothing
//!   brings it back by itself (stopped, failed, config-error; in `--monitor-only`: down
//!   or stale), or the supervisor does not answer (`skymesh status` only).

use serde::Serialize;

use crate::state::{Phase, StatusEntry};

/// The mesh's health, ordered from good to bad.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Health {
    Ok,
    Degraded,
    Critical,
}

impl Health {
    /// The exit code of `skymesh status`.
    pub fn exit_code(self) -> u8 {
        match self {
            Health::Ok => 0,
            Health::Degraded => 1,
            Health::Critical => 2,
        }
    }

    /// The HTTP status of `/healthz`.
    pub fn http_status(self) -> u16 {
        match self {
            Health::Ok => 200,
            _ => 503,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Health::Ok => "ok",
            Health::Degraded => "degraded",
            Health::Critical => "critical",
        }
    }
}

/// The phase named by a `/status` state string; `None` for one this build does not know.
pub fn parse_phase(state: &str) -> Option<Phase> {
    Phase::ALL.into_iter().find(|p| p.as_str() == state)
}

/// The health of one service entry.
pub fn of_entry(e: &StatusEntry) -> Health {
    match parse_phase(&e.state) {
        Some(Phase::Running) => Health::Ok,
        Some(Phase::Stopped | Phase::Failed | Phase::ConfigError | Phase::Down | Phase::Stale)
        | None
            if e.critical =>
        {
            Health::Critical
        }
        _ => Health::Degraded,
    }
}

/// The health of the mesh: the worst of its services (`Ok` for a mesh without any).
pub fn of(rows: &[StatusEntry]) -> Health {
    rows.iter().map(of_entry).max().unwrap_or(Health::Ok)
}

/// A service that is not `running`, as listed in the `/healthz` body.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NotRunning {
    pub name: String,
    pub state: String,
    pub critical: bool,
}

/// The `/healthz` JSON body.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub health: Health,
    /// What `skymesh status` exits with for the same state.
    pub exit_code: u8,
    pub services: usize,
    pub running: usize,
    pub not_running: Vec<NotRunning>,
}

/// The `/healthz` report for `rows`.
pub fn report(rows: &[StatusEntry]) -> Report {
    let health = of(rows);
    let not_running: Vec<NotRunning> = rows
        .iter()
        .filter(|r| of_entry(r) != Health::Ok)
        .map(|r| NotRunning {
            name: r.name.clone(),
            state: r.state.clone(),
            critical: r.critical,
        })
        .collect();
    Report {
        health,
        exit_code: health.exit_code(),
        services: rows.len(),
        running: rows.len() - not_running.len(),
        not_running,
    }
}

/// One line for the end of `skymesh status`: `health: ok (3/3 running)` or
/// `health: critical (2/3 running; not running: gc* failed)`.
pub fn summary(rows: &[StatusEntry]) -> String {
    let r = report(rows);
    let mut s = format!(
        "health: {} ({}/{} running",
        r.health.as_str(),
        r.running,
        r.services
    );
    if !r.not_running.is_empty() {
        let list: Vec<String> = r
            .not_running
            .iter()
            .map(|n| {
                format!(
                    "{}{} {}",
                    n.name,
                    if n.critical { "*" } else { "" },
                    n.state
                )
            })
            .collect();
        s.push_str("; not running: ");
        s.push_str(&list.join(", "));
    }
    s.push(')');
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, state: &str, critical: bool) -> StatusEntry {
        StatusEntry {
            name: name.into(),
            pid: None,
            state: state.into(),
            restarts: 0,
            uptime_s: 0.0,
            heartbeat_age_s: None,
            last_exit_code: None,
            critical,
            adopted: false,
        }
    }

    #[test]
    fn every_phase_string_parses_back() {
        for p in Phase::ALL {
            assert_eq!(parse_phase(p.as_str()), Some(p));
        }
        assert_eq!(parse_phase("exploded"), None);
    }

    #[test]
    fn all_running_is_ok_and_exit_0() {
        let rows = [row("a", "running", true), row("b", "running", false)];
        assert_eq!(of(&rows), Health::Ok);
        assert_eq!(of(&rows).exit_code(), 0);
        assert_eq!(of(&rows).http_status(), 200);
        assert_eq!(of(&[]), Health::Ok);
    }

    #[test]
    fn degraded_or_restarting_is_exit_1() {
        // Whatever the criticality: the service is (coming) back by itself.
        for state in ["degraded", "starting", "backoff", "stopping"] {
            for critical in [false, true] {
                let rows = [row("a", "running", true), row("b", state, critical)];
                assert_eq!(of(&rows), Health::Degraded, "{state} critical={critical}");
                assert_eq!(of(&rows).exit_code(), 1);
                assert_eq!(of(&rows).http_status(), 503);
            }
        }
        // A non-critical service that is gone degrades the mesh, no more.
        for state in [
            "stopped",
            "failed",
            "config-error",
            "down",
            "stale",
            "new-state",
        ] {
            let rows = [row("a", "running", true), row("b", state, false)];
            assert_eq!(of(&rows), Health::Degraded, "{state}");
        }
    }

    #[test]
    fn a_critical_service_down_is_exit_2() {
        for state in [
            "stopped",
            "failed",
            "config-error",
            "down",
            "stale",
            "new-state",
        ] {
            let rows = [
                row("a", "backoff", false),
                row("b", state, true),
                row("c", "running", true),
            ];
            assert_eq!(of(&rows), Health::Critical, "{state}");
            assert_eq!(of(&rows).exit_code(), 2);
            assert_eq!(of(&rows).http_status(), 503);
        }
    }

    #[test]
    fn report_lists_what_is_not_running() {
        let rows = [
            row("a", "running", true),
            row("b", "backoff", false),
            row("gc", "failed", true),
        ];
        let r = report(&rows);
        assert_eq!(r.health, Health::Critical);
        assert_eq!((r.services, r.running, r.exit_code), (3, 1, 2));
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["health"], "critical");
        assert_eq!(v["not_running"][1]["name"], "gc");
        assert_eq!(
            summary(&rows),
            "health: critical (1/3 running; not running: b backoff, gc* failed)"
        );
        assert_eq!(summary(&rows[..1]), "health: ok (1/1 running)");
    }
}
