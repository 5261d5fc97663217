//! The console's JSON documents (pure: built from the mesh's and the vehicles'
//! state at a given time). Shapes are documented in docs/console.md.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use skymesh_ipc_types::{
    AckResult, ArbiterEventKind, AuthorityChange, CommandKind, CommandSource, RefusalReason,
    NO_HOLDER,
};

use crate::console::feed::{ground_speed, VehicleLog};
use crate::procfs::ProcUsage;
use crate::state::ServiceEntry;
use crate::vehicles::{Latest, STATUS_STALE};

/// CPU use between two reads shorter apart than this is not recomputed (a second
/// browser tab polling does not make the figure jumpy).
const CPU_MIN_SPAN: Duration = Duration::from_millis(500);

/// Turns each service's CPU time into a percentage of one core between reads.
#[derive(Debug, Default)]
pub struct CpuMeter {
    /// Per service: pid, when read, CPU seconds then, the last percentage.
    last: HashMap<String, (u32, Instant, f64, Option<f64>)>,
}

impl CpuMeter {
    /// The CPU use of `name` (process `pid`, `cpu_seconds` used so far) since the
    /// previous read of the same process, in percent of one core; `None` on the
    /// first read of a process.
    pub fn percent(&mut self, name: &str, pid: u32, cpu_seconds: f64, now: Instant) -> Option<f64> {
        match self.last.get_mut(name) {
            Some((p, at, cpu, pct)) if *p == pid => {
                let span = now.saturating_duration_since(*at);
                if span >= CPU_MIN_SPAN {
                    let used = (cpu_seconds - *cpu).max(0.0);
                    *pct = Some(used / span.as_secs_f64() * 100.0);
                    *at = now;
                    *cpu = cpu_seconds;
                }
                *pct
            }
            _ => {
                self.last
                    .insert(name.to_string(), (pid, now, cpu_seconds, None));
                None
            }
        }
    }
}

fn round(v: f64, places: i32) -> f64 {
    let f = 10f64.powi(places);
    (v * f).round() / f
}

fn secs(ns: u64) -> f64 {
    Duration::from_nanos(ns).as_secs_f64()
}

/// One row of the service table.
pub fn service_row(
    e: &ServiceEntry,
    usage: Option<ProcUsage>,
    cpu_percent: Option<f64>,
    now_ns: u64,
) -> Value {
    let s = e.to_status(now_ns);
    json!({
        "name": s.name,
        "state": s.state,
        "pid": s.pid,
        "restarts": s.restarts,
        "uptime_s": s.uptime_s,
        "heartbeat_age_s": s.heartbeat_age_s,
        "last_exit_code": s.last_exit_code,
        "critical": s.critical,
        "adopted": s.adopted,
        "cpu_seconds": usage.map(|u| round(u.cpu_seconds, 2)),
        "cpu_percent": cpu_percent.map(|p| round(p, 1)),
        "memory_bytes": usage.map(|u| u.resident_bytes),
    })
}

fn source_name(wire: u8) -> Value {
    if wire == NO_HOLDER {
        return Value::Null;
    }
    CommandSource::try_from(wire)
        .map(|s| Value::from(s.as_str()))
        .unwrap_or_else(|_| Value::from(format!("source {wire}")))
}

/// One vehicle's card: its newest state, status and authority, the arbiter's last
/// decisions and events (newest first), and the plot's history (seconds before now).
pub fn vehicle(id: u8, l: &Latest, log: &VehicleLog, now_ns: u64) -> Value {
    let age = |stamp: u64| round(secs(now_ns.saturating_sub(stamp)), 3);
    let fresh = l
        .status
        .filter(|s| now_ns.saturating_sub(s.header.stamp_ns) <= STATUS_STALE.as_nanos() as u64);
    let link_up = fresh.is_some_and(|s| s.link_up != 0);
    let pos = l.state.filter(|s| s.position_valid != 0);
    let status = l.status.as_ref();
    let authority = l.authority.map(|a| {
        let sources: Vec<&str> = CommandSource::ALL
            .iter()
            .filter(|s| a.emergency_by(**s))
            .map(|s| s.as_str())
            .collect();
        json!({
            "flight": source_name(a.flight_holder),
            "payload": source_name(a.payload_holder),
            "flight_change": AuthorityChange::try_from(a.flight_change).map(|c| c.as_str()).unwrap_or("unknown"),
            "emergency": a.emergency != 0,
            "emergency_sources": sources,
        })
    });
    let decisions: Vec<Value> = log
        .acks
        .iter()
        .rev()
        .map(|a| {
            json!({
                "age_s": age(a.header.stamp_ns),
                "source": source_name(a.source),
                "kind": CommandKind::try_from(a.kind).map(|k| k.as_str().to_string()).unwrap_or_else(|_| format!("kind {}", a.kind)),
                "command_id": a.command_id,
                "result": AckResult::try_from(a.result).map(|r| r.as_str()).unwrap_or("unknown"),
                "reason": RefusalReason::try_from(a.reason).map(|r| r.as_str()).unwrap_or("unknown"),
                "detail": a.detail.as_str(),
            })
        })
        .collect();
    let events: Vec<Value> = log
        .events
        .iter()
        .rev()
        .map(|e| {
            json!({
                "age_s": age(e.header.stamp_ns),
                "kind": ArbiterEventKind::try_from(e.kind).map(|k| k.as_str().to_string()).unwrap_or_else(|_| format!("kind {}", e.kind)),
                "source": source_name(e.source),
                "detail": e.detail.as_str(),
            })
        })
        .collect();
    let history: Vec<[f64; 3]> = log
        .history
        .iter()
        .map(|p| {
            [
                -round(secs(now_ns.saturating_sub(p.stamp_ns)), 2),
                round(f64::from(p.alt_rel_m), 2),
                round(f64::from(p.ground_speed_mps), 2),
            ]
        })
        .collect();
    json!({
        "id": id,
        "link_up": link_up,
        "telemetry_age_s": l.state.map(|s| age(s.header.stamp_ns)),
        "status_age_s": l.status.map(|s| age(s.header.stamp_ns)),
        "mode": status.map_or("unknown", |s| s.flight_mode().as_str()),
        "armed": link_up && status.is_some_and(|s| s.armed != 0),
        "lat_deg": pos.map(|s| s.lat_deg),
        "lon_deg": pos.map(|s| s.lon_deg),
        "alt_rel_m": pos.map(|s| round(f64::from(s.alt_rel_m), 2)),
        "alt_msl_m": pos.map(|s| round(f64::from(s.alt_msl_m), 2)),
        "ground_speed_mps": pos.map(|s| round(f64::from(ground_speed(&s)), 2)),
        "climb_mps": pos.map(|s| round(-f64::from(s.vel_ned_mps[2]), 2)),
        "heading_deg": pos.map(|s| round(f64::from(s.heading_deg), 1)),
        "battery_pct": status.and_then(|s| (0..=100).contains(&s.battery_remaining_pct).then_some(s.battery_remaining_pct)),
        "battery_v": status.map(|s| round(f64::from(s.battery_voltage_v), 2)),
        "ekf_healthy": status.map(|s| s.ekf_healthy != 0),
        "ekf_flags": status.map(|s| s.ekf_flags),
        "gps_fix": status.map(|s| s.gps_fix_type().as_str()),
        "satellites": status.map(|s| s.satellites),
        "status_text": status.map(|s| s.status_text.as_str()).filter(|t| !t.is_empty()),
        "authority": authority,
        "decisions": decisions,
        "events": events,
        "history": history,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::{
        ArbiterEvent, AuthorityState, CommandAck, FixedStr, FlightMode, SampleHeader, VehicleState,
        VehicleStatus,
    };

    const NOW: u64 = 50_000_000_000;

    fn at(age_ms: u64) -> SampleHeader {
        SampleHeader {
            stamp_ns: NOW - age_ms * 1_000_000,
            ..SampleHeader::default()
        }
    }

    #[test]
    fn a_vehicle_card_has_every_field() {
        let l = Latest {
            state: Some(VehicleState {
                header: at(10),
                position_valid: 1,
                alt_rel_m: 7.25,
                vel_ned_mps: [3.0, 4.0, -1.0],
                lat_deg: -35.0,
                ..VehicleState::default()
            }),
            status: Some(VehicleStatus {
                header: at(200),
                mode: FlightMode::Guided.to_wire(),
                armed: 1,
                link_up: 1,
                ekf_healthy: 1,
                battery_remaining_pct: 80,
                ..VehicleStatus::default()
            }),
            authority: Some(AuthorityState {
                flight_holder: CommandSource::Safety.to_wire(),
                emergency: 1,
                emergency_sources: 1 << CommandSource::Operator.to_wire(),
                flight_change: AuthorityChange::Emergency.to_wire(),
                ..AuthorityState::default()
            }),
        };
        let mut log = VehicleLog::default();
        log.record(l.state.as_ref().unwrap());
        log.ack(CommandAck {
            header: at(100),
            source: CommandSource::Operator.to_wire(),
            kind: CommandKind::EmergencyStop.to_wire(),
            result: AckResult::Accepted.to_wire(),
            command_id: 9,
            detail: FixedStr::new("braking"),
            ..CommandAck::default()
        });
        log.event(ArbiterEvent {
            header: at(90),
            kind: ArbiterEventKind::EmergencyStop.to_wire(),
            source: CommandSource::Operator.to_wire(),
            ..ArbiterEvent::default()
        });
        let v = vehicle(1, &l, &log, NOW);
        assert_eq!(v["link_up"], true);
        assert_eq!(v["armed"], true);
        assert_eq!(v["mode"], "guided");
        assert_eq!(v["alt_rel_m"], 7.25);
        assert_eq!(v["ground_speed_mps"], 5.0);
        assert_eq!(v["climb_mps"], 1.0);
        assert_eq!(v["battery_pct"], 80);
        assert_eq!(v["ekf_healthy"], true);
        assert_eq!(v["authority"]["flight"], "safety");
        assert_eq!(v["authority"]["payload"], Value::Null);
        assert_eq!(v["authority"]["emergency"], true);
        assert_eq!(v["authority"]["emergency_sources"][0], "operator");
        assert_eq!(v["decisions"][0]["kind"], "emergency_stop");
        assert_eq!(v["decisions"][0]["result"], "accepted");
        assert_eq!(v["decisions"][0]["detail"], "braking");
        assert_eq!(v["events"][0]["kind"], "emergency_stop");
        assert_eq!(v["events"][0]["age_s"], 0.09);
        assert_eq!(v["history"][0][1], 7.25);
    }

    #[test]
    fn before_any_sample_everything_is_unknown() {
        let v = vehicle(3, &Latest::default(), &VehicleLog::default(), NOW);
        assert_eq!(v["id"], 3);
        assert_eq!(v["link_up"], false);
        assert_eq!(v["mode"], "unknown");
        assert_eq!(v["alt_rel_m"], Value::Null);
        assert_eq!(v["authority"], Value::Null);
        assert_eq!(v["history"].as_array().unwrap().len(), 0);
    }

    #[test]
    fn cpu_percent_needs_two_reads_of_the_same_process() {
        let mut m = CpuMeter::default();
        let t0 = Instant::now();
        assert_eq!(m.percent("a", 1, 10.0, t0), None);
        let p = m
            .percent("a", 1, 10.5, t0 + Duration::from_secs(1))
            .unwrap();
        assert!((p - 50.0).abs() < 1e-9, "{p}");
        // Too soon after: the last figure.
        assert_eq!(
            m.percent("a", 1, 11.0, t0 + Duration::from_millis(1100)),
            Some(p)
        );
        // A new process starts over.
        assert_eq!(m.percent("a", 2, 0.1, t0 + Duration::from_secs(3)), None);
    }
}
